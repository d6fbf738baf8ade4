//! Tree queries against independent references: closed-form sphere distances, brute force over all
//! leaf pairs, and the single-body queries.

use super::*;
use crate::test_bodies::random_body;
use crate::{distance, growth, NewtonParams};
use rand::{Rng, SeedableRng};
use sublevel_core::body::ellipsoid;
use sublevel_core::math::{Isometry3, Point3, Real, UnitQuaternion, Vector3};

mod margin;

/// The cheap bounds' default rounding slack.
const SLACK: Real = TreeQueryParams::DEFAULT.cheap_slack;

/// A containment tree for tests: leaves given, parents are spheres containing their children's
/// bounding spheres (containment in closed form: |c_i − c| + r_i ≤ r).
struct TestTree {
    bodies: Vec<Body>,
    children: Vec<Vec<usize>>,
    depth: Vec<usize>,
}

impl BodyTree for TestTree {
    fn root(&self) -> usize {
        0
    }
    fn node_count(&self) -> usize {
        self.bodies.len()
    }
    fn body(&self, node: usize) -> &Body {
        &self.bodies[node]
    }
    fn children(&self, node: usize) -> &[usize] {
        &self.children[node]
    }
    fn depth(&self, node: usize) -> usize {
        self.depth[node]
    }
}

impl TestTree {
    fn leaves(&self) -> Vec<usize> {
        (0..self.bodies.len()).filter(|&i| self.children[i].is_empty()).collect()
    }
}

fn containing_sphere(bodies: &[&Body]) -> Body {
    let spheres: Vec<(Point3, Real)> = bodies.iter().map(|b| b.bounding_sphere().unwrap()).collect();
    let c = spheres.iter().map(|s| s.0.coords).sum::<Vector3>() / spheres.len() as Real;
    let r = spheres.iter().map(|(p, r)| (p.coords - c).norm() + r).fold(0.0, Real::max) * 1.001;
    ellipsoid([c.x, c.y, c.z], [r; 3]).unwrap()
}

/// Root → `groups` middle nodes → `per_group` leaves each; leaves from `leaf(group, k)`.
fn three_level_tree(groups: usize, per_group: usize, leaf: impl Fn(usize, usize) -> Body) -> TestTree {
    let mut bodies = vec![];
    let mut children = vec![vec![]];
    let mut depth = vec![0];
    let mut mids = vec![];
    let mut groups_leaves = vec![];
    for g in 0..groups {
        let leaves: Vec<Body> = (0..per_group).map(|k| leaf(g, k)).collect();
        let mid = containing_sphere(&leaves.iter().collect::<Vec<_>>());
        groups_leaves.push(leaves);
        mids.push(mid);
    }
    let root = containing_sphere(&mids.iter().collect::<Vec<_>>());
    bodies.push(root);
    for (mid, leaves) in mids.into_iter().zip(groups_leaves) {
        let m = bodies.len();
        bodies.push(mid);
        children.push(vec![]);
        depth.push(1);
        children[0].push(m);
        for l in leaves {
            let i = bodies.len();
            bodies.push(l);
            children.push(vec![]);
            depth.push(2);
            children[m].push(i);
        }
    }
    TestTree { bodies, children, depth }
}

fn sphere_tree(seed: u64) -> (TestTree, Vec<(Vector3, Real)>) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut spheres = vec![];
    for g in 0..3 {
        let gc = Vector3::new(0.8 * g as Real - 0.8, rng.random_range(-0.2..0.2), 0.0);
        for _ in 0..3 {
            let c = gc
                + Vector3::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
            spheres.push((c, rng.random_range(0.1..0.3)));
        }
    }
    let s = spheres.clone();
    let tree = three_level_tree(3, 3, |g, k| {
        let (c, r) = s[3 * g + k];
        ellipsoid([c.x, c.y, c.z], [r; 3]).unwrap()
    });
    (tree, spheres)
}

fn random_rotation(rng: &mut impl Rng) -> UnitQuaternion {
    UnitQuaternion::from_euler_angles(rng.random(), rng.random(), rng.random())
}

fn random_pose(rng: &mut impl Rng, spread: Real) -> Isometry3 {
    Isometry3::from_parts(
        Vector3::new(
            rng.random_range(-spread..spread),
            rng.random_range(-spread..spread),
            rng.random_range(-spread..spread),
        )
        .into(),
        UnitQuaternion::from_euler_angles(rng.random(), rng.random(), rng.random()),
    )
}

