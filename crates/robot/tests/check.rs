//! Robot fits and configuration checks on a small robot whose answers have closed forms: a fixed
//! base cube (a mesh), a prismatic arm (a URDF box) and a revolute tip (a smaller cube mesh).
//!
//! ```text
//! base  cube mesh, half side 0.1, at the origin
//! arm   box 0.2³, at (0.5 + slide, 0, 0)                 prismatic along x
//! tip   cube mesh, half side 0.05, at the arm + (0, 0, 0.5), turned by `turn` about z
//! ```

use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_robot::fitted::LinkShape;
use sublevel_robot::{fit_robot, CheckOptions, FittedRobot, RobotChecker, RobotFitSettings, WorldMesh, WorldObject};

/// The robot of the module docs.
const URDF: &str = include_str!("data/slider.urdf");

/// The unit cube [−0.5, 0.5]³ as 12 triangles (OBJ, quads split by the reader).
const CUBE: &str = include_str!("data/cube.obj");

fn robot() -> (FittedRobot, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE).unwrap();
    std::fs::write(dir.path().join("slider.urdf"), URDF).unwrap();
    let mut settings = RobotFitSettings { cache_dir: Some(dir.path().join("cache")), ..Default::default() };
    settings.compound.excess_tolerance = Some(0.2);
    settings.compound.max_parts = 2;
    let robot = fit_robot(&dir.path().join("slider.urdf"), None, &settings, &|_| {}).unwrap();
    (robot, dir)
}

/// Distance between two axis-aligned boxes (centers, half extents): the closed form.
fn box_distance(c1: Vector3, h1: Vector3, c2: Vector3, h2: Vector3) -> Real {
    let gap = (c1 - c2).abs() - h1 - h2;
    gap.sup(&Vector3::zeros()).norm()
}

fn boxed(name: &str, half: Real, at: [Real; 3]) -> WorldObject {
    WorldObject::primitive(
        name,
        Primitive::Box { half_extents: Vector3::repeat(half) },
        Isometry3::translation(at[0], at[1], at[2]),
    )
}

#[test]
fn the_fit_keeps_primitives_exact_and_every_mesh_vertex_inside_its_body() {
    let (robot, dir) = robot();
    assert_eq!(robot.geometries.len(), 3);
    assert_eq!(robot.file.report.fitted, 2, "two scales of one mesh: two fits");
    assert!(matches!(robot.geometries[1].shape, LinkShape::Primitive(Primitive::Box { .. })));
    for g in &robot.geometries {
        if let LinkShape::Mesh { body: root, vertices, .. } = &g.shape {
            for v in vertices {
                assert!(root.value_at(v) <= 1.0 + 1e-9, "{}: vertex {v} outside the root body", g.name);
            }
        }
    }
    // A second fit reads both meshes from the cache, and the saved file reads back the same.
    let mut settings = RobotFitSettings { cache_dir: Some(dir.path().join("cache")), ..Default::default() };
    settings.compound.excess_tolerance = Some(0.2);
    settings.compound.max_parts = 2;
    let again = fit_robot(&dir.path().join("slider.urdf"), None, &settings, &|_| {}).unwrap();
    assert_eq!((again.file.report.fitted, again.file.report.cached), (0, 2));
    let path = dir.path().join("slider.robot.json");
    robot.save(&path).unwrap();
    let read = FittedRobot::load(&path).unwrap();
    assert_eq!(read.geometries.len(), 3);
    assert_eq!(read.self_pairs, vec![(0, 1), (0, 2), (1, 2)]);
}

