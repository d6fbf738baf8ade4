//! The behaviour every [`Store`] must show, as one check that each implementation's tests run
//! (redb, PostgreSQL), and a throwaway PostgreSQL cluster for the PostgreSQL store's test.

use super::Store;
use crate::{
    BodyRecord, InstanceRecord, JobRecord, JobRecordState, MeshRecord, PlanningContext, RobotRecord, SceneMeta,
    StoredPose,
};
use sublevel_core::body::ellipsoid;

fn inst(body: &str, tx: f64) -> InstanceRecord {
    InstanceRecord {
        body_id: body.into(),
        pose: StoredPose { rotation: [1.0, 0.0, 0.0, 0.0], translation: [tx, 0.0, 0.0] },
    }
}

fn job(state: JobRecordState, created: u64) -> JobRecord {
    JobRecord {
        kind: "fit".into(),
        name: "egg".into(),
        state,
        body_id: String::new(),
        error: String::new(),
        message: String::new(),
        created_unix_ms: created,
        finished_unix_ms: 0,
    }
}

/// The mesh kept with body `b-3`: a tetrahedron (meters; the last coordinate not a short decimal,
/// so a lossy float encoding would show).
pub(crate) fn tetra() -> MeshRecord {
    MeshRecord {
        vertices: vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 1.0 / 3.0]],
        triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]],
    }
}

/// A robot record: one link holding a sphere.
fn robot() -> RobotRecord {
    let file = serde_json::json!({
        "format": "sublevel.robot.v1",
        "name": "ball",
        "urdf": "<robot name=\"ball\"><link name=\"base\"/></robot>",
        "geometries": [{
            "link": "base", "index": 0,
            "origin": {"translation": [0.0, 0.0, 0.5], "rotation": [1.0, 0.0, 0.0, 0.0]},
            "primitive": {"primitive": "sphere", "radius": 0.25}
        }]
    });
    RobotRecord { name: "ball".into(), file: serde_json::from_value(file).unwrap() }
}