/// Poses of two sphere trees ([`sphere_tree`]): A near the origin, B `x` ∈ `along` meters along
/// the x axis and near it, both turned at random.
fn separated_poses(rng: &mut impl Rng, along: std::ops::Range<Real>) -> (Isometry3, Isometry3) {
    let pa = random_pose(rng, 0.5);
    let pb = Isometry3::from_parts(
        (Vector3::new(rng.random_range(along), 0.0, 0.0) + random_pose(rng, 0.5).translation.vector).into(),
        random_rotation(rng),
    );
    (pa, pb)
}

/// Closed form of the distance of two posed sphere trees: max(0, |c_a − c_b| − r_a − r_b),
/// minimized over all leaf pairs.
fn sphere_distance(sa: &[(Vector3, Real)], pa: &Isometry3, sb: &[(Vector3, Real)], pb: &Isometry3) -> Real {
    sa.iter()
        .flat_map(|(ca, ra)| sb.iter().map(move |(cb, rb)| (*ca, *ra, *cb, *rb)))
        .map(|(ca, ra, cb, rb)| ((pa * Point3::from(ca)) - (pb * Point3::from(cb))).norm() - ra - rb)
        .fold(Real::INFINITY, Real::min)
        .max(0.0)
}

/// Brute force: (min distance over all leaf pairs, its pair, every leaf pair's distance).
fn brute_force(a: &TestTree, pa: &Isometry3, b: &TestTree, pb: &Isometry3) -> (Real, Vec<Real>) {
    let mut all = vec![];
    for &i in &a.leaves() {
        for &j in &b.leaves() {
            let r = distance(&a.bodies[i], pa, &b.bodies[j], pb, None, &NewtonParams::default());
            assert!(r.status.converged());
            all.push(r.distance);
        }
    }
    (all.iter().cloned().fold(Real::INFINITY, Real::min), all)
}

#[test]
fn sphere_trees_match_the_closed_form() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let (ta, sa) = sphere_tree(10);
    let (tb, sb) = sphere_tree(20);
    for _ in 0..40 {
        let (pa, pb) = separated_poses(&mut rng, 1.0..4.0);
        let exact = sphere_distance(&sa, &pa, &sb, &pb);
        let r = tree_distance(&ta, &pa, &tb, &pb, None, &TreeQueryParams::default()).unwrap();
        assert!(r.converged && r.within_tolerance, "{r:?}");
        assert!((r.lower - exact).abs() < 1e-7 && (r.upper - exact).abs() < 1e-7, "{} {} vs {exact}", r.lower, r.upper);
        assert!(r.pairs_evaluated < 81 + 30, "searched {} pairs", r.pairs_evaluated);
    }
}

#[test]
fn tolerance_brackets_the_brute_force_minimum() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    let ta = three_level_tree(2, 3, |g, k| {
        rescaled(
            &random_body(4, 300 + 3 * g as u64 + k as u64),
            0.25,
            Vector3::new(0.7 * g as Real - 0.35, 0.5 * k as Real - 0.5, 0.0),
        )
    });
    let tb = three_level_tree(3, 2, |g, k| {
        ellipsoid([0.6 * g as Real - 0.6, 0.4 * k as Real, 0.1], [0.2, 0.12, 0.3]).unwrap()
    });
    for case in 0..25 {
        let pa = random_pose(&mut rng, 0.3);
        let shift = Vector3::new(rng.random_range(0.5..3.0), rng.random_range(-0.5..0.5), 0.0);
        let pb = Isometry3::from_parts(shift.into(), random_rotation(&mut rng));
        let (exact, all) = brute_force(&ta, &pa, &tb, &pb);
        for tol in [0.0, 0.01, 0.05, 0.3] {
            let params = TreeQueryParams { tolerance: tol, ..Default::default() };
            let r = tree_distance(&ta, &pa, &tb, &pb, None, &params).unwrap();
            assert!(r.converged && r.within_tolerance, "case {case} tol {tol}: {r:?}");
            assert!(r.upper - r.lower <= tol + 1e-12, "case {case} tol {tol}: {} {}", r.lower, r.upper);
            assert!(
                r.lower <= exact + 1e-9 && exact <= r.upper + 1e-9,
                "case {case}: {exact} ∉ [{}, {}]",
                r.lower,
                r.upper
            );
            assert!(all.iter().all(|d| r.lower <= d + 1e-9), "case {case}: lower bound above a leaf pair");
            if tol == 0.0 {
                assert!((r.upper - exact).abs() < 1e-8, "case {case}: {} vs {exact}", r.upper);
            }
        }
    }
}

/// `body` with its normalization center moved to `at` and its sublevel set scaled by `size`.
fn rescaled(body: &Body, size: Real, at: Vector3) -> Body {
    Body::new(body.polynomial().clone(), [at.x, at.y, at.z], body.scale() * size, body.report.clone()).unwrap()
}

