//! Integration tests: the planner API (Query, QueryStream, CheckScene) against closed forms for
//! spheres and brute force over all pairs.

use crate::util::{add, assert_status, at, config, upload_sphere, Server};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

fn q(kind: pb::QueryKind, a: &str, b: &str) -> pb::PlannerQuery {
    pb::PlannerQuery { kind: kind as i32, first: a.into(), second: b.into(), ..Default::default() }
}

fn collide(a: &str, b: &str, margin: f64) -> pb::PlannerQuery {
    pb::PlannerQuery { margin, ..q(pb::QueryKind::Collide, a, b) }
}

fn pose_of(id: &str, t: [f64; 3]) -> pb::InstancePose {
    pb::InstancePose { instance_id: id.into(), pose: Some(at(t)) }
}

fn distance_of(a: &pb::QueryAnswer) -> &pb::DistanceAnswer {
    match &a.answer {
        Some(pb::query_answer::Answer::Distance(d)) => d,
        other => panic!("expected a distance answer, got {other:?}"),
    }
}

fn collide_of(a: &pb::QueryAnswer) -> &pb::CollideAnswer {
    match &a.answer {
        Some(pb::query_answer::Answer::Collide(c)) => c,
        other => panic!("expected a collide answer, got {other:?}"),
    }
}

/// Two spheres r = 0.5 and 0.25 at 0 and 2 m on x, in their own scene.
async fn two_spheres(c: &mut SublevelClient<Channel>) -> (String, String, String) {
    let b1 = upload_sphere(c, "r05", [0.0; 3], 0.5).await;
    let b2 = upload_sphere(c, "r025", [0.0; 3], 0.25).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "p".into() }).await.unwrap().into_inner().scene_id;
    let i1 = add(c, &scene, &b1, at([0.0; 3])).await;
    let i2 = add(c, &scene, &b2, at([2.0, 0.0, 0.0])).await;
    (scene, i1, i2)
}

