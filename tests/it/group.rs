//! Integration tests: containment of sublevel sets (paper §V, eqs. "p.sosconvex", "s.procedure",
//! "tau.sos") and the StartGroupJob service.

use crate::util::{add, at, config, upload_sphere, Server};
use rand::{Rng, SeedableRng};
use std::f64::consts::PI;
use sublevel::body::ellipsoid;
use sublevel::fit::containment::{contain_bodies, ContainmentSettings};
use sublevel::math::{pose_from_parts, Isometry3, Matrix3, Real, UnitQuaternion, Vector3};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::Body;
use tonic::Code;

fn demo(name: &str) -> Body {
    Body::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/demo").join(name)).unwrap()
}

/// World points on the boundary of a posed body, by bisection along `n` random rays from its
/// interior point (independent of the library's own verification sampler).
fn boundary_samples(body: &Body, pose: &Isometry3, n: usize, seed: u64) -> Vec<Vector3> {
    let posed = body.posed(pose);
    let c = posed.interior_point();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let dir = loop {
                let v =
                    Vector3::new(rng.random::<Real>() - 0.5, rng.random::<Real>() - 0.5, rng.random::<Real>() - 0.5);
                if v.norm() > 1e-3 && v.norm() <= 0.5 {
                    break v.normalize();
                }
            };
            let (mut lo, mut hi) = (0.0, 1.0);
            while posed.value(&(c + dir * hi)) <= 1.0 {
                hi *= 2.0;
            }
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if posed.value(&(c + dir * mid)) <= 1.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            c + dir * lo
        })
        .collect()
}

/// Exact volume of the sublevel set of a degree-2 body: p(x) = (x − m)ᵀA(x − m) + p_min in world
/// coordinates, volume 4/3 π (1 − p_min)^{3/2} / √det A.
fn quadric_volume(body: &Body) -> Real {
    let e = body.posed(&Isometry3::identity()).eval(&body.interior_point().coords);
    let a = e.hessian / 2.0;
    4.0 / 3.0 * PI * (1.0 - body.min_value()).powf(1.5) / a.determinant().sqrt()
}

/// Minimum volume of a spheroid x²/A² + (y² + z²)/B² ≤ 1 containing the balls of radius r at
/// ±a·eₓ: for each A > a + r the smallest B² is max over the ball's boundary
/// (x, ρ) = (a + r cos θ, r sin θ) of ρ² / (1 − x²/A²); then a golden-section search over A of
/// the volume 4/3 π A B².
fn two_ball_spheroid_volume(a: Real, r: Real) -> Real {
    let b2 = |big_a: Real| {
        let mut best: Real = 0.0;
        let n = 20_000;
        for i in 0..=n {
            let th = PI * i as Real / n as Real;
            let (x, rho) = (a + r * th.cos(), r * th.sin());
            best = best.max(rho * rho / (1.0 - x * x / (big_a * big_a)));
        }
        best
    };
    let vol = |big_a: Real| 4.0 / 3.0 * PI * big_a * b2(big_a);
    let (mut lo, mut hi) = ((a + r) * (1.0 + 1e-9), 10.0 * (a + r));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..100 {
        let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if vol(x1) < vol(x2) {
            hi = x2;
        } else {
            lo = x1;
        }
    }
    vol(0.5 * (lo + hi))
}

#[test]
fn one_ellipsoid_at_degree_2_is_that_ellipsoid() {
    let radii = Vector3::new(1.5, 1.0, 0.6);
    let center = Vector3::new(0.5, -1.0, 2.0);
    let e = ellipsoid([center.x, center.y, center.z], [radii.x, radii.y, radii.z]).unwrap();
    let rot = UnitQuaternion::from_euler_angles(0.3, -0.5, 1.1);
    let t = Vector3::new(0.2, 0.4, -0.3);
    let pose = Isometry3::from_parts(t.into(), rot);
    let settings = ContainmentSettings::default().with_degree(2).with_multiplier_degree(0).with_solver_tolerance(1e-10);
    let body = contain_bodies(&[(&e, pose)], &settings, &mut |_| {}).unwrap();

    // As for the point fit, the log-det optimum at 2d = 2 is p = 1/4 + 3/4 q, q the ellipsoid's
    // form q(x) = |diag(1/r) Rᵀ(x − t) − c/r|² (det P = det A · min p, maximal at min p = 1/4).
    let r = rot.to_rotation_matrix().into_inner();
    let inv = Matrix3::from_diagonal(&radii.map(|v| 1.0 / v));
    let q = |x: &Vector3| (inv * (r.transpose() * (x - t) - center)).norm_squared();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let world_center = r * center + t;
    let mut max_err: Real = 0.0;
    for _ in 0..500 {
        // Points of the ellipsoid scaled by 1.4 about its center (inside, on and outside the body).
        let u =
            Vector3::new(rng.random::<Real>(), rng.random::<Real>(), rng.random::<Real>()) * 2.0 - Vector3::repeat(1.0);
        let x = world_center + r * radii.component_mul(&u) * 1.4 / 3f64.sqrt();
        let want = 0.25 + 0.75 * q(&x);
        max_err = max_err.max((body.value_at(&x.into()) - want).abs() / (1.0 + want));
    }
    assert!(max_err < 1e-5, "max |p − (1/4 + 3/4 q)| / (1 + ·) = {max_err:e}");
    let rep = &body.report;
    assert_eq!(rep.method, "containment");
    assert!(rep.max_point_value <= 1.0 && rep.max_point_value > 1.0 - 1e-6, "{}", rep.max_point_value);
    assert!(rep.convexity_margin.unwrap() > 0.0);
    let exact = 4.0 / 3.0 * PI * radii.x * radii.y * radii.z;
    assert!(rep.volume_std_error < 0.01 * rep.volume);
    assert!(
        (rep.volume - exact).abs() < 3.0 * rep.volume_std_error,
        "{} vs {exact} ± {}",
        rep.volume,
        rep.volume_std_error
    );
    let solve = rep.solve.as_ref().expect("solve details");
    assert_eq!((solve.contained_bodies, solve.multiplier_degree, body.degree()), (1, Some(0), 2), "{solve:?}");
    assert!(solve.iterations > 0 && solve.frame.is_none());
}