/// Put / get / list / delete of bodies, scenes, instances (scoped by scene, also for ids that
/// share a prefix) and job records; a record that would not read back is refused; `open()` a
/// second time (a restart) finds everything written before. `open` must return a store over the
/// same, initially empty, data each time.
pub(crate) fn check_store(open: &dyn Fn() -> Box<dyn Store>) {
    let body = ellipsoid([0.0; 3], [1.0, 2.0, 3.0]).unwrap();
    {
        let s = open();
        assert!(s.list_bodies().unwrap().is_empty() && s.list_scenes().unwrap().is_empty());
        s.put_body("b-1", &BodyRecord::single("egg", body.to_file())).unwrap();
        s.put_body("b-2", &BodyRecord::single("two", body.to_file())).unwrap();
        s.put_body("b-3", &BodyRecord { mesh: Some(tetra()), ..BodyRecord::single("meshed", body.to_file()) }).unwrap();
        s.put_scene("s-1", &SceneMeta::named("one")).unwrap();
        // "s-10" shares the prefix "s-1": its instances must not leak into s-1.
        let mut ten = SceneMeta::named("ten");
        ten.planning = PlanningContext {
            names: [("i-c".to_owned(), "shelf#1".to_owned())].into(),
            allowed_collision: None,
            joint_positions: vec![("panda_joint1".into(), 0.25)],
            robot: Some(crate::SceneRobot {
                robot_id: "r-1".into(),
                base: crate::StoredPose { rotation: [1.0, 0.0, 0.0, 0.0], translation: [0.5, 0.0, 0.1] },
                attached: vec![crate::AttachedRecord {
                    link: "hand".into(),
                    name: "can".into(),
                    primitive: sublevel_core::primitive::Primitive::Sphere { radius: 0.03 }.to_file(),
                    origin: crate::StoredPose { rotation: [1.0, 0.0, 0.0, 0.0], translation: [0.0, 0.0, 0.1] },
                }],
                link_padding: vec![("hand".into(), 0.01)],
            }),
        };
        s.put_scene("s-10", &ten).unwrap();
        s.put_robot("r-1", &robot()).unwrap();
        s.put_robot("r-2", &robot()).unwrap();
        assert!(s.delete_robot("r-2").unwrap());
        s.put_instances("s-1", &[("i-a", &inst("b-1", 1.0)), ("i-b", &inst("b-1", 2.0))], false).unwrap();
        s.put_instances("s-10", &[("i-c", &inst("b-1", 3.0))], false).unwrap();
        s.put_instances("s-1", &[("i-b", &inst("b-1", 5.0))], true).unwrap();
        s.put_job("j-1", &job(JobRecordState::Running, 1)).unwrap();
        s.put_job("j-2", &job(JobRecordState::Succeeded, 2)).unwrap();
        s.put_job("j-3", &job(JobRecordState::Failed, 3)).unwrap();
        s.delete_jobs(&["j-3"]).unwrap();
        // Refused writes change nothing.
        let mut nan = body.to_file();
        nan.report.volume = f64::NAN;
        assert!(s.put_body("b-nan", &BodyRecord::single("nan", nan)).is_err());
        let mut bad = inst("b-1", 0.0);
        bad.pose.translation[0] = f64::INFINITY;
        assert!(s.put_instances("s-1", &[("i-bad", &bad)], true).is_err());
    }
    let s = open();
    let b = s.get_body("b-1").unwrap().unwrap();
    assert_eq!(b.name, "egg");
    assert_eq!(b.body.coefficients, body.to_file().coefficients);
    assert!(b.mesh.is_none(), "a body stored without a mesh reads back without one");
    assert_eq!(s.get_body("b-3").unwrap().unwrap().mesh, Some(tetra()), "the mesh kept with a body reads back");
    assert_eq!(s.list_bodies().unwrap().iter().map(|(k, _)| k.as_str()).collect::<Vec<_>>(), ["b-1", "b-2", "b-3"]);
    let one = s.get_scene("s-1").unwrap().unwrap();
    assert_eq!(one.meta.name, "one");
    assert_eq!(one.instances.keys().collect::<Vec<_>>(), ["i-a", "i-b"]);
    assert_eq!(one.instances["i-b"].pose.translation[0], 5.0);
    assert_eq!(s.list_scenes().unwrap().len(), 2);
    let ten = s.get_scene("s-10").unwrap().unwrap();
    assert_eq!(ten.meta.planning.names["i-c"], "shelf#1");
    assert_eq!(ten.meta.planning.joint_positions, [("panda_joint1".to_owned(), 0.25)]);
    let placed = ten.meta.planning.robot.as_ref().expect("the scene's robot is stored");
    assert_eq!((placed.robot_id.as_str(), placed.base.translation), ("r-1", [0.5, 0.0, 0.1]));
    assert_eq!(placed.attached[0].name, "can");
    assert_eq!(placed.link_padding, [("hand".to_owned(), 0.01)]);
    let robots = s.list_robots().unwrap();
    assert_eq!(robots.iter().map(|(k, _)| k.as_str()).collect::<Vec<_>>(), ["r-1"]);
    assert_eq!(robots[0].1.file.urdf, robot().file.urdf);
    assert!(s.delete_robot("r-1").unwrap());
    assert!(!s.delete_robot("r-1").unwrap());
    let jobs = s.list_jobs().unwrap();
    assert_eq!(jobs.iter().map(|(k, _)| k.as_str()).collect::<Vec<_>>(), ["j-1", "j-2"]);
    assert_eq!(jobs[0].1, job(JobRecordState::Running, 1));

    s.replace_instances("s-1", &["i-a"], &[("i-d", &inst("b-2", 7.0))]).unwrap();
    let one = s.get_scene("s-1").unwrap().unwrap();
    assert_eq!(one.instances.keys().collect::<Vec<_>>(), ["i-b", "i-d"]);
    assert!(s.delete_instance("s-1", "i-b").unwrap());
    assert!(!s.delete_instance("s-1", "i-b").unwrap());
    assert!(s.delete_scene("s-1").unwrap());
    assert!(!s.delete_scene("s-1").unwrap());
    assert!(s.get_scene("s-1").unwrap().is_none());
    let ten = s.get_scene("s-10").unwrap().unwrap();
    assert_eq!(ten.instances.len(), 1, "deleting s-1 must keep the instances of s-10");
    assert!(s.delete_body("b-1").unwrap());
    assert!(s.get_body("b-1").unwrap().is_none());
    assert!(!s.delete_body("b-1").unwrap());
    assert!(s.quarantined().unwrap().is_empty());
}

