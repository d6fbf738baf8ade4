//! Integration tests: robots on the command line. `sublevel robot check` answers the MotionBenchMaker
//! Panda's labelled configurations as pinocchio + coal do on the OBJ meshes (verdicts, world and
//! self, minimum distance to 10 µm); `sublevel robot fit` writes a robot file from a URDF and
//! refuses what it cannot read, naming the URDF element.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

fn sublevel(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_sublevel")).args(args).output().unwrap()
}

fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path).to_str().unwrap().to_owned()
}

#[test]
fn robot_check_answers_the_labelled_configurations_of_a_scene() {
    let labels = std::fs::read_to_string(repo("data/robots/mbm_panda/labels_obj.csv")).unwrap();
    let header: Vec<&str> = labels.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = labels
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| r[0] == "cage" && r[1] == "2")
        .collect();
    assert_eq!(rows.len(), 200);
    let dir = tempfile::tempdir().unwrap();
    let configs: PathBuf = dir.path().join("q.csv");
    let mut text =
        String::from("panda_joint1,panda_joint2,panda_joint3,panda_joint4,panda_joint5,panda_joint6,panda_joint7\n");
    for r in &rows {
        text.push_str(&r[col("q1")..=col("q7")].join(","));
        text.push('\n');
    }
    std::fs::write(&configs, text).unwrap();
    let out = sublevel(&[
        "robot",
        "check",
        &repo("data/robots/panda/panda.robot.json"),
        "--scene",
        &repo("data/robots/mbm_panda/scenes/cage/scene0002.yaml"),
        "--configs",
        configs.to_str().unwrap(),
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let answers: Vec<Value> =
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(answers.len(), rows.len());
    let (mut colliding, mut free) = (0, 0);
    for (a, r) in answers.iter().zip(&rows) {
        let flag = |name: &str| r[col(name)] == "1";
        assert_eq!(a["collides"], flag("collides"), "{r:?}");
        assert_eq!(a["world"], flag("collides_world"), "{r:?}");
        assert_eq!(a["self"], flag("collides_self"), "{r:?}");
        assert_eq!(a["converged"], true);
        if flag("collides_world") {
            colliding += 1;
            assert_eq!(a["distance"].as_f64(), Some(0.0));
        } else {
            free += 1;
            let mesh: f64 = r[col("min_world_dist_m")].parse().unwrap();
            let ours = a["distance"].as_f64().unwrap();
            assert!((ours - mesh).abs() < 1e-5, "{r:?}: {ours} vs {mesh}");
            let pair = a["pair"].as_array().unwrap();
            assert!(pair[0].as_str().unwrap().starts_with("panda_"), "{pair:?}");
        }
    }
    assert!(colliding > 20 && free > 20, "{colliding} colliding, {free} free");
}

#[test]
fn robot_fit_writes_a_robot_file_and_names_what_it_cannot_read() {
    let dir = tempfile::tempdir().unwrap();
    let cube = "v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5\nv -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    std::fs::create_dir_all(dir.path().join("pkg/meshes")).unwrap();
    std::fs::write(dir.path().join("pkg/meshes/cube.obj"), cube).unwrap();
    let urdf = r#"<robot name="two"><link name="a"><collision><geometry><mesh filename="package://pkg/meshes/cube.obj" scale="0.1 0.1 0.1"/></geometry></collision></link>
      <link name="b"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
      <joint name="j" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"#;
    let urdf_path = dir.path().join("two.urdf");
    std::fs::write(&urdf_path, urdf).unwrap();
    let out_path = dir.path().join("two.robot.json");
    let cache = dir.path().join("cache");
    let fit = |package_dir: &str| {
        sublevel(&[
            "robot",
            "fit",
            urdf_path.to_str().unwrap(),
            "--package-dir",
            package_dir,
            "--tolerance",
            "0.1",
            "--max-parts",
            "2",
            "--cache",
            cache.to_str().unwrap(),
            "--output",
            out_path.to_str().unwrap(),
        ])
    };
    let missing = fit(dir.path().join("elsewhere").to_str().unwrap());
    assert!(!missing.status.success());
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(stderr.contains("urdf.link[a].collision[0].mesh") && stderr.contains("not found"), "{stderr}");
    let ok = fit(dir.path().to_str().unwrap());
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let robot = sublevel::robot::FittedRobot::load(&out_path).unwrap();
    assert_eq!(robot.model.variable_names(), vec!["j"]);
    assert_eq!(robot.geometries.len(), 2);
    assert_eq!(robot.self_pairs, vec![(0, 1)]);
    // The pair is moved by one joint: the fit built its clearance table.
    assert_eq!(robot.clearance.len(), 1);
    // A configuration CSV naming a joint the robot lacks is refused, naming the header cell.
    let q = dir.path().join("q.csv");
    std::fs::write(&q, "k\n0.1\n").unwrap();
    let bad = sublevel(&["robot", "check", out_path.to_str().unwrap(), "--configs", q.to_str().unwrap()]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("configs.header[0]"));
    // The sphere link, turned 1 rad about y at 0.3 m above the cube: free of it (no world: no distance).
    std::fs::write(&q, "j\n1.0\n").unwrap();
    let out = sublevel(&["robot", "check", out_path.to_str().unwrap(), "--configs", q.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let a: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((a["collides"].as_bool(), a["self"].as_bool()), (Some(false), Some(false)));
}

#[test]
fn robot_plan_times_its_path_within_the_joint_limits_and_prints_moveit_yaml() {
    let args = |extra: &[&str]| {
        let mut a = vec![
            "robot".to_owned(),
            "plan".to_owned(),
            repo("data/robots/panda/panda.robot.json"),
            "--scene".to_owned(),
            repo("data/robots/mbm_panda/scenes/box/scene0001.yaml"),
            "--request".to_owned(),
            repo("data/robots/mbm_panda/requests/box/request0001.yaml"),
            "--timeout".to_owned(),
            "30".to_owned(),
            "--trajectory".to_owned(),
            "--joint-limits".to_owned(),
            repo("data/robots/panda/joint_limits.yaml"),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let run = |extra: &[&str]| {
        let a = args(extra);
        let out = sublevel(&a.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        out
    };
    let out = run(&["--json", "--sample-dt", "0.001"]);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["status"], "solved");
    let t = &v["trajectory"];
    assert_eq!(t["certified"], true);
    let reals = |x: &Value| x.as_array().unwrap().iter().map(|y| y.as_f64().unwrap()).collect::<Vec<f64>>();
    let rows = |x: &Value| x.as_array().unwrap().iter().map(reals).collect::<Vec<_>>();
    let (vmax, amax) = (reals(&t["max_velocity"]), reals(&t["max_acceleration"]));
    // The Panda's joint_limits.yaml.
    assert_eq!(vmax, [2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]);
    assert_eq!(amax, [3.75, 1.875, 2.5, 3.125, 3.75, 5.0, 5.0]);
    let (q, qd, qdd, time) =
        (rows(&t["positions"]), rows(&t["velocities"]), rows(&t["accelerations"]), reals(&t["time_from_start"]));
    let path = rows(&v["path"]);
    assert_eq!(q[0], path[0]);
    assert_eq!(q.last(), path.last());
    assert!(qd[0].iter().chain(qd.last().unwrap()).all(|x| *x == 0.0));
    assert_eq!(*time.last().unwrap(), t["duration"].as_f64().unwrap());
    for (v, a) in qd.iter().zip(&qdd) {
        for j in 0..7 {
            assert!(v[j].abs() <= vmax[j] * (1.0 + 1e-6) && a[j].abs() <= amax[j] * (1.0 + 1e-6));
        }
    }
    // The same trajectory as MoveIt's RobotTrajectory YAML, every 0.25 s.
    let yaml = String::from_utf8(run(&["--moveit", "--sample-dt", "0.25"]).stdout).unwrap();
    assert!(yaml.starts_with("joint_trajectory:\n  joint_names: [panda_joint1, "), "{yaml}");
    let points = yaml.matches("- positions: [").count();
    let duration = t["duration"].as_f64().unwrap();
    assert_eq!(points, (duration / 0.25).ceil() as usize + 1);
    assert!(yaml.contains("time_from_start: {sec: 0, nanosec: 0}"));
    // A bad setting names its flag.
    let out = sublevel(&args(&["--velocity-scaling", "2"]).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--velocity-scaling"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
