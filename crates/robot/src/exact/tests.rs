//! The exact stage against parry's whole-shape queries on random poses, and the box gaps against
//! the axes projected one by one.

use super::*;

/// A torus about z (major radius `big`, minor `small`), `n × m` quads cut in triangles: a
/// non-convex closed mesh whose pairs touch in many places.
fn torus(big: Real, small: Real, n: u32, m: u32) -> SharedShape {
    let tau = std::f64::consts::TAU;
    let mut points = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (tau * Real::from(i) / Real::from(n), tau * Real::from(j) / Real::from(m));
            let rho = big + small * v.cos();
            points.push(parry3d_f64::math::Vector::new(rho * u.cos(), rho * u.sin(), small * v.sin()));
        }
    }
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let k = |a: u32, b: u32| (a % n) * m + (b % m);
            triangles.push([k(i, j), k(i + 1, j), k(i + 1, j + 1)]);
            triangles.push([k(i, j), k(i + 1, j + 1), k(i, j + 1)]);
        }
    }
    SharedShape::trimesh(points, triangles).expect("a valid torus")
}

/// A deterministic pose near the origin: a rotation from a random unit quaternion and a
/// translation in a cube of half side `reach` (xorshift, so the test needs no crate).
fn pose(state: &mut u64, reach: Real) -> parry3d_f64::math::Pose {
    let mut next = || {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        (*state >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
    };
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(next(), next(), next(), next()));
    let t = Vector3::new(next(), next(), next()) * reach;
    parry_pose(&Isometry3::from_parts(t.into(), q))
}

/// parry's own verdict on the whole shapes: the reference the descents must reproduce.
fn parry_verdict(
    pa: &parry3d_f64::math::Pose,
    a: &SharedShape,
    pb: &parry3d_f64::math::Pose,
    b: &SharedShape,
    padding: Real,
) -> bool {
    if padding == 0.0 {
        parry3d_f64::query::intersection_test(pa, a.as_ref(), pb, b.as_ref()).expect("supported").intersecting
    } else {
        !matches!(
            parry3d_f64::query::closest_points(pa, a.as_ref(), pb, b.as_ref(), padding).expect("supported"),
            ClosestPoints::Disjoint
        )
    }
}

/// The separating-axis gap over the 15 axes, each normalized and projected directly: the
/// reference of the C = Aᵀ B form.
fn generic_box_gap(a: &PlacedBox, b: &PlacedBox, stop: Real) -> Real {
    let d = b.center - a.center;
    // Rounding of the projections: a hair below the exact gap.
    let hair = 1e-12 * (d.norm() + a.half.norm() + b.half.norm());
    let mut gap = Real::NEG_INFINITY;
    let mut axis = |n: Vector3| {
        let len = n.norm();
        if len > 1e-9 {
            let n = n / len;
            gap = gap.max(n.dot(&d).abs() - a.radius(&n) - b.radius(&n) - hair);
        }
        gap > stop
    };
    for i in 0..3 {
        if axis(a.axes.column(i).into_owned()) || axis(b.axes.column(i).into_owned()) {
            return gap;
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            if axis(a.axes.column(i).cross(&b.axes.column(j))) {
                return gap;
            }
        }
    }
    gap
}

#[test]
fn box_gaps_match_the_axes_projected_directly_and_never_exceed_the_distance() {
    let mut state = 0x1234_5678_9abc_def1;
    let mut separated = 0;
    for k in 0..2000 {
        let (pa, pb) = (pose(&mut state, 0.2), pose(&mut state, 0.4));
        let half = |s: &mut u64| {
            let p = pose(s, 0.1);
            Vector3::new(p.translation.x.abs() + 0.01, p.translation.y.abs() + 1e-6, p.translation.z.abs() + 0.05)
        };
        let (ha, hb) = (half(&mut state), half(&mut state));
        let iso = |p: &parry3d_f64::math::Pose| {
            let (q, t) = (p.rotation, p.translation);
            Isometry3::from_parts(
                Vector3::new(t.x, t.y, t.z).into(),
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
            )
        };
        let a = PlacedBox::new(&iso(&pa), &(Vector3::zeros(), ha));
        let b = PlacedBox::new(&iso(&pb), &(Vector3::zeros(), hb));
        let (got, reference) = (box_gap(&a, &b), generic_box_gap(&a, &b, Real::INFINITY));
        assert!((got - reference).abs() < 1e-12, "box pair {k}: {got} against {reference}");
        // A lower bound of the boxes' distance (parry's, 0 when they overlap).
        let (ca, cb) = (SharedShape::cuboid(ha.x, ha.y, ha.z), SharedShape::cuboid(hb.x, hb.y, hb.z));
        let distance = parry3d_f64::query::distance(&pa, ca.as_ref(), &pb, cb.as_ref()).expect("boxes").distance;
        assert!(got <= distance + 1e-12, "box pair {k}: gap {got} above the distance {distance}");
        if distance > 0.0 {
            separated += 1;
            // The stop: the first axis past it ends the search, with its gap.
            let stopped = box_gap_past(&a, &b, 0.0);
            assert!(stopped <= got + 1e-15 && (stopped > 0.0) == (got > 0.0), "box pair {k}");
        }
    }
    assert!(separated > 300, "{separated} separated pairs");
}

