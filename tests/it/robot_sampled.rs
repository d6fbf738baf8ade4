//! Integration tests: sampled `CheckMotions` (a resolution > 0) against single-configuration
//! checks of the same samples, and checks answered on kept checkers after the scene changed.
//!
//! The fitted Panda in MotionBenchMaker's first `bookshelf_small` scene. A sampled motion's
//! samples are recomputed here (n = max(1, ⌈‖b − a‖ · resolution⌉), t = i / n) and each checked
//! alone by the in-process `RobotChecker::check`: the motion is valid exactly when none collides,
//! and otherwise its `contact_t` is the smallest colliding sample of the first rake block holding
//! one, its configuration and sample count those of that block.

use crate::util::{assert_status, config, Server};
use std::path::PathBuf;
use sublevel::robot::{rake_order, CheckOptions, FittedRobot, RobotChecker, BLOCK};
use sublevel::scene::moveit::{allowed_override, world_objects, PlanningScene};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots").join(path)
}

/// The labelled configurations of `bookshelf_small` scene 1, in file order.
fn labelled() -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(data("mbm_panda/labels_obj.csv")).unwrap();
    text.lines()
        .skip(1)
        .filter_map(|line| {
            let c: Vec<&str> = line.split(',').collect();
            (c[0] == "bookshelf_small" && c[1] == "1").then(|| c[4..11].iter().map(|v| v.parse().unwrap()).collect())
        })
        .collect()
}

fn columns(rows: &[Vec<f64>]) -> Option<pb::ConfigurationColumns> {
    Some(pb::ConfigurationColumns { joint_names: Vec::new(), values: rows.iter().flatten().copied().collect() })
}

/// Uploads the Panda and imports the scene: (robot id, scene id, the import's instances).
async fn setup(c: &mut SublevelClient<Channel>, yaml: &[u8]) -> (String, String, Vec<pb::ImportedInstance>) {
    let robot_file = std::fs::read(data("panda/panda.robot.json")).unwrap();
    let robot = c.upload_robot(pb::UploadRobotRequest { name: "panda".into(), robot_file }).await.unwrap();
    let req = pb::ImportSceneRequest {
        scene: Some(pb::import_scene_request::Scene::Yaml(yaml.to_vec())),
        ..Default::default()
    };
    let imported = c.import_scene(req).await.unwrap().into_inner();
    (robot.into_inner().robot.unwrap().robot_id, imported.scene_id, imported.instances)
}

#[tokio::test]
async fn sampled_motions_answer_as_single_checks_of_their_samples() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let yaml = std::fs::read(data("mbm_panda/scenes/bookshelf_small/scene0001.yaml")).unwrap();
    let (robot_id, scene_id, _) = setup(&mut c, &yaml).await;

    let robot = FittedRobot::load(&data("panda/panda.robot.json")).unwrap();
    let scene = PlanningScene::from_yaml(&yaml).unwrap();
    let (world, _) = world_objects(&scene).unwrap();
    let allowed = allowed_override(&scene);
    let mut checker = RobotChecker::new(&robot, world, &allowed).unwrap();
    let base = sublevel::math::Isometry3::identity();
    let verdict = CheckOptions { distance: false, ..CheckOptions::default() };

    // Motions between consecutive labelled configurations, and one motion of no length.
    let q = labelled();
    let mut starts: Vec<Vec<f64>> = q[..24].to_vec();
    let mut ends: Vec<Vec<f64>> = q[1..25].to_vec();
    starts.push(q[0].clone());
    ends.push(q[0].clone());
    let resolution = 6.0;
    let req = pb::CheckMotionsRequest {
        robot_id: robot_id.clone(),
        scene_id: scene_id.clone(),
        start: columns(&starts),
        end: columns(&ends),
        resolution,
        ..Default::default()
    };
    let got = c.check_motions(req.clone()).await.unwrap().into_inner();
    assert_eq!(got.count as usize, starts.len());
    assert_eq!(got.samples.len(), starts.len());
    let (mut valid, mut invalid) = (0, 0);
    for (m, (a, b)) in starts.iter().zip(&ends).enumerate() {
        let length = a.iter().zip(b).map(|(x, y)| (y - x) * (y - x)).sum::<f64>().sqrt();
        let n = ((length * resolution).ceil() as usize).max(1);
        let sample = |i: usize| -> Vec<f64> {
            let t = i as f64 / n as f64;
            a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect()
        };
        let collides: Vec<bool> =
            (0..=n).map(|i| i > 0 && checker.check(&sample(i), &base, &verdict).unwrap().collides).collect();
        assert!(got.decided[m], "{m}");
        assert_eq!(got.steps[m], 0, "{m}");
        assert_eq!(got.valid[m], !collides.iter().any(|&x| x), "motion {m}");
        let contact = &got.contact_configuration[7 * m..7 * m + 7];
        if got.valid[m] {
            valid += 1;
            assert_eq!(got.samples[m] as usize, n, "{m}: every sample checked");
            assert!(got.contact_t[m].is_nan() && contact.iter().all(|v| v.is_nan()), "{m}");
            assert!(got.robot_link[m].is_empty(), "{m}");
            continue;
        }
        invalid += 1;
        // The first rake block holding a colliding sample, and its smallest colliding sample.
        let order = rake_order(n, BLOCK);
        let blocks: Vec<&[usize]> = order.chunks(BLOCK).collect();
        let first = blocks.iter().position(|b| b.iter().any(|&i| collides[i])).unwrap();
        let i = blocks[first].iter().copied().filter(|&i| collides[i]).min().unwrap();
        assert_eq!(got.contact_t[m].to_bits(), (i as f64 / n as f64).to_bits(), "motion {m}");
        assert_eq!(contact, sample(i).as_slice(), "motion {m}");
        let taken: usize = blocks[..=first].iter().map(|b| b.len()).sum();
        assert_eq!(got.samples[m] as usize, taken, "motion {m}");
        assert!(got.robot_link[m].starts_with("panda_"), "{m}: {}", got.robot_link[m]);
        assert!(!got.other[m].is_empty(), "{m}");
    }
    assert!(valid >= 3 && invalid >= 3, "{valid} valid, {invalid} invalid");

    // The certified check of the same motions: a motion proven free has no colliding sample.
    let certified = c.check_motions(pb::CheckMotionsRequest { resolution: 0.0, ..req.clone() }).await.unwrap();
    let certified = certified.into_inner();
    assert!(certified.samples.iter().all(|&s| s == 0));
    for m in 0..starts.len() {
        if certified.valid[m] {
            assert!(got.valid[m], "motion {m}: proven free, yet a sample collides");
        }
    }

    // A bad resolution is refused, naming it.
    for bad in [-1.0, f64::NAN, f64::INFINITY, 1e9] {
        let req = pb::CheckMotionsRequest { resolution: bad, ..req.clone() };
        assert_status(c.check_motions(req).await, Code::InvalidArgument, "resolution");
    }
    server.stop().await;
}