#[test]
fn two_spheres_at_degree_2_give_the_minimum_volume_spheroid() {
    let (a, rad) = (1.0, 0.5);
    let s = ellipsoid([0.0; 3], [rad; 3]).unwrap();
    let left = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [-a, 0.0, 0.0]).unwrap();
    let right = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [a, 0.0, 0.0]).unwrap();
    let settings =
        ContainmentSettings::default().with_degree(2).with_solver_tolerance(1e-10).with_volume_samples(20_000);
    let body = contain_bodies(&[(&s, left), (&s, right)], &settings, &mut |_| {}).unwrap();
    for (k, pose) in [left, right].iter().enumerate() {
        for x in boundary_samples(&s, pose, 2000, k as u64) {
            let v = body.value_at(&x.into());
            assert!(v <= 1.0 + 1e-7, "p = {v} at {x}");
        }
    }
    // S-lemma: at 2d = 2, 2k = 0 the relaxation is exact, so the set is the minimum-volume
    // enclosing ellipsoid — by symmetry a spheroid about the x axis.
    let got = quadric_volume(&body);
    let want = two_ball_spheroid_volume(a, rad);
    assert!(((got - want) / want).abs() < 1e-3, "volume {got} vs spheroid {want}");
    // Its Hessian is diagonal with equal y and z entries (a spheroid about the x axis).
    let h = body.posed(&Isometry3::identity()).eval(&Vector3::zeros()).hessian;
    assert!((h[(1, 1)] - h[(2, 2)]).abs() < 1e-5 * h[(1, 1)] && h[(0, 1)].abs() < 1e-6 * h[(1, 1)], "{h}");
}

#[test]
fn chair_and_human_at_degree_4_contain_both_and_beat_degree_2() {
    let chair = demo("chair_101.json");
    let human = demo("human_10.json");
    let chair_pose = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]).unwrap();
    let (c, s) = ((0.25f64).cos(), (0.25f64).sin());
    let human_pose = pose_from_parts("pose", [c, 0.0, 0.0, s], [0.9, 0.1, 0.0]).unwrap();
    let pairs = [(&chair, chair_pose), (&human, human_pose)];
    let settings4 = ContainmentSettings::default().with_degree(4).with_volume_samples(50_000);
    let mut stages = Vec::new();
    let quartic = contain_bodies(&pairs, &settings4, &mut |p| stages.push(p.stage)).unwrap();
    let quadric = contain_bodies(&pairs, &settings4.clone().with_degree(2), &mut |_| {}).unwrap();
    for (k, (body, pose)) in pairs.iter().enumerate() {
        for x in boundary_samples(body, pose, 2000, 10 + k as u64) {
            let v = quartic.value_at(&x.into());
            assert!(v <= 1.0 + 1e-7, "2d = 4: p = {v} at {x} on body {k}");
            let v = quadric.value_at(&x.into());
            assert!(v <= 1.0 + 1e-7, "2d = 2: p = {v} at {x} on body {k}");
        }
    }
    let (r4, r2) = (&quartic.report, &quadric.report);
    assert!(r4.volume >= chair.report.volume && r4.volume >= human.report.volume, "{}", r4.volume);
    let exact2 = quadric_volume(&quadric);
    assert!((r2.volume - exact2).abs() < 3.0 * r2.volume_std_error, "{} vs {exact2}", r2.volume);
    assert!(r4.volume < exact2, "2d = 4 volume {} ± {} vs 2d = 2 {exact2}", r4.volume, r4.volume_std_error);
    use sublevel::fit::FitStage::*;
    // One Solve report per interior-point iteration (the fits' shared solver reports each).
    let solve_reports = stages.iter().filter(|s| **s == Solve).count();
    assert!(solve_reports > 5, "{solve_reports} Solve reports");
    stages.dedup();
    assert_eq!(stages, vec![Hull, Build, Solve, Verify, Volume, Done]);
    assert!(r4.convexity_margin.unwrap() > -1e-7, "{:?}", r4.convexity_margin);
}