#[test]
fn triangles_apart_on_the_common_line_never_intersect() {
    // Random triangle pairs in a 2 cm cube, against parry's triangle–triangle test.
    let mut state = 0x0bad_5eed_1234_5678;
    let point = |s: &mut u64| pose(s, 0.01).translation;
    let (mut apart, mut intersecting) = (0, 0);
    for k in 0..20_000 {
        let u = [point(&mut state), point(&mut state), point(&mut state)];
        let v = [point(&mut state), point(&mut state), point(&mut state)];
        let id = parry3d_f64::math::Pose::IDENTITY;
        let (tu, tv) =
            (parry3d_f64::shape::Triangle::new(u[0], u[1], u[2]), parry3d_f64::shape::Triangle::new(v[0], v[1], v[2]));
        let hit = parry3d_f64::query::intersection_test(&id, &tu, &id, &tv).expect("triangles").intersecting;
        if apart_on_common_line(u, v) {
            assert!(!hit, "triangle pair {k}: called apart, parry finds them intersecting");
            apart += 1;
        }
        intersecting += usize::from(hit);
    }
    // Most pairs that cut each other's planes without meeting are told apart here.
    assert!(apart > 2_000 && intersecting > 2_000, "{apart} apart, {intersecting} intersecting");
}

/// A slack the searches are tested with: a third of the way above 5 mm.
const SLACK: Slack = Slack { fraction: 1.0 / 3.0, floor: 0.005 };

/// A search with [`SLACK`] (`got`, within `max_dist`) against the exact distance (`reference`,
/// parry's): the triangles it found are no closer than the exact distance, and its bound no
/// farther. Returns whether it stopped short of the exact distance.
fn brackets(reference: &ClosestPoints, got: &ClosestPoints, max_dist: Real, what: &str) -> bool {
    let exact = match reference {
        ClosestPoints::Intersecting => 0.0,
        ClosestPoints::WithinMargin(a, b) => (*a - *b).length(),
        ClosestPoints::Disjoint => Real::INFINITY,
    };
    match got {
        ClosestPoints::Intersecting => {
            assert_eq!(exact, 0.0, "{what}");
            false
        }
        ClosestPoints::WithinMargin(a, b) => {
            let d = (*a - *b).length();
            let bound = SLACK.bound(d);
            assert!(exact <= d + 1e-9 && bound <= exact + 1e-9, "{what}: {d} (bound {bound}) against {exact}");
            d > exact + 1e-9
        }
        ClosestPoints::Disjoint => {
            assert!(SLACK.bound(max_dist) <= exact + 1e-9, "{what}: nothing within {max_dist}, {exact}");
            exact <= max_dist
        }
    }
}

#[test]
fn mesh_pairs_match_parrys_verdict_on_random_poses() {
    let (a, b) = (torus(0.1, 0.03, 24, 12), torus(0.08, 0.02, 20, 10));
    let mut state = 0x9e37_79b9_7f4a_7c15;
    let (mut counts, mut near) = ([0usize; 2], 0);
    let (hint, touching) = (PairHint::default(), PairHint::default());
    let mut short = 0;
    for k in 0..600 {
        let padding = if k % 2 == 0 { 0.0 } else { 0.01 };
        let (pa, pb) = (pose(&mut state, 0.02), pose(&mut state, 0.16));
        let expected = parry_verdict(&pa, &a, &pb, &b, padding);
        let (ma, mb) = (a.as_trimesh().expect("mesh"), b.as_trimesh().expect("mesh"));
        // Cold, and warm from the last pair found touching: parry's verdict either way.
        assert_eq!(
            meshes_touch(ma, &pa, mb, &pb, padding, &PairHint::default()),
            expected,
            "pose {k}, padding {padding}"
        );
        assert_eq!(meshes_touch(ma, &pa, mb, &pb, padding, &touching), expected, "pose {k}, padding {padding}");
        counts[usize::from(expected)] += 1;
        // The closest points within 5 cm: parry's answer, the same distance.
        let reference = parry3d_f64::query::closest_points(&pa, a.as_ref(), &pb, b.as_ref(), 0.05).expect("supported");
        // Cold, and warm from the last pose's closest triangles: the same answer.
        let cold = meshes_closest_points(ma, &pa, mb, &pb, 0.05, &PairHint::default(), Slack::EXACT);
        let warm = meshes_closest_points(ma, &pa, mb, &pb, 0.05, &hint, Slack::EXACT);
        assert_eq!(cold, warm, "pose {k}");
        let loose = meshes_closest_points(ma, &pa, mb, &pb, 0.05, &PairHint::default(), SLACK);
        short += usize::from(brackets(&reference, &loose, 0.05, &format!("pose {k}")));
        match (reference, warm) {
            (ClosestPoints::WithinMargin(a1, a2), ClosestPoints::WithinMargin(b1, b2)) => {
                let (da, db) = ((a1 - a2).length(), (b1 - b2).length());
                assert!((da - db).abs() < 1e-9, "pose {k}: {da} against {db}");
                assert!(a.distance_to_point(&pa, b1, false) < 1e-9);
                assert!(b.distance_to_point(&pb, b2, false) < 1e-9);
                near += 1;
            }
            (reference, got) => assert_eq!(reference, got, "pose {k}"),
        }
    }
    assert!(near > 30, "{near} pairs within 5 cm");
    // Both verdicts occur often: the poses straddle contact.
    assert!(counts[0] > 100 && counts[1] > 100, "{counts:?}");
    // The slack's searches stop short of the exact distance on some poses.
    assert!(short > 5, "{short} searches with the slack stopped short");
}

