//! Integration tests: `CheckInstanceMotions` over gRPC against closed forms — a ball moving into
//! a ball, one moving away, a fitted ball moving onto a primitive one — and bad input refused
//! naming the field.

use crate::primitives::{primitive, upload_primitive};
use crate::util::{add, assert_status, at, config, upload_sphere, Server};
use sublevel::service::pb;
use tonic::Code;
use tonic_types::StatusExt;

/// The pose columns of translations `ts` (identity rotations).
fn columns(ts: &[[f64; 3]]) -> Vec<f64> {
    ts.iter().flat_map(|t| [1.0, 0.0, 0.0, 0.0, t[0], t[1], t[2]]).collect()
}

/// Balls r = 0.5 at the origin (a), r = 0.3 at (3, 0, 0) (b) and a fitted ball r = 0.2 at
/// (0, 3, 0) (h). Motion 0 moves a 4 m along +x into b: contact when the centres are 0.8 apart,
/// t* = 2.2 / 4; motion 1 moves a 4 m along −x, away from both: free; motion 2 moves h 4 m
/// along −y onto a: contact at centre distance 0.7, t* = 2.3 / 4. Each contact within
/// tolerance / 4 m before t* (never after), with its pose and other instance; NaN and empty
/// strings where there is none.
#[tokio::test]
async fn instance_motions_answer_their_closed_forms() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let big = upload_primitive(&mut c, "big", primitive(pb::PrimitiveKind::Sphere, &[], 0.5, 0.0)).await;
    let small = upload_primitive(&mut c, "small", primitive(pb::PrimitiveKind::Sphere, &[], 0.3, 0.0)).await;
    let fitted = upload_sphere(&mut c, "fitted", [0.0; 3], 0.2).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let a = add(&mut c, &scene, &big, at([0.0; 3])).await;
    let b = add(&mut c, &scene, &small, at([3.0, 0.0, 0.0])).await;
    let h = add(&mut c, &scene, &fitted, at([0.0, 3.0, 0.0])).await;

    let tolerance = 1e-4;
    let request = pb::CheckInstanceMotionsRequest {
        scene_id: scene.clone(),
        instance_ids: vec![a.clone(), a.clone(), h.clone()],
        start_poses: columns(&[[0.0; 3], [0.0; 3], [0.0, 3.0, 0.0]]),
        end_poses: columns(&[[4.0, 0.0, 0.0], [-4.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
        tolerance,
        ..Default::default()
    };
    let r = c.check_instance_motions(request.clone()).await.unwrap().into_inner();
    assert_eq!(r.count, 3);
    assert_eq!((r.valid.as_slice(), r.decided.as_slice()), (&[false, true, false][..], &[true; 3][..]));
    assert_eq!(r.other, vec![b.clone(), String::new(), a.clone()]);
    assert_eq!(r.contact_pose.len(), 21);
    for (m, t_star) in [(0, 2.2 / 4.0), (2, 2.3 / 4.0)] {
        let t = r.contact_t[m];
        assert!(t <= t_star + 1e-12 && t_star - t <= 1.25 * tolerance / 4.0 + 1e-12, "motion {m}: {t} vs {t_star}");
        assert!(r.steps[m] >= 2, "{:?}", r.steps);
    }
    assert_eq!(&r.contact_pose[..4], &[1.0, 0.0, 0.0, 0.0]);
    assert!((r.contact_pose[4] - 4.0 * r.contact_t[0]).abs() < 1e-12);
    assert!((r.contact_pose[14 + 5] - (3.0 - 4.0 * r.contact_t[2])).abs() < 1e-12);
    assert!(r.contact_t[1].is_nan() && r.contact_pose[7..14].iter().all(|v| v.is_nan()));
    assert!(r.steps[1] >= 1);

    // Padding 0.2 m: motion 0 touches 0.2 m earlier, t* = 2.0 / 4.
    let padded = pb::CheckInstanceMotionsRequest { padding: 0.2, ..request };
    let p = c.check_instance_motions(padded).await.unwrap().into_inner();
    assert!(p.contact_t[0] <= 0.5 + 1e-12 && 0.5 - p.contact_t[0] <= 1.25 * tolerance / 4.0 + 1e-12, "{p:?}");
    server.stop().await;
}

/// On a planner stream the motions run among the stream's own poses: with b moved privately to
/// (2, 0, 0), motion 0 touches it at centre distance 0.8, t* = 1.2 / 4, while a unary Query still
/// answers t* = 2.2 / 4 among the stored poses.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn instance_motions_on_a_stream_use_its_view() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let big = upload_primitive(&mut c, "big", primitive(pb::PrimitiveKind::Sphere, &[], 0.5, 0.0)).await;
    let small = upload_primitive(&mut c, "small", primitive(pb::PrimitiveKind::Sphere, &[], 0.3, 0.0)).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let a = add(&mut c, &scene, &big, at([0.0; 3])).await;
    let b = add(&mut c, &scene, &small, at([3.0, 0.0, 0.0])).await;
    let tolerance = 1e-4;
    let motions = pb::CheckInstanceMotionsRequest {
        instance_ids: vec![a.clone()],
        start_poses: columns(&[[0.0; 3]]),
        end_poses: columns(&[[4.0, 0.0, 0.0]]),
        tolerance,
        ..Default::default()
    };
    let close = |t: f64, t_star: f64| t <= t_star + 1e-12 && t_star - t <= 1.25 * tolerance / 4.0 + 1e-12;

    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let mut answers = c.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    tx.send(pb::QueryRequest {
        scene_id: scene.clone(),
        poses: vec![pb::InstancePose { instance_id: b.clone(), pose: Some(at([2.0, 0.0, 0.0])) }],
        instance_motions: Some(motions.clone()),
        ..Default::default()
    })
    .await
    .unwrap();
    let r = answers.message().await.unwrap().unwrap().instance_motions.unwrap();
    assert!(close(r.contact_t[0], 1.2 / 4.0) && r.other == [b.clone()], "{r:?}");
    let req =
        pb::QueryRequest { scene_id: scene.clone(), instance_motions: Some(motions.clone()), ..Default::default() };
    let r = c.query(req).await.unwrap().into_inner().instance_motions.unwrap();
    assert!(close(r.contact_t[0], 2.2 / 4.0), "{r:?}");
    // Another scene is refused naming the field.
    let other = pb::CheckInstanceMotionsRequest { scene_id: "s-0000000000000000".into(), ..motions };
    tx.send(pb::QueryRequest { instance_motions: Some(other), ..Default::default() }).await.unwrap();
    assert_status(answers.message().await, Code::InvalidArgument, "instance_motions.scene_id");
    server.stop().await;
}

/// Bad input: each error names its field (INVALID_ARGUMENT with a BadRequest field violation),
/// an unknown instance is NOT_FOUND naming its entry, and a halfspace cannot move.
#[tokio::test]
async fn instance_motions_refuse_bad_input_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let big = upload_primitive(&mut c, "big", primitive(pb::PrimitiveKind::Sphere, &[], 0.5, 0.0)).await;
    let floor = pb::Primitive {
        kind: pb::PrimitiveKind::Halfspace as i32,
        normal: Some(pb::Vec3 { x: 0.0, y: 0.0, z: 1.0 }),
        ..Default::default()
    };
    let ground = upload_primitive(&mut c, "floor", floor).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let a = add(&mut c, &scene, &big, at([0.0, 0.0, 2.0])).await;
    let f = add(&mut c, &scene, &ground, at([0.0; 3])).await;
    let good = pb::CheckInstanceMotionsRequest {
        scene_id: scene.clone(),
        instance_ids: vec![a.clone(), a.clone()],
        start_poses: columns(&[[0.0, 0.0, 2.0], [0.0, 0.0, 2.0]]),
        end_poses: columns(&[[0.0, 0.0, 0.0], [1.0, 0.0, 2.0]]),
        ..Default::default()
    };
    // The floor: a ball falling 2 m touches it at z = 0.5, t* = 0.75 (default tolerance 1 mm).
    let r = c.check_instance_motions(good.clone()).await.unwrap().into_inner();
    assert!(r.contact_t[0] <= 0.75 && 0.75 - r.contact_t[0] <= 1.25e-3 / 2.0 + 1e-12, "{r:?}");
    assert_eq!((r.other[0].as_str(), r.valid[1]), (f.as_str(), true));

    let mut unit = good.end_poses.clone();
    unit[7] = 0.9;
    let cases = [
        (pb::CheckInstanceMotionsRequest { instance_ids: vec![], ..good.clone() }, "instance_ids"),
        (
            pb::CheckInstanceMotionsRequest { instance_ids: vec![a.clone(), String::new()], ..good.clone() },
            "instance_ids[1]",
        ),
        (pb::CheckInstanceMotionsRequest { start_poses: vec![1.0; 13], ..good.clone() }, "start_poses"),
        (pb::CheckInstanceMotionsRequest { end_poses: unit, ..good.clone() }, "end_poses[7] (motion 1)"),
        (pb::CheckInstanceMotionsRequest { padding: -0.1, ..good.clone() }, "padding"),
        (pb::CheckInstanceMotionsRequest { tolerance: f64::NAN, ..good.clone() }, "tolerance"),
        (
            pb::CheckInstanceMotionsRequest { instance_ids: vec![a.clone(), f.clone()], ..good.clone() },
            "instance_ids[1]",
        ),
        (pb::CheckInstanceMotionsRequest { scene_id: String::new(), ..good.clone() }, "scene_id"),
    ];
    for (request, field) in cases {
        let e = c.check_instance_motions(request).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{field}: {e:?}");
        let bad = e.get_details_bad_request().expect("BadRequest details");
        assert_eq!(bad.field_violations[0].field, field, "{bad:?}");
    }
    let unknown =
        pb::CheckInstanceMotionsRequest { instance_ids: vec![a.clone(), "i-0000000000000000".into()], ..good.clone() };
    assert_status(c.check_instance_motions(unknown).await, Code::NotFound, "instance_ids[1]");
    let no_scene = pb::CheckInstanceMotionsRequest { scene_id: "s-0000000000000000".into(), ..good };
    assert_status(c.check_instance_motions(no_scene).await, Code::NotFound, "s-0000000000000000");
    server.stop().await;
}