#[test]
fn margin_queries_agree_with_brute_force() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let (ta, _) = sphere_tree(30);
    let (tb, _) = sphere_tree(40);
    let mut root_decided = 0;
    for case in 0..40 {
        let pa = random_pose(&mut rng, 0.2);
        let pb = Isometry3::from_parts(
            Vector3::new(rng.random_range(1.5..6.0), rng.random_range(-1.0..1.0), 0.0).into(),
            random_rotation(&mut rng),
        );
        let (exact, _) = brute_force(&ta, &pa, &tb, &pb);
        for m in [0.0, 0.05, 0.2, 1.0] {
            let r = tree_closer_than(&ta, &pa, &tb, &pb, m, None, &TreeQueryParams::default()).unwrap();
            assert!(r.converged);
            // Closer: a distance below the margin, or 0 (touching or overlapping) at margin 0.
            let closer = exact < m || exact == 0.0;
            if (exact - m).abs() > 1e-9 || exact == 0.0 {
                assert_eq!(r.closer, closer, "case {case} margin {m}: brute {exact}, {r:?}");
            }
            if r.closer {
                assert!((r.bound < m || r.bound == 0.0) && (r.bound - exact) >= -1e-9, "{r:?}");
            } else {
                assert!(r.bound >= m && r.bound <= exact + 1e-9);
            }
            // The roots are decisive when they are farther apart than the margin.
            let roots = distance(ta.body(0), &pa, tb.body(0), &pb, None, &NewtonParams::default()).distance;
            if roots >= m + 1e-9 {
                assert_eq!(r.level, 0, "case {case}: roots {roots} ≥ {m} but level {}", r.level);
                root_decided += 1;
            }
        }
    }
    assert!(root_decided > 10, "{root_decided}");
}

#[test]
fn growth_collision_agrees_with_brute_force() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let (ta, _) = sphere_tree(50);
    let tb =
        three_level_tree(2, 2, |g, k| ellipsoid([0.5 * g as Real, 0.3 * k as Real, 0.0], [0.25, 0.1, 0.15]).unwrap());
    let (mut hits, mut misses) = (0, 0);
    for case in 0..60 {
        let pa = random_pose(&mut rng, 0.2);
        let pb = Isometry3::from_parts(
            Vector3::new(rng.random_range(0.0..2.5), rng.random_range(-0.6..0.6), rng.random_range(-0.3..0.3)).into(),
            random_rotation(&mut rng),
        );
        let mut brute_min: Option<Real> = None;
        for &i in &ta.leaves() {
            for &j in &tb.leaves() {
                let g = growth(&ta.bodies[i], &pa, &tb.bodies[j], &pb, None, &NewtonParams::default());
                assert!(g.status.converged());
                if g.value <= 1.0 {
                    brute_min = Some(brute_min.map_or(g.value, |m: Real| m.min(g.value)));
                }
            }
        }
        let quick = tree_collide(&ta, &pa, &tb, &pb, false, None, &TreeQueryParams::default()).unwrap();
        let full = tree_collide(&ta, &pa, &tb, &pb, true, None, &TreeQueryParams::default()).unwrap();
        assert!(quick.converged && full.converged);
        assert_eq!(quick.colliding, brute_min.is_some(), "case {case}");
        assert_eq!(full.colliding, brute_min.is_some(), "case {case}");
        if let Some(m) = brute_min {
            hits += 1;
            let g = full.growth.as_ref().unwrap().value;
            assert!((g - m).abs() < 1e-8, "case {case}: {g} vs brute {m}");
        } else {
            misses += 1;
        }
    }
    assert!(hits > 5 && misses > 5, "{hits} {misses}");
}

#[test]
fn warm_started_queries_give_the_cold_answers() {
    let (ta, _) = sphere_tree(60);
    let (tb, _) = sphere_tree(70);
    let pa = Isometry3::identity();
    let mut warm: Option<TreeWarmStart> = None;
    for step in 0..30 {
        let t = step as Real * 0.01;
        let pb = Isometry3::from_parts(
            Vector3::new(2.6 - t, 0.1 * t, 0.05).into(),
            UnitQuaternion::from_euler_angles(0.2 + t, 0.1, -0.3 * t),
        );
        let params = TreeQueryParams::default();
        let w = tree_distance(&ta, &pa, &tb, &pb, warm.as_ref(), &params).unwrap();
        let c = tree_distance(&ta, &pa, &tb, &pb, None, &params).unwrap();
        assert!((w.lower - c.lower).abs() < 1e-8 && (w.upper - c.upper).abs() < 1e-8, "step {step}");
        assert_eq!(w.best.as_ref().map(|b| b.leaves), c.best.as_ref().map(|b| b.leaves));
        assert!(w.warm_start.distance_pairs() > 0);
        warm = Some(w.warm_start);
    }
}

