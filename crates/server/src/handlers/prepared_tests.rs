//! The prepared checkers: kept while their robot and scene stay as they were, rebuilt when
//! either changes, bounded, and answering as a checker built afresh from the catalog does.

use super::*;
use rand::{Rng, SeedableRng};
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

/// A plane of points (a wall 0.45 m in front of the Panda's base, 2.5 cm apart) in scene `scene`
/// as cloud `name`, each a ball of `radius`; the cloud's points (world frame).
fn wall(catalog: &Catalog, scene: &str, name: &str, x: Real, radius: Real) -> Vec<Vector3> {
    let points: Vec<[f32; 3]> =
        (0..=40).flat_map(|i| (0..=40).map(move |k| [x as f32, -0.5 + 0.025 * i as f32, 0.025 * k as f32])).collect();
    let frame = sublevel_scene::CloudFrame {
        points,
        holes: 0,
        sensor_pose: Isometry3::identity(),
        noise_radius: radius,
        filter: sublevel_robot::cloud::filter::CloudFilter { voxel: 0.0, ..Default::default() },
        self_filter: None,
    };
    let built = catalog.build_point_cloud(scene, &frame).unwrap();
    let stored: Vec<Vector3> = built.cloud.points().iter().map(|p| Vector3::from(*p)).collect();
    catalog.set_point_cloud(scene, name, built, sublevel_scene::DEFAULT_MAX_CLOUD_BYTES).unwrap();
    stored
}

/// Distance from `p` to the triangle `a b c` (Ericson, Real-Time Collision Detection, 5.1.5).
fn point_triangle(p: Vector3, a: Vector3, b: Vector3, c: Vector3) -> Real {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.norm();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (p - (a + ab * (d1 / (d1 - d3)))).norm();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (p - (a + ac * (d2 / (d2 - d6)))).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return (p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))))).norm();
    }
    let denom = 1.0 / (va + vb + vc);
    (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm()
}

/// The brute-force gap between the Panda at `q` and a cloud: the least, over every point and
/// every triangle of every link mesh, of the point's distance to the triangle, less the noise
/// radius (a mesh's bounding ball skips the points that cannot beat the best so far).
fn brute_gap(robot: &FittedRobot, q: &[Real], points: &[Vector3], radius: Real) -> Real {
    let mut poses = Vec::new();
    robot.model.forward_kinematics(q, &Isometry3::identity(), &mut poses).unwrap();
    let mut best = Real::INFINITY;
    for g in &robot.geometries {
        let sublevel_robot::LinkShape::Mesh { vertices, triangles, .. } = &g.shape else {
            panic!("the Panda's geometries are meshes")
        };
        let pose = poses[g.link] * g.origin;
        let (center, reach) = g.sphere;
        for p in points {
            let y = pose.inverse_transform_point(&(*p).into()).coords;
            if (y - center).norm() - reach - radius >= best {
                continue;
            }
            for t in triangles {
                let [a, b, c] = t.map(|i| vertices[i as usize].coords);
                best = best.min(point_triangle(y, a, b, c) - radius);
            }
        }
    }
    best
}

/// Configurations of the Panda against a wall of points: every verdict and distance equals the
/// brute force over every point ball; a replaced cloud is never answered from the old checker.
#[test]
fn cloud_checks_equal_brute_force_and_a_replaced_cloud_rebuilds_the_checker() {
    let (catalog, robot_id, _, _) = setup();
    let scene = catalog.create_scene("wall").unwrap();
    let robot = catalog.robot(&robot_id).unwrap().robot.clone();
    let r = 0.01;
    let points = wall(&catalog, &scene, "camera", 0.45, r);
    let cache = PreparedCheckers::new(1);
    let prepared = cache.get(&catalog, &asked(&robot_id, &scene)).unwrap();
    assert_eq!(prepared.world.scene_version, catalog.scene_version(&scene).unwrap());
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let (mut colliding, mut free) = (0, 0);
    for _ in 0..24 {
        let q: Vec<Real> = (0..robot.model.dof())
            .map(|k| {
                let (lo, hi) = robot.model.variable_joint(k).limits.unwrap_or((-3.0, 3.0));
                rng.random_range(lo..hi)
            })
            .collect();
        let gap = brute_gap(&robot, &q, &points, r);
        if gap.abs() < 1e-6 {
            continue;
        }
        let answer = check(&prepared, &q);
        if answer.self_collision {
            continue;
        }
        assert_eq!(answer.world, gap <= 0.0, "q = {q:?}: brute-force gap {gap}");
        if answer.world {
            colliding += 1;
        } else {
            free += 1;
            assert!((answer.distance - gap).abs() < 1e-6, "q = {q:?}: {} vs {gap}", answer.distance);
            let (_, object) = answer.pair.unwrap();
            assert_eq!(prepared.world.objects[object].name, "camera");
        }
    }
    assert!(colliding >= 3 && free >= 3, "{colliding} colliding, {free} free");

    // A configuration reaching into the wall; the wall replaced by one out of reach.
    let reach = middle(&robot);
    assert!(brute_gap(&robot, &reach, &points, r) <= 0.0, "the middle configuration reaches the wall");
    assert!(check(&prepared, &reach).world);
    let version = catalog.scene_version(&scene).unwrap();
    let far = wall(&catalog, &scene, "camera", 2.0, r);
    assert!(brute_gap(&robot, &reach, &far, r) > 0.5);
    let replaced = cache.get(&catalog, &asked(&robot_id, &scene)).unwrap();
    assert!(!Arc::ptr_eq(&prepared, &replaced), "the cloud changed: a new setting");
    assert_eq!(replaced.world.scene_version, version + 1);
    let answer = check(&replaced, &reach);
    assert!(!answer.world);
    assert!((answer.distance - brute_gap(&robot, &reach, &far, r)).abs() < 1e-6);
    assert!(Arc::ptr_eq(&replaced, &cache.get(&catalog, &asked(&robot_id, &scene)).unwrap()));
    // Removed: the robot is alone.
    catalog.remove_point_cloud(&scene, "camera").unwrap();
    let alone = cache.get(&catalog, &asked(&robot_id, &scene)).unwrap();
    assert!(!Arc::ptr_eq(&replaced, &alone) && alone.world.objects.is_empty());
}