/// A stream's poses are its own: answers follow them (closed form ‖c₁ − c₂‖ − r₁ − r₂), warm
/// starts kick in from the second request, the stored scene and a second stream never see them;
/// candidate states are answered per state and leave the view as it was.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn query_stream_keeps_a_private_view_with_warm_starts() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (scene, i1, i2) = two_spheres(&mut c).await;

    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let mut answers = c.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    let mut other_c = server.client().await;
    let (tx2, rx2) = tokio::sync::mpsc::channel(4);
    let mut other = other_c.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx2)).await.unwrap().into_inner();
    for (k, x) in [3.0, 3.1, 3.2, 3.3].into_iter().enumerate() {
        let req = pb::QueryRequest {
            scene_id: if k == 0 { scene.clone() } else { String::new() },
            poses: vec![pose_of(&i2, [x, 0.0, 0.0])],
            queries: vec![q(pb::QueryKind::Distance, &i1, &i2), q(pb::QueryKind::Growth, &i1, &i2)],
            request_id: 100 + k as u64,
            ..Default::default()
        };
        tx.send(req).await.unwrap();
        let r = answers.message().await.unwrap().unwrap();
        assert_eq!(r.request_id, 100 + k as u64);
        let d = distance_of(&r.answers[0]);
        assert!((d.distance - (x - 0.75)).abs() < 1e-9, "{d:?}");
        assert_eq!(d.solve.as_ref().unwrap().warm_started, k > 0, "{d:?}");
        let Some(pb::query_answer::Answer::Growth(g)) = &r.answers[1].answer else { panic!() };
        assert!((g.value - ((x - 0.25) / 0.5f64).powi(2)).abs() < 1e-8, "{g:?}");
        // The other stream (no pose updates) sees the stored pose: 2 − 0.75.
        let req = pb::QueryRequest {
            scene_id: scene.clone(),
            queries: vec![q(pb::QueryKind::Distance, &i1, &i2)],
            ..Default::default()
        };
        tx2.send(req).await.unwrap();
        let r2 = other.message().await.unwrap().unwrap();
        assert!((distance_of(&r2.answers[0]).distance - 1.25).abs() < 1e-9);
    }
    // Candidate states: i2 at 1, 4 and 1.5 m; answered per state; the view keeps x = 3.3.
    let req = pb::QueryRequest {
        queries: vec![q(pb::QueryKind::Distance, &i1, &i2), collide(&i1, &i2, 0.5)],
        states: [1.0, 4.0, 1.5]
            .iter()
            .map(|&x| pb::CandidateState { poses: vec![pose_of(&i2, [x, 0.0, 0.0])] })
            .collect(),
        ..Default::default()
    };
    tx.send(req).await.unwrap();
    let r = answers.message().await.unwrap().unwrap();
    assert_eq!(r.states.len(), 3);
    for (st, x) in r.states.iter().zip([1.0, 4.0, 1.5]) {
        assert!((distance_of(&st.answers[0]).distance - (x - 0.75)).abs() < 1e-9);
        assert_eq!(st.any_collision, x - 0.75 < 0.5, "x = {x}");
        assert_eq!(collide_of(&st.answers[1]).collides, x - 0.75 < 0.5);
    }
    let req = pb::QueryRequest { queries: vec![q(pb::QueryKind::Distance, &i1, &i2)], ..Default::default() };
    tx.send(req).await.unwrap();
    let r = answers.message().await.unwrap().unwrap();
    assert!((distance_of(&r.answers[0]).distance - (3.3 - 0.75)).abs() < 1e-9, "states must not move the view");
    // Nothing was written: the stored pose is still x = 2.
    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    let stored = view.instances.iter().find(|i| i.instance_id == i2).unwrap();
    assert_eq!(stored.pose.as_ref().unwrap().translation.as_ref().unwrap().x, 2.0);
    // Eight states 0.94 m apart (past the warm starts' reach, half of 0.75 m), the distance query
    // not cold: solved like cold ones (on the batch's lanes), the closed form, and the last state's
    // warm start kept for the pair: a query 5 cm from it starts warm.
    let far: Vec<[f64; 3]> = (0..8).map(|k| [1.5 + 0.5 * k as f64, 0.8 * (k % 2) as f64, 0.0]).collect();
    let req = pb::QueryRequest {
        queries: vec![q(pb::QueryKind::Distance, &i1, &i2)],
        states: far.iter().map(|&x| pb::CandidateState { poses: vec![pose_of(&i2, x)] }).collect(),
        ..Default::default()
    };
    tx.send(req).await.unwrap();
    let r = answers.message().await.unwrap().unwrap();
    for (st, x) in r.states.iter().zip(&far) {
        let gap = (x[0] * x[0] + x[1] * x[1]).sqrt() - 0.75;
        let d = distance_of(&st.answers[0]);
        assert!((d.distance - gap).abs() < 1e-9 && d.solve.as_ref().unwrap().converged, "{x:?}: {d:?}");
        assert!(!d.solve.as_ref().unwrap().warm_started, "{x:?}: {d:?}");
    }
    let last = far[7];
    let req = pb::QueryRequest {
        poses: vec![pose_of(&i2, [last[0] + 0.05, last[1], 0.0])],
        queries: vec![q(pb::QueryKind::Distance, &i1, &i2)],
        ..Default::default()
    };
    tx.send(req).await.unwrap();
    let r = answers.message().await.unwrap().unwrap();
    let d = distance_of(&r.answers[0]);
    let gap = ((last[0] + 0.05).powi(2) + last[1] * last[1]).sqrt() - 0.75;
    assert!((d.distance - gap).abs() < 1e-9, "{d:?}");
    assert!(d.solve.as_ref().unwrap().warm_started, "the lanes keep the last state's warm start: {d:?}");

    // A bad request ends the stream with a status naming the field.
    let req = pb::QueryRequest { poses: vec![pose_of("i-nope", [0.0; 3])], ..Default::default() };
    tx.send(req).await.unwrap();
    let e = answers.message().await.unwrap_err();
    assert_eq!(e.code(), Code::NotFound, "{e:?}");
    assert!(e.message().contains("poses[0].instance_id"), "{e:?}");
    drop(tx);
    drop(tx2);
    server.stop().await;
}

