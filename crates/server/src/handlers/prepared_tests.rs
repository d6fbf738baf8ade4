//! The prepared checkers: kept while their robot and scene stay as they were, rebuilt when
//! either changes, bounded, and answering as a checker built afresh from the catalog does.

use super::*;
use sublevel_core::math::{pose_from_parts, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_robot::{CheckOptions, ConfigurationAnswer, RobotFile};
use sublevel_scene::moveit::AllowedCollisionMatrix;
use sublevel_scene::store::MemoryStore;

/// A catalog holding the fitted Panda and a scene of a ball on its base and a box far away:
/// (catalog, robot id, scene id, ball instance id).
fn setup() -> (Catalog, String, String, String) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/robots/panda/panda.robot.json");
    let file: RobotFile = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let catalog = Catalog::open(Box::new(MemoryStore::new()), Default::default()).unwrap();
    let robot = catalog.add_robot("panda", file).unwrap().id.clone();
    let ball = catalog.add_primitive("ball", Primitive::Sphere { radius: 0.1 }).unwrap();
    let block = catalog.add_primitive("block", Primitive::Box { half_extents: Vector3::new(0.1, 0.1, 0.1) }).unwrap();
    let scene = catalog.create_scene("s").unwrap();
    let at = |x: Real, z: Real| pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, z]).unwrap();
    let on_base = catalog.add_instance(&scene, &ball, at(0.0, 0.2)).unwrap();
    catalog.add_instance(&scene, &block, at(3.0, 0.0)).unwrap();
    (catalog, robot, scene, on_base)
}

fn asked(robot_id: &str, scene_id: &str) -> Asked {
    Asked {
        robot_id: robot_id.into(),
        scene_id: scene_id.into(),
        base: None,
        attached: Vec::new(),
        link_padding: HashMap::new(),
        poses: Vec::new(),
    }
}

/// The middle of every joint's limits.
fn middle(robot: &FittedRobot) -> Vec<Real> {
    (0..robot.model.dof())
        .map(|k| robot.model.variable_joint(k).limits.map_or(0.0, |(lo, hi)| 0.5 * (lo + hi)))
        .collect()
}

/// `q` checked by a checker of `prepared` (taken and given back).
fn check(prepared: &Prepared, q: &[Real]) -> ConfigurationAnswer {
    let mut checker = prepared.take().unwrap();
    let options = CheckOptions { distance: true, ..CheckOptions::default() };
    let answer = checker.with_dependent_mut(|_, c| c.check(q, &prepared.base, &options)).unwrap();
    prepared.put(checker);
    answer
}

/// `q` checked by a checker built afresh from the catalog's robot and world.
fn fresh(catalog: &Catalog, robot_id: &str, scene_id: &str, q: &[Real]) -> ConfigurationAnswer {
    let robot = catalog.robot(robot_id).unwrap().robot.clone();
    let world = catalog.robot_world(scene_id).unwrap();
    let allowed = world.planning.allowed_override();
    let mut checker = RobotChecker::new(&robot, world.objects.clone(), &allowed).unwrap();
    let options = CheckOptions { distance: true, ..CheckOptions::default() };
    checker.check(q, &Isometry3::identity(), &options).unwrap()
}