#[test]
fn world_distances_and_verdicts_match_the_closed_form() {
    let (robot, _dir) = robot();
    // Below the arm's track and beside the base.
    let world = vec![boxed("low", 0.05, [0.8, 0.0, -0.4]), boxed("side", 0.1, [0.0, 0.45, 0.0])];
    let mut checker = RobotChecker::new(&robot, world.clone(), &|_, _| None).unwrap();
    let half = |h: Real| Vector3::repeat(h);
    for k in 0..=40 {
        let slide = -0.29 + 0.03 * k as Real;
        let arm = Vector3::new(0.5 + slide, 0.0, 0.0);
        let tip = arm + Vector3::new(0.0, 0.0, 0.5);
        let expected = world
            .iter()
            .flat_map(|o| {
                let c = o.pose.translation.vector;
                let h = match o.as_primitive() {
                    Some(Primitive::Box { half_extents }) => *half_extents,
                    _ => unreachable!(),
                };
                [
                    box_distance(Vector3::zeros(), half(0.1), c, h),
                    box_distance(arm, half(0.1), c, h),
                    box_distance(tip, half(0.05), c, h),
                ]
            })
            .fold(Real::INFINITY, Real::min);
        let a = checker.check(&[slide, 0.0], &Isometry3::identity(), &CheckOptions::default()).unwrap();
        assert!(a.converged);
        if expected > 1e-9 {
            assert!(!a.world, "slide {slide}: free at {expected} m");
            assert!((a.distance - expected).abs() < 1e-9, "slide {slide}: {} vs {expected}", a.distance);
            let (x, y) = a.witnesses.unwrap();
            assert!(((x - y).norm() - expected).abs() < 1e-9);
        } else {
            assert!(a.world && a.distance == 0.0, "slide {slide}: overlapping");
        }
        let verdict = checker
            .check(&[slide, 0.0], &Isometry3::identity(), &CheckOptions { distance: false, ..Default::default() })
            .unwrap();
        assert_eq!(verdict.world, a.world, "slide {slide}: the verdict alone agrees");
    }
    // Padding: the arm 0.05 m above `low` (slide 0.3: the arm's bottom at −0.1, low's top at −0.35).
    let a = checker.check(&[0.3, 0.0], &Isometry3::identity(), &CheckOptions::default()).unwrap();
    assert!((a.distance - 0.25).abs() < 1e-9, "{}", a.distance);
    for (padding, collides) in [(0.2, false), (0.3, true)] {
        let options = CheckOptions { padding, ..Default::default() };
        assert_eq!(checker.check(&[0.3, 0.0], &Isometry3::identity(), &options).unwrap().world, collides);
    }
    // Link padding: the arm's alone, on top of the options' padding; the distance stays 0.25 and
    // the verdict turns where padding + the arm's padding passes 0.25.
    for (global, arm, collides) in [(0.0, 0.2, false), (0.0, 0.3, true), (0.1, 0.14, false), (0.1, 0.16, true)] {
        checker.set_link_padding(&[("arm".to_owned(), arm), ("tip".to_owned(), 0.0)]).unwrap();
        for distance in [false, true] {
            let options = CheckOptions { padding: global, distance, ..Default::default() };
            let a = checker.check(&[0.3, 0.0], &Isometry3::identity(), &options).unwrap();
            assert_eq!(a.world, collides, "padding {global} + arm {arm}, distance {distance}");
            if distance && !collides {
                assert!((a.distance - 0.25).abs() < 1e-9, "{}", a.distance);
            }
        }
    }
    // A self pair takes both links' padding: base and arm 0.6 m apart at slide 0.3 (checked as
    // base–arm: the base cube's face at x = 0.1, the arm's at 0.7).
    for (base, arm, collides) in [(0.3, 0.29, false), (0.3, 0.31, true)] {
        checker.set_link_padding(&[("base".to_owned(), base), ("arm".to_owned(), arm)]).unwrap();
        let a = checker.check(&[0.3, 0.0], &Isometry3::identity(), &CheckOptions::default()).unwrap();
        assert_eq!(a.self_collision, collides, "base {base} + arm {arm}");
    }
    // Another link's padding does not touch the arm's pair.
    checker.set_link_padding(&[("tip".to_owned(), 0.3)]).unwrap();
    assert!(!checker.check(&[0.3, 0.0], &Isometry3::identity(), &CheckOptions::default()).unwrap().world);
    let field = |e| match e {
        sublevel_core::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other:?}"),
    };
    assert_eq!(field(checker.set_link_padding(&[("nope".to_owned(), 0.1)]).unwrap_err()), "link_padding[nope]");
    assert_eq!(field(checker.set_link_padding(&[("arm".to_owned(), -0.1)]).unwrap_err()), "link_padding[arm]");
    checker.set_link_padding(&[]).unwrap();
}