// ---------------------------------------------------------------------------------------------
// Service
// ---------------------------------------------------------------------------------------------

async fn watch_to_end(c: &mut SublevelClient<tonic::transport::Channel>, job_id: String) -> Vec<pb::FitJobUpdate> {
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id }).await.unwrap().into_inner();
    let mut out = Vec::new();
    while let Some(u) = stream.message().await.unwrap() {
        out.push(u);
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn group_job_stores_the_body_and_replaces_the_instances() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = config(dir.path());
    config.fit.volume_samples = 20_000;
    let server = Server::start(config).await;
    let mut c = server.client().await;
    let ball = upload_sphere(&mut c, "ball", [0.0; 3], 0.5).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "g".into() }).await.unwrap().into_inner().scene_id;
    let i1 = add(&mut c, &scene, &ball, at([-1.0, 0.0, 0.0])).await;
    let i2 = add(&mut c, &scene, &ball, at([1.0, 0.0, 0.0])).await;

    let req = |ids: Vec<String>, degree: u32, replace: bool| pb::StartGroupJobRequest {
        scene_id: scene.clone(),
        instance_ids: ids,
        degree,
        multiplier_degree: 0,
        name: "pair".into(),
        replace,
    };
    // Without replace: the body is stored, the scene is unchanged.
    let job = c.start_group_job(req(vec![i1.clone(), i2.clone()], 2, false)).await.unwrap().into_inner().job_id;
    let updates = watch_to_end(&mut c, job).await;
    let last = updates.last().unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    let got = c.get_body(pb::GetBodyRequest { body_id: last.body_id.clone() }).await.unwrap().into_inner();
    let body = Body::from_file(serde_json::from_str(&got.body_json).unwrap()).unwrap();
    let want = two_ball_spheroid_volume(1.0, 0.5);
    assert!(((quadric_volume(&body) - want) / want).abs() < 1e-3, "{} vs {want}", quadric_volume(&body));
    let listed = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    assert!(listed.iter().any(|b| b.body_id == last.body_id), "new body listed");
    let sc = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    assert_eq!(sc.instances.len(), 2);

    // With replace (empty ids = all): one instance of the new body at identity pose remains.
    let job = c.start_group_job(req(vec![], 2, true)).await.unwrap().into_inner().job_id;
    let updates = watch_to_end(&mut c, job).await;
    let last = updates.last().unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    assert!(updates.iter().any(|u| u.message.starts_with("group: ")), "stage messages name the step");
    let sc = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    assert_eq!(sc.instances.len(), 1);
    assert_eq!(sc.instances[0].body_id, last.body_id);

    // Errors, each naming its field.
    let err = c.start_group_job(pb::StartGroupJobRequest { scene_id: "s-nope".into(), ..req(vec![], 2, false) }).await;
    assert_eq!(err.unwrap_err().code(), Code::NotFound);
    let err = c.start_group_job(req(vec![], 3, false)).await.unwrap_err();
    assert_eq!(err.code(), Code::InvalidArgument);
    assert!(err.message().contains("degree"), "{}", err.message());
    let err = c.start_group_job(pb::StartGroupJobRequest { multiplier_degree: 1, ..req(vec![], 2, false) }).await;
    let err = err.unwrap_err();
    assert!(err.code() == Code::InvalidArgument && err.message().contains("multiplier_degree"), "{err:?}");
    let only = sc.instances[0].instance_id.clone();
    let err = c.start_group_job(req(vec![only.clone(), only.clone()], 2, false)).await.unwrap_err();
    assert!(err.code() == Code::InvalidArgument && err.message().contains("instance_ids"), "{err:?}");
    let err = c.start_group_job(req(vec![i1.clone()], 2, false)).await.unwrap_err();
    assert_eq!(err.code(), Code::NotFound, "{err:?}");
    let many: Vec<String> = (0..17).map(|k| format!("i-{k}")).collect();
    let err = c.start_group_job(req(many, 2, false)).await.unwrap_err();
    assert_eq!(err.code(), Code::ResourceExhausted, "{err:?}");
    let empty = c.create_scene(pb::CreateSceneRequest { name: "e".into() }).await.unwrap().into_inner().scene_id;
    let err = c.start_group_job(pb::StartGroupJobRequest { scene_id: empty, ..req(vec![], 2, false) }).await;
    let err = err.unwrap_err();
    assert!(err.code() == Code::InvalidArgument && err.message().contains("instance_ids"), "{err:?}");
    server.stop().await;
}