#[test]
fn a_setting_is_kept_until_its_scene_changes_and_answers_as_a_fresh_checker() {
    let (catalog, robot_id, scene_id, ball) = setup();
    let cache = PreparedCheckers::new(1);
    let q = middle(&catalog.robot(&robot_id).unwrap().robot);
    let first = cache.get(&catalog, &asked(&robot_id, &scene_id)).unwrap();
    let again = cache.get(&catalog, &asked(&robot_id, &scene_id)).unwrap();
    assert!(Arc::ptr_eq(&first, &again), "the same setting twice: one entry");
    let answer = check(&again, &q);
    assert!(answer.world, "the ball on the base collides");
    assert_eq!(answer, fresh(&catalog, &robot_id, &scene_id, &q));

    // The ball moved away: the entry is stale, a new one takes its place.
    let away = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0, 3.0, 0.2]).unwrap();
    catalog.set_poses(&scene_id, &[(ball.clone(), away)]).unwrap();
    let moved = cache.get(&catalog, &asked(&robot_id, &scene_id)).unwrap();
    assert!(!Arc::ptr_eq(&first, &moved));
    assert_eq!(lock(&cache.entries).len(), 1);
    let answer = check(&moved, &q);
    assert!(!answer.world, "the ball is 3 m away");
    assert_eq!(answer, fresh(&catalog, &robot_id, &scene_id, &q));

    // Moved back: the same poses as the first entry's, which is gone; the answers are the first's.
    let back = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.2]).unwrap();
    catalog.set_poses(&scene_id, &[(ball.clone(), back)]).unwrap();
    let returned = cache.get(&catalog, &asked(&robot_id, &scene_id)).unwrap();
    assert!(!Arc::ptr_eq(&moved, &returned) && !Arc::ptr_eq(&first, &returned));
    assert_eq!(check(&returned, &q), fresh(&catalog, &robot_id, &scene_id, &q));

    // The allowed-collision matrix now allows the ball: a new planning context, a new entry.
    let planning = sublevel_scene::PlanningContext {
        allowed_collision: Some(AllowedCollisionMatrix {
            names: Vec::new(),
            allowed: Vec::new(),
            defaults: vec![(ball.clone(), true)],
        }),
        ..Default::default()
    };
    catalog.set_planning(&scene_id, planning).unwrap();
    let allowing = cache.get(&catalog, &asked(&robot_id, &scene_id)).unwrap();
    assert!(!Arc::ptr_eq(&returned, &allowing));
    let answer = check(&allowing, &q);
    assert!(!answer.world, "contacts with the ball are allowed");
    assert_eq!(answer, fresh(&catalog, &robot_id, &scene_id, &q));

    // A view's pose of the ball, an attached object: entries of their own beside the scene's.
    let mut viewed = asked(&robot_id, &scene_id);
    viewed.poses = vec![(ball.clone(), away)];
    let view = cache.get(&catalog, &viewed).unwrap();
    assert_eq!(view.world.objects.iter().find(|o| o.name == ball).unwrap().pose, away);
    let mut holding = asked(&robot_id, &scene_id);
    holding.attached = vec![pb::AttachedObject {
        link: "panda_hand".into(),
        name: "held".into(),
        primitive: Some(pb::Primitive { kind: pb::PrimitiveKind::Sphere as i32, radius: 0.05, ..Default::default() }),
        origin: None,
    }];
    let held = cache.get(&catalog, &holding).unwrap();
    assert_eq!(held.robot.geometries.len(), allowing.robot.geometries.len() + 1);
    assert_eq!(lock(&cache.entries).len(), 3);
    assert!(Arc::ptr_eq(&allowing, &cache.get(&catalog, &asked(&robot_id, &scene_id)).unwrap()));

    // A deleted scene's entries go; a bad setting is refused and not kept.
    cache.forget_scene(&scene_id);
    assert_eq!(lock(&cache.entries).len(), 0);
    let mut bad = asked(&robot_id, &scene_id);
    bad.link_padding.insert("panda_tail".into(), 0.1);
    assert!(cache.get(&catalog, &bad).is_err());
    assert_eq!(lock(&cache.entries).len(), 0);
}

#[test]
fn the_least_recently_used_setting_goes_first_and_idle_checkers_are_bounded() {
    let (catalog, robot_id, scene_id, _) = setup();
    let cache = PreparedCheckers::new(1);
    assert_eq!((cache.max_entries, cache.max_idle), (8, 2));
    let padded = |k: usize| {
        let mut a = asked(&robot_id, &scene_id);
        a.link_padding.insert("panda_link0".into(), 0.01 * k as Real);
        a
    };
    let kept: Vec<Arc<Prepared>> = (0..8).map(|k| cache.get(&catalog, &padded(k)).unwrap()).collect();
    // Setting 0 used again, then a ninth: setting 1, now the least recently used, goes.
    assert!(Arc::ptr_eq(&kept[0], &cache.get(&catalog, &padded(0)).unwrap()));
    cache.get(&catalog, &padded(8)).unwrap();
    assert_eq!(lock(&cache.entries).len(), 8);
    assert!(Arc::ptr_eq(&kept[0], &cache.get(&catalog, &padded(0)).unwrap()));
    assert!(!Arc::ptr_eq(&kept[1], &cache.get(&catalog, &padded(1)).unwrap()));

    // Three checkers in use at once; two are kept idle after.
    let prepared = &kept[0];
    let taken: Vec<Checker> = (0..3).map(|_| prepared.take().unwrap()).collect();
    assert_eq!(lock(&prepared.idle).len(), 0);
    for c in taken {
        prepared.put(c);
    }
    assert_eq!(lock(&prepared.idle).len(), 2);
}