#[test]
fn a_turned_mesh_link_against_a_sphere_matches_the_closed_form() {
    let (robot, _dir) = robot();
    let center = Vector3::new(0.7, 0.12, 0.5);
    let world = vec![WorldObject::primitive(
        "ball",
        Primitive::Sphere { radius: 0.03 },
        Isometry3::translation(center.x, center.y, center.z),
    )];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    for k in 0..12 {
        let turn = -3.0 + 0.5 * k as Real;
        let slide = 0.05;
        // The ball's center in the tip's frame; its distance to the cube [−0.05, 0.05]³, less r.
        let tip = Isometry3::from_parts(
            Vector3::new(0.5 + slide, 0.0, 0.5).into(),
            sublevel_core::math::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn),
        );
        let local = tip.inverse_transform_point(&Point3::from(center)).coords;
        let tip_d = ((local.abs() - Vector3::repeat(0.05)).sup(&Vector3::zeros())).norm() - 0.03;
        let arm_d =
            box_distance(Vector3::new(0.5 + slide, 0.0, 0.0), Vector3::repeat(0.1), center, Vector3::zeros()) - 0.03;
        let expected = tip_d.min(arm_d);
        let a = checker.check(&[slide, turn], &Isometry3::identity(), &CheckOptions::default()).unwrap();
        if expected > 1e-9 {
            assert!((a.distance - expected).abs() < 1e-8, "turn {turn}: {} vs {expected}", a.distance);
        } else {
            assert!(a.world, "turn {turn}: the ball touches the tip");
        }
    }
}

#[test]
fn self_collision_follows_the_geometry_and_the_allowed_pairs() {
    let (robot, _dir) = robot();
    let mut checker = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
    // The arm (half 0.1 at 0.5 + slide) meets the base (half 0.1 at 0) at slide −0.3.
    for (slide, collides) in [(-0.35, true), (-0.31, true), (-0.29, false), (0.2, false)] {
        let a = checker.check(&[slide, 0.0], &Isometry3::identity(), &CheckOptions::default()).unwrap();
        assert_eq!(a.self_collision, collides, "slide {slide}");
        assert_eq!(a.collides, collides);
        if collides {
            assert_eq!(a.self_pair, Some((0, 1)));
        }
        assert!(a.distance.is_infinite(), "no world: no distance");
    }
    let allowed = |a: &str, b: &str| ((a, b) == ("base", "arm") || (a, b) == ("arm", "base")).then_some(true);
    let mut allowing = RobotChecker::new(&robot, Vec::new(), &allowed).unwrap();
    assert_eq!(allowing.self_pairs(), &[(0, 2), (1, 2)]);
    assert!(!allowing.check(&[-0.35, 0.0], &Isometry3::identity(), &CheckOptions::default()).unwrap().collides);
}

#[test]
fn bad_input_is_refused_naming_the_field() {
    let (robot, _dir) = robot();
    let mut checker = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
    let field = |e: sublevel_robot::Error| match e {
        sublevel_robot::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other}"),
    };
    let id = Isometry3::identity();
    assert_eq!(field(checker.check(&[0.0], &id, &CheckOptions::default()).unwrap_err()), "q");
    assert_eq!(field(checker.check(&[0.0, Real::NAN], &id, &CheckOptions::default()).unwrap_err()), "q[1]");
    let options = CheckOptions { padding: -1.0, ..Default::default() };
    assert_eq!(field(checker.check(&[0.0, 0.0], &id, &options).unwrap_err()), "padding");
    let mut file = robot.file.clone();
    file.geometries[0].link = "nowhere".into();
    assert_eq!(field(FittedRobot::from_file(file).unwrap_err()), "geometries[0].link");
    let mut file = robot.file.clone();
    file.geometries[0].mesh.as_mut().unwrap().triangles[0][1] = 99;
    assert_eq!(field(FittedRobot::from_file(file).unwrap_err()), "geometries[0].mesh.triangles[0]");
    let mut file = robot.file.clone();
    file.format = "other".into();
    assert_eq!(field(FittedRobot::from_file(file).unwrap_err()), "format");
}