/// Collide-with-margin on spheres 1.25 m apart (gap between surfaces): a small margin is decided
/// by the bounding spheres alone, a margin 5 cm under the gap by the separating axis (its
/// certified lower bound is within 10⁻⁸ m of the gap here: the axis is a node direction of the
/// support bounds), a margin 10⁻¹⁰ m under the gap by the solve, a larger one collides; unary
/// Query answers cold; bad margins and kinds are refused naming the field.
#[tokio::test]
async fn collide_with_margin_and_unary_query() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (scene, i1, i2) = two_spheres(&mut c).await;
    let req = pb::QueryRequest {
        scene_id: scene.clone(),
        queries: vec![
            collide(&i1, &i2, 0.05),
            collide(&i1, &i2, 1.25 - 1e-10),
            collide(&i1, &i2, 1.3),
            collide(&i1, &i2, 0.0),
            collide(&i1, &i2, 1.2),
        ],
        ..Default::default()
    };
    let r = c.query(req.clone()).await.unwrap().into_inner();
    let got: Vec<_> = r.answers.iter().map(collide_of).collect();
    assert!(
        !got[0].collides && got[0].decided_by_bounds && got[0].distance <= 1.25 && got[0].solve.is_none(),
        "{:?}",
        got[0]
    );
    assert!(!got[1].collides && !got[1].decided_by_bounds && (got[1].distance - 1.25).abs() < 1e-9, "{:?}", got[1]);
    assert!(got[2].collides && (got[2].distance - 1.25).abs() < 1e-9, "{:?}", got[2]);
    assert!(!got[3].collides);
    // The bounding spheres (looser than the bodies) do not decide 1.2; the separating axis does.
    assert!(
        !got[4].collides && got[4].decided_by_bounds && got[4].distance > 1.2 && got[4].distance <= 1.25 + 1e-12,
        "{:?}",
        got[4]
    );
    assert!((got[4].distance - 1.25).abs() < 1e-8 && got[4].solve.is_none(), "{:?}", got[4]);
    // Unary answers are cold every time.
    let r = c.query(pb::QueryRequest { queries: vec![q(pb::QueryKind::Distance, &i1, &i2)], ..req.clone() }).await;
    let d = *distance_of(&r.unwrap().into_inner().answers[0]);
    assert!(!d.solve.unwrap().warm_started);
    // Overlap: move i2 onto i1 in the request.
    let r = c
        .query(pb::QueryRequest {
            poses: vec![pose_of(&i2, [0.5, 0.0, 0.0])],
            queries: vec![collide(&i1, &i2, 0.0)],
            ..req.clone()
        })
        .await
        .unwrap()
        .into_inner();
    // Overlapping spheres: a common point on the line of centers decides it, with no solve.
    let touching = collide_of(&r.answers[0]);
    assert!(touching.collides && touching.decided_by_bounds && touching.distance == 0.0, "{touching:?}");
    assert!(touching.solve.is_none(), "{touching:?}");

    // Signed distance: spheres r = 0.5, 0.25 with centers 0.6 m apart overlap by 0.15 m; the
    // penetration normal is the center line; the gradient is (∓n, …) as the separated formula.
    let signed = pb::PlannerQuery { signed: true, with_gradient: true, ..q(pb::QueryKind::Distance, &i1, &i2) };
    for (x, expected) in [(0.6, -0.15), (2.0, 1.25)] {
        let r = c
            .query(pb::QueryRequest {
                poses: vec![pose_of(&i2, [x, 0.0, 0.0])],
                queries: vec![signed.clone()],
                ..req.clone()
            })
            .await
            .unwrap()
            .into_inner();
        let d = distance_of(&r.answers[0]);
        assert!((d.signed_distance - expected).abs() < 1e-8, "x = {x}: {d:?}");
        let g = d.signed_gradient_b.as_ref().unwrap().linear.as_ref().unwrap();
        assert!((g.x - 1.0).abs() < 1e-6 && g.y.abs() < 1e-6, "moving B away along +x increases it: {g:?}");
        if expected < 0.0 {
            assert!((d.penetration_depth + expected).abs() < 1e-8);
            assert!((d.penetration_normal.as_ref().unwrap().x - 1.0).abs() < 1e-6, "{d:?}");
        }
    }

    let bad = pb::QueryRequest { queries: vec![collide(&i1, &i2, -1.0)], ..req.clone() };
    assert_status(c.query(bad).await, Code::InvalidArgument, "queries[0].margin");
    let bad = pb::QueryRequest { queries: vec![q(pb::QueryKind::Unspecified, &i1, &i2)], ..req.clone() };
    assert_status(c.query(bad).await, Code::InvalidArgument, "queries[0].kind");
    let bad = pb::QueryRequest { queries: vec![q(pb::QueryKind::Distance, &i1, "i-nope")], ..req.clone() };
    assert_status(c.query(bad).await, Code::NotFound, "i-nope");
    let bad = pb::QueryRequest {
        states: vec![pb::CandidateState { poses: vec![pose_of(&i2, [f64::NAN, 0.0, 0.0])] }],
        ..req.clone()
    };
    assert_status(c.query(bad).await, Code::InvalidArgument, "states[0].poses[0].pose.translation");
    server.stop().await;
}