#[test]
fn a_single_body_is_a_one_node_tree() {
    let a = random_body(6, 7);
    let b = random_body(4, 8);
    let pa = Isometry3::identity();
    let pb =
        Isometry3::from_parts(Vector3::new(2.2, 0.3, -0.1).into(), UnitQuaternion::from_euler_angles(0.3, 0.2, 0.1));
    let r = tree_distance(&a, &pa, &b, &pb, None, &TreeQueryParams::default()).unwrap();
    let d = distance(&a, &pa, &b, &pb, None, &NewtonParams::default());
    assert!((r.lower - d.distance).abs() < 1e-12 && (r.upper - d.distance).abs() < 1e-12);
    assert_eq!((r.level, r.best.unwrap().leaves), (0, (0, 0)));
}

#[test]
fn gradient_of_the_active_leaf_pair_matches_finite_differences() {
    let (ta, _) = sphere_tree(80);
    let (tb, _) = sphere_tree(90);
    let pa = Isometry3::identity();
    let pb =
        Isometry3::from_parts(Vector3::new(2.4, 0.2, 0.1).into(), UnitQuaternion::from_euler_angles(0.1, 0.4, 0.2));
    let p = TreeQueryParams::default();
    let r = tree_distance(&ta, &pa, &tb, &pb, None, &p).unwrap();
    let (_, gb) = r.gradient().unwrap();
    let h = 1e-6;
    for k in 0..3 {
        let mut v = Vector3::zeros();
        v[k] = h;
        let plus = crate::gradient::perturb_pose(&pb, &v, &Vector3::zeros());
        let minus = crate::gradient::perturb_pose(&pb, &-v, &Vector3::zeros());
        let fd = (tree_distance(&ta, &pa, &tb, &plus, None, &p).unwrap().lower
            - tree_distance(&ta, &pa, &tb, &minus, None, &p).unwrap().lower)
            / (2.0 * h);
        assert!((fd - gb.linear[k]).abs() < 1e-5, "component {k}: fd {fd} vs {}", gb.linear[k]);
    }
}

#[test]
fn bad_input_is_an_error_naming_the_field() {
    let (ta, _) = sphere_tree(1);
    let pose = Isometry3::identity();
    let bad = TreeQueryParams { tolerance: -1.0, ..Default::default() };
    let e = tree_distance(&ta, &pose, &ta, &pose, None, &bad).unwrap_err().to_string();
    assert!(e.contains("tolerance"), "{e}");
    let e = tree_closer_than(&ta, &pose, &ta, &pose, Real::NAN, None, &TreeQueryParams::default()).unwrap_err();
    assert!(e.to_string().contains("margin"), "{e}");
    let mut broken = sphere_tree(2).0;
    broken.children[1].push(99);
    let e = tree_distance(&broken, &pose, &ta, &pose, None, &TreeQueryParams::default()).unwrap_err().to_string();
    assert!(e.contains("tree_a"), "{e}");
    let mut cyclic = sphere_tree(3).0;
    cyclic.children[1].push(0);
    let e = tree_collide(&ta, &pose, &cyclic, &pose, false, None, &TreeQueryParams::default()).unwrap_err();
    assert!(e.to_string().contains("tree_b"), "{e}");
}

/// The bundled compound bodies (data/compound/), chair and human first.
const BUNDLED: [&str; 5] = ["chair_101", "human_10", "hand_181", "octopus_121", "vase_361"];

/// Every bundled compound body (data/compound/*.json); a missing file fails the test.
fn bundled_compounds() -> Vec<(String, sublevel_core::compound::CompoundBody)> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join("data/compound");
    let mut out = vec![];
    for name in BUNDLED {
        let path = dir.join(format!("{name}.json"));
        let c =
            sublevel_core::compound::CompoundBody::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        out.push((name.to_string(), c));
    }
    out
}

