//! Integration tests: the robot surface refuses what a hostile or careless client sends, over
//! gRPC against a real server. Mesh names never reach the server's disk; a robot over the size
//! limits is refused before a job exists; `CancelFitJob` stops a robot fit in its mesh stage;
//! a robot file edited after it was written is refused; joint values outside the URDF limits are
//! refused wherever configurations enter (checks, motions, a scene's joint positions).

use crate::util::{assert_status, config, Server};
use std::collections::HashMap;
use std::path::PathBuf;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots").join(path)
}

/// The unit cube [−0.5, 0.5]³ (OBJ quads).
const CUBE: &str = "v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5\n\
v -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5\n\
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";

/// A one-link robot whose only geometry is the mesh `name`.
fn one_mesh_urdf(name: &str) -> String {
    format!(
        r#"<robot name="probe"><link name="base"><collision><geometry><mesh filename="{name}" scale="0.2 0.2 0.2"/></geometry></collision></link></robot>"#
    )
}

fn fit_request(urdf: String, meshes: HashMap<String, Vec<u8>>) -> pb::StartRobotFitJobRequest {
    pb::StartRobotFitJobRequest {
        name: String::new(),
        urdf,
        srdf: String::new(),
        meshes,
        tolerance: 0.2,
        max_parts: 2,
        leaves: false,
    }
}

/// A URDF mesh named `file:///ABS`, an absolute path, a `..` path or another URL scheme is
/// refused before a job exists, whatever the request's `meshes` keys say — even when the named
/// file exists on the server's disk and is a valid mesh: the server reads only the bytes the
/// request carries, by the exact name. A name refused for what it is never says whether a file
/// exists there.
#[tokio::test]
async fn mesh_names_never_reach_the_servers_disk() {
    let dir = tempfile::tempdir().unwrap();
    let on_disk = dir.path().join("real_cube.obj");
    std::fs::write(&on_disk, CUBE).unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let abs = on_disk.display().to_string();
    let missing = dir.path().join("missing.obj").display().to_string();
    for name in [
        format!("file://{abs}"),
        abs.clone(),
        format!("file://{missing}"),
        "../../etc/passwd.obj".to_owned(),
        "meshes/../../x.obj".to_owned(),
        "http://host/x.obj".to_owned(),
        "package://onlypackage".to_owned(),
        "C:\\meshes\\x.obj".to_owned(),
    ] {
        let meshes: HashMap<String, Vec<u8>> = [(name.clone(), b"garbage".to_vec())].into();
        let e = c.start_robot_fit_job(fit_request(one_mesh_urdf(&name), meshes)).await.expect_err(&name);
        assert_eq!(e.code(), Code::InvalidArgument, "{name}: {e:?}");
        assert!(e.message().contains("a mesh name must be"), "{name}: {}", e.message());
        assert!(!e.message().contains("not found") && !e.message().contains("searched"), "{}", e.message());
        assert!(
            !e.message().contains(&dir.path().display().to_string()[1..])
                || name.contains(&abs)
                || name.contains(&missing)
        );
    }
    // The same URDF name with a safe spelling fits the bytes sent, not a file of the disk: a
    // garbage body under the name fails as garbage, naming the mesh, without the data directory.
    let name = "meshes/real_cube.obj";
    let meshes: HashMap<String, Vec<u8>> = [(name.to_owned(), b"garbage".to_vec())].into();
    let job_id = c.start_robot_fit_job(fit_request(one_mesh_urdf(name), meshes)).await.unwrap().into_inner().job_id;
    let updates = crate::util::watch_to_end(&mut c, job_id).await;
    let last = updates.last().unwrap();
    assert_eq!(last.state, pb::JobState::Failed as i32, "{last:?}");
    assert!(last.error.contains("urdf.link[base].collision[0].mesh"), "{}", last.error);
    assert!(!last.error.contains(&dir.path().display().to_string()), "the data directory leaked: {}", last.error);
    server.stop().await;
}

