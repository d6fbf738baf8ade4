//! Clearance tables against closed forms and against parry's whole-mesh distance.
//!
//! ```text
//! base  cube mesh, half side 0.1, at the origin
//! arm   box 0.2³ at (0.5 + slide, 0, 0)                    prismatic along x
//! tip   cube mesh, half side 0.05, at the arm + (0, 0, 0.5), turned by `turn` about z
//! base–arm  d = max(0, |0.5 + s| − 0.2)                     (one entry: slide)
//! base–tip  d = √(dx² + 0.35²), dx = max(0, |0.5 + s| − 0.05(|cos t| + |sin t|) − 0.1)
//!           (the tip's extreme vertex along x lies within the base's y range; two entries)
//! ```

use base64::Engine;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::clearance::{ClearanceSettings, ClearanceTable, CLEARANCE_UNIT};
use sublevel_robot::{fit_robot, CheckOptions, FittedRobot, RobotChecker, RobotFile, RobotFitSettings};

/// The slider of `check.rs` (`data/slider.urdf`), its tip's joint turned continuous.
fn urdf() -> String {
    include_str!("data/slider.urdf").replace(r#"type="revolute""#, r#"type="continuous""#)
}

/// The unit cube [−0.5, 0.5]³ (OBJ quads).
const CUBE: &str = include_str!("data/cube.obj");

const MAX_LOSS: Real = 0.004;

fn slider(tables: bool) -> (FittedRobot, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE).unwrap();
    std::fs::write(dir.path().join("slider.urdf"), urdf()).unwrap();
    let mut settings = RobotFitSettings {
        cache_dir: Some(dir.path().join("cache")),
        clearance: tables.then_some(ClearanceSettings { max_loss: MAX_LOSS, max_cells: 40_000, threads: 2 }),
        ..Default::default()
    };
    settings.compound.excess_tolerance = Some(0.2);
    settings.compound.max_parts = 2;
    (fit_robot(&dir.path().join("slider.urdf"), None, &settings, &|_| {}).unwrap(), dir)
}

fn table<'a>(robot: &'a FittedRobot, a: &str, b: &str) -> &'a ClearanceTable {
    let index = |n: &str| robot.geometries.iter().position(|g| g.name == n).unwrap();
    let pair = (index(a).min(index(b)), index(a).max(index(b)));
    robot.clearance.iter().find(|t| t.geometries == pair).unwrap()
}

struct Rng(u64);

impl Rng {
    fn range(&mut self, lo: Real, hi: Real) -> Real {
        self.0 = self.0.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        lo + (hi - lo) * ((self.0 >> 11) as Real / (1u64 << 53) as Real)
    }
}

#[test]
fn table_bounds_never_exceed_the_closed_form_distances_and_lose_at_most_their_stated_slack() {
    let (robot, _dir) = slider(true);
    // Three checked pairs, each moved by one or two joints: three tables.
    assert_eq!(robot.clearance.len(), 3);
    let (base_arm, base_tip) = (table(&robot, "base", "arm"), table(&robot, "base", "tip"));
    // The bound loses the cell's Lipschitz term (≤ MAX_LOSS), the distance's own change across
    // the half cell (≤ MAX_LOSS) and one stored step.
    let slack = 2.0 * MAX_LOSS + CLEARANCE_UNIT + 1e-12;
    let mut rng = Rng(17);
    let (mut decided, mut capped) = (0, 0);
    for _ in 0..4000 {
        let (s, t) = (rng.range(-1.0, 1.0), rng.range(-3.0 * std::f64::consts::PI, 3.0 * std::f64::consts::PI));
        let q = [s, t];
        let x = (0.5 + s).abs();
        let d_arm = (x - 0.2).max(0.0);
        let dx = (x - 0.05 * (t.cos().abs() + t.sin().abs()) - 0.1).max(0.0);
        let d_tip = (dx * dx + 0.35 * 0.35).sqrt();
        for (table, d) in [(base_arm, d_arm), (base_tip, d_tip)] {
            let lb = table.lower_bound(&q);
            assert!(lb <= d + 1e-12, "bound {lb} above the distance {d} at {q:?}");
            // Values are stored up to 255 steps (5.1 cm): beyond, the bound is the cap's.
            if d < 250.0 * CLEARANCE_UNIT {
                assert!(d - lb <= slack, "bound {lb} loses {} at {q:?}", d - lb);
                decided += usize::from(lb > 0.0);
            } else {
                capped += 1;
                assert!(lb >= 250.0 * CLEARANCE_UNIT - slack, "capped bound {lb} at {q:?}");
            }
        }
    }
    assert!(decided > 100 && capped > 1000, "both regimes occur: {decided} decided, {capped} capped");
    // A continuous joint's table reads a turn later the same.
    let turned = base_tip.lower_bound(&[0.1, 0.3 + 2.0 * std::f64::consts::PI]);
    assert!((base_tip.lower_bound(&[0.1, 0.3]) - turned).abs() < 1e-12);
    // Outside a limited joint's range the table has no answer.
    assert_eq!(base_arm.lower_bound(&[1.5, 0.0]), Real::NEG_INFINITY);
}

