use super::*;
use crate::test_bodies::random_body;
use rand::{Rng, SeedableRng};
use sublevel_core::body::ellipsoid;
use sublevel_core::math::{Real, UnitQuaternion, Vector3};

/// Random poses in a cube of half-width `half` (meters), uniform quaternions.
fn poses(n: usize, half: Real, seed: u64) -> Vec<(Isometry3, Isometry3)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let pose = |rng: &mut rand_chacha::ChaCha8Rng| {
        let t = Vector3::from_fn(|_, _| rng.random_range(-half..half));
        let q = nalgebra::Quaternion::from(nalgebra::Vector4::from_fn(|_, _| rng.random_range(-1.0..1.0)));
        Isometry3::from_parts(t.into(), UnitQuaternion::new_normalize(q))
    };
    (0..n).map(|_| (pose(&mut rng), pose(&mut rng))).collect()
}

#[test]
fn spheres_match_the_closed_form_on_every_lane() {
    // Spheres of radii 0.5 and 0.3 (centers 0.1 off their frames' origins): the distance is
    // ‖c_a − c_b‖ − 0.8, or 0 when they overlap; 64 poses, a sixth or so overlapping.
    let (a, b) = (ellipsoid([0.1, 0.0, 0.0], [0.5; 3]).unwrap(), ellipsoid([0.0, -0.1, 0.0], [0.3; 3]).unwrap());
    let pairs = poses(64, 1.0, 3);
    let params = NewtonParams::default();
    let mut overlapping = 0;
    for warm_starts in [false, true] {
        for ((pa, pb), d) in pairs.iter().zip(cold_distances(&a, &b, &pairs, &params, warm_starts)) {
            let gap = (pa * sublevel_core::math::Point3::new(0.1, 0.0, 0.0)
                - pb * sublevel_core::math::Point3::new(0.0, -0.1, 0.0))
            .norm()
                - 0.8;
            assert!(d.status.converged(), "{d:?}");
            assert!((d.distance - gap.max(0.0)).abs() < 1e-9, "{} vs {gap}", d.distance);
            assert_eq!(d.overlapping, gap <= 0.0);
            overlapping += usize::from(d.overlapping);
            let (ca, cb) = (
                pa * sublevel_core::math::Point3::new(0.1, 0.0, 0.0),
                pb * sublevel_core::math::Point3::new(0.0, -0.1, 0.0),
            );
            if d.overlapping && (ca - cb).norm() > 0.3 {
                // The growth minimizer (both witnesses): the point of B's sphere nearest A's
                // center (outside B), in closed form.
                let nearest = cb + (ca - cb).normalize() * 0.3;
                assert!((d.witness_a - nearest).norm() < 1e-9 && d.witness_b == d.witness_a, "{d:?}");
            }
            if !d.overlapping {
                // The witnesses lie on the spheres, the normal along the witness segment.
                assert!((a.value_at(&(pa.inverse() * d.witness_a)) - 1.0).abs() < 1e-9);
                assert!((b.value_at(&(pb.inverse() * d.witness_b)) - 1.0).abs() < 1e-9);
                assert!((d.witness_b - d.witness_a - d.normal * d.distance).norm() < 1e-9);
                assert_eq!(d.warm_start.valid, warm_starts, "a warm start only when asked for");
            }
        }
    }
    assert!(overlapping > 4 && overlapping < 100, "{overlapping} overlapping answers of 128");
}

#[test]
fn lanes_give_the_single_pair_answers_at_every_degree() {
    // Ellipsoids (2d = 2) and nonquadratic sos-convex bodies at 2d = 4, 6, 8, 150 random poses
    // each (some overlapping; 2d ≥ 4 through the single-precision coarse stage):
    // every answer converged, with the single-pair solver's overlap flag, distance (1e-9 m)
    // and witnesses (1e-6 m; the bodies are strictly convex, so the witnesses are unique).
    let params = NewtonParams::default();
    for degree in [2, 4, 6, 8] {
        let (a, b) = (random_body(degree, 11), random_body(degree, 12));
        let pairs = poses(150, 1.5, degree as u64);
        let batch = cold_distances(&a, &b, &pairs, &params, true);
        let (mut separated, mut worst) = (0, 0.0 as Real);
        for ((pa, pb), d) in pairs.iter().zip(&batch) {
            let s = distance(&a, pa, &b, pb, None, &params);
            assert!(d.status.converged() && s.status.converged());
            assert_eq!(d.overlapping, s.overlapping);
            assert!((d.witness_a - s.witness_a).norm() < 1e-6 && (d.witness_b - s.witness_b).norm() < 1e-6);
            worst = worst.max((d.distance - s.distance).abs());
            if !d.overlapping {
                separated += 1;
                // The warm start it keeps restarts the same query converged at once.
                assert!(d.warm_start.valid);
                let again = distance(&a, pa, &b, pb, Some(&d.warm_start), &params);
                assert!(again.warm_started && again.iterations <= 1, "{again:?}");
            }
        }
        assert!(worst < 1e-9, "2d = {degree}: distances differ by {worst:e} m");
        assert!(separated > 30 && separated < 150, "2d = {degree}: {separated} separated of 150");
    }
}