/// A URDF over the size limits (600 links on fixed joints) is refused with RESOURCE_EXHAUSTED
/// before a job exists, by StartRobotFitJob and UploadRobot alike.
#[tokio::test]
async fn robots_over_the_size_limits_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let n = sublevel::robot::limits::MAX_LINKS + 88;
    let mut urdf = String::from(r#"<robot name="long"><link name="l0"/>"#);
    for i in 1..n {
        urdf.push_str(&format!(
            r#"<link name="l{i}"><collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link><joint name="j{i}" type="fixed"><parent link="l{}"/><child link="l{i}"/><origin xyz="0.1 0 0"/></joint>"#,
            i - 1
        ));
    }
    urdf.push_str("</robot>");
    let e = c.start_robot_fit_job(fit_request(urdf.clone(), HashMap::new())).await.unwrap_err();
    assert_eq!(e.code(), Code::ResourceExhausted, "{e:?}");
    assert!(e.message().contains(&format!("{n} links")) && e.message().contains("limit of 512"), "{}", e.message());
    let jobs = c.list_fit_jobs(pb::ListFitJobsRequest::default()).await.unwrap().into_inner();
    assert!(jobs.jobs.is_empty(), "no job may exist: {jobs:?}");
    // The same robot as a robot file.
    let file = serde_json::json!({"format": "sublevel.robot.v1", "name": "long", "urdf": urdf, "geometries": []});
    let req = pb::UploadRobotRequest { name: "long".into(), robot_file: file.to_string().into_bytes() };
    assert_status(c.upload_robot(req).await, Code::ResourceExhausted, "links");
    server.stop().await;
}

/// `CancelFitJob` reaches the mesh fits, which run on their own threads: the job is CANCELLED
/// when the call returns, nothing is stored, and the fitting slot is free again (a second job
/// runs to its end).
#[tokio::test]
async fn cancel_reaches_a_robot_fits_mesh_stage() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    // 24 links, each a distinct mesh (by scale), fitted as trees of up to 8 leaves at a tight
    // tolerance: minutes of SDPs.
    let mut urdf = String::from(r#"<robot name="many"><link name="l0"/>"#);
    for i in 1..=24 {
        let s = 0.1 + 0.01 * i as f64;
        urdf.push_str(&format!(
            r#"<link name="l{i}"><collision><geometry><mesh filename="meshes/cube.obj" scale="{s} {} {}"/></geometry></collision></link><joint name="j{i}" type="fixed"><parent link="l0"/><child link="l{i}"/><origin xyz="{} 0 0"/></joint>"#,
            s * 1.3,
            s * 0.7,
            i as f64
        ));
    }
    urdf.push_str("</robot>");
    let meshes: HashMap<String, Vec<u8>> = [("meshes/cube.obj".to_owned(), CUBE.as_bytes().to_vec())].into();
    let mut req = fit_request(urdf, meshes.clone());
    req.tolerance = 1e-4;
    req.max_parts = 8;
    req.leaves = true;
    let job_id = c.start_robot_fit_job(req).await.unwrap().into_inner().job_id;
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id: job_id.clone() }).await.unwrap().into_inner();
    // Wait until the fit is running (its first mesh under way or done).
    while let Some(u) = stream.message().await.unwrap() {
        if u.stage != pb::FitStage::Queued as i32 {
            break;
        }
    }
    let t = std::time::Instant::now();
    let job = c.cancel_fit_job(pb::CancelFitJobRequest { job_id: job_id.clone() }).await.unwrap().into_inner();
    let job = job.job.unwrap();
    assert_eq!(job.state, pb::JobState::Cancelled as i32, "after {:?}: {job:?}", t.elapsed());
    let robots = c.list_robots(pb::ListRobotsRequest::default()).await.unwrap().into_inner();
    assert!(robots.robots.is_empty(), "{robots:?}");
    // The slot is free: a small fit runs to its end.
    let small = one_mesh_urdf("meshes/cube.obj");
    let job_id = c.start_robot_fit_job(fit_request(small, meshes)).await.unwrap().into_inner().job_id;
    let last = crate::util::watch_to_end(&mut c, job_id).await.pop().unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    server.stop().await;
}

/// Uploads a changed copy of the fitted Panda's file and asserts the refusal names `field`.
async fn refused(c: &mut SublevelClient<Channel>, file: &serde_json::Value, field: &str) {
    let req = pb::UploadRobotRequest { name: "edited".into(), robot_file: file.to_string().into_bytes() };
    assert_status(c.upload_robot(req).await, Code::InvalidArgument, field);
}

