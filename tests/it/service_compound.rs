//! Compound bodies through the service: upload, store, scenes and every query RPC,
//! checked against an independent reference — brute force over all leaf pairs with the
//! single-body `distance` query in-process (the minimum over leaf pairs is the model distance) —
//! and single-body scenes answered exactly as before.

use crate::util::{add, assert_status, at, config, demo_bodies, pose, upload_body, Server};
use std::path::Path;
use sublevel::compound::CompoundBody;
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::query::{distance, NewtonParams};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

/// Tolerance of the service's answers against the brute-force reference (meters).
const TOL: f64 = 1e-6;

fn compound(name: &str) -> (CompoundBody, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/compound").join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (CompoundBody::from_json(&text).unwrap(), text)
}

async fn upload_json(c: &mut SublevelClient<Channel>, name: &str, json: String) -> pb::UploadBodyResponse {
    let req = pb::UploadBodyRequest { name: name.into(), body: Some(pb::upload_body_request::Body::BodyJson(json)) };
    c.upload_body(req).await.unwrap().into_inner()
}

fn iso(q: [f64; 4], t: [f64; 3]) -> Isometry3 {
    pose_from_parts("pose", q, t).unwrap()
}

/// The reference: min over every leaf pair of the single-body distance (converged Newton answers),
/// with the minimizing leaf pair.
fn brute_force(a: &CompoundBody, pa: &Isometry3, b: &CompoundBody, pb: &Isometry3) -> (f64, (usize, usize)) {
    let params = NewtonParams::default();
    let mut best = (f64::INFINITY, (0, 0));
    for i in a.leaves() {
        for j in b.leaves() {
            let r = distance(a.body(i), pa, b.body(j), pb, None, &params);
            assert!(r.status.converged(), "leaf pair ({i}, {j}) did not converge");
            if r.distance < best.0 {
                best = (r.distance, (i, j));
            }
        }
    }
    best
}

