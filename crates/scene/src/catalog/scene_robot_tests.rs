//! The robot of a scene against closed forms: a one-joint arm whose ball sweeps a circle about
//! its base, placed, moved, given an attached ball, and read back after a restart.

use super::*;
use crate::store::RedbStore;
use crate::{AttachedRecord, SceneRobot, StoredPose};
use sublevel_core::math::pose_from_parts;
use sublevel_core::primitive::Primitive;
use sublevel_robot::{CheckOptions, RobotFile};

/// The one-joint arm of `tests/data/arm.robot.json`: a revolute joint `j` about z at the base;
/// link `arm` holds a ball of radius 0.1 m at (0.5, 0, 0) in its frame.
fn arm() -> RobotFile {
    serde_json::from_str(include_str!("../../../../tests/data/arm.robot.json")).unwrap()
}

fn open(dir: &std::path::Path) -> Catalog {
    Catalog::open(Box::new(RedbStore::open_dir(dir).unwrap()), NewtonParams::default()).unwrap()
}

fn at(x: f64, y: f64) -> StoredPose {
    StoredPose { rotation: [1.0, 0.0, 0.0, 0.0], translation: [x, y, 0.0] }
}

fn distance(c: &Catalog, scene: &str) -> f64 {
    let options = CheckOptions { distance: true, ..CheckOptions::default() };
    c.check_scene_robot(scene, &options, &[]).unwrap().expect("the scene has a robot").answer.distance
}

#[test]
fn a_scene_robot_is_placed_moved_attached_and_survives_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let scene;
    {
        let c = open(dir.path());
        let robot = c.add_robot("", arm()).unwrap();
        scene = c.create_scene("cell").unwrap();
        // An obstacle ball of radius 0.2 m at (1, 1.5, 0).
        let ball = c.add_primitive("ball", Primitive::Sphere { radius: 0.2 }).unwrap();
        let obstacle = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [1.0, 1.5, 0.0]).unwrap();
        c.add_instance(&scene, &ball, obstacle).unwrap();

        assert!(matches!(c.set_joint_positions(&scene, &["j".into()], &[1.0]), Err(Error::FailedPrecondition(_))));
        assert!(c.check_scene_robot(&scene, &CheckOptions::default(), &[]).unwrap().is_none());
        // A bad attachment stores nothing.
        let mut record =
            SceneRobot { robot_id: robot.id.clone(), base: at(1.0, 0.0), attached: vec![], link_padding: vec![] };
        record.attached.push(AttachedRecord {
            link: "hand".into(),
            name: "can".into(),
            primitive: Primitive::Sphere { radius: 0.05 }.to_file(),
            origin: at(0.0, 0.0),
        });
        match c.set_scene_robot(&scene, record.clone(), None) {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "attached[0].link"),
            other => panic!("{other:?}"),
        }
        assert!(c.placed_robot(&scene).unwrap().is_none());
        record.attached.clear();

        // Base at (1, 0, 0), j = π/2: the arm's ball is at (1, 0.5, 0); the obstacle 1 m away
        // center to center, so the distance is 1 − 0.1 − 0.2 = 0.7 m.
        c.set_scene_robot(&scene, record, Some((&["j".into()], &[std::f64::consts::FRAC_PI_2]))).unwrap();
        assert!((distance(&c, &scene) - 0.7).abs() < 1e-9);
        // j = 0: the ball at (1.5, 0, 0), √(0.5² + 1.5²) − 0.3 from the obstacle.
        c.set_joint_positions(&scene, &["j".into()], &[0.0]).unwrap();
        assert!((distance(&c, &scene) - ((0.25f64 + 2.25).sqrt() - 0.3)).abs() < 1e-9);
        // All or nothing: an unknown joint changes nothing.
        match c.set_joint_positions(&scene, &["k".into()], &[1.0]) {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "joint_positions.joint_names[0]"),
            other => panic!("{other:?}"),
        }
        c.set_joint_positions(&scene, &["j".into()], &[std::f64::consts::FRAC_PI_2]).unwrap();

        // A ball of radius 0.05 m attached 0.3 m farther along the arm, at (1, 0.8, 0):
        // 0.7 − 0.05 − 0.2 = 0.45 m from the obstacle.
        let can = AttachedRecord {
            link: "arm".into(),
            name: "can".into(),
            primitive: Primitive::Sphere { radius: 0.05 }.to_file(),
            origin: at(0.8, 0.0),
        };
        c.attach_object(&scene, can.clone()).unwrap();
        assert!((distance(&c, &scene) - 0.45).abs() < 1e-9);
        let bad = AttachedRecord { link: "nowhere".into(), ..can };
        match c.attach_object(&scene, bad) {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "attached.link"),
            other => panic!("{other:?}"),
        }
        assert!(matches!(c.detach_object(&scene, "cup"), Err(Error::NotFound { .. })));
        // Link padding: 0.5 m on the arm makes the attached ball collide (0.45 < 0.5).
        let mut padded = c.placed_robot(&scene).unwrap().unwrap().record.clone();
        padded.link_padding = vec![("arm".into(), 0.5)];
        c.set_scene_robot(&scene, padded, None).unwrap();
        let check = c.check_scene_robot(&scene, &CheckOptions::default(), &[]).unwrap().unwrap();
        assert!(check.answer.collides && check.answer.world);
    }
    {
        // After a restart: the same robot, joint position, padding and attached ball.
        let c = open(dir.path());
        let placed = c.placed_robot(&scene).unwrap().unwrap();
        assert_eq!(placed.record.attached.len(), 1);
        assert_eq!(placed.link_padding, [("arm".to_owned(), 0.5)]);
        let mut unpadded = placed.record.clone();
        unpadded.link_padding.clear();
        c.set_scene_robot(&scene, unpadded, None).unwrap();
        assert!((distance(&c, &scene) - 0.45).abs() < 1e-9);
        c.detach_object(&scene, "can").unwrap();
        assert!((distance(&c, &scene) - 0.7).abs() < 1e-9);
        // The stored robot is not deleted while the scene holds it (naming the scene); once the
        // scene lets it go, it is.
        let e = c.delete_robot(&placed.robot_id).unwrap_err();
        assert!(matches!(&e, Error::FailedPrecondition(m) if m.contains(&scene)), "{e}");
        assert!(c.placed_robot(&scene).unwrap().is_some());
        assert!(c.clear_scene_robot(&scene).unwrap());
        assert!(c.placed_robot(&scene).unwrap().is_none());
        c.delete_robot(&placed.robot_id).unwrap();
    }
}