/// A robot file changed after it was written is refused, naming what changed: its clearance
/// tables' cells overwritten, a mesh's SHA-256 zeroed, two geometries' links swapped, a mesh
/// scale of zero or mirrored, a geometry origin far away or with a non-unit quaternion, a
/// halfspace for a link mesh, or no digest at all. The file as written uploads, and the digest
/// is the same after a JSON round trip.
#[tokio::test]
async fn robot_files_edited_after_they_were_written_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let text = std::fs::read_to_string(data("panda/panda.robot.json")).unwrap();
    let file: serde_json::Value = serde_json::from_str(&text).unwrap();
    let parsed: sublevel::robot::RobotFile = serde_json::from_str(&text).unwrap();
    assert_eq!(parsed.digest().unwrap(), parsed.integrity);
    assert!(parsed.integrity.starts_with("sha256:"));

    let tables = file["clearance"].as_array().unwrap().len();
    assert!(tables > 0);
    for k in [0, tables - 1] {
        let mut f = file.clone();
        // 0xFF in every cell: the largest clearance, "free" everywhere (base64 of 0xFF bytes:
        // `////` per three, `//8=` for two left, `/w==` for one).
        let text = f["clearance"][k]["data"].as_str().unwrap().to_owned();
        let n = text.len() / 4 * 3 - text.bytes().rev().take_while(|&b| b == b'=').count();
        let tail = ["", "/w==", "//8="][n % 3];
        let ff = format!("{}{tail}", "////".repeat(n / 3));
        assert_eq!(ff.len(), text.len());
        f["clearance"][k]["data"] = ff.into();
        refused(&mut c, &f, "integrity").await;
    }
    let first_mesh = file["geometries"].as_array().unwrap().iter().position(|g| g.get("mesh").is_some()).unwrap();
    let mut f = file.clone();
    f["geometries"][first_mesh]["mesh"]["sha256"] = "0".repeat(64).into();
    refused(&mut c, &f, "integrity").await;
    let mut f = file.clone();
    let (l0, l1) = (f["geometries"][0]["link"].clone(), f["geometries"][1]["link"].clone());
    f["geometries"][0]["link"] = l1;
    f["geometries"][1]["link"] = l0;
    refused(&mut c, &f, "geometries[0].").await;
    for scale in [[0.0, 0.0, 0.0], [-1.0, 1.0, 1.0]] {
        let mut f = file.clone();
        f["geometries"][first_mesh]["mesh"]["scale"] = serde_json::json!(scale);
        refused(&mut c, &f, &format!("geometries[{first_mesh}].mesh")).await;
    }
    let mut f = file.clone();
    f["geometries"][0]["origin"]["translation"] = serde_json::json!([1e300, 0.0, 0.0]);
    refused(&mut c, &f, "geometries[0].origin").await;
    let mut f = file.clone();
    f["geometries"][0]["origin"]["rotation"] = serde_json::json!([2.0, 0.0, 0.0, 0.0]);
    refused(&mut c, &f, "geometries[0].origin").await;
    let mut f = file.clone();
    let g = f["geometries"][first_mesh].as_object_mut().unwrap();
    g.remove("mesh");
    g.remove("compound");
    g.insert("primitive".into(), serde_json::json!({"primitive": "halfspace", "normal": [0, 0, 1], "offset": 0}));
    refused(&mut c, &f, &format!("geometries[{first_mesh}].mesh")).await;
    let mut f = file.clone();
    f.as_object_mut().unwrap().remove("integrity");
    refused(&mut c, &f, "integrity").await;

    // The file as written, and as re-serialized, uploads.
    let req = pb::UploadRobotRequest { name: "panda".into(), robot_file: text.into_bytes() };
    c.upload_robot(req).await.unwrap();
    let again = serde_json::to_vec(&parsed).unwrap();
    c.upload_robot(pb::UploadRobotRequest { name: "panda2".into(), robot_file: again }).await.unwrap();
    server.stop().await;
}

const JOINTS: [&str; 7] =
    ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", "panda_joint6", "panda_joint7"];