/// Chair poses against the human at the origin: far, near, rotated near, overlapping.
const QZ: [f64; 4] = [0.9238795325112867, 0.0, 0.0, 0.3826834323650898];
const CHAIR_POSES: [([f64; 4], [f64; 3]); 4] = [
    ([1.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0]),
    ([1.0, 0.0, 0.0, 0.0], [1.1, 0.1, 0.0]),
    (QZ, [0.9, -0.2, 0.05]),
    ([1.0, 0.0, 0.0, 0.0], [0.1, 0.0, 0.0]),
];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn compound_chair_and_human_answer_the_brute_force_model_distance_on_every_rpc() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (chair, chair_json) = compound("chair_101.json");
    let (human, human_json) = compound("human_10.json");
    let up = upload_json(&mut c, "chair", chair_json).await;
    assert_eq!((up.nodes as usize, up.nonconvex), (chair.node_count(), false));
    // The smallest sos-convexity margin over the nodes: certified, i.e. ≥ −tolerance × the Hessian
    // scale (fit::sos_convexity); a fitted node can sit on the boundary within the solver tolerance.
    // The Hessian's coefficients are at most (2d)² × the largest coefficient of p.
    let hessian_scale = chair
        .nodes()
        .iter()
        .map(|n| {
            let d = n.body.degree() as f64;
            d * d * n.body.polynomial().coefficients().iter().fold(0.0, |m: f64, c| m.max(c.abs()))
        })
        .fold(0.0, f64::max);
    let floor = -sublevel::fit::sos_convexity::SOS_CONVEXITY_TOLERANCE * hessian_scale;
    assert!(up.convexity_margin.is_finite() && up.convexity_margin >= floor, "{} < {floor}", up.convexity_margin);
    let chair_id = up.body_id;
    let human_id = upload_json(&mut c, "human", human_json).await.body_id;
    let listed = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    let nodes: Vec<u32> = listed.iter().map(|b| b.nodes).collect();
    assert!(nodes.contains(&(chair.node_count() as u32)) && nodes.contains(&(human.node_count() as u32)));

    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let h = add(&mut c, &scene, &human_id, at([0.0; 3])).await;
    let ch = add(&mut c, &scene, &chair_id, at([0.0; 3])).await;
    let ph = iso([1.0, 0.0, 0.0, 0.0], [0.0; 3]);
    for (q, t) in CHAIR_POSES {
        crate::util::set_pose(&mut c, &scene, &ch, pose(q, t)).await;
        let pc = iso(q, t);
        let (want, leaves) = brute_force(&chair, &pc, &human, &ph);

        // Distance, both orders (tree node ids follow the order).
        let req = |a: &str, b: &str| pb::DistanceRequest {
            scene_id: scene.clone(),
            instance_a: a.into(),
            instance_b: b.into(),
            with_gradient: true,
            ..Default::default()
        };
        let d = c.distance(req(&ch, &h)).await.unwrap().into_inner().answer.unwrap();
        let tree = d.tree.expect("a compound answer carries its tree bounds");
        assert!((d.distance - want).abs() <= TOL, "pose {t:?}: {} vs brute force {want}", d.distance);
        assert!(tree.lower <= tree.upper + 1e-12 && (tree.upper - want).abs() <= TOL, "{tree:?}");
        assert!(d.solve.as_ref().unwrap().converged && tree.within_tolerance);
        assert_eq!(d.overlapping, want <= 0.0);
        assert!(tree.pairs_evaluated >= 1 && tree.level >= 1, "{tree:?}");
        let lp = tree.leaves.expect("the best leaf pair");
        let (la, lb) = (lp.node_a as usize, lp.node_b as usize);
        assert!(chair.children(la).is_empty() && human.children(lb).is_empty());
        if want > 1e-3 {
            // Separated: a unique closest leaf pair, the brute force's, with a gradient.
            assert_eq!((la, lb), leaves);
            assert!(d.gradient_a.is_some());
        }
        let r = c.distance(req(&h, &ch)).await.unwrap().into_inner().answer.unwrap();
        assert!((r.distance - want).abs() <= TOL, "reversed: {} vs {want}", r.distance);

        // BatchQuery, rows: distance both ways and growth (overlap iff the model distance is 0).
        let pair = |kind: pb::QueryKind, first: &str, second: &str| pb::QueryPair {
            kind: kind as i32,
            first: first.into(),
            second: second.into(),
            ..Default::default()
        };
        let pairs = vec![
            pair(pb::QueryKind::Distance, &ch, &h),
            pair(pb::QueryKind::Distance, &h, &ch),
            pair(pb::QueryKind::Growth, &ch, &h),
        ];
        let batch = pb::BatchQueryRequest { scene_id: scene.clone(), pairs, columns: None };
        let answers = c.batch_query(batch).await.unwrap().into_inner().answers;
        for a in &answers[..2] {
            let Some(pb::query_answer::Answer::Distance(d)) = &a.answer else { panic!("distance answer") };
            assert!((d.distance - want).abs() <= TOL, "batch: {} vs {want}", d.distance);
            assert!(d.tree.is_some());
        }
        let Some(pb::query_answer::Answer::Growth(g)) = &answers[2].answer else { panic!("growth answer") };
        assert!(g.tree.is_some() && g.solve.as_ref().unwrap().converged);
        if want > 1e-6 {
            assert!(g.separated, "distance {want} but growth {}", g.value);
        } else {
            assert!(!g.separated && g.value <= 1.0, "overlapping but growth {}", g.value);
        }

        // BatchQuery, columns: the value column is the distance, upper and level filled.
        let columns = pb::PairColumns {
            kind: pb::QueryKind::Distance as i32,
            instance_ids: vec![ch.clone(), h.clone()],
            first: vec![0, 1],
            second: vec![1, 0],
            margin: 0.0,
            cold: false,
        };
        let batch = pb::BatchQueryRequest { scene_id: scene.clone(), pairs: vec![], columns: Some(columns) };
        let cols = c.batch_query(batch).await.unwrap().into_inner().columns.unwrap();
        assert_eq!((cols.value.len(), cols.upper.len(), cols.level.len()), (2, 2, 2));
        for k in 0..2 {
            assert!((cols.value[k] - want).abs() <= TOL && (cols.upper[k] - want).abs() <= TOL, "{cols:?}");
            assert!(cols.converged[k] && cols.level[k] >= 1);
        }

        // Query (planner): collide with a 5 cm margin decides as the brute force does.
        let margin = 0.05;
        let q = pb::PlannerQuery {
            kind: pb::QueryKind::Collide as i32,
            first: ch.clone(),
            second: h.clone(),
            margin,
            ..Default::default()
        };
        let req = pb::QueryRequest { scene_id: scene.clone(), queries: vec![q], ..Default::default() };
        let out = c.query(req).await.unwrap().into_inner();
        let Some(pb::query_answer::Answer::Collide(col)) = &out.answers[0].answer else { panic!("collide") };
        assert_eq!(col.collides, want < margin, "collide at {t:?}: model distance {want}");
        assert!(col.tree.is_some());

        // CheckScene: the pair is reported iff closer than the margin, with the model distance.
        let check = pb::CheckSceneRequest { scene_id: scene.clone(), margin: 0.3, ..Default::default() };
        let found = c.check_scene(check).await.unwrap().into_inner().pairs;
        assert_eq!(found.len(), usize::from(want < 0.3), "check at {t:?}: model distance {want}");
        if let Some(p) = found.first() {
            let d = p.distance.as_ref().unwrap();
            assert!((d.distance - want).abs() <= TOL && d.tree.is_some());
        }
    }
    // A bound tolerance stops early with bounds around the model distance.
    crate::util::set_pose(&mut c, &scene, &ch, at([2.0, 0.0, 0.0])).await;
    let (want, _) = brute_force(&chair, &iso([1.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0]), &human, &ph);
    let req = pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: ch.clone(),
        instance_b: h.clone(),
        tolerance: 0.5,
        ..Default::default()
    };
    let d = c.distance(req.clone()).await.unwrap().into_inner().answer.unwrap();
    let tree = d.tree.unwrap();
    assert!(tree.lower <= want + TOL && tree.upper >= want - TOL && tree.upper - tree.lower <= 0.5 + 1e-12);
    assert_eq!(d.distance, tree.lower);
    let bad = pb::DistanceRequest { tolerance: -1.0, ..req };
    assert_status(c.distance(bad).await, Code::InvalidArgument, "tolerance");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_single_body_scene_answers_as_before_without_tree_fields() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (chair, human) = demo_bodies();
    let (bc, bh) = (upload_body(&mut c, "chair", &chair).await, upload_body(&mut c, "human", &human).await);
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let (pc, ph) = (iso([1.0, 0.0, 0.0, 0.0], [1.2, 0.0, 0.0]), iso([1.0, 0.0, 0.0, 0.0], [0.0; 3]));
    let ich = add(&mut c, &scene, &bc, at([1.2, 0.0, 0.0])).await;
    let ih = add(&mut c, &scene, &bh, at([0.0; 3])).await;
    let want = distance(&chair, &pc, &human, &ph, None, &NewtonParams::default());
    let d = crate::util::distance(&mut c, &scene, &ich, &ih).await;
    assert!((d.distance - want.distance).abs() <= 1e-9, "{} vs {}", d.distance, want.distance);
    assert!(d.tree.is_none() && d.solve.unwrap().converged);
    let got = c.get_body(pb::GetBodyRequest { body_id: bc }).await.unwrap().into_inner();
    assert_eq!(got.nodes, 1);
    assert!(!got.body_json.contains("\"nodes\""));
    let columns = pb::PairColumns {
        kind: pb::QueryKind::Distance as i32,
        instance_ids: vec![ich, ih],
        first: vec![0],
        second: vec![1],
        margin: 0.0,
        cold: false,
    };
    let batch = pb::BatchQueryRequest { scene_id: scene, pairs: vec![], columns: Some(columns) };
    let cols = c.batch_query(batch).await.unwrap().into_inner().columns.unwrap();
    assert!((cols.value[0] - want.distance).abs() <= 1e-9);
    assert!(cols.upper.is_empty() && cols.level.is_empty(), "no tree columns without a compound pair");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_compound_uploads_are_invalid_argument_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (_, text) = compound("chair_101.json");
    let good: serde_json::Value = serde_json::from_str(&text).unwrap();
    let upload = |v: serde_json::Value| pb::UploadBodyRequest {
        name: "bad".into(),
        body: Some(pb::upload_body_request::Body::BodyJson(v.to_string())),
    };
    let leaf = good["nodes"].as_array().unwrap().iter().position(|n| n["children"].as_array().unwrap().is_empty());
    let leaf = leaf.unwrap();
    let mut v = good.clone();
    v["nodes"][leaf]["body"]["scale"] = (-1.0).into();
    assert_status(
        c.upload_body(upload(v)).await,
        Code::InvalidArgument,
        &format!("body_json.nodes[{leaf}].body.scale"),
    );
    let root = good["root"].as_u64().unwrap() as usize;
    let mut v = good.clone();
    v["nodes"][root]["children"][0] = 999.into();
    assert_status(
        c.upload_body(upload(v)).await,
        Code::InvalidArgument,
        &format!("body_json.nodes[{root}].children[0]"),
    );
    let mut v = good.clone();
    v["root"] = 999.into();
    assert_status(c.upload_body(upload(v)).await, Code::InvalidArgument, "body_json.root");
    let mut v = good.clone();
    v["format"] = "sublevel.compound.v0".into();
    assert_status(c.upload_body(upload(v)).await, Code::InvalidArgument, "body_json.format");
    let mut v = good.clone();
    v["nodes"][leaf]["excess"] = (-0.5).into();
    assert_status(c.upload_body(upload(v)).await, Code::InvalidArgument, &format!("body_json.nodes[{leaf}].excess"));
    let mut v = good.clone();
    let many: Vec<serde_json::Value> = (0..200).map(|_| good["nodes"][leaf].clone()).collect();
    v["nodes"] = many.into();
    assert_status(c.upload_body(upload(v)).await, Code::InvalidArgument, "body_json.nodes");
    // A node that is not sos-convex is refused: x⁴ − 3x²y² + y⁴ + z² is not convex.
    let mut v = good.clone();
    v["nodes"][leaf]["body"]["exponents"] = serde_json::json!([[4, 0, 0], [2, 2, 0], [0, 4, 0], [0, 0, 2]]);
    v["nodes"][leaf]["body"]["coefficients"] = serde_json::json!([1.0, -3.0, 1.0, 1.0]);
    assert_status(c.upload_body(upload(v)).await, Code::InvalidArgument, &format!("body_json.nodes[{leaf}].body"));
    assert!(c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies.is_empty());
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reopened_store_still_has_its_compound_bodies_and_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let (chair, chair_json) = compound("chair_101.json");
    let (human, human_json) = compound("human_10.json");
    let (scene, ch, h, chair_id);
    {
        let server = Server::start(config(dir.path())).await;
        let mut c = server.client().await;
        chair_id = upload_json(&mut c, "chair", chair_json).await.body_id;
        let human_id = upload_json(&mut c, "human", human_json).await.body_id;
        scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
        ch = add(&mut c, &scene, &chair_id, at([1.1, 0.1, 0.0])).await;
        h = add(&mut c, &scene, &human_id, at([0.0; 3])).await;
        server.stop().await;
    }
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let got = c.get_body(pb::GetBodyRequest { body_id: chair_id }).await.unwrap().into_inner();
    assert_eq!(got.nodes as usize, chair.node_count());
    let back = CompoundBody::from_json(&got.body_json).unwrap();
    assert_eq!(back.node_count(), chair.node_count());
    let (want, _) =
        brute_force(&chair, &iso([1.0, 0.0, 0.0, 0.0], [1.1, 0.1, 0.0]), &human, &iso([1.0, 0.0, 0.0, 0.0], [0.0; 3]));
    let d = crate::util::distance(&mut c, &scene, &ch, &h).await;
    assert!((d.distance - want).abs() <= TOL && d.tree.is_some(), "{} vs {want}", d.distance);
    server.stop().await;
}

