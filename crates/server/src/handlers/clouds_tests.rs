//! `UpdatePointCloud` and `RemovePointCloud` through the service: frames as a ROS bridge sends
//! them (PointCloud2 bytes with an intensity field, a 16-bit depth image), checked against the
//! one-joint arm by closed forms; the scene version in every answer; the errors' fields.

use super::*;
use crate::convert as cv;
use sublevel_core::math::{pose_from_parts, Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_scene::store::MemoryStore;
use sublevel_scene::{SceneRobot, StoredPose};
use tonic::Code;

/// The arm's ball: radius 0.1 m at 0.5 m from the joint, about z.
fn arm_ball(j: Real) -> Vector3 {
    Vector3::new(0.5 * j.cos(), 0.5 * j.sin(), 0.0)
}

/// A service over a catalog holding the arm of `tests/data/arm.robot.json`, placed in a new
/// scene: (service, scene id).
fn cell(config: ServerConfig) -> (SublevelService, String) {
    let catalog = Catalog::open(Box::new(MemoryStore::new()), Default::default()).unwrap();
    let file = serde_json::from_str(include_str!("../../../../tests/data/arm.robot.json")).unwrap();
    let robot = catalog.add_robot("", file).unwrap();
    let scene = catalog.create_scene("cell").unwrap();
    let base = StoredPose::from_isometry(&Isometry3::identity());
    let record = SceneRobot { robot_id: robot.id.clone(), base, attached: vec![], link_padding: vec![] };
    catalog.set_scene_robot(&scene, record, None).unwrap();
    (SublevelService::new(Arc::new(catalog), config), scene)
}

/// The sensor: 1 m above the origin, rotated 0.8 rad about x.
fn sensor() -> Isometry3 {
    pose_from_parts("sensor", [0.4f64.cos(), 0.4f64.sin(), 0.0, 0.0], [0.1, -0.2, 1.0]).unwrap()
}

fn sensor_pb() -> pb::Pose {
    cv::pose_to_proto(&sensor())
}

/// World points as a PointCloud2 from [`sensor`]: 16-byte records (x, y, z, intensity).
fn packed(world: &[Vector3]) -> pb::PackedPoints {
    let mut data = Vec::new();
    for p in world {
        let q = sensor().inverse_transform_point(&(*p).into());
        for v in [q.x as f32, q.y as f32, q.z as f32, 7.0] {
            data.extend(v.to_le_bytes());
        }
    }
    pb::PackedPoints { data, point_step: 16, ..Default::default() }
}

fn update(
    scene: &str,
    name: &str,
    frame: pb::update_point_cloud_request::Frame,
    filter: Option<pb::CloudFilter>,
) -> Request<pb::UpdatePointCloudRequest> {
    Request::new(pb::UpdatePointCloudRequest {
        scene_id: scene.into(),
        name: name.into(),
        frame: Some(frame),
        sensor_pose: Some(sensor_pb()),
        noise_radius: Some(0.01),
        filter,
        ..Default::default()
    })
}

/// No voxel grid: every finite point kept.
fn no_voxel() -> Option<pb::CloudFilter> {
    Some(pb::CloudFilter { voxel: Some(0.0), ..Default::default() })
}

/// The scene robot checked at joint angles `js`, with distances.
async fn check(svc: &SublevelService, scene: &str, js: &[Real]) -> pb::CheckConfigurationsResponse {
    let req = pb::CheckConfigurationsRequest {
        scene_id: scene.into(),
        configurations: Some(pb::ConfigurationColumns { joint_names: vec!["j".into()], values: js.to_vec() }),
        distance: true,
        ..Default::default()
    };
    svc.check_configurations(Request::new(req)).await.unwrap().into_inner()
}

/// A ring of 60 points of radius 0.12 m about the arm's ball at j = 0 (z = 0), and two holes.
fn ring() -> Vec<Vector3> {
    (0..60)
        .map(|k| {
            let a = k as Real * std::f64::consts::TAU / 60.0;
            arm_ball(0.0) + 0.12 * Vector3::new(a.cos(), a.sin(), 0.0)
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn packed_points_become_an_obstacle_of_every_check() {
    use pb::update_point_cloud_request::Frame;
    let (svc, scene) = cell(ServerConfig::default());
    let mut points = packed(&ring());
    // Two holes: a NaN x and an infinite z.
    for bad in [f32::NAN, f32::INFINITY] {
        points.data.extend([bad, 0.0, bad, 0.0].iter().flat_map(|v| v.to_le_bytes()));
    }
    let r = svc.update_point_cloud(update(&scene, "camera", Frame::Points(points), no_voxel())).await.unwrap();
    let r = r.into_inner();
    let counts = r.counts.unwrap();
    assert_eq!((counts.input, counts.holes, counts.kept), (62, 2, 60));
    assert!(r.memory_bytes > 60 * 24 && r.seconds > 0.0);

    // The ring's points are 0.12 m from the ball's center at j = 0: 0.02 − 0.01 m from its
    // surface, a gap of 0.01 m: free; at j = 0.1 the ball's center moved 0.05 m: inside the ring.
    let got = check(&svc, &scene, &[0.0, 0.1, 1.5]).await;
    assert_eq!(got.scene_version, r.scene_version);
    let cloud = svc.catalog.get_scene(&scene).unwrap().clouds["camera"].cloud.clone();
    for (k, j) in [0.0, 0.1, 1.5].into_iter().enumerate() {
        let nearest =
            cloud.points().iter().map(|p| (Vector3::from(*p) - arm_ball(j)).norm()).fold(Real::INFINITY, Real::min);
        let gap = nearest - 0.1 - 0.01;
        assert_eq!(got.collides[k], gap <= 0.0, "j = {j}: gap {gap}");
        if gap > 0.0 {
            assert!((got.distance[k] - gap).abs() < 1e-9, "j = {j}: {} vs {gap}", got.distance[k]);
            assert_eq!(got.world_object[k], "camera");
        }
    }
    assert!(!got.collides[0] && got.collides[1] && !got.collides[2]);
    // GetScene lists it.
    let view = svc.get_scene(Request::new(pb::GetSceneRequest { scene_id: scene.clone() })).await.unwrap().into_inner();
    assert_eq!(view.scene_version, r.scene_version);
    let summary = &view.point_clouds[0];
    assert_eq!((summary.name.as_str(), summary.points, summary.noise_radius), ("camera", 60, 0.01));
    assert_eq!((summary.memory_bytes, summary.version), (r.memory_bytes, r.scene_version));

    // CheckScene: an obstacle ball near the ring is reported with the cloud.
    let ball = svc.catalog.add_primitive("ball", Primitive::Sphere { radius: 0.1 }).unwrap();
    let at = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.5, 0.3, 0.0]).unwrap();
    let obstacle = svc.catalog.add_instance(&scene, &ball, at).unwrap();
    let req = pb::CheckSceneRequest { scene_id: scene.clone(), margin: 0.2, ..Default::default() };
    let out = svc.check_scene(Request::new(req)).await.unwrap().into_inner();
    assert_eq!(out.scene_version, r.scene_version + 1);
    assert_eq!(out.robot.as_ref().unwrap().scene_version, out.scene_version);
    let pair = out.pairs.iter().find(|p| p.first == obstacle && p.second == "camera").unwrap();
    let want = cloud
        .points()
        .iter()
        .map(|p| (Vector3::from(*p) - at.translation.vector).norm())
        .fold(Real::INFINITY, Real::min)
        - 0.1
        - 0.01;
    assert!((pair.distance.as_ref().unwrap().distance - want).abs() < 1e-9);

    // Replaced by an empty frame (a valid, empty cloud): j = 0.1 is free of it.
    let empty = pb::PackedPoints::default();
    let r2 = svc.update_point_cloud(update(&scene, "camera", Frame::Points(empty), None)).await.unwrap().into_inner();
    assert_eq!(r2.scene_version, r.scene_version + 2);
    assert_eq!(r2.counts.unwrap().kept, 0);
    let got = check(&svc, &scene, &[0.1]).await;
    assert!(!got.collides[0] && got.scene_version == r2.scene_version);
    // Removed.
    let rm = pb::RemovePointCloudRequest { scene_id: scene.clone(), name: "camera".into() };
    let removed = svc.remove_point_cloud(Request::new(rm.clone())).await.unwrap().into_inner();
    assert_eq!(removed.scene_version, r2.scene_version + 1);
    assert_eq!(svc.remove_point_cloud(Request::new(rm)).await.unwrap_err().code(), Code::NotFound);
}

/// A flat wall 1 m in front of the camera (1000 mm in every pixel, 0 in two): every point at
/// z = 1 in the sensor frame, placed in the world by the sensor pose.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_depth_image_of_a_wall_lands_where_the_sensor_sees_it() {
    use pb::update_point_cloud_request::Frame;
    let (svc, scene) = cell(ServerConfig::default());
    let (w, h) = (32u32, 24u32);
    let mut depth = vec![1000u16; (w * h) as usize];
    depth[0] = 0;
    depth[100] = 0;
    let image = pb::DepthImage {
        width: w,
        height: h,
        fx: 40.0,
        fy: 40.0,
        cx: 15.5,
        cy: 11.5,
        pixels: Some(pb::depth_image::Pixels::DepthU16(depth.iter().flat_map(|v| v.to_le_bytes()).collect())),
        depth_scale: 0.0,
    };
    let r = svc.update_point_cloud(update(&scene, "wall", Frame::Depth(image), no_voxel())).await.unwrap();
    let counts = r.into_inner().counts.unwrap();
    assert_eq!((counts.input, counts.holes, counts.kept), (768, 2, 766));
    let cloud = svc.catalog.get_scene(&scene).unwrap().clouds["wall"].cloud.clone();
    for p in cloud.points() {
        let q = sensor().inverse_transform_point(&Vector3::from(*p).into());
        assert!((q.z - 1.0).abs() < 1e-6, "{q:?}");
        assert!(q.x.abs() <= 15.5 / 40.0 + 1e-6 && q.y.abs() <= 11.5 / 40.0 + 1e-6);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_frames_name_their_field() {
    use pb::update_point_cloud_request::Frame;
    let (svc, scene) = cell(ServerConfig { max_cloud_bytes: 1000, ..ServerConfig::default() });
    let points = || packed(&ring());
    let refused = |r: Result<Response<pb::UpdatePointCloudResponse>, Status>| {
        let s = r.unwrap_err();
        let field = tonic_types::StatusExt::get_details_bad_request(&s).map(|b| b.field_violations[0].field.clone());
        (s.code(), field.unwrap_or_default(), s.message().to_owned())
    };
    let bad = |f: Frame| update(&scene, "camera", f, None);
    let mut odd = points();
    odd.data.push(0);
    assert_eq!(refused(svc.update_point_cloud(bad(Frame::Points(odd))).await).1, "points.data");
    let mut off = points();
    off.z_offset = 14;
    off.x_offset = 1;
    assert_eq!(refused(svc.update_point_cloud(bad(Frame::Points(off))).await).1, "points.z_offset");
    let image = pb::DepthImage { width: 0, height: 2, fx: 1.0, fy: 1.0, ..Default::default() };
    assert_eq!(refused(svc.update_point_cloud(bad(Frame::Depth(image))).await).1, "depth.width");
    let mut no_frame = bad(Frame::Points(points()));
    no_frame.get_mut().frame = None;
    assert_eq!(refused(svc.update_point_cloud(no_frame).await).1, "frame");
    let filter = Some(pb::CloudFilter { voxel: Some(5.0), ..Default::default() });
    let voxel = update(&scene, "camera", Frame::Points(points()), filter);
    assert_eq!(refused(svc.update_point_cloud(voxel).await).1, "filter.voxel");
    let mut radius = bad(Frame::Points(points()));
    radius.get_mut().noise_radius = Some(-0.5);
    assert_eq!(refused(svc.update_point_cloud(radius).await).1, "noise_radius");
    let unnamed = update(&scene, "", Frame::Points(points()), None);
    assert_eq!(refused(svc.update_point_cloud(unnamed).await).1, "name");
    let nowhere = update("s-0000000000000000", "camera", Frame::Points(points()), None);
    assert_eq!(refused(svc.update_point_cloud(nowhere).await).0, Code::NotFound);
    // The server's cloud memory: 60 points take more than 1000 bytes.
    let (code, _, message) =
        refused(svc.update_point_cloud(update(&scene, "c", Frame::Points(points()), no_voxel())).await);
    assert_eq!(code, Code::ResourceExhausted);
    assert!(message.contains("--max-cloud-bytes") && message.contains("limit of 1000 bytes"), "{message}");
    // Nothing changed.
    assert!(svc.catalog.get_scene(&scene).unwrap().clouds.is_empty());
    assert_eq!(svc.catalog.cloud_bytes(), 0);
}

/// 200 points on a sphere of radius 0.05 m about the arm's ball at j = 1 (z = 0), and 3 lone
/// points far from everything (outliers of the bodies model).
fn blob() -> Vec<Vector3> {
    let mut points: Vec<Vector3> = (0..200)
        .map(|k| {
            // A Fibonacci sphere.
            let z = 1.0 - 2.0 * (k as Real + 0.5) / 200.0;
            let a = k as Real * 2.399_963_229_728_653;
            let s = (1.0 - z * z).sqrt();
            arm_ball(1.0) + 0.05 * Vector3::new(s * a.cos(), s * a.sin(), z)
        })
        .collect();
    points.extend([Vector3::new(-0.8, 0.0, 0.3), Vector3::new(0.0, -0.9, -0.4), Vector3::new(0.7, 0.7, 0.7)]);
    points
}

/// The bodies model through the service: the blob becomes one body and the lone points outliers;
/// the body never answers free where the blob's points collide and its distance is never over
/// theirs (it contains every inlier's ball); a repeated frame keeps the body; GetScene says the model; bad
/// settings are refused naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_bodies_model_contains_the_points_and_keeps_its_body() {
    use pb::update_point_cloud_request::Frame;
    let (svc, scene) = cell(ServerConfig::default());
    let frame = || Frame::Points(packed(&blob()));
    let sweep: Vec<Real> = (0..=72).map(|k| -3.0 + k as Real / 12.0).collect();
    // The reference: the blob's points alone (the lone points are the bodies model's outliers).
    let inliers = Frame::Points(packed(&blob()[..200]));
    svc.update_point_cloud(update(&scene, "camera", inliers, no_voxel())).await.unwrap();
    let points = check(&svc, &scene, &sweep).await;

    let bodies_request = || {
        let mut r = update(&scene, "camera", frame(), no_voxel());
        r.get_mut().model = pb::CloudModel::Bodies as i32;
        r
    };
    let first = svc.update_point_cloud(bodies_request()).await.unwrap().into_inner();
    let report = first.bodies.unwrap();
    assert_eq!((report.clusters, report.outliers, report.fitted, report.reused), (1, 3, 1, 0));
    let bodies = check(&svc, &scene, &sweep).await;
    assert_eq!(bodies.scene_version, first.scene_version);
    let (mut both, mut only_bodies) = (0, 0);
    for (k, j) in sweep.iter().enumerate() {
        if points.collides[k] {
            assert!(bodies.collides[k], "j = {}: free of the body, not of the points", j);
            both += 1;
        } else if bodies.collides[k] {
            only_bodies += 1;
        } else {
            assert!(bodies.distance[k] <= points.distance[k] + 1e-9, "j = {}", j);
            // The body hugs the points: within a few centimeters of their distance.
            assert!(bodies.distance[k] > points.distance[k] - 0.03, "j = {}", j);
        }
    }
    assert!(both >= 3 && only_bodies <= 3, "{both} colliding in both, {only_bodies} in the bodies only");

    // The same frame again: the body is kept, no fit.
    let second = svc.update_point_cloud(bodies_request()).await.unwrap().into_inner();
    let report = second.bodies.unwrap();
    assert_eq!((report.clusters, report.reused, report.fitted), (1, 1, 0));
    assert!(second.scene_version > first.scene_version);
    let view = svc.get_scene(Request::new(pb::GetSceneRequest { scene_id: scene.clone() })).await.unwrap().into_inner();
    let summary = &view.point_clouds[0];
    assert_eq!((summary.model, summary.bodies, summary.points), (pb::CloudModel::Bodies as i32, 1, 203));

    // Bad settings name their field; the stored cloud is untouched.
    let refused = |r: Result<Response<pb::UpdatePointCloudResponse>, Status>| {
        let s = r.unwrap_err();
        assert_eq!(s.code(), Code::InvalidArgument);
        tonic_types::StatusExt::get_details_bad_request(&s).map(|b| b.field_violations[0].field.clone()).unwrap()
    };
    let mut r = bodies_request();
    r.get_mut().bodies = Some(pb::CloudBodyOptions { degree: 6, ..Default::default() });
    assert_eq!(refused(svc.update_point_cloud(r).await), "bodies.degree");
    let mut r = bodies_request();
    r.get_mut().bodies = Some(pb::CloudBodyOptions { tolerance: -1.0, ..Default::default() });
    assert_eq!(refused(svc.update_point_cloud(r).await), "bodies.tolerance");
    let mut r = bodies_request();
    r.get_mut().bodies = Some(pb::CloudBodyOptions { rescale_limit: 0.5, ..Default::default() });
    assert_eq!(refused(svc.update_point_cloud(r).await), "bodies.rescale_limit");
    let mut r = bodies_request();
    r.get_mut().model = 7;
    assert_eq!(refused(svc.update_point_cloud(r).await), "model");
    assert_eq!(svc.catalog.scene_version(&scene).unwrap(), second.scene_version);
}