/// Boundary point of a convex body on the ray from its interior point along `dir` (unit), by
/// bisection on p = 1 (independent of the body's radial and support tables); returns a point
/// with p ≤ 1 within 1e-12 m of the crossing.
fn ray_boundary(body: &Body, dir: &Vector3) -> Point3 {
    let c = body.interior_point();
    let mut hi = body.scale();
    while body.value_at(&(c + dir * hi)) <= 1.0 {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    while hi - lo > 1e-12 {
        let mid = 0.5 * (lo + hi);
        if body.value_at(&(c + dir * mid)) <= 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    c + dir * lo
}

/// Unit directions spread over the sphere (Fibonacci lattice).
fn sphere_directions(n: usize) -> Vec<Vector3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|k| {
            let z = 1.0 - 2.0 * (k as Real + 0.5) / n as Real;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * k as Real;
            Vector3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

#[test]
fn bounding_boxes_contain_the_boundary_of_every_bundled_body() {
    let dirs = sphere_directions(400);
    let (mut checked, mut total) = (0, 0);
    for (name, compound) in bundled_compounds() {
        total += compound.node_count();
        for node in 0..compound.node_count() {
            let body = &compound.nodes()[node].body;
            let Some((c, h)) = body.bounding_box() else { continue };
            let (sc, sr) = body.bounding_sphere().unwrap();
            assert!((sc - c).norm() < 1e-12 && (sr - h.norm()).abs() < 1e-12, "{name} node {node}: box ≠ sphere's");
            for d in &dirs {
                let x = ray_boundary(body, d);
                let excess = ((x - c).abs() - h).max();
                assert!(excess <= 1e-9, "{name} node {node}: boundary point {x} outside the box by {excess} m");
            }
            checked += 1;
        }
    }
    // Only nonconvex bodies (no proven box) are skipped.
    assert!(10 * checked >= 9 * total, "{checked} of {total} bodies checked");
}

#[test]
fn cheap_bounds_never_exceed_the_distance_of_any_bundled_node_pair() {
    use super::search::CheapBounds;
    let all = bundled_compounds();
    let (chair, human) = (&all[0].1, &all[1].1);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let params = NewtonParams::default();
    let (mut separated, mut tight, mut unconverged) = (0, 0, 0);
    for _ in 0..6 {
        let pa = random_pose(&mut rng, 1.5);
        let pb = random_pose(&mut rng, 0.3);
        let cheap = CheapBounds::new(&pa, &pb, SLACK);
        for i in 0..chair.node_count() {
            for j in 0..human.node_count() {
                let (ba, bb) = (chair.body(i), human.body(j));
                let gap = cheap.gap(ba, bb).unwrap();
                let r = distance(ba, &pa, bb, &pb, None, &params);
                if !r.status.converged() {
                    unconverged += 1;
                    continue;
                }
                // A pruned pair's true distance is ≥ the bound that pruned it.
                assert!(gap <= r.distance + 1e-9, "pair ({i}, {j}): cheap bound {gap} > distance {}", r.distance);
                // The bound contains the bounding spheres' gap.
                let (ca, ra) = ba.bounding_sphere().unwrap();
                let (cb, rb) = bb.bounding_sphere().unwrap();
                let spheres = ((pa * ca) - (pb * cb)).norm() - ra - rb;
                assert!(gap >= spheres - 1e-9, "pair ({i}, {j}): {gap} < sphere gap {spheres}");
                if r.distance > 0.0 {
                    separated += 1;
                    tight += usize::from(gap > 0.5 * r.distance);
                }
            }
        }
    }
    assert!(separated > 500 && unconverged * 100 < separated, "{separated} separated, {unconverged} unconverged");
    eprintln!("cheap bound > half the distance for {tight} of {separated} separated node pairs");
}

#[test]
fn cheap_bounds_match_closed_forms_on_boxes_of_spheres() {
    use super::search::CheapBounds;
    // Spheres r = 0.5 at the origin and at x = 3: boxes of half extent 0.5, gap 2 on the x axis.
    let a = ellipsoid([0.0; 3], [0.5; 3]).unwrap();
    let b = ellipsoid([3.0, 0.0, 0.0], [0.5; 3]).unwrap();
    let id = Isometry3::identity();
    // Tolerance 1e-8: each box is padded by 1e-9 of its width for rounding (fit::volume::bounding_box).
    let g = CheapBounds::new(&id, &id, SLACK).gap(&a, &b).unwrap();
    assert!((g - 2.0).abs() < 1e-8, "{g}");
    // B turned 45° about z around its center: its box reaches 0.5·√2 along x, gap 2.5 − 0.5·√2.
    let turn = Isometry3::rotation_wrt_point(
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_4),
        Point3::new(3.0, 0.0, 0.0),
    );
    // The boxes' axes give 2.5 − 0.5·√2 = 1.79; the spheres' certified support bounds along the
    // centers' direction give the distance 2 up to their interpolation (< 1 % of a radius).
    let g = CheapBounds::new(&id, &turn, SLACK).gap(&a, &b).unwrap();
    assert!((2.0 - 0.005..=2.0).contains(&g) && g > 2.5 - 0.5 * 2f64.sqrt(), "{g}");
    // Overlapping boxes: a negative gap (no bound beyond 0).
    let g = CheapBounds::new(&id, &Isometry3::translation(-2.5, 0.0, 0.0), SLACK).gap(&a, &b).unwrap();
    assert!(g < 0.0, "{g}");
}

#[test]
fn warm_queries_start_from_the_active_leaf_pair() {
    let all = bundled_compounds();
    let (chair, human) = (&all[0].1, &all[1].1);
    let id = Isometry3::identity();
    let params = TreeQueryParams::default();
    let mut warm: Option<TreeWarmStart> = None;
    for k in 0..12 {
        let s = k as Real / 11.0;
        let pose = Isometry3::from_parts(
            Vector3::new(-1.4 + 0.4 * s, 0.3, 0.1).into(),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.3 * s),
        );
        let cold = tree_distance(chair, &pose, human, &id, None, &params).unwrap();
        let w = tree_distance(chair, &pose, human, &id, warm.as_ref(), &params).unwrap();
        assert!((w.lower - cold.lower).abs() < 1e-7 && (w.upper - cold.upper).abs() < 1e-7, "step {k}");
        assert_eq!(w.warm_start.active_pair(), w.best.as_ref().map(|b| b.leaves), "step {k}");
        if let Some(prev) = warm.as_ref().and_then(TreeWarmStart::active_pair) {
            // The previous active pair is solved first.
            assert_eq!(w.leaf_pairs[0].leaves, prev, "step {k}");
            assert!(w.pairs_evaluated <= cold.pairs_evaluated + 1, "step {k}");
        }
        warm = Some(w.warm_start);
    }
}

/// Leaves below `node` (itself for a leaf).
fn leaves_below<T: BodyTree>(tree: &T, node: usize) -> Vec<usize> {
    let mut out = vec![];
    let mut stack = vec![node];
    while let Some(n) = stack.pop() {
        if tree.children(n).is_empty() {
            out.push(n);
        }
        stack.extend_from_slice(tree.children(n));
    }
    out
}

#[test]
fn leaf_support_bounds_contain_every_leaf_below() {
    let all = bundled_compounds();
    let dirs = sphere_directions(60);
    let rays = sphere_directions(300);
    for (name, tree) in all.iter().take(2) {
        // Boundary samples of every leaf (independent of the support tables).
        let samples: Vec<Vec<Point3>> = (0..tree.node_count())
            .map(|i| {
                if tree.children(i).is_empty() {
                    rays.iter().map(|d| ray_boundary(tree.body(i), d)).collect()
                } else {
                    vec![]
                }
            })
            .collect();
        let mut gain = 0.0;
        for node in 0..tree.node_count() {
            let leaves = leaves_below(tree, node);
            for n in &dirs {
                let bound = tree.leaf_support_upper(node, n).unwrap();
                let reach = leaves
                    .iter()
                    .flat_map(|&l| samples[l].iter())
                    .map(|x| n.dot(&x.coords))
                    .fold(Real::NEG_INFINITY, Real::max);
                assert!(bound >= reach - 1e-12, "{name} node {node}: bound {bound} < sample {reach} along {n}");
                // Never looser than the node's own body.
                let own = tree.body(node).support_upper(n).unwrap();
                assert!(bound <= own + 1e-9, "{name} node {node}: {bound} > own {own}");
                gain += own - bound;
            }
        }
        // The leaves' hull is tighter than the containment fits on average.
        let mean_gain = gain / (tree.node_count() * dirs.len()) as Real;
        assert!(mean_gain > 1e-3, "{name}: mean gain {mean_gain} m");
    }
}

/// Brute force over the leaf pairs of two bundled trees: every leaf pair's Newton distance.
fn leaf_distances(
    a: &sublevel_core::compound::CompoundBody,
    pa: &Isometry3,
    b: &sublevel_core::compound::CompoundBody,
    pb: &Isometry3,
) -> std::collections::HashMap<(usize, usize), Real> {
    let mut out = std::collections::HashMap::new();
    for i in a.leaves() {
        for j in b.leaves() {
            let r = distance(a.body(i), pa, b.body(j), pb, None, &NewtonParams::default());
            assert!(r.status.converged(), "leaf pair ({i}, {j})");
            out.insert((i, j), r.distance);
        }
    }
    out
}

/// Checks a kept cut against brute force: its pairs cover every leaf pair, and each pair's bound
/// is below the distance of every leaf pair under it.
fn check_cut(
    warm: &TreeWarmStart,
    a: &sublevel_core::compound::CompoundBody,
    b: &sublevel_core::compound::CompoundBody,
    leaf: &std::collections::HashMap<(usize, usize), Real>,
    what: &str,
) {
    let cut = warm.cut.as_ref().unwrap_or_else(|| panic!("{what}: no cut kept"));
    let mut covered = std::collections::HashSet::new();
    for p in cut.pairs(SLACK) {
        let (la, lb) = (leaves_below(a, p.a as usize), leaves_below(b, p.b as usize));
        for &i in &la {
            for &j in &lb {
                let d = leaf[&(i, j)];
                assert!(
                    p.lower <= d + 1e-9,
                    "{what}: cut pair ({}, {}) bound {} > leaf ({i}, {j}) {d}",
                    p.a,
                    p.b,
                    p.lower
                );
                covered.insert((i, j));
            }
        }
    }
    assert_eq!(covered.len(), leaf.len(), "{what}: the cut misses leaf pairs");
}

/// The chair's pose at `s ∈ [0, 1]` of the slide-and-turn through the human of `sublevel-lab bench`
/// (`crates/lab/examples/tree_profile.rs`).
fn slide_pose(s: Real) -> Isometry3 {
    let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, 1.0, 0.1));
    Isometry3::from_parts(
        Vector3::new(-2.5 + 5.0 * s, 0.3, 0.1).into(),
        UnitQuaternion::from_axis_angle(&axis, 1.5 * s),
    )
}