/// An OFF mesh of two boxes forming an L (a nonconvex shape): [0, 1] × [0, 0.3] × [0, 0.3] and
/// [0, 0.3] × [0.3, 1] × [0, 0.3], meters.
fn l_shape_off() -> String {
    let boxes = [([0.0, 0.0, 0.0], [1.0, 0.3, 0.3]), ([0.0, 0.3, 0.0], [0.3, 1.0, 0.3])];
    let quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let mut v = Vec::new();
    let mut f = Vec::new();
    for (k, (lo, hi)) in boxes.iter().enumerate() {
        for i in 0..8 {
            let pick = |bit: usize, axis: usize| if i & bit == 0 { lo[axis] } else { hi[axis] };
            v.push(format!("{} {} {}", pick(4, 0), pick(2, 1), pick(1, 2)));
        }
        for q in quads {
            let o = 8 * k;
            f.push(format!("3 {} {} {}", o + q[0], o + q[1], o + q[2]));
            f.push(format!("3 {} {} {}", o + q[0], o + q[2], o + q[3]));
        }
    }
    format!("OFF\n{} {} 0\n{}\n{}\n", v.len(), f.len(), v.join("\n"), f.join("\n"))
}

/// A fit job with `parts` fits a compound body, reporting progress per part, and stores it (a
/// tree of more than one node); bad compound options are refused before a job exists.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_job_with_parts_reports_progress_per_part_and_stores_a_compound_body() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let mesh = |data: String| pb::Mesh {
        data: data.into_bytes(),
        mesh_format: pb::MeshFormat::Off as i32,
        ..Default::default()
    };
    let req = pb::StartFitJobRequest {
        name: "ell".into(),
        degree: 2,
        parts: 2,
        source: Some(pb::start_fit_job_request::Source::Mesh(mesh(l_shape_off()))),
        ..Default::default()
    };
    let bad = pb::StartFitJobRequest { auto_parts: true, ..req.clone() };
    assert_status(c.start_fit_job(bad).await, Code::InvalidArgument, "parts");
    let bad = pb::StartFitJobRequest { parts: 0, auto_parts: true, ..req.clone() };
    assert_status(c.start_fit_job(bad).await, Code::InvalidArgument, "tolerance");
    let bad = pb::StartFitJobRequest { tolerance: -1.0, ..req.clone() };
    assert_status(c.start_fit_job(bad).await, Code::InvalidArgument, "tolerance");
    let points = pb::start_fit_job_request::Source::Points(pb::PointCloud {
        xyz: crate::util::sphere_points([0.0; 3], 1.0, 50),
    });
    let bad = pb::StartFitJobRequest { source: Some(points), ..req.clone() };
    assert_status(c.start_fit_job(bad).await, Code::InvalidArgument, "mesh");

    let job_id = c.start_fit_job(req).await.unwrap().into_inner().job_id;
    let updates = crate::util::watch_to_end(&mut c, job_id).await;
    let last = updates.last().unwrap().clone();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    let per_part: Vec<(u32, u32)> = updates.iter().filter(|u| u.part > 0).map(|u| (u.part, u.parts)).collect();
    assert!(!per_part.is_empty(), "no per-part progress in {updates:?}");
    assert!(per_part.iter().all(|&(j, n)| 1 <= j && j <= n && n <= 2), "{per_part:?}");
    let got = c.get_body(pb::GetBodyRequest { body_id: last.body_id }).await.unwrap().into_inner();
    let body = CompoundBody::from_json(&got.body_json).unwrap();
    assert_eq!(got.nodes as usize, body.node_count());
    assert!(body.leaf_count() >= 1);
    // Every box corner lies inside some leaf body (the fit's containment).
    let corners_inside = |body: &CompoundBody| {
        for x in [0.0, 1.0] {
            for y in [0.0, 0.3] {
                let p = sublevel::math::Point3::new(x, y, 0.3);
                assert!(body.leaves().any(|l| body.body(l).value_at(&p) <= 1.0 + 1e-9), "{p:?} outside every leaf");
            }
        }
    };
    corners_inside(&body);

    // The same L as an ASCII STL triangle soup (each triangle with its own three vertices) is
    // welded and fitted alike: as many nodes, every corner inside a leaf. A point cloud is refused.
    let stl =
        pb::Mesh { data: l_shape_stl().into_bytes(), mesh_format: pb::MeshFormat::Stl as i32, ..Default::default() };
    let req = pb::StartFitJobRequest {
        name: "ell-stl".into(),
        degree: 2,
        parts: 2,
        source: Some(pb::start_fit_job_request::Source::Mesh(stl)),
        ..Default::default()
    };
    let xyz = pb::Mesh {
        data: b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n".to_vec(),
        mesh_format: pb::MeshFormat::Xyz as i32,
        ..Default::default()
    };
    let bad = pb::StartFitJobRequest { source: Some(pb::start_fit_job_request::Source::Mesh(xyz)), ..req.clone() };
    assert_status(c.start_fit_job(bad).await, Code::InvalidArgument, "mesh.mesh_format");
    let job_id = c.start_fit_job(req).await.unwrap().into_inner().job_id;
    let last = crate::util::watch_to_end(&mut c, job_id).await.pop().unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    let from_stl = c.get_body(pb::GetBodyRequest { body_id: last.body_id }).await.unwrap().into_inner();
    let from_stl = CompoundBody::from_json(&from_stl.body_json).unwrap();
    assert_eq!(from_stl.node_count(), body.node_count());
    corners_inside(&from_stl);
    server.stop().await;
}

