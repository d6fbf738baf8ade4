//! Integration tests: exact primitives over gRPC. Boxes, spheres, cylinders and halfspaces
//! uploaded with `UploadBody.primitive`, read back, instantiated and queried against closed forms
//! (Distance, BatchQuery collide, Query, CheckScene), a fitted body against a primitive, and bad
//! input refused naming the field.

use crate::util::{add, assert_status, at, config, distance, pose, upload_sphere, Server};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

/// A `Primitive` message of `kind` with its fields.
pub(crate) fn primitive(kind: pb::PrimitiveKind, size: &[f64], radius: f64, height: f64) -> pb::Primitive {
    pb::Primitive { kind: kind as i32, size: size.to_vec(), radius, height, ..Default::default() }
}

/// Uploads `p` as a primitive body named `name`; its id.
pub(crate) async fn upload_primitive(c: &mut SublevelClient<Channel>, name: &str, p: pb::Primitive) -> String {
    let req = pb::UploadBodyRequest { name: name.into(), body: Some(pb::upload_body_request::Body::Primitive(p)) };
    c.upload_body(req).await.unwrap().into_inner().body_id
}

/// A floor {z ≤ 0}.
fn floor() -> pb::Primitive {
    pb::Primitive {
        kind: pb::PrimitiveKind::Halfspace as i32,
        normal: Some(pb::Vec3 { x: 0.0, y: 0.0, z: 1.0 }),
        ..Default::default()
    }
}