/// A PostgreSQL cluster in a temporary directory on a loopback port, stopped on drop.
#[cfg(feature = "postgres")]
pub(crate) struct TempPostgres {
    dir: tempfile::TempDir,
    bin: std::path::PathBuf,
    root: bool,
    /// `postgres://…` URL of its `postgres` database.
    pub(crate) url: String,
}

#[cfg(feature = "postgres")]
impl TempPostgres {
    /// Starts one with `initdb` and `pg_ctl` from `/usr/lib/postgresql/*/bin` (or `PG_BIN`).
    /// `Ok(Err(reason))` when no PostgreSQL binaries are installed (the caller skips);
    /// `Err(reason)` when they are but the cluster does not start (the caller fails). As root the
    /// cluster runs as the `postgres` user (PostgreSQL refuses to run as root).
    pub(crate) fn start() -> Result<Result<Self, String>, String> {
        use std::process::Command;
        let bin = match std::env::var_os("PG_BIN") {
            Some(p) => std::path::PathBuf::from(p),
            None => {
                let Ok(entries) = std::fs::read_dir("/usr/lib/postgresql") else {
                    return Ok(Err("no /usr/lib/postgresql (install the Debian package postgresql)".into()));
                };
                let mut found: Vec<_> = entries
                    .filter_map(|e| e.ok().map(|e| e.path().join("bin")))
                    .filter(|p| p.join("initdb").exists())
                    .collect();
                found.sort();
                match found.pop() {
                    Some(bin) => bin,
                    None => return Ok(Err("no initdb under /usr/lib/postgresql/*/bin".into())),
                }
            }
        };
        let root = Command::new("id").arg("-u").output().map(|o| o.stdout.starts_with(b"0\n")).unwrap_or(false);
        let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
        let port =
            std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map_err(|e| e.to_string())?.port();
        let data = dir.path().join("data");
        if root {
            let ok = Command::new("chown").args(["postgres:postgres"]).arg(dir.path()).status();
            if !ok.is_ok_and(|s| s.success()) {
                return Err("cannot chown the cluster directory to postgres".into());
            }
        }
        let run = |args: Vec<String>| -> Result<(), String> {
            let mut cmd = if root {
                let mut c = Command::new("runuser");
                c.args(["-u", "postgres", "--"]);
                c
            } else {
                Command::new(bin.join(&args[0]))
            };
            if root {
                cmd.arg(bin.join(&args[0]));
            }
            let out = cmd.args(&args[1..]).output().map_err(|e| format!("{}: {e}", args[0]))?;
            if !out.status.success() {
                return Err(format!("{} failed: {}", args[0], String::from_utf8_lossy(&out.stderr)));
            }
            Ok(())
        };
        let data_s = data.display().to_string();
        run(vec![
            "initdb".into(),
            "-D".into(),
            data_s.clone(),
            "-U".into(),
            "postgres".into(),
            "-A".into(),
            "trust".into(),
        ])?;
        let opts = format!("-c listen_addresses=127.0.0.1 -p {port} -k {}", dir.path().display());
        let log = dir.path().join("log").display().to_string();
        run(vec![
            "pg_ctl".into(),
            "-D".into(),
            data_s,
            "-l".into(),
            log,
            "-o".into(),
            opts,
            "-w".into(),
            "start".into(),
        ])?;
        Ok(Ok(Self { dir, bin, root, url: format!("postgres://postgres@127.0.0.1:{port}/postgres") }))
    }
}

#[cfg(feature = "postgres")]
impl Drop for TempPostgres {
    fn drop(&mut self) {
        let pg_ctl = self.bin.join("pg_ctl");
        let data = self.dir.path().join("data");
        let mut cmd = if self.root {
            let mut c = std::process::Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(pg_ctl);
            c
        } else {
            std::process::Command::new(pg_ctl)
        };
        let _ = cmd.arg("-D").arg(data).args(["-m", "immediate", "stop"]).output();
    }
}