/// [`l_shape_off`] as an ASCII STL: every triangle with its own three vertices.
fn l_shape_stl() -> String {
    let off = l_shape_off();
    let mut lines = off.lines().skip(1);
    let counts: Vec<usize> = lines.next().unwrap().split_whitespace().map(|v| v.parse().unwrap()).collect();
    let vertices: Vec<&str> = lines.by_ref().take(counts[0]).collect();
    let mut out = String::from("solid ell\n");
    for face in lines.take(counts[1]) {
        let idx: Vec<usize> = face.split_whitespace().skip(1).map(|v| v.parse().unwrap()).collect();
        out.push_str("facet normal 0 0 0\nouter loop\n");
        for i in idx {
            out.push_str(&format!("vertex {}\n", vertices[i]));
        }
        out.push_str("endloop\nendfacet\n");
    }
    out.push_str("endsolid ell\n");
    out
}

/// A three-node tree of spheres in the compound file form: a root of radius `root_r` at the
/// origin over spheres of radius 1 at x = ±5 (`sublevel.compound.v1`, each node p = |u|²).
fn sphere_tree(root_r: f64) -> String {
    let sphere = |x: f64, r: f64| {
        serde_json::json!({
            "degree": 2, "exponents": [[2, 0, 0], [0, 2, 0], [0, 0, 2]], "coefficients": [1.0, 1.0, 1.0],
            "center": [x, 0.0, 0.0], "scale": r
        })
    };
    serde_json::json!({
        "format": "sublevel.compound.v1",
        "root": 0,
        "nodes": [
            { "body": sphere(0.0, root_r), "children": [1, 2], "depth": 0, "excess": 0.0 },
            { "body": sphere(-5.0, 1.0), "children": [], "depth": 1, "excess": 0.0 },
            { "body": sphere(5.0, 1.0), "children": [], "depth": 1, "excess": 0.0 },
        ]
    })
    .to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tree_whose_parent_misses_its_children_is_refused_and_a_certified_one_answers_alike_on_every_rpc() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let upload = |json: String| pb::UploadBodyRequest {
        name: "tree".into(),
        body: Some(pb::upload_body_request::Body::BodyJson(json)),
    };
    // A 0.1 m root over 1 m spheres 5 m away, and a 2.5 m root that covers them partly: the
    // parent does not contain its children, shown by a point of the child.
    for r in [0.1, 2.5] {
        let status = c.upload_body(upload(sphere_tree(r))).await.unwrap_err();
        assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
        let m = status.message();
        assert!(m.contains("body_json.nodes[0]") && m.contains("does not contain its child"), "{m}");
    }
    assert!(c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies.is_empty());

    // A 6 m root holds both (certified by the S-procedure): a 0.5 m ball at x = 5.8 overlaps the
    // child at x = 5 (centers 0.8 m apart, radii 1.5 m) on every path.
    let tree = c.upload_body(upload(sphere_tree(6.0))).await.unwrap().into_inner().body_id;
    let ball = crate::util::upload_sphere(&mut c, "ball", [0.0; 3], 0.5).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let t = add(&mut c, &scene, &tree, at([0.0; 3])).await;
    let b = add(&mut c, &scene, &ball, at([5.8, 0.0, 0.0])).await;
    let req = pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: t.clone(),
        instance_b: b.clone(),
        ..Default::default()
    };
    let d = c.distance(req.clone()).await.unwrap().into_inner().answer.unwrap();
    assert!(d.overlapping && d.distance == 0.0, "{d:?}");
    let q = pb::PlannerQuery {
        kind: pb::QueryKind::Collide as i32,
        first: t.clone(),
        second: b.clone(),
        ..Default::default()
    };
    let out = c.query(pb::QueryRequest { scene_id: scene.clone(), queries: vec![q], ..Default::default() }).await;
    let Some(pb::query_answer::Answer::Collide(col)) = &out.unwrap().into_inner().answers[0].answer else {
        panic!("collide")
    };
    assert!(col.collides, "{col:?}");
    let check = pb::CheckSceneRequest { scene_id: scene.clone(), ..Default::default() };
    assert_eq!(c.check_scene(check).await.unwrap().into_inner().pairs.len(), 1);
    let columns = pb::PairColumns {
        kind: pb::QueryKind::Collide as i32,
        instance_ids: vec![t.clone(), b.clone()],
        first: vec![0],
        second: vec![1],
        margin: 0.0,
        cold: false,
    };
    let batch = pb::BatchQueryRequest { scene_id: scene.clone(), pairs: vec![], columns: Some(columns) };
    let cols = c.batch_query(batch).await.unwrap().into_inner().columns.unwrap();
    assert!(cols.value[0] == 0.0 && cols.overlapping[0], "{cols:?}");
    // 1.5 m further out the ball is 0.8 m clear of the child.
    crate::util::set_pose(&mut c, &scene, &b, at([7.3, 0.0, 0.0])).await;
    let d = c.distance(req).await.unwrap().into_inner().answer.unwrap();
    assert!((d.distance - 0.8).abs() < 1e-6 && !d.overlapping, "{d:?}");
    server.stop().await;
}