#[tokio::test]
async fn checks_after_a_scene_change_answer_on_the_changed_scene() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let yaml = std::fs::read(data("mbm_panda/scenes/bookshelf_small/scene0001.yaml")).unwrap();
    let (robot_id, scene_id, instances) = setup(&mut c, &yaml).await;

    let robot = FittedRobot::load(&data("panda/panda.robot.json")).unwrap();
    let scene = PlanningScene::from_yaml(&yaml).unwrap();
    let (mut world, _) = world_objects(&scene).unwrap();
    let allowed = allowed_override(&scene);
    let base = sublevel::math::Isometry3::identity();
    let q = labelled();
    let one = |k: usize| pb::CheckConfigurationsRequest {
        robot_id: robot_id.clone(),
        scene_id: scene_id.clone(),
        configurations: columns(std::slice::from_ref(&q[k])),
        ..Default::default()
    };

    // One configuration per request (answered inline), then the same again: single checks' answers.
    let mut reference = RobotChecker::new(&robot, world.clone(), &allowed).unwrap();
    let verdict = CheckOptions { distance: false, ..CheckOptions::default() };
    let mut hits = Vec::new();
    for (k, qk) in q.iter().enumerate().take(40) {
        let want = reference.check(qk, &base, &verdict).unwrap();
        for _ in 0..2 {
            let got = c.check_configurations(one(k)).await.unwrap().into_inner();
            let verdict = (got.collides[0], got.world[0], got.self_collision[0]);
            assert_eq!(verdict, (want.collides, want.world, want.self_collision), "configuration {k}");
            assert_eq!(got.world_object[0].is_empty(), !want.world, "configuration {k}");
        }
        if want.world {
            hits.push(k);
        }
    }
    assert!(!hits.is_empty(), "some configuration hits the shelf");

    // Every shape the hit configurations touch moves 10 m up: those configurations no longer
    // touch the world, as a checker of the moved world says.
    let mut moved = Vec::new();
    for &k in &hits {
        let got = c.check_configurations(one(k)).await.unwrap().into_inner();
        moved.push(got.world_object[0].clone());
    }
    moved.sort();
    moved.dedup();
    let mut poses = Vec::new();
    for name in &moved {
        let instance = instances.iter().find(|i| &i.name == name).unwrap();
        let object = world.iter_mut().find(|o| &o.name == name).unwrap();
        object.pose.translation.vector.z += 10.0;
        let (t, r) = (object.pose.translation.vector, object.pose.rotation);
        poses.push(pb::InstancePose {
            instance_id: instance.instance_id.clone(),
            pose: Some(crate::util::pose([r.w, r.i, r.j, r.k], [t.x, t.y, t.z])),
        });
    }
    c.set_poses(pb::SetPosesRequest { scene_id: scene_id.clone(), poses }).await.unwrap();
    let mut reference = RobotChecker::new(&robot, world, &allowed).unwrap();
    for &k in &hits {
        let want = reference.check(&q[k], &base, &verdict).unwrap();
        let got = c.check_configurations(one(k)).await.unwrap().into_inner();
        assert_eq!((got.collides[0], got.world[0]), (want.collides, want.world), "configuration {k}");
        assert!(!got.world[0] || !moved.contains(&got.world_object[0]), "configuration {k}: {}", got.world_object[0]);
    }
    server.stop().await;
}