#[test]
fn the_distance_gradient_matches_central_differences() {
    let (robot, _dir) = robot();
    let world = vec![
        WorldObject::primitive("ball", Primitive::Sphere { radius: 0.03 }, Isometry3::translation(0.62, 0.2, 0.55)),
        boxed("low", 0.05, [0.8, 0.0, -0.4]),
    ];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let options = CheckOptions { gradient: true, ..Default::default() };
    let id = Isometry3::identity();
    let h = 1e-6;
    let mut checked = 0;
    for (slide, turn) in [(0.0, 0.3), (0.1, -0.7), (-0.1, 1.1), (0.05, 2.0), (0.2, 0.0)] {
        let a = checker.check(&[slide, turn], &id, &options).unwrap();
        assert!(!a.world);
        let g = a.gradient.clone().unwrap();
        let mut d = |q: [Real; 2]| checker.check(&q, &id, &CheckOptions::default()).unwrap().distance;
        let fd = [
            (d([slide + h, turn]) - d([slide - h, turn])) / (2.0 * h),
            (d([slide, turn + h]) - d([slide, turn - h])) / (2.0 * h),
        ];
        for k in 0..2 {
            assert!((g[k] - fd[k]).abs() < 1e-5, "q = ({slide}, {turn}): ∂d/∂q{k} {} vs {}", g[k], fd[k]);
        }
        checked += 1;
    }
    assert_eq!(checked, 5);
}

#[test]
fn an_attached_object_moves_with_its_link_and_collides_like_it() {
    let (mut robot, _dir) = robot();
    // A 0.1 m cube held 0.2 m beyond the tip (the tip at the arm + (0, 0, 0.5)), turning with it.
    let held = robot
        .attach(
            "tip",
            "tool",
            Primitive::Box { half_extents: Vector3::repeat(0.05) },
            Isometry3::translation(0.2, 0.0, 0.0),
        )
        .unwrap();
    assert_eq!(robot.geometries[held].name, "tool");
    // An obstacle the tool reaches at turn 0 and the tip alone does not.
    let world = vec![boxed("post", 0.05, [0.79, 0.0, 0.5])];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let id = Isometry3::identity();
    let a = checker.check(&[0.0, 0.0], &id, &CheckOptions::default()).unwrap();
    assert!(a.world && a.pair == Some((held, 0)), "{a:?}");
    // Turned by π/2 about z the tool points along y; the tip is then the closest, 0.19 m away.
    let a = checker.check(&[0.0, std::f64::consts::FRAC_PI_2], &id, &CheckOptions::default()).unwrap();
    assert!(!a.world);
    let post = Vector3::new(0.79, 0.0, 0.5);
    let tool = box_distance(Vector3::new(0.5, 0.2, 0.5), Vector3::repeat(0.05), post, Vector3::repeat(0.05));
    let tip = box_distance(Vector3::new(0.5, 0.0, 0.5), Vector3::repeat(0.05), post, Vector3::repeat(0.05));
    assert!((tip - 0.19).abs() < 1e-12 && tool > tip);
    assert!((a.distance - tool.min(tip)).abs() < 1e-9, "{} vs {}", a.distance, tool.min(tip));
    let field = |e: sublevel_robot::Error| match e {
        sublevel_robot::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other}"),
    };
    let half = Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 };
    assert_eq!(field(robot.attach("nowhere", "x", Primitive::Sphere { radius: 0.1 }, id).unwrap_err()), "link");
    assert_eq!(field(robot.attach("tip", "x", half, id).unwrap_err()), "primitive");
}