fn panda() -> FittedRobot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    FittedRobot::load(&path).unwrap()
}

/// parry's whole-mesh distance of the Panda's geometries `pair`, its links at `poses` (meters).
fn mesh_distance(robot: &FittedRobot, poses: &[Isometry3], (a, b): (usize, usize)) -> Real {
    let shape = |g: usize| match &robot.geometries[g].shape {
        sublevel_robot::LinkShape::Mesh { exact, .. } => exact.clone(),
        sublevel_robot::LinkShape::Primitive(_) => unreachable!("the Panda's links are meshes"),
    };
    let pose = |g: usize| {
        let p = poses[robot.geometries[g].link] * robot.geometries[g].origin;
        let (v, r) = (p.translation.vector, p.rotation.quaternion());
        parry3d_f64::math::Pose::from_parts(
            parry3d_f64::math::Vector::new(v.x, v.y, v.z),
            parry3d_f64::math::Rot3::from_xyzw(r.i, r.j, r.k, r.w),
        )
    };
    parry3d_f64::query::distance(&pose(a), shape(a).as_ref(), &pose(b), shape(b).as_ref()).unwrap().distance
}

/// A configuration drawn uniformly within the joint limits.
fn uniform(robot: &FittedRobot, rng: &mut Rng) -> Vec<Real> {
    let model = &robot.model;
    (0..model.dof())
        .map(|k| {
            let (lo, hi) = model.variable_joint(k).limits.unwrap();
            rng.range(lo, hi)
        })
        .collect()
}

#[test]
fn checks_with_tables_answer_as_checks_without_them() {
    let with = panda();
    let without = panda().with_clearance(Vec::new()).unwrap();
    assert!(without.clearance.is_empty());
    let mut a = RobotChecker::new(&with, Vec::new(), &|_, _| None).unwrap();
    let mut b = RobotChecker::new(&without, Vec::new(), &|_, _| None).unwrap();
    let mut rng = Rng(5);
    let (mut by_table, mut colliding) = (0, 0);
    let mut poses = Vec::new();
    for _ in 0..1500 {
        let q = uniform(&with, &mut rng);
        let options = CheckOptions { padding: rng.range(0.0, 0.02), distance: false, ..Default::default() };
        let (x, y) = (
            a.check(&q, &Isometry3::identity(), &options).unwrap(),
            b.check(&q, &Isometry3::identity(), &options).unwrap(),
        );
        assert_eq!((x.collides, x.self_collision), (y.collides, y.self_collision), "at {q:?}");
        // Either may name a different contact first: each named pair's meshes are within the
        // padding (parry's whole-mesh distance).
        for pair in [x.self_pair, y.self_pair].into_iter().flatten() {
            with.model.forward_kinematics(&q, &Isometry3::identity(), &mut poses).unwrap();
            let d = mesh_distance(&with, &poses, pair);
            assert!(d <= options.padding + 1e-9, "{pair:?} named at {d} m, padding {} at {q:?}", options.padding);
        }
        by_table += x.pairs_table;
        colliding += usize::from(x.collides);
        assert_eq!(y.pairs_table, 0);
    }
    assert!(by_table > 700 && colliding > 50, "{by_table} pairs by the tables, {colliding} colliding");
}