/// Cold distance and collide queries over many candidate states run four states per SIMD pass
/// (`sublevel::query::batch`): every state's answer is still the closed form ‖c₁ − c₂‖ − r₁ − r₂
/// (0 and a common witness when overlapping), next to warm queries of the same request; a collide
/// query the cheap bounds clear (settled ahead of the lanes) gives a certified lower bound above
/// the margin, one whose spheres overlap gives distance 0 from a common point with no solve, and
/// either gives the same answer, to the bit, as the query asked alone.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cold_candidate_states_match_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (scene, i1, i2) = two_spheres(&mut c).await;
    let cold = |kind, a: &str, b: &str| pb::PlannerQuery { cold: true, ..q(kind, a, b) };
    let xs: Vec<[f64; 3]> =
        (0..24).map(|k| [0.4 + 0.15 * k as f64, 0.3 * (k % 3) as f64, -0.2 + 0.05 * k as f64]).collect();
    let req = pb::QueryRequest {
        scene_id: scene.clone(),
        queries: vec![
            cold(pb::QueryKind::Distance, &i1, &i2),
            pb::PlannerQuery { cold: true, ..collide(&i1, &i2, 0.5) },
            q(pb::QueryKind::Distance, &i2, &i1),
        ],
        states: xs.iter().map(|&x| pb::CandidateState { poses: vec![pose_of(&i2, x)] }).collect(),
        ..Default::default()
    };
    let r = c.query(req).await.unwrap().into_inner();
    assert_eq!(r.states.len(), xs.len());
    let (mut overlapping, mut cleared, mut touching) = (0, 0, 0);
    for (st, x) in r.states.iter().zip(&xs) {
        let gap = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt() - 0.75;
        for answer in [distance_of(&st.answers[0]), distance_of(&st.answers[2])] {
            assert!(answer.solve.as_ref().is_some_and(|s| s.converged), "{answer:?}");
            assert!((answer.distance - gap.max(0.0)).abs() < 1e-9, "x = {x:?}: {} vs {gap}", answer.distance);
            assert_eq!(answer.overlapping, gap <= 0.0);
        }
        let c1 = collide_of(&st.answers[1]);
        assert_eq!(c1.collides, gap < 0.5, "x = {x:?}");
        if c1.decided_by_bounds && c1.collides {
            // A common point proved overlap: distance 0, no solve.
            assert!(gap <= 1e-12 && c1.distance == 0.0 && c1.solve.is_none(), "x = {x:?}: {c1:?}");
            touching += 1;
        } else if c1.decided_by_bounds {
            // A certified lower bound above the margin, no solve.
            assert!(c1.distance > 0.5 && c1.distance <= gap + 1e-12 && c1.solve.is_none(), "x = {x:?}: {c1:?}");
            cleared += 1;
        } else {
            assert!((c1.distance - gap.max(0.0)).abs() < 1e-9, "x = {x:?}: {c1:?}");
        }
        // The same collide query alone (no lanes: its bounds asked by the answer itself) answers the
        // same: to the bit where the cheap tests decide (the same bounds and common point), to
        // 1e-12 m where a solve does (the lanes' cold starts are the single-pair starts up to
        // rounding, and a lane's answer is the single-pair answer to the KKT tolerance).
        let alone = pb::QueryRequest {
            scene_id: scene.clone(),
            poses: vec![pose_of(&i2, *x)],
            queries: vec![pb::PlannerQuery { cold: true, ..collide(&i1, &i2, 0.5) }],
            ..Default::default()
        };
        let r1 = c.query(alone).await.unwrap().into_inner();
        let c2 = collide_of(&r1.answers[0]);
        assert_eq!((c2.collides, c2.decided_by_bounds), (c1.collides, c1.decided_by_bounds), "x = {x:?}");
        if c1.decided_by_bounds {
            assert_eq!(c2.distance.to_bits(), c1.distance.to_bits(), "x = {x:?}: {c2:?} vs {c1:?}");
        } else {
            assert!((c2.distance - c1.distance).abs() <= 1e-12, "x = {x:?}: {c2:?} vs {c1:?}");
        }
        overlapping += usize::from(gap <= 0.0);
    }
    assert!(overlapping > 0 && overlapping < xs.len(), "the states must cross contact: {overlapping}");
    assert!(cleared > 0 && cleared < xs.len(), "the cheap bounds must clear some states, not all: {cleared}");
    assert!(touching > 0 && touching <= overlapping, "a common point must decide overlapping states: {touching}");
    // Without states: five cold queries of the same pair in one request (one group of lanes).
    let req = pb::QueryRequest {
        scene_id: scene.clone(),
        poses: vec![pose_of(&i2, [1.2, -0.4, 0.3])],
        queries: (0..5).map(|_| cold(pb::QueryKind::Distance, &i1, &i2)).collect(),
        ..Default::default()
    };
    let r = c.query(req).await.unwrap().into_inner();
    let gap = (1.2f64 * 1.2 + 0.4 * 0.4 + 0.3 * 0.3).sqrt() - 0.75;
    assert_eq!(r.answers.len(), 5);
    for a in &r.answers {
        assert!((distance_of(a).distance - gap).abs() < 1e-9, "{} vs {gap}", distance_of(a).distance);
    }
    server.stop().await;
}