/// A box of half side `half` as a closed 12-triangle mesh in its own frame, with the ellipsoid of
/// semi-axes 1.75·half (which contains the box's corners at √3·half) as its body when `with_body`.
fn box_mesh(half: Real, with_body: bool) -> std::sync::Arc<WorldMesh> {
    let v = |x: Real, y: Real, z: Real| Point3::new(x * half, y * half, z * half);
    let vertices = vec![
        v(-1.0, -1.0, -1.0),
        v(1.0, -1.0, -1.0),
        v(1.0, 1.0, -1.0),
        v(-1.0, 1.0, -1.0),
        v(-1.0, -1.0, 1.0),
        v(1.0, -1.0, 1.0),
        v(1.0, 1.0, 1.0),
        v(-1.0, 1.0, 1.0),
    ];
    let triangles = vec![
        [0, 3, 2],
        [0, 2, 1],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ];
    let body = with_body.then(|| sublevel_core::body::ellipsoid([0.0; 3], [1.75 * half; 3]).unwrap());
    std::sync::Arc::new(WorldMesh::new(vertices, triangles, body).unwrap())
}

#[test]
fn a_box_mesh_object_answers_as_the_box_primitive() {
    let (robot, _dir) = robot();
    // `low` and `side` stay apart; the arm runs into `wall` from slide 0.29 on and through it (the
    // wall, smaller than the arm, never holds the arm wholly inside it).
    let place: [(&str, Real, [Real; 3]); 3] =
        [("low", 0.05, [0.8, 0.0, -0.4]), ("side", 0.1, [0.0, 0.45, 0.0]), ("wall", 0.06, [1.05, 0.0, 0.0])];
    let primitives: Vec<_> = place.iter().map(|&(name, half, at)| boxed(name, half, at)).collect();
    let mut reference = RobotChecker::new(&robot, primitives, &|_, _| None).unwrap();
    for with_body in [false, true] {
        let meshes = place
            .iter()
            .map(|&(name, half, at)| {
                WorldObject::mesh(name, box_mesh(half, with_body), Isometry3::translation(at[0], at[1], at[2]))
            })
            .collect();
        let mut checker = RobotChecker::new(&robot, meshes, &|_, _| None).unwrap();
        let (mut free, mut colliding) = (0, 0);
        for k in 0..=60 {
            let q = [-0.29 + 0.02 * k as Real, 0.4];
            let a = reference.check(&q, &Isometry3::identity(), &CheckOptions::default()).unwrap();
            let b = checker.check(&q, &Isometry3::identity(), &CheckOptions::default()).unwrap();
            assert!(a.converged && b.converged);
            assert_eq!((b.world, b.collides), (a.world, a.collides), "body {with_body}, q {q:?}");
            if a.world {
                colliding += 1;
                assert_eq!(b.distance, 0.0);
            } else {
                free += 1;
                // Triangle against triangle (parry's GJK): agreement to 1e-8 m.
                assert!((b.distance - a.distance).abs() < 1e-8, "q {q:?}: {} vs {}", b.distance, a.distance);
                assert_eq!(b.pair, a.pair);
                let (x, y) = b.witnesses.unwrap();
                assert!(((x - y).norm() - b.distance).abs() < 1e-8);
            }
            let options = CheckOptions { distance: false, ..Default::default() };
            assert_eq!(checker.check(&q, &Isometry3::identity(), &options).unwrap().world, a.world, "q {q:?}");
        }
        assert!(free > 10 && colliding > 10, "{free} free, {colliding} colliding");
        // A motion into the wall stops where the arm's face (x = 0.6 + slide) meets the wall's
        // (x = 0.99): slide 0.39, t* = 0.49 / 0.8.
        let mut motions = sublevel_robot::MotionChecker::new(&mut checker).unwrap();
        let options = sublevel_robot::MotionOptions { tolerance: 1e-6, ..Default::default() };
        let m = motions.check_motion(&[-0.1, 0.0], &[0.7, 0.0], &Isometry3::identity(), &options).unwrap();
        let (t, exact) = (m.contact.unwrap(), 0.49 / 0.8);
        assert!(!m.valid && t <= exact + 1e-12 && t >= exact - 1e-6 / 0.8 - 1e-9, "body {with_body}: t {t} vs {exact}");
    }
}