#[test]
fn tables_survive_a_save_and_a_stale_or_damaged_table_is_refused_by_name() {
    let (robot, dir) = slider(true);
    let path = dir.path().join("slider.robot.json");
    robot.save(&path).unwrap();
    let back = FittedRobot::load(&path).unwrap();
    assert_eq!(back.clearance.len(), robot.clearance.len());
    let q = [0.2, 0.7];
    for (x, y) in back.clearance.iter().zip(&robot.clearance) {
        assert_eq!(x.lower_bound(&q), y.lower_bound(&q));
    }
    let file: RobotFile = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let refused = |edit: &dyn Fn(&mut RobotFile)| {
        let mut f = file.clone();
        edit(&mut f);
        match FittedRobot::from_file(f) {
            Err(sublevel_core::Error::InvalidArgument { field, .. }) => field,
            other => panic!("accepted: {:?}", other.map(|r| r.clearance.len())),
        }
    };
    // The tip's joint moved: every table over `turn` is stale.
    let field = refused(&|f| f.urdf = f.urdf.replace(r#"<origin xyz="0 0 0.5"/>"#, r#"<origin xyz="0 0 0.6"/>"#));
    assert!(field.starts_with("clearance[") && field.ends_with("].key"), "{field}");
    assert_eq!(refused(&|f| f.clearance[0].data = "not base64!".into()), "clearance[0].data");
    assert_eq!(refused(&|f| f.clearance[0].cells[0] += 1), "clearance[0].data");
    assert_eq!(refused(&|f| f.clearance[0].geometries[0] = "nowhere".into()), "clearance[0].geometries");
    assert_eq!(refused(&|f| f.clearance[0].joints = vec!["x".into()]), "clearance[0].joints");
    assert_eq!(refused(&|f| f.clearance[0].unit = -1.0), "clearance[0].unit");
    assert_eq!(refused(&|f| f.clearance[1].contacts = "AAAA".into()), "clearance[1].contacts");
    // Well-formed edits the tables' own checks cannot see are caught by the file's digest: every
    // cell of a table changed (its lowest bit flipped), the key left as it was.
    let ff = |f: &mut RobotFile| {
        let cells = base64::engine::general_purpose::STANDARD.decode(&f.clearance[0].data).unwrap();
        let flipped: Vec<u8> = cells.iter().map(|c| c ^ 1).collect();
        f.clearance[0].data = base64::engine::general_purpose::STANDARD.encode(flipped);
    };
    assert_eq!(refused(&ff), "integrity");
    assert_eq!(refused(&|f| f.integrity.clear()), "integrity");
    // Sealed again, the same edit loads: the digest detects changes, it does not sign.
    let mut f = file.clone();
    ff(&mut f);
    f.seal().unwrap();
    assert!(FittedRobot::from_file(f).is_ok());
}

/// A build of the tables inside a cancelled scope stops with `Cancelled` (the job's
/// `CancelFitJob` reaches this stage through its threads).
#[test]
fn a_cancelled_scope_stops_the_tables_build() {
    let (robot, _dir) = slider(false);
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let built = sublevel_core::cancel::cancellable(flag, || {
        sublevel_robot::clearance::build_clearance_tables(&robot, &ClearanceSettings::default(), &|_| {})
    });
    assert!(matches!(built, Err(sublevel_core::Error::Cancelled(_))), "{:?}", built.map(|t| t.len()));
}

/// The Panda's stored tables against parry's whole-mesh distance (an independent reference).
#[test]
fn the_pandas_tables_never_exceed_the_meshes_distance() {
    let robot = panda();
    assert_eq!(robot.clearance.len(), 4, "link 5 with link 7, the hand and both fingers");
    let model = &robot.model;
    let mut rng = Rng(11);
    let mut poses = Vec::new();
    let mut compared = 0;
    for _ in 0..150 {
        let q = uniform(&robot, &mut rng);
        model.forward_kinematics(&q, &Isometry3::identity(), &mut poses).unwrap();
        for t in &robot.clearance {
            let lb = t.lower_bound(&q);
            if lb <= 0.0 {
                continue;
            }
            let d = mesh_distance(&robot, &poses, t.geometries);
            assert!(lb <= d + 1e-12, "bound {lb} above the mesh distance {d} at {q:?}");
            compared += 1;
        }
    }
    assert!(compared > 200, "{compared} bounds compared");
}