/// `body` scaled by `k` about its frame's origin, then moved by `shift` (meters, its frame):
/// {x : p((x − k·c − shift)/(k·s)) ≤ 1}.
fn rescaled(body: &Body, k: Real, shift: Vector3) -> Body {
    let c = body.center() * k + shift;
    Body::new(body.polynomial().clone(), [c.x, c.y, c.z], body.scale() * k, Default::default()).unwrap()
}

#[test]
fn lanes_give_the_single_pair_answers_at_extreme_scales_and_offsets() {
    // Where single precision ran short while the coarse stage held its points in A's frame
    // (the batch then ran at 0.08–0.8× the single-query rate): a 2 mm body against a 1 m one
    // up to 5 m away, a 1 m body whose center is 1 km from its frame's origin (B posed next
    // to it), and a 100 m body against a 1 cm one; and where the double-precision lanes ran
    // short in A's frame (they then failed, and the single-pair solver answered: 0.09× the
    // single-query rate on 1 cm bodies 10 km from A's frame origin) and their line search
    // measured stationarity in meters (1 cm bodies: 1.5× the Newton iterations). At 2d = 4,
    // 6, 8 (the degrees with a coarse stage) every batch answer converged with the single-pair
    // solver's overlap flag and distance (to 1e-9 of 1 + the distance, meters) and witnesses
    // (to 1e-6 of the larger body's size), and the batch's answers took at most 1.25× the
    // single-pair solver's Newton iterations (measured 0.95–1.12×; with the lanes in A's frame
    // 1.64× on the 1 cm bodies at 2d = 4: the pairs they leave take the single-pair solver's
    // growth-first path, about twice a lane's iterations).
    let params = NewtonParams::default();
    let zero = Vector3::zeros();
    for degree in [4, 6, 8] {
        let (unit_a, unit_b) = (random_body(degree, 31), random_body(degree, 32));
        // A with its center moved `o` meters from its frame's origin (a body fitted in map
        // coordinates) and B posed near it again: pb ← pa·T(o)·pa⁻¹·pb.
        let o = Vector3::new(800.0, -500.0, 300.0);
        let far = |o: Vector3, pairs: Vec<(Isometry3, Isometry3)>| -> Vec<(Isometry3, Isometry3)> {
            let m = Isometry3::translation(o.x, o.y, o.z);
            pairs.into_iter().map(|(pa, pb)| (pa, pa * m * pa.inv_mul(&pb))).collect()
        };
        let o10 = Vector3::new(8000.0, -5000.0, 3000.0);
        let cases = [
            ("2 mm against 1 m", rescaled(&unit_a, 0.003, zero), unit_b.clone(), poses(40, 2.5, 100 + degree as u64)),
            (
                "A's center 1 km from its origin",
                rescaled(&unit_a, 1.0, o),
                unit_b.clone(),
                far(o, poses(40, 1.5, 200 + degree as u64)),
            ),
            (
                "100 m against 1 cm",
                rescaled(&unit_a, 140.0, zero),
                rescaled(&unit_b, 0.014, zero),
                poses(40, 150.0, 300 + degree as u64),
            ),
            (
                "1 cm bodies, A's center 10 km from its origin",
                rescaled(&unit_a, 0.01, o10),
                rescaled(&unit_b, 0.01, zero),
                far(o10, poses(40, 0.015, 400 + degree as u64)),
            ),
        ];
        for (name, a, b, pairs) in cases {
            let size = a.scale().max(b.scale());
            let batch = cold_distances(&a, &b, &pairs, &params, false);
            let (mut batch_iterations, mut single_iterations) = (0, 0);
            for ((pa, pb), d) in pairs.iter().zip(&batch) {
                let s = distance(&a, pa, &b, pb, None, &params);
                (batch_iterations, single_iterations) =
                    (batch_iterations + d.iterations, single_iterations + s.iterations);
                assert!(d.status.converged() && s.status.converged(), "2d = {degree}, {name}: {d:?} {s:?}");
                assert_eq!(d.overlapping, s.overlapping, "2d = {degree}, {name}");
                let gap = (d.distance - s.distance).abs();
                assert!(gap <= 1e-9 * (1.0 + s.distance), "2d = {degree}, {name}: {} vs {}", d.distance, s.distance);
                let w = (d.witness_a - s.witness_a).norm().max((d.witness_b - s.witness_b).norm());
                assert!(w <= 1e-6 * size, "2d = {degree}, {name}: witnesses {w:e} m apart");
            }
            assert!(
                batch_iterations as Real <= 1.25 * single_iterations as Real,
                "2d = {degree}, {name}: {batch_iterations} Newton iterations against {single_iterations}"
            );
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[test]
fn four_lane_cold_starts_are_the_single_pair_starts() {
    // The 4-lane cold starts against the single-pair solver's (`cold_start`), at every degree,
    // on 203 relative poses (a short last chunk; many pairs overlapping, so every branch runs:
    // facing support points, the radial segment, overlap tests): the same decision for every
    // pair, and the same points to 1e-12 of the bodies' sizes (the arithmetic differs only in
    // rounding: fused multiply-adds, the rotation matrix formula).
    let Some(cpu) = sublevel_kernels::Avx2Fma::detect() else {
        return;
    };
    use super::super::distance::cold_start;
    use sublevel_core::body::PosedBody;
    for degree in [2, 4, 6, 8] {
        let (a, b) = (random_body(degree, 21), random_body(degree, 22));
        let rels: Vec<Isometry3> = poses(203, 1.2, 30 + degree as u64).iter().map(|(pa, pb)| pa.inv_mul(pb)).collect();
        let lanes = lanes::cold_starts_on_lanes(cpu, &a, &b, &rels);
        let size = a.scale() + b.scale();
        let (mut some, mut none) = (0, 0);
        for (rel, got) in rels.iter().zip(&lanes) {
            let want = cold_start(&PosedBody::unposed(&a), &PosedBody::new(&b, rel));
            match (got, want) {
                (Some((x, y)), Some((x0, y0))) => {
                    some += 1;
                    assert!((x - x0).norm() <= 1e-12 * size && (y - y0).norm() <= 1e-12 * size, "2d = {degree}");
                }
                (None, None) => none += 1,
                _ => panic!("2d = {degree}: {got:?} vs {want:?} at {rel:?}"),
            }
        }
        assert!(some > 50 && none > 10, "2d = {degree}: {some} starts, {none} without");
    }
}

#[test]
fn small_batches_and_empty_ones_answer_pair_by_pair() {
    let (a, b) = (random_body(6, 1), random_body(6, 2));
    let params = NewtonParams::default();
    assert!(cold_distances(&a, &b, &[], &params, false).is_empty());
    let pairs = poses(3, 2.0, 5);
    for ((pa, pb), d) in pairs.iter().zip(cold_distances(&a, &b, &pairs, &params, false)) {
        let s = distance(&a, pa, &b, pb, None, &params);
        assert_eq!(d.distance, s.distance);
    }
}

/// The batch reads its thresholds from the settings: with `min_lane_batch` above the batch's size
/// every pair goes through the single-pair solver (the answers are [`distance`]'s to the bit), and
/// with the coarse stage and the checks of predicted points off (`coarse_min_degree`,
/// `verify_min_degree` past every degree) the lanes still give the single-pair answers.
#[test]
fn batch_settings_are_read_from_the_settings() {
    let (a, b) = (random_body(6, 31), random_body(8, 32));
    let pairs = poses(40, 1.5, 9);
    let single: Vec<DistanceResult> =
        pairs.iter().map(|(pa, pb)| distance(&a, pa, &b, pb, None, &NewtonParams::default())).collect();
    let one_by_one = NewtonParams {
        batch: BatchSettings { min_lane_batch: pairs.len() + 1, ..BatchSettings::default() },
        ..NewtonParams::default()
    };
    for (d, s) in cold_distances(&a, &b, &pairs, &one_by_one, false).iter().zip(&single) {
        assert_eq!((d.distance.to_bits(), d.iterations), (s.distance.to_bits(), s.iterations));
    }
    let fine_only = NewtonParams {
        batch: BatchSettings { coarse_min_degree: 100, verify_min_degree: 100, ..BatchSettings::default() },
        ..NewtonParams::default()
    };
    for (d, s) in cold_distances(&a, &b, &pairs, &fine_only, false).iter().zip(&single) {
        assert!(d.status.converged() && s.status.converged());
        assert!((d.distance - s.distance).abs() <= 1e-9 * (1.0 + s.distance), "{} vs {}", d.distance, s.distance);
    }
}