/// Candidate states in columns (`QueryRequest.state_columns`): 16 states posing two small spheres
/// around a big one, three cold pairs each, answered in one `AnswerColumns` (row s·3 + k) that
/// matches the closed form ‖c₁ − c₂‖ − r₁ − r₂ (0 when overlapping) and the same request sent as
/// `states`; with `queries`, one StateAnswers per state. Bad columns are refused naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn state_columns_match_the_closed_form_and_the_states_form() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let big = upload_sphere(&mut c, "r05", [0.0; 3], 0.5).await;
    let small = upload_sphere(&mut c, "r025", [0.0; 3], 0.25).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "sc".into() }).await.unwrap().into_inner().scene_id;
    let b = add(&mut c, &scene, &big, at([0.0; 3])).await;
    let s1 = add(&mut c, &scene, &small, at([3.0, 0.0, 0.0])).await;
    let s2 = add(&mut c, &scene, &small, at([0.0, 3.0, 0.0])).await;
    // State k: s1 on a line through the big sphere, s2 on a circle around it (a rotated pose: the
    // answers must not depend on the spheres' orientation).
    let states: Vec<([f64; 3], [f64; 3])> = (0..16)
        .map(|k| {
            let t = k as f64;
            ([0.2 + 0.12 * t, 0.1, -0.05 * t], [1.1 * (0.4 * t).cos(), 1.1 * (0.4 * t).sin(), 0.3])
        })
        .collect();
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let mut numbers = Vec::new();
    for (x1, x2) in &states {
        numbers.extend_from_slice(&[1.0, 0.0, 0.0, 0.0, x1[0], x1[1], x1[2]]);
        numbers.extend_from_slice(&[h, 0.0, h, 0.0, x2[0], x2[1], x2[2]]);
    }
    let packed = pb::StateColumns { instance_ids: vec![s1.clone(), s2.clone()], poses: numbers };
    let ids = vec![b.clone(), s1.clone(), s2.clone()];
    let columns = pb::PairColumns {
        kind: pb::QueryKind::Distance as i32,
        instance_ids: ids,
        first: vec![0, 0, 1],
        second: vec![1, 2, 2],
        margin: 0.0,
        cold: true,
    };
    let req = pb::QueryRequest {
        scene_id: scene.clone(),
        columns: Some(columns.clone()),
        state_columns: Some(packed.clone()),
        ..Default::default()
    };
    let r = c.query(req.clone()).await.unwrap().into_inner();
    assert!(r.states.is_empty() && r.answers.is_empty());
    let cols = r.columns.unwrap();
    assert_eq!(cols.value.len(), 3 * states.len());
    let norm =
        |a: [f64; 3], b: [f64; 3]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    let mut overlapping = 0;
    for (s, (x1, x2)) in states.iter().enumerate() {
        let gaps = [norm(*x1, [0.0; 3]) - 0.75, norm(*x2, [0.0; 3]) - 0.75, norm(*x1, *x2) - 0.5];
        for (k, gap) in gaps.into_iter().enumerate() {
            let row = 3 * s + k;
            assert!(cols.converged[row], "state {s}, pair {k}");
            assert!((cols.value[row] - gap.max(0.0)).abs() < 1e-9, "state {s}, pair {k}: {} vs {gap}", cols.value[row]);
            assert_eq!(cols.overlapping[row], gap <= 0.0, "state {s}, pair {k}");
            overlapping += usize::from(gap <= 0.0);
        }
    }
    assert!(overlapping > 0 && overlapping < 3 * states.len(), "the states must cross contact: {overlapping}");
    // The same states as messages: the same answers, state by state.
    let as_states: Vec<pb::CandidateState> = states
        .iter()
        .map(|(x1, x2)| pb::CandidateState {
            poses: vec![
                pose_of(&s1, *x1),
                pb::InstancePose {
                    instance_id: s2.clone(),
                    pose: Some(pb::Pose {
                        rotation: Some(pb::Quaternion { w: h, x: 0.0, y: h, z: 0.0 }),
                        translation: Some(pb::Vec3 { x: x2[0], y: x2[1], z: x2[2] }),
                    }),
                },
            ],
        })
        .collect();
    let messages = pb::QueryRequest { state_columns: None, states: as_states, ..req.clone() };
    let per_state = c.query(messages).await.unwrap().into_inner().states;
    for (s, st) in per_state.iter().enumerate() {
        let sc = st.columns.as_ref().unwrap();
        for k in 0..3 {
            assert!((sc.value[k] - cols.value[3 * s + k]).abs() < 1e-12, "state {s}, pair {k}");
        }
    }
    // With queries instead of columns: one StateAnswers per state.
    let with_queries = pb::QueryRequest {
        columns: None,
        queries: vec![q(pb::QueryKind::Distance, &b, &s1), collide(&s1, &s2, 0.1)],
        ..req.clone()
    };
    let r = c.query(with_queries).await.unwrap().into_inner();
    assert_eq!(r.states.len(), states.len());
    for (st, (x1, x2)) in r.states.iter().zip(&states) {
        let gap = norm(*x1, [0.0; 3]) - 0.75;
        assert!((distance_of(&st.answers[0]).distance - gap.max(0.0)).abs() < 1e-9);
        assert_eq!(st.any_collision, norm(*x1, *x2) - 0.5 < 0.1);
    }
    // Refused, naming the field.
    let refused =
        |state_columns: pb::StateColumns| pb::QueryRequest { state_columns: Some(state_columns), ..req.clone() };
    let short = pb::StateColumns { poses: packed.poses[..20].to_vec(), ..packed.clone() };
    assert_status(c.query(refused(short)).await, Code::InvalidArgument, "state_columns.poses");
    let repeated = pb::StateColumns { instance_ids: vec![s1.clone(), s1.clone()], ..packed.clone() };
    assert_status(c.query(refused(repeated)).await, Code::InvalidArgument, "state_columns.instance_ids[1]");
    let mut unnormed = packed.clone();
    unnormed.poses[7 * 5] = 2.0;
    assert_status(c.query(refused(unnormed)).await, Code::InvalidArgument, "state_columns.poses[35] (state 2");
    let unknown = pb::StateColumns { instance_ids: vec![s1.clone(), "nope".into()], ..packed.clone() };
    assert_status(c.query(refused(unknown)).await, Code::NotFound, "state_columns.instance_ids[1]");
    let both = pb::QueryRequest { states: vec![pb::CandidateState::default()], ..req.clone() };
    assert_status(c.query(both).await, Code::InvalidArgument, "state_columns");
    server.stop().await;
}