#[test]
fn warm_motion_through_contact_matches_cold_and_brute_force() {
    // The profile's slide-and-turn motion through the human (`crates/lab/examples/tree_profile.rs`),
    // coarser: warm queries carry the cut of the previous step (motion bounds, axes re-evaluated)
    // and must give the cold answer and the brute-force minimum at every step, in contact too.
    let all = bundled_compounds();
    let (chair, human) = (&all[0].1, &all[1].1);
    let id = Isometry3::identity();
    let params = TreeQueryParams::default();
    let steps = 36;
    let mut warm: Option<TreeWarmStart> = None;
    let mut margin_warm: Option<TreeWarmStart> = None;
    let (mut contact, mut kept) = (0, 0);
    for k in 0..steps {
        let s = k as Real / (steps - 1) as Real;
        let pose = slide_pose(s);
        let leaf = leaf_distances(chair, &pose, human, &id);
        let exact = leaf.values().cloned().fold(Real::INFINITY, Real::min);
        let cold = tree_distance(chair, &pose, human, &id, None, &params).unwrap();
        let w = tree_distance(chair, &pose, human, &id, warm.as_ref(), &params).unwrap();
        for (r, what) in [(&cold, "cold"), (&w, "warm")] {
            assert!(r.converged && r.within_tolerance, "step {k} {what}");
            assert!((r.upper - exact).abs() < 1e-9, "step {k} {what}: upper {} vs brute {exact}", r.upper);
            // Both are Newton answers converged to the KKT tolerance (1e-10): a warm and a cold solve
            // of the same leaf pair agree to ~1e-12, so `lower` is checked at the tolerance of `upper`.
            assert!(r.lower <= exact + 1e-9, "step {k} {what}: lower {} > brute {exact}", r.lower);
            check_cut(&r.warm_start, chair, human, &leaf, &format!("step {k} {what}"));
        }
        assert!((w.lower - cold.lower).abs() < 1e-9 && (w.upper - cold.upper).abs() < 1e-9, "step {k}");
        contact += usize::from(exact == 0.0);
        kept += w.pairs_pruned_by_spheres;
        // Margin queries along the same motion, warm from their own previous answer.
        let m = tree_closer_than(chair, &pose, human, &id, 0.05, margin_warm.as_ref(), &params).unwrap();
        let mc = tree_closer_than(chair, &pose, human, &id, 0.05, None, &params).unwrap();
        assert!(m.converged && mc.converged, "step {k}");
        assert_eq!(m.closer, exact < 0.05, "step {k}: margin, brute {exact}");
        assert_eq!(m.closer, mc.closer, "step {k}");
        margin_warm = Some(m.warm_start);
        warm = Some(w.warm_start);
    }
    assert!(contact >= 3 && contact < steps - 10, "{contact} steps in contact");
    assert!(kept > steps * 20, "{kept} pairs decided by bounds");
}