fn columns(names: &[&str], values: &[f64]) -> Option<pb::ConfigurationColumns> {
    Some(pb::ConfigurationColumns {
        joint_names: names.iter().map(|s| (*s).to_owned()).collect(),
        values: values.to_vec(),
    })
}

/// Joint values outside the URDF limits are refused, naming the value, by CheckConfigurations
/// (10 rad, 1e300, the upper limit + 1e-7; a few ulps past is rounding, admitted), CheckMotions (an end 100 rad away; an end naming
/// other joints than its start) and SetJointPositions (100 rad, and the stored positions stay);
/// the limits themselves are accepted.
#[tokio::test]
async fn joint_values_outside_the_urdf_limits_are_refused_where_configurations_enter() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let bytes = std::fs::read(data("panda/panda.robot.json")).unwrap();
    let robot = c
        .upload_robot(pb::UploadRobotRequest { name: "panda".into(), robot_file: bytes })
        .await
        .unwrap()
        .into_inner()
        .robot
        .unwrap();
    let (lower, upper) = (robot.lower.clone(), robot.upper.clone());
    let mid: Vec<f64> = lower.iter().zip(&upper).map(|(l, u)| 0.5 * (l + u)).collect();
    let check = |values: Vec<f64>| pb::CheckConfigurationsRequest {
        robot_id: robot.robot_id.clone(),
        configurations: columns(&JOINTS, &values),
        ..Default::default()
    };
    // Past a limit by more than rounding (LIMIT_ROUNDING · max(1, |bound|), 1e-9 relative): refused.
    for (k, v) in [(0, 10.0), (2, 1e300), (3, upper[3] + 1e-7), (5, lower[5] - 1e-7)] {
        let mut q = mid.clone();
        q.extend(mid.iter().copied());
        q[7 + k] = v;
        let e = c.check_configurations(check(q)).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        assert!(e.message().contains(&format!("configurations.values[{}]", 7 + k)), "{}", e.message());
        assert!(e.message().contains(JOINTS[k]) && e.message().contains("limits"), "{}", e.message());
    }
    // The limits themselves are states, and so are values rounded a few ulps past them.
    let answer = c.check_configurations(check([lower.clone(), upper.clone()].concat())).await.unwrap().into_inner();
    assert_eq!(answer.collides.len(), 2);
    let rounded: Vec<f64> = lower.iter().map(|v| v - 1e-15).chain(upper.iter().map(|v| v + 1e-15)).collect();
    let answer = c.check_configurations(check(rounded)).await.unwrap().into_inner();
    assert_eq!(answer.collides.len(), 2);

    let motion = |start: Option<pb::ConfigurationColumns>, end| pb::CheckMotionsRequest {
        robot_id: robot.robot_id.clone(),
        start,
        end,
        ..Default::default()
    };
    let mut far = mid.clone();
    far[0] += 100.0;
    assert_status(
        c.check_motions(motion(columns(&JOINTS, &mid), columns(&JOINTS, &far))).await,
        Code::InvalidArgument,
        "end.values[0]",
    );
    assert_status(
        c.check_motions(motion(columns(&JOINTS[..2], &mid[..2]), columns(&JOINTS[2..4], &mid[2..4]))).await,
        Code::InvalidArgument,
        "end.joint_names",
    );

    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    c.set_scene_robot(pb::SetSceneRobotRequest {
        scene_id: scene.clone(),
        robot_id: robot.robot_id.clone(),
        joint_positions: columns(&JOINTS, &mid),
        ..Default::default()
    })
    .await
    .unwrap();
    assert_status(
        c.set_joint_positions(pb::SetJointPositionsRequest {
            scene_id: scene.clone(),
            joint_positions: columns(&["panda_joint4"], &[100.0]),
        })
        .await,
        Code::InvalidArgument,
        "joint_positions.values[0]",
    );
    let kept = c.get_scene(pb::GetSceneRequest { scene_id: scene }).await.unwrap().into_inner();
    let j4 = kept.joint_positions.iter().find(|j| j.name == "panda_joint4").unwrap();
    assert_eq!(j4.position, mid[3]);
    server.stop().await;
}