#[test]
fn a_bad_mesh_object_is_refused_naming_the_field() {
    let field = |e| match e {
        sublevel_core::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other:?}"),
    };
    let p = |x: Real| Point3::new(x, 0.0, 0.0);
    let tri = || vec![p(0.0), Point3::new(0.0, 1.0, 0.0), Point3::new(0.0, 0.0, 1.0)];
    assert_eq!(field(WorldMesh::new(tri(), vec![], None).unwrap_err()), "triangles");
    assert_eq!(field(WorldMesh::new(tri(), vec![[0, 1, 3]], None).unwrap_err()), "triangles[0]");
    assert_eq!(
        field(WorldMesh::new(vec![p(Real::NAN), p(1.0), p(2.0)], vec![[0, 1, 2]], None).unwrap_err()),
        "vertices[0]"
    );
    // A body too small to hold the mesh.
    let small = sublevel_core::body::ellipsoid([0.0; 3], [0.5; 3]).unwrap();
    assert_eq!(field(WorldMesh::new(tri(), vec![[0, 1, 2]], Some(small)).unwrap_err()), "body");
}

/// A small deterministic generator (xorshift64*), uniform in [0, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> Real {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as Real / (1u64 << 53) as Real
    }

    fn range(&mut self, lo: Real, hi: Real) -> Real {
        lo + (hi - lo) * self.next()
    }

    fn pose(&mut self, spread: Real) -> Isometry3 {
        let axis = Vector3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
        let angle = self.range(-3.1, 3.1);
        Isometry3::new(
            Vector3::new(self.range(-spread, spread), self.range(-spread, spread), self.range(-spread, spread)),
            axis.normalize() * angle,
        )
    }
}

fn panda() -> FittedRobot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    FittedRobot::load(&path).unwrap()
}

#[test]
fn sphere_trees_cover_every_triangle_of_the_link_meshes() {
    let (robot, _dir) = robot();
    let panda = panda();
    let mut meshes = 0;
    for g in robot.geometries.iter().chain(&panda.geometries) {
        if let LinkShape::Mesh { vertices, triangles, spheres, .. } = &g.shape {
            meshes += 1;
            assert_eq!(spheres.uncovered_triangle(vertices, triangles, 6), None, "{}", g.name);
            // Every node's ball holds its children's leaves' balls' worth of mesh: the leaves are
            // small, and the root is no larger than needed to hold the mesh's bounding ball.
            assert!(spheres.leaves().all(|s| s.radius <= spheres.leaf_radius + 1e-6), "{}", g.name);
            assert!(spheres.nodes[0].sphere.radius <= g.sphere.1 * 1.001 + 1e-9, "{}", g.name);
        }
    }
    assert_eq!(meshes, 2 + 11);
}