#[test]
fn warm_starts_from_unrelated_poses_stay_exact() {
    // Large, random jumps between queries: the kept cut's motion bounds must stay valid (and
    // mostly fail, sending the search back to the trees).
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
    let (ta, sa) = sphere_tree(80);
    let (tb, sb) = sphere_tree(90);
    let mut warm: Option<TreeWarmStart> = None;
    for case in 0..60 {
        let (pa, pb) = separated_poses(&mut rng, 0.5..3.5);
        let exact = sphere_distance(&sa, &pa, &sb, &pb);
        for tol in [0.0, 0.05] {
            let params = TreeQueryParams { tolerance: tol, ..Default::default() };
            let r = tree_distance(&ta, &pa, &tb, &pb, warm.as_ref(), &params).unwrap();
            assert!(r.converged && r.within_tolerance, "case {case}");
            assert!(
                r.lower <= exact + 1e-9 && exact <= r.upper + 1e-7,
                "case {case}: {exact} ∉ [{}, {}]",
                r.lower,
                r.upper
            );
            if tol == 0.0 {
                assert!((r.upper - exact).abs() < 1e-7, "case {case}: {} vs {exact}", r.upper);
            }
            warm = Some(r.warm_start);
        }
    }
}

#[test]
fn far_groups_carry_over_fine_motion_and_stay_valid() {
    // A fine slide of the chair towards and into the human (≈ 1 cm a step, the bench's warm
    // motion): the warm start's far group (pairs far above the threshold, checked as one) is
    // carried from step to step and erodes; every warm answer must equal the cold one, and the
    // cut (near and far pairs, far ones at the group's bound) must bound every leaf pair below it.
    let all = bundled_compounds();
    let (chair, human) = (&all[0].1, &all[1].1);
    let id = Isometry3::identity();
    let params = TreeQueryParams::default();
    let steps = 120;
    let mut warm: Option<TreeWarmStart> = None;
    let (mut grouped, mut carried) = (0, 0);
    for k in 0..steps {
        let s = 0.15 + 0.25 * k as Real / (steps - 1) as Real;
        let pose = slide_pose(s);
        let cold = tree_distance(chair, &pose, human, &id, None, &params).unwrap();
        let w = tree_distance(chair, &pose, human, &id, warm.as_ref(), &params).unwrap();
        assert!(w.converged && w.within_tolerance, "step {k}");
        assert!((w.upper - cold.upper).abs() < 1e-9, "step {k}: warm {} vs cold {}", w.upper, cold.upper);
        assert!(w.lower <= cold.upper + 1e-9 && w.lower >= cold.upper - 1e-9, "step {k}: lower {}", w.lower);
        let far = w.warm_start.cut.as_ref().and_then(|c| c.far.clone());
        if let Some(far) = &far {
            grouped += 1;
            let previous = warm.as_ref().and_then(|p| p.cut.as_ref()).and_then(|c| c.far.as_ref());
            carried += usize::from(previous.is_some_and(|p| std::sync::Arc::ptr_eq(p, far)));
        }
        if k % 30 == 29 {
            let leaf = leaf_distances(chair, &pose, human, &id);
            check_cut(&w.warm_start, chair, human, &leaf, &format!("step {k}"));
        }
        warm = Some(w.warm_start);
    }
    assert!(grouped > steps / 2, "{grouped} of {steps} steps kept a far group");
    assert!(carried > steps / 3, "{carried} of {steps} steps carried the previous far group");
}