/// A unit cube turned 45° about z at the origin and a ball r = 0.25 at (2, 0, 0): distance
/// 2 − √½ − 0.25 exactly (the cube's corner faces the ball); a floor under them: the cube's and
/// the ball's heights; a fitted ball against the cube; collide queries either side of the
/// distance; CheckScene finds the close pairs, never the two floors; the bodies read back as the
/// primitives they are.
#[tokio::test]
async fn uploaded_primitives_answer_their_closed_forms() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let cube = upload_primitive(&mut c, "cube", primitive(pb::PrimitiveKind::Box, &[1.0; 3], 0.0, 0.0)).await;
    let ball = upload_primitive(&mut c, "ball", primitive(pb::PrimitiveKind::Sphere, &[], 0.25, 0.0)).await;
    let ground = upload_primitive(&mut c, "floor", floor()).await;
    let fitted = upload_sphere(&mut c, "fitted", [0.0; 3], 0.2).await;

    let got = c.get_body(pb::GetBodyRequest { body_id: cube.clone() }).await.unwrap().into_inner();
    assert_eq!(got.primitive, Some(primitive(pb::PrimitiveKind::Box, &[1.0; 3], 0.0, 0.0)));
    assert!(got.data.is_none());
    assert_eq!(got.body_json, r#"{"primitive":"box","size":[1.0,1.0,1.0]}"#);
    let listed = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    let summary = listed.iter().find(|b| b.body_id == cube).unwrap();
    assert_eq!((summary.primitive.as_str(), summary.degree, summary.volume), ("box", 0, 1.0));
    assert_eq!(listed.iter().find(|b| b.body_id == fitted).unwrap().primitive, "");

    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let (s, q) = (std::f64::consts::FRAC_PI_8.sin(), std::f64::consts::FRAC_PI_8.cos());
    let a = add(&mut c, &scene, &cube, pose([q, 0.0, 0.0, s], [0.0, 0.0, 1.0])).await;
    let b = add(&mut c, &scene, &ball, at([2.0, 0.0, 1.0])).await;
    let f = add(&mut c, &scene, &ground, at([0.0; 3])).await;
    let g = add(&mut c, &scene, &ground, at([0.0, 0.0, -3.0])).await;
    let h = add(&mut c, &scene, &fitted, at([0.0, 2.0, 1.0])).await;

    let want = 2.0 - 0.5f64.sqrt() - 0.25;
    let d = distance(&mut c, &scene, &a, &b).await;
    assert!((d.distance - want).abs() < 1e-12, "{} vs {want}", d.distance);
    assert!(d.solve.as_ref().unwrap().converged);
    assert!((d.witness_b.as_ref().unwrap().x - 1.75).abs() < 1e-12);
    assert!((distance(&mut c, &scene, &f, &a).await.distance - 0.5).abs() < 1e-12);
    assert!((distance(&mut c, &scene, &b, &f).await.distance - 0.75).abs() < 1e-12);
    // The fitted ball r = 0.2 at (0, 2, 1) against the turned cube, whose corner reaches y = √½.
    let e = distance(&mut c, &scene, &h, &a).await;
    assert!((e.distance - (2.0 - 0.5f64.sqrt() - 0.2)).abs() < 1e-7, "{}", e.distance);

    // Collide at margins either side of the distance.
    let query = |margin: f64| pb::PlannerQuery {
        kind: pb::QueryKind::Collide as i32,
        first: a.clone(),
        second: b.clone(),
        margin,
        ..Default::default()
    };
    let req = pb::QueryRequest { scene_id: scene.clone(), queries: vec![query(1.1), query(1.0)], ..Default::default() };
    let answers = c.query(req).await.unwrap().into_inner().answers;
    let collides: Vec<bool> = answers
        .iter()
        .map(|x| match &x.answer {
            Some(pb::query_answer::Answer::Collide(c)) => c.collides,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(collides, [true, false]);

    // CheckScene at 0.6 m: the cube over the floor (0.5) only; the two floors are never a pair.
    let check = pb::CheckSceneRequest { scene_id: scene.clone(), margin: 0.6, ..Default::default() };
    let pairs = c.check_scene(check).await.unwrap().into_inner().pairs;
    let mut found: Vec<(String, String)> = pairs.iter().map(|p| (p.first.clone(), p.second.clone())).collect();
    found.sort();
    let pair = |x: &String, y: &String| if x < y { (x.clone(), y.clone()) } else { (y.clone(), x.clone()) };
    assert_eq!(found, vec![pair(&a, &f)]);
    assert!(!found.contains(&pair(&f, &g)));
    server.stop().await;
}

/// Bad primitives are INVALID_ARGUMENT naming the field (with BadRequest details); growth with a
/// primitive and the distance of two halfspaces are INVALID_ARGUMENT naming the instance's field;
/// a halfspace cannot be grouped.
#[tokio::test]
async fn bad_primitives_and_unanswerable_queries_are_refused_naming_the_field() {
    use tonic_types::StatusExt;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let up = |p: pb::Primitive| pb::UploadBodyRequest {
        name: "bad".into(),
        body: Some(pb::upload_body_request::Body::Primitive(p)),
    };
    let cases = [
        (primitive(pb::PrimitiveKind::Box, &[1.0, -2.0, 1.0], 0.0, 0.0), "primitive.size[1]"),
        (primitive(pb::PrimitiveKind::Box, &[1.0, 2.0], 0.0, 0.0), "primitive.size"),
        (primitive(pb::PrimitiveKind::Box, &[1.0; 3], 0.5, 0.0), "primitive.radius"),
        (primitive(pb::PrimitiveKind::Cylinder, &[], 0.5, 0.0), "primitive.height"),
        (primitive(pb::PrimitiveKind::Unspecified, &[], 0.5, 0.0), "primitive.kind"),
        (pb::Primitive { kind: pb::PrimitiveKind::Halfspace as i32, ..Default::default() }, "primitive.normal"),
    ];
    for (p, field) in cases {
        let e = c.upload_body(up(p)).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        let bad = e.get_details_bad_request().expect("BadRequest details");
        assert_eq!(bad.field_violations[0].field, field, "{bad:?}");
    }
    assert!(c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies.is_empty());

    let cube = upload_primitive(&mut c, "cube", primitive(pb::PrimitiveKind::Box, &[1.0; 3], 0.0, 0.0)).await;
    let ground = upload_primitive(&mut c, "floor", floor()).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let a = add(&mut c, &scene, &cube, at([0.0, 0.0, 1.0])).await;
    let f = add(&mut c, &scene, &ground, at([0.0; 3])).await;
    let g = add(&mut c, &scene, &ground, at([0.0, 0.0, -1.0])).await;
    let req =
        pb::DistanceRequest { scene_id: scene.clone(), instance_a: f.clone(), instance_b: g, ..Default::default() };
    assert_status(c.distance(req).await, Code::InvalidArgument, "instance_b");
    let req = pb::GrowthRequest {
        scene_id: scene.clone(),
        instance_1: a.clone(),
        instance_2: f.clone(),
        ..Default::default()
    };
    assert_status(c.growth(req).await, Code::InvalidArgument, "growth measure is defined for sos-convex bodies");
    let group = pb::StartGroupJobRequest {
        scene_id: scene.clone(),
        instance_ids: vec![a, f],
        degree: 2,
        name: "g".into(),
        ..Default::default()
    };
    assert_status(c.start_group_job(group).await, Code::InvalidArgument, "instance_ids[1]");
    server.stop().await;
}