#[test]
fn ball_distances_to_primitives_match_shape_distance() {
    use sublevel_query::shape::{shape_distance, ShapeRef};
    use sublevel_robot::spheres::primitive_signed_distance;
    let shapes = [
        Primitive::Box { half_extents: Vector3::new(0.3, 0.1, 0.2) },
        Primitive::Sphere { radius: 0.25 },
        Primitive::Cylinder { radius: 0.15, half_height: 0.3 },
        Primitive::Capsule { radius: 0.1, half_height: 0.25 },
        Primitive::Halfspace { normal: Vector3::new(0.0, 0.6, 0.8), offset: 0.1 },
    ];
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut compared = 0;
    for p in &shapes {
        for _ in 0..400 {
            let pose_p = rng.pose(0.5);
            let radius = rng.range(0.01, 0.2);
            let center = Isometry3::translation(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let ball = Primitive::Sphere { radius };
            let local = pose_p.inverse_transform_point(&Point3::from(center.translation.vector)).coords;
            let ours = primitive_signed_distance(p, &local) - radius;
            let d = shape_distance(ShapeRef::Primitive(&ball), &center, ShapeRef::Primitive(p), &pose_p, None).unwrap();
            assert_eq!(d.overlapping, ours <= 0.0, "{p:?}: {ours} vs {}", d.distance);
            if !d.overlapping {
                assert!((d.distance - ours).abs() < 1e-9, "{p:?}: {ours} vs {}", d.distance);
                compared += 1;
            }
        }
    }
    assert!(compared > 500, "{compared} free pairs compared");
}

/// The world of a MotionBenchMaker planning scene (its boxes and cylinders; MoveIt's YAML as
/// the scenes write it: `dimensions` full box sizes or [height, radius], orientation x, y, z, w).
fn mbm_world(path: &str) -> Vec<WorldObject> {
    let text = std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).unwrap();
    let numbers = |line: &str| -> Vec<Real> {
        let inner = &line[line.find('[').unwrap() + 1..line.find(']').unwrap()];
        inner.split(',').map(|x| x.trim().parse().unwrap()).collect()
    };
    let (mut world, mut name, mut kind, mut dims, mut position) = (Vec::new(), String::new(), "", vec![], vec![]);
    for line in text.lines().map(str::trim) {
        if let Some(id) = line.strip_prefix("- id: ") {
            name = id.to_owned();
        } else if let Some(k) = line.strip_prefix("- type: ") {
            kind = if k == "box" { "box" } else { "cylinder" };
        } else if line.starts_with("dimensions:") {
            dims = numbers(line);
        } else if line.starts_with("- position:") {
            position = numbers(line);
        } else if line.starts_with("orientation:") && !name.is_empty() {
            let q = numbers(line);
            let rotation =
                sublevel_core::math::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]));
            let pose =
                Isometry3::from_parts(nalgebra::Translation3::new(position[0], position[1], position[2]), rotation);
            let p = if kind == "box" {
                Primitive::Box { half_extents: Vector3::new(dims[0], dims[1], dims[2]) / 2.0 }
            } else {
                Primitive::Cylinder { radius: dims[1], half_height: dims[0] / 2.0 }
            };
            world.push(WorldObject::primitive(&name, p, pose));
            name.clear();
        }
    }
    world
}

#[test]
fn panda_verdicts_and_distances_agree_with_and_without_the_sphere_stages() {
    // Without its clearance tables, which decide most of the pairs the trees would.
    let robot = panda().with_clearance(Vec::new()).unwrap();
    let world = mbm_world("../../data/robots/mbm_panda/scenes/bookshelf_small/scene0001.yaml");
    assert_eq!(world.len(), 7);
    // The reference: the sphere trees and the inner balls off (the sos bound and the meshes).
    let mut off = RobotChecker::new(&robot, world.clone(), &|_, _| None).unwrap();
    off.set_sphere_stage(false);
    off.set_contact_proofs(false);
    let mut on = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let limits: Vec<(Real, Real)> = (0..robot.model.dof())
        .map(|k| robot.model.variable_joint(k).limits.unwrap_or((-std::f64::consts::PI, std::f64::consts::PI)))
        .collect();
    let mut rng = Rng(42);
    let (mut decided, mut proved, mut colliding, mut free) = (0, 0, 0, 0);
    for k in 0..300 {
        let q: Vec<Real> = limits.iter().map(|&(lo, hi)| rng.range(lo, hi)).collect();
        let base = Isometry3::identity();
        for padding in [0.0, 0.01] {
            let verdict = CheckOptions { padding, distance: false, ..Default::default() };
            let (a, b) = (off.check(&q, &base, &verdict).unwrap(), on.check(&q, &base, &verdict).unwrap());
            assert_eq!(
                (a.world, a.self_collision),
                (b.world, b.self_collision),
                "configuration {k}, padding {padding}"
            );
            decided += b.pairs_spheres;
            proved += b.pairs_proved;
            assert_eq!(a.pairs_proved, 0);
            if b.collides {
                colliding += 1;
            } else {
                free += 1;
            }
        }
        if k % 3 == 0 {
            let full = CheckOptions::default();
            let (a, b) = (off.check(&q, &base, &full).unwrap(), on.check(&q, &base, &full).unwrap());
            assert_eq!((a.world, a.self_collision), (b.world, b.self_collision), "configuration {k}");
            assert!(a.distance == b.distance || (a.distance - b.distance).abs() < 1e-9, "configuration {k}");
        }
    }
    assert!(
        decided > 100 && proved > 30 && colliding > 30 && free > 30,
        "{decided} pairs by spheres, {proved} proved, {colliding} / {free}"
    );
}