/// The separating-axis bound of two single bodies ([`axis_lower_bound`]) against the exact
/// distance (the cold Newton answer, converged) on the cold chair_101 / human_10 poses of
/// `sublevel-lab bench` at 2d = 4, 6, 8: it never exceeds the distance (10⁻⁹ m), is ≤ 0 for every
/// overlapping pair, and shows separation for most separated pairs whose bounding spheres overlap
/// (125 of 139, 104 of 117 and 88 of 100; the test asserts at least 70 %).
#[test]
fn axis_bound_is_below_the_distance_and_shows_most_separations_the_spheres_miss() {
    let poses = crate::test_bodies::bench_cold_poses(300);
    let id = Isometry3::identity();
    for degree in [4usize, 6, 8] {
        let (chair, human) = crate::test_bodies::bench_bodies(degree);
        let ((ca, ra), (ch, rh)) = (chair.bounding_sphere().unwrap(), human.bounding_sphere().unwrap());
        let (mut missed, mut shown) = (0, 0);
        for p in &poses {
            let d = distance(&chair, p, &human, &id, None, &NewtonParams::default());
            assert!(d.status.converged());
            let exact = if d.overlapping { 0.0 } else { d.distance };
            let bound = axis_lower_bound(&chair, p, &human, &id).unwrap();
            assert!(bound <= exact + 1e-9, "2d = {degree}: bound {bound} above the distance {exact}");
            let spheres_apart = ((p * ca) - ch).norm() > ra + rh;
            if !d.overlapping && !spheres_apart {
                missed += 1;
                shown += usize::from(bound > 0.0);
            }
        }
        assert!(10 * shown >= 7 * missed, "2d = {degree}: the axis shows {shown} of {missed} separations");
    }
}