/// A cold BatchQuery in columns (`PairColumns.cold`): twelve pairs of the same two bodies, solved
/// four per SIMD pass, each the closed form ‖c₁ − c₂‖ − r₁ − r₂ (0 when overlapping), and no warm
/// start left behind (the next warm query of a pair starts cold).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cold_columns_match_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let big = upload_sphere(&mut c, "r05", [0.0; 3], 0.5).await;
    let small = upload_sphere(&mut c, "r025", [0.0; 3], 0.25).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "cols".into() }).await.unwrap().into_inner().scene_id;
    let mut ids = vec![add(&mut c, &scene, &big, at([0.0; 3])).await];
    let centers: Vec<[f64; 3]> = (0..12).map(|k| [0.3 + 0.2 * k as f64, 0.1 * (k % 4) as f64, -0.3]).collect();
    for x in &centers {
        ids.push(add(&mut c, &scene, &small, at(*x)).await);
    }
    let columns = pb::PairColumns {
        kind: pb::QueryKind::Distance as i32,
        instance_ids: ids.clone(),
        first: vec![0; centers.len()],
        second: (1..=centers.len() as u32).collect(),
        margin: 0.0,
        cold: true,
    };
    let batch = pb::BatchQueryRequest { scene_id: scene.clone(), pairs: vec![], columns: Some(columns) };
    let cols = c.batch_query(batch).await.unwrap().into_inner().columns.unwrap();
    let mut overlapping = 0;
    for (k, x) in centers.iter().enumerate() {
        let gap = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt() - 0.75;
        assert!(cols.converged[k], "pair {k}");
        assert!((cols.value[k] - gap.max(0.0)).abs() < 1e-9, "pair {k}: {} vs {gap}", cols.value[k]);
        assert_eq!(cols.overlapping[k], gap <= 0.0, "pair {k}");
        overlapping += usize::from(gap <= 0.0);
    }
    assert!(overlapping > 0 && overlapping < centers.len(), "the pairs must cross contact: {overlapping}");
    // Cold answers keep no warm start: a warm query of the last pair starts cold.
    let again = c
        .distance(pb::DistanceRequest {
            scene_id: scene.clone(),
            instance_a: ids[0].clone(),
            instance_b: ids[centers.len()].clone(),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner()
        .answer
        .unwrap();
    assert!(!again.solve.unwrap().warm_started);
    server.stop().await;
}

/// CheckScene on a 10 × 10 grid of spheres (r = 0.2, spacing 1 m, so neighbors are 0.6 m apart
/// and diagonal ones 1.014 m) plus one sphere overlapping a corner: every pair within the margin,
/// exactly as brute force over all pairs finds them, with far fewer narrow-phase solves.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn check_scene_finds_what_brute_force_finds() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let ball = upload_sphere(&mut c, "ball", [0.0; 3], 0.2).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "grid".into() }).await.unwrap().into_inner().scene_id;
    let mut centers = Vec::new();
    for i in 0..10 {
        for j in 0..10 {
            centers.push([i as f64, j as f64, 0.0]);
        }
    }
    centers.push([0.1, 0.05, 0.0]);
    let mut ids = Vec::new();
    for c0 in &centers {
        ids.push(add(&mut c, &scene, &ball, at(*c0)).await);
    }
    for margin in [0.0, 0.7] {
        let r = c
            .check_scene(pb::CheckSceneRequest { scene_id: scene.clone(), margin, ..Default::default() })
            .await
            .unwrap()
            .into_inner();
        let mut expected = Vec::new();
        for a in 0..centers.len() {
            for b in a + 1..centers.len() {
                let d =
                    ((centers[a][0] - centers[b][0]).powi(2) + (centers[a][1] - centers[b][1]).powi(2)).sqrt() - 0.4;
                if d < margin || d <= 0.0 {
                    let (x, y) = if ids[a] < ids[b] { (&ids[a], &ids[b]) } else { (&ids[b], &ids[a]) };
                    expected.push((x.clone(), y.clone(), d.max(0.0)));
                }
            }
        }
        let mut got: Vec<_> = r
            .pairs
            .iter()
            .map(|p| {
                let (x, y) = if p.first < p.second { (&p.first, &p.second) } else { (&p.second, &p.first) };
                (x.clone(), y.clone(), p.distance.as_ref().unwrap().distance)
            })
            .collect();
        got.sort_by(|a, b| a.partial_cmp(b).unwrap());
        expected.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(got.len(), expected.len(), "margin {margin}");
        for (g, e) in got.iter().zip(&expected) {
            assert_eq!((&g.0, &g.1), (&e.0, &e.1));
            assert!((g.2 - e.2).abs() < 1e-8, "{g:?} vs {e:?}");
        }
        assert_eq!(r.instances, 101);
        assert_eq!(r.all_pairs, 101 * 100 / 2);
        assert!(r.narrow_phase_solves <= r.candidate_pairs && r.candidate_pairs < r.all_pairs / 10, "{r:?}");
        eprintln!(
            "CheckScene margin {margin}: {} pairs found, {} candidates, {} solves of {} pairs",
            r.pairs.len(),
            r.candidate_pairs,
            r.narrow_phase_solves,
            r.all_pairs
        );
    }
    // One instance against the rest, with a pose override that moves it next to (5, 5).
    let r = c
        .check_scene(pb::CheckSceneRequest {
            scene_id: scene.clone(),
            margin: 0.15,
            instance_ids: vec![ids[100].clone()],
            poses: vec![pose_of(&ids[100], [5.5, 5.0, 0.0])],
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(r.all_pairs, 100);
    let mut names: Vec<_> =
        r.pairs.iter().map(|p| if p.first == ids[100] { p.second.clone() } else { p.first.clone() }).collect();
    names.sort();
    let mut want = vec![ids[55].clone(), ids[65].clone()];
    want.sort();
    assert_eq!(names, want, "the moved sphere is 0.1 m from (5,5) and (6,5) and more than 0.7 m from every other");
    server.stop().await;
}

/// Queries in columns (BatchQuery and QueryStream) give the same answers as one message per pair:
/// three spheres against closed forms ‖c₁ − c₂‖ − r₁ − r₂ (witnesses on the line of centers), the
/// growth d(p₁‖p₂) = ((‖c₁ − c₂‖ − r₂)/r₁)², COLLIDE decided by bounds with NaN points, per-state
/// columns; bad columns are refused naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn columns_answer_like_pairs_and_name_bad_fields() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (scene, i1, i2) = two_spheres(&mut c).await;
    let b3 = upload_sphere(&mut c, "r01", [0.0; 3], 0.1).await;
    let i3 = add(&mut c, &scene, &b3, at([0.0, 5.0, 0.0])).await;
    let ids = vec![i1.clone(), i2.clone(), i3.clone()];
    let columns = |kind: pb::QueryKind, first: Vec<u32>, second: Vec<u32>, margin: f64| pb::PairColumns {
        kind: kind as i32,
        instance_ids: ids.clone(),
        first,
        second,
        margin,
        cold: false,
    };
    let batch = |cols: pb::PairColumns| pb::BatchQueryRequest {
        scene_id: scene.clone(),
        pairs: Vec::new(),
        columns: Some(cols),
    };
    // (i1, i2): centers 2 m apart, radii 0.5 + 0.25; (i1, i3): 5 m, 0.5 + 0.1; (i3, i2): √29 m.
    let expected = [2.0 - 0.75, 5.0 - 0.6, 29f64.sqrt() - 0.35];
    let (first, second) = (vec![0, 0, 2], vec![1, 2, 1]);
    let r = c
        .batch_query(batch(columns(pb::QueryKind::Distance, first.clone(), second.clone(), 0.0)))
        .await
        .unwrap()
        .into_inner();
    assert!(r.answers.is_empty());
    let col = r.columns.unwrap();
    assert_eq!(col.kind, pb::QueryKind::Distance as i32);
    assert_eq!((col.value.len(), col.point_a.len(), col.point_b.len()), (3, 9, 9));
    for (k, want) in expected.iter().enumerate() {
        assert!((col.value[k] - want).abs() < 1e-9, "pair {k}: {} vs {want}", col.value[k]);
        let gap: f64 = (0..3).map(|j| (col.point_a[3 * k + j] - col.point_b[3 * k + j]).powi(2)).sum::<f64>().sqrt();
        assert!((gap - want).abs() < 1e-9, "witnesses {k} are {gap} apart");
        assert!(col.converged[k] && !col.overlapping[k] && !col.lower_bound[k]);
    }
    assert!(col.decided_by_bounds.is_empty());
    // Pair 0's witness on the r = 0.5 sphere at the origin, towards i2 at (2, 0, 0).
    assert!((col.point_a[0] - 0.5).abs() < 1e-9 && col.point_a[1].abs() < 1e-9);

    // The same pairs as messages: the same values.
    let pairs = first
        .iter()
        .zip(&second)
        .map(|(&i, &j)| pb::QueryPair {
            kind: pb::QueryKind::Distance as i32,
            first: ids[i as usize].clone(),
            second: ids[j as usize].clone(),
            ..Default::default()
        })
        .collect();
    let r = c.batch_query(pb::BatchQueryRequest { scene_id: scene.clone(), pairs, columns: None }).await.unwrap();
    for (k, a) in r.into_inner().answers.iter().enumerate() {
        assert!((distance_of(a).distance - col.value[k]).abs() < 1e-12);
    }

    // Growth d(i1 ‖ i2) = ((2 − 0.25)/0.5)² = 12.25.
    let r = c.batch_query(batch(columns(pb::QueryKind::Growth, vec![0], vec![1], 0.0))).await.unwrap();
    let g = r.into_inner().columns.unwrap();
    assert!((g.value[0] - 12.25).abs() < 1e-7, "{g:?}");

    // COLLIDE with a 0.5 m margin: (i1, i2) 1.25 m apart is decided by the bounding spheres.
    let r = c.batch_query(batch(columns(pb::QueryKind::Collide, vec![0], vec![1], 0.5))).await.unwrap();
    let k = r.into_inner().columns.unwrap();
    assert_eq!(k.decided_by_bounds, vec![true]);
    assert!(!k.overlapping[0] && k.converged[0] && k.point_a.iter().all(|v| v.is_nan()));
    assert!(k.value[0] <= 1.25 + 1e-9 && k.value[0] > 0.5, "a lower bound above the margin: {}", k.value[0]);

    // Bad columns.
    let r = c.batch_query(batch(columns(pb::QueryKind::Distance, vec![0, 3], vec![1, 1], 0.0))).await;
    assert_status(r, Code::InvalidArgument, "columns.first[1]");
    let r = c.batch_query(batch(columns(pb::QueryKind::Distance, vec![0, 1], vec![1], 0.0))).await;
    assert_status(r, Code::InvalidArgument, "columns.second");
    let r = c.batch_query(batch(columns(pb::QueryKind::Collide, vec![0], vec![1], -1.0))).await;
    assert_status(r, Code::InvalidArgument, "columns.margin");
    let r = c.batch_query(batch(columns(pb::QueryKind::Unspecified, vec![0], vec![1], 0.0))).await;
    assert_status(r, Code::InvalidArgument, "columns.kind");
    let mut both = batch(columns(pb::QueryKind::Distance, vec![0], vec![1], 0.0));
    both.pairs.push(pb::QueryPair::default());
    assert_status(c.batch_query(both).await, Code::InvalidArgument, "columns");
    let mut unknown = columns(pb::QueryKind::Distance, vec![0], vec![1], 0.0);
    unknown.instance_ids[1] = "i-nope".into();
    let r = c
        .batch_query(pb::BatchQueryRequest { scene_id: scene.clone(), pairs: Vec::new(), columns: Some(unknown) })
        .await;
    assert_status(r, Code::NotFound, "i-nope");

    // A stream in columns: the view's pose moves i2 to x = 3; candidate states answer per state.
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let mut answers = c.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    let req = pb::QueryRequest {
        scene_id: scene.clone(),
        poses: vec![pose_of(&i2, [3.0, 0.0, 0.0])],
        columns: Some(columns(pb::QueryKind::Distance, vec![0], vec![1], 0.0)),
        ..Default::default()
    };
    tx.send(req).await.unwrap();
    let r = answers.message().await.unwrap().unwrap();
    assert!(r.answers.is_empty());
    assert!((r.columns.unwrap().value[0] - 2.25).abs() < 1e-9);
    let req = pb::QueryRequest {
        columns: Some(columns(pb::QueryKind::Collide, vec![0], vec![1], 0.5)),
        states: [1.0, 4.0].iter().map(|&x| pb::CandidateState { poses: vec![pose_of(&i2, [x, 0.0, 0.0])] }).collect(),
        ..Default::default()
    };
    tx.send(req).await.unwrap();
    let r = answers.message().await.unwrap().unwrap();
    let verdicts: Vec<bool> = r.states.iter().map(|s| s.columns.as_ref().unwrap().overlapping[0]).collect();
    assert_eq!(verdicts, vec![true, false], "0.25 m < 0.5 m collides, 3.25 m does not");
    assert_eq!(r.states.iter().map(|s| s.any_collision).collect::<Vec<_>>(), vec![true, false]);
}