/// Crossings of the ray from `x` along `dir` with the triangles (Möller and Trumbore's test).
fn ray_crossings(vertices: &[Point3], triangles: &[[u32; 3]], x: &Vector3, dir: &Vector3) -> usize {
    triangles
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| vertices[i as usize].coords);
            let (e1, e2) = (b - a, c - a);
            let p = dir.cross(&e2);
            let det = e1.dot(&p);
            if det.abs() < 1e-15 {
                return false;
            }
            let s = x - a;
            let u = s.dot(&p) / det;
            let q = s.cross(&e1);
            let v = dir.dot(&q) / det;
            let t = e2.dot(&q) / det;
            (0.0..=1.0).contains(&u) && v >= 0.0 && u + v <= 1.0 && t > 0.0
        })
        .count()
}

#[test]
fn inner_balls_lie_inside_the_link_meshes() {
    use parry3d_f64::query::PointQuery;
    let (robot, _dir) = robot();
    let panda = panda();
    let (mut meshes, mut balls) = (0, 0);
    for g in robot.geometries.iter().chain(&panda.geometries) {
        let LinkShape::Mesh { vertices, triangles, inner, .. } = &g.shape else { continue };
        meshes += usize::from(!inner.is_empty());
        for c in &inner.components {
            for s in &c.balls {
                balls += 1;
                // Inside: an odd number of crossings along three rays (brute force, every
                // triangle of the mesh; the Panda's balls lie in one component each).
                for dir in [Vector3::new(0.31, 0.52, 0.79), Vector3::new(-0.7, 0.2, 0.1), Vector3::new(0.1, -0.3, -0.9)]
                {
                    assert_eq!(ray_crossings(vertices, triangles, &s.center, &dir) % 2, 1, "{}: {s:?}", g.name);
                }
                // No triangle within the radius (each triangle's own distance, parry).
                let x = parry3d_f64::math::Vector::new(s.center.x, s.center.y, s.center.z);
                for t in triangles {
                    let [a, b, c] = t.map(|i| {
                        parry3d_f64::math::Vector::new(
                            vertices[i as usize].x,
                            vertices[i as usize].y,
                            vertices[i as usize].z,
                        )
                    });
                    let d = parry3d_f64::shape::Triangle::new(a, b, c).distance_to_local_point(x, true);
                    assert!(d >= s.radius, "{}: a triangle at {d} m from {s:?}", g.name);
                }
                // The component's bounding ball holds the ball.
                assert!((s.center - c.bound.center).norm() + s.radius <= c.bound.radius, "{}", g.name);
            }
        }
    }
    // The test robot's two closed meshes and the Panda's ten closed links (link6's welded soup
    // is open in places).
    assert!(meshes >= 12 && balls >= 100, "{meshes} meshes with inner balls, {balls} balls");
}