#[test]
fn a_mesh_against_primitives_matches_parrys_verdict_on_random_poses() {
    let mesh = ExactShape { shape: torus(0.1, 0.03, 24, 12), offset: Isometry3::identity() };
    let primitives = [
        Primitive::Box { half_extents: Vector3::new(0.3, 0.2, 0.01) },
        Primitive::Cylinder { radius: 0.02, half_height: 0.15 },
        Primitive::Sphere { radius: 0.04 },
        Primitive::Capsule { radius: 0.015, half_height: 0.1 },
    ];
    let mut state = 0x2545_f491_4f6c_dd1d;
    for p in &primitives {
        let solid = exact_primitive(p);
        let (mut counts, mut near, mut short) = ([0usize; 2], 0, 0);
        let warm = PairHint::default();
        for k in 0..400 {
            let padding = if k % 2 == 0 { 0.0 } else { 0.01 };
            let (pm, ps) = (pose(&mut state, 0.02), pose(&mut state, 0.15));
            let ps = ps * parry_pose(&solid.offset);
            let expected = parry_verdict(&pm, &mesh.shape, &ps, &solid.shape, padding);
            let m = mesh.shape.as_trimesh().expect("mesh");
            let got = mesh_touches_solid(m, &pm, solid.shape.as_ref(), &ps, padding);
            assert_eq!(got, Some(expected), "{p:?}, pose {k}, padding {padding}");
            counts[usize::from(expected)] += 1;
            // The closest points within 5 cm: parry's answer, the same distance.
            let reference =
                parry3d_f64::query::closest_points(&pm, mesh.shape.as_ref(), &ps, solid.shape.as_ref(), 0.05)
                    .expect("supported");
            let loose = mesh_solid_closest_points(m, &pm, solid.shape.as_ref(), &ps, 0.05, &warm, false, SLACK);
            short += usize::from(brackets(&reference, &loose.expect("bounded"), 0.05, &format!("{p:?}, pose {k}")));
            let cold = PairHint::default();
            let got = mesh_solid_closest_points(m, &pm, solid.shape.as_ref(), &ps, 0.05, &cold, false, Slack::EXACT)
                .expect("bounded");
            // Started from the last pose's closest triangle (any triangle is a valid start): the
            // same answer.
            let again = mesh_solid_closest_points(m, &pm, solid.shape.as_ref(), &ps, 0.05, &warm, false, Slack::EXACT);
            match (got, again.expect("bounded")) {
                (ClosestPoints::WithinMargin(a1, a2), ClosestPoints::WithinMargin(b1, b2)) => {
                    assert!(((a1 - a2).length() - (b1 - b2).length()).abs() < 1e-12, "{p:?}, pose {k}");
                }
                (a, b) => assert_eq!(a, b, "{p:?}, pose {k}"),
            }
            if cold.get().is_some() {
                warm.set(cold.get());
            }
            match (reference, got) {
                (ClosestPoints::WithinMargin(a1, a2), ClosestPoints::WithinMargin(b1, b2)) => {
                    let (da, db) = ((a1 - a2).length(), (b1 - b2).length());
                    assert!((da - db).abs() < 1e-9, "{p:?}, pose {k}: {da} against {db}");
                    // Witness points: on the mesh's surface and the solid's.
                    assert!(mesh.shape.distance_to_point(&pm, b1, false) < 1e-9);
                    assert!(solid.shape.distance_to_point(&ps, b2, false) < 1e-9);
                    near += 1;
                }
                (reference, got) => assert_eq!(reference, got, "{p:?}, pose {k}"),
            }
        }
        assert!(counts[0] > 50 && counts[1] > 50 && near > 30, "{p:?}: {counts:?}, {near} within 5 cm");
        assert!(short > 5, "{p:?}: {short} searches with the slack stopped short");
    }
    // A halfspace is unbounded: parry's own test answers it.
    let plane = exact_primitive(&Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 });
    let m = mesh.shape.as_trimesh().expect("mesh");
    let id = parry3d_f64::math::Pose::IDENTITY;
    assert_eq!(mesh_touches_solid(m, &id, plane.shape.as_ref(), &id, 0.0), None);
}
