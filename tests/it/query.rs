//! Integration tests: query. The Newton / active-set solvers (`query::distance`, `query::growth`)
//! against the level-0 sos certificates (`query::sdp_certificate`, exact for sos-convex bodies,
//! paper §IV-A), on random pose pairs of real fitted bodies and of closed-form ellipsoids.
//!
//! Tolerances (stated once, used everywhere):
//!
//! ```text
//! squared distance:  |d_newton² − γ_sdp|  ≤ 1e-6 · max(1, γ_sdp)        (mesh units²)
//! growth:            |g_newton − g_sdp|   ≤ 1e-6 · max(1, |g_sdp|)      (dimensionless)
//! ```
//!
//! A certificate counts only if Clarabel reports `Solved`, or `AlmostSolved` with its a-posteriori
//! check passed (coefficient residual and the gap between γ and the verified bound both within the
//! same tolerance; in practice only overlapping distance pairs, whose optimum is degenerate). The
//! verified bound must not exceed the Newton value (a lower bound) by more than the tolerance.
//!
//! The real-mesh bodies are read from `tests/data/{chair_101,human_10}.deg{4,6}.json` (fits of
//! data/psb); when a file is absent the test prints why and passes without checking.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;
use sublevel::body::ellipsoid;
use sublevel::conic::SdpStatus;
use sublevel::math::{pose_from_parts, Isometry3, Point3, Real, Vector3};
use sublevel::query::sdp_certificate::{certify_distance, certify_growth};
use sublevel::query::{distance, growth, NewtonParams};
use sublevel::Body;

/// Relative tolerance of every Newton-vs-SDP comparison (see the module docs).
const REL_TOL: Real = 1e-6;

/// What kind of pose pair to draw.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PairKind {
    /// B anywhere within a few body sizes of A.
    Random,
    /// B's center close to A's: the bodies overlap (most of the time).
    Overlapping,
    /// B moved along the line of centers until the certified distance is small.
    NearTouching,
}

/// Counts of the pairs a harness run checked, by outcome.
#[derive(Debug, Default)]
struct Tally {
    pairs: usize,
    separated: usize,
    overlapping: usize,
    near_touching: usize,
    /// Largest relative Newton-vs-SDP difference of the squared distance.
    max_rel_distance: Real,
    /// Largest relative Newton-vs-SDP difference of the growth measure (both orders).
    max_rel_growth: Real,
}

impl Tally {
    fn merge(&mut self, other: &Tally) {
        self.pairs += other.pairs;
        self.separated += other.separated;
        self.overlapping += other.overlapping;
        self.near_touching += other.near_touching;
        self.max_rel_distance = self.max_rel_distance.max(other.max_rel_distance);
        self.max_rel_growth = self.max_rel_growth.max(other.max_rel_growth);
    }
}

/// Accepts a certificate's status: `Solved`, or `AlmostSolved` when its a-posteriori check passed:
/// γ − verified bound ≤ `REL_TOL · scale`. The verified bound already absorbs the coefficient
/// residual (folded into the Gram blocks, `sdp_certificate::verify`), so the residual itself is only
/// bounded loosely (≤ 100 · `REL_TOL · scale`): on overlapping chair / human pairs Clarabel ends
/// `AlmostSolved` with residuals of 1.8·10⁻⁶ on some hosts (their BLAS kernels) and below 10⁻⁶ on
/// others, with the verified bound 4·10⁻⁸ m² below γ either way.
fn certificate_trusted(status: SdpStatus, residual: Real, value: Real, verified: Real, scale: Real) -> bool {
    status == SdpStatus::Solved
        || (status == SdpStatus::AlmostSolved
            && residual <= 100.0 * REL_TOL * scale
            && value - verified <= REL_TOL * scale)
}

fn random_rotation(rng: &mut ChaCha8Rng) -> [Real; 4] {
    loop {
        let q: [Real; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let n = q.iter().map(|v| v * v).sum::<Real>().sqrt();
        if n > 0.1 && n <= 1.0 {
            return q.map(|v| v / n);
        }
    }
}

fn pose(q: [Real; 4], t: Vector3) -> Isometry3 {
    pose_from_parts("pose", q, [t.x, t.y, t.z]).expect("unit quaternion")
}

/// A body's size: its normalization scale (the fits normalize the mesh into the unit ball).
fn size(b: &Body) -> Real {
    b.scale()
}

/// Draws one pose pair of the given kind for bodies `a`, `b`.
fn draw_pair(rng: &mut ChaCha8Rng, a: &Body, b: &Body, kind: PairKind) -> (Isometry3, Isometry3) {
    let reach = size(a) + size(b);
    let pa = pose(random_rotation(rng), Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)) * reach);
    let qb = random_rotation(rng);
    // Place B's interior point relative to A's interior point.
    let interior_a = pa * a.interior_point();
    let dir = loop {
        let v = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
        if v.norm() > 0.1 && v.norm() <= 1.0 {
            break v.normalize();
        }
    };
    let place = |dist: Real| {
        // Translation putting B's interior point at interior_a + dist · dir.
        let target = interior_a.coords + dir * dist;
        let rotated = pose(qb, Vector3::zeros()) * b.interior_point();
        pose(qb, target - rotated.coords)
    };
    match kind {
        PairKind::Random => (pa, place(rng.random_range(0.2..2.5) * reach)),
        PairKind::Overlapping => (pa, place(rng.random_range(0.0..0.25) * reach)),
        PairKind::NearTouching => {
            // Start well apart and slide B towards A along the line of centers by (almost) the
            // certified distance; translation is 1-Lipschitz for the distance, so the pair stays
            // separated while the gap shrinks geometrically.
            let mut along = 2.5 * reach;
            for _ in 0..8 {
                let pb = place(along);
                let cert = certify_distance(a, &pa, b, &pb).expect("certificate");
                if cert.distance < 1e-3 * reach {
                    break;
                }
                along -= 0.9 * cert.distance;
            }
            (pa, place(along))
        }
    }
}

/// Checks Newton against the certificates on one pair: distance (a, b), growth (a‖b) and (b‖a).
fn check_pair(a: &Body, pa: &Isometry3, b: &Body, pb: &Isometry3, label: &str, tally: &mut Tally) {
    let params = NewtonParams::default();
    let cert = certify_distance(a, pa, b, pb).unwrap_or_else(|e| panic!("{label}: distance certificate: {e}"));
    let newton = distance(a, pa, b, pb, None, &params);
    assert!(newton.status.converged(), "{label}: Newton distance did not converge: {newton:?}");
    let (dn2, gamma) = (newton.distance * newton.distance, cert.squared_distance);
    let scale = gamma.max(1.0);
    assert!(
        certificate_trusted(cert.solver_status, cert.residual, gamma, cert.verified_squared_distance, scale),
        "{label}: distance certificate not trusted: {cert:?}"
    );
    assert!(cert.verified_squared_distance <= dn2 + REL_TOL * scale, "{label}: verified bound above Newton: {cert:?}");
    tally.max_rel_distance = tally.max_rel_distance.max((dn2 - gamma).abs() / scale);
    assert!(
        (dn2 - gamma).abs() <= REL_TOL * scale,
        "{label}: squared distance Newton {dn2:.12e} vs SDP {gamma:.12e} (status {})",
        cert.solver_status
    );
    // The Newton witnesses are feasible and realize the distance.
    let (xa, xb) = (pa.inverse() * newton.witness_a, pb.inverse() * newton.witness_b);
    assert!(a.value_at(&xa) <= 1.0 + 1e-6 && b.value_at(&xb) <= 1.0 + 1e-6, "{label}: witnesses infeasible");
    assert!(((newton.witness_b - newton.witness_a).norm() - newton.distance).abs() <= 1e-9 * (1.0 + newton.distance));

    for (p1, q1, p2, q2, which) in [(a, pa, b, pb, "a‖b"), (b, pb, a, pa, "b‖a")] {
        let gc = certify_growth(p1, q1, p2, q2).unwrap_or_else(|e| panic!("{label}: growth {which} certificate: {e}"));
        let gn = growth(p1, q1, p2, q2, None, &params);
        assert!(gn.status.converged(), "{label}: Newton growth {which} did not converge: {gn:?}");
        let scale = gc.value.abs().max(1.0);
        assert!(
            certificate_trusted(gc.solver_status, gc.residual, gc.value, gc.verified_value, scale),
            "{label}: growth {which} certificate not trusted: {gc:?}"
        );
        assert!(gc.verified_value <= gn.value + REL_TOL * scale, "{label}: growth {which} verified bound above Newton");
        tally.max_rel_growth = tally.max_rel_growth.max((gn.value - gc.value).abs() / scale);
        assert!(
            (gn.value - gc.value).abs() <= REL_TOL * gc.value.abs().max(1.0),
            "{label}: growth {which} Newton {:.12e} vs SDP {:.12e} (status {})",
            gn.value,
            gc.value,
            gc.solver_status
        );
        // Overlap per growth and per distance agree (away from the touching boundary).
        if (gc.value - 1.0).abs() > 1e-4 {
            assert_eq!(gc.value < 1.0, newton.overlapping, "{label}: growth {which} = {} vs distance", gc.value);
        }
    }
    tally.pairs += 1;
    if newton.overlapping {
        tally.overlapping += 1;
    } else {
        tally.separated += 1;
        if newton.distance < 1e-2 * (size(a) + size(b)) {
            tally.near_touching += 1;
        }
    }
}

/// Runs `count` pairs of each kind in `kinds` (round robin), seeded.
fn run_harness(a: &Body, b: &Body, kinds: &[PairKind], count: usize, seed: u64, name: &str) -> Tally {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut tally = Tally::default();
    for i in 0..count {
        let kind = kinds[i % kinds.len()];
        let (pa, pb) = draw_pair(&mut rng, a, b, kind);
        check_pair(a, &pa, b, &pb, &format!("{name} pair {i} ({kind:?})"), &mut tally);
    }
    tally
}

fn data_path(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests").join("data").join(file)
}

/// Loads a fitted body, or explains on stderr why the test is skipped.
/// A bundled fitted body of `tests/data/` (a missing file fails the test: nothing is skipped).
fn load_bundled(file: &str) -> Body {
    let path = data_path(file);
    Body::load(&path).unwrap_or_else(|e| panic!("{} (bundled in tests/data/, see SOURCE.md): {e}", path.display()))
}

const ALL_KINDS: [PairKind; 3] = [PairKind::Random, PairKind::Overlapping, PairKind::NearTouching];

/// Newton agrees with the SDP certificate (tolerances in the module docs) on 120 seeded pose pairs
/// of the degree-4 chair_101 and human_10 bodies: random, overlapping and near-touching pairs,
/// both orders of the growth measure.
#[test]
fn newton_matches_certificates_on_real_meshes_deg4() {
    let (chair, human) = (load_bundled("chair_101.deg4.json"), load_bundled("human_10.deg4.json"));
    assert_eq!((chair.degree(), human.degree()), (4, 4));
    let mut tally = run_harness(&chair, &human, &ALL_KINDS, 90, 7, "chair/human deg4");
    tally.merge(&run_harness(&human, &chair, &ALL_KINDS, 30, 8, "human/chair deg4"));
    eprintln!("deg4 real meshes: {tally:?}");
    assert!(tally.pairs >= 100);
    assert!(tally.overlapping >= 10 && tally.near_touching >= 10 && tally.separated >= 30, "{tally:?}");
}

/// The same check on a handful of pairs of the degree-6 bodies (84 × 84 Gram matrices).
#[test]
fn newton_matches_certificates_on_real_meshes_deg6() {
    let (chair, human) = (load_bundled("chair_101.deg6.json"), load_bundled("human_10.deg6.json"));
    assert_eq!((chair.degree(), human.degree()), (6, 6));
    let tally = run_harness(&chair, &human, &ALL_KINDS, 6, 11, "chair/human deg6");
    eprintln!("deg6 real meshes: {tally:?}");
    assert!(tally.overlapping >= 1 && tally.separated >= 2, "{tally:?}");
}

/// Harness self-check on closed-form bodies (runs today): 45 seeded pairs of two rotated,
/// translated ellipsoids, Newton vs certificate with the tolerances of the module docs.
#[test]
fn newton_matches_certificates_on_ellipsoids() {
    let a = ellipsoid([0.1, -0.2, 0.05], [0.9, 0.3, 0.5]).expect("ellipsoid");
    let b = ellipsoid([0.0, 0.3, 0.1], [0.4, 1.0, 0.25]).expect("ellipsoid");
    let tally = run_harness(&a, &b, &ALL_KINDS, 45, 3, "ellipsoids");
    eprintln!("ellipsoids: {tally:?}");
    assert!(tally.overlapping >= 5 && tally.near_touching >= 5 && tally.separated >= 15, "{tally:?}");
}

/// Harness self-check against closed forms: for spheres, Newton and the certificate both equal
/// dist = ‖c₁ − c₂‖ − r₁ − r₂ and d(p₁‖p₂) = max(0, ‖c₁ − c₂‖ − r₂)² / r₁² (tolerance 1e-6).
#[test]
fn spheres_match_closed_forms_in_harness() {
    let (r1, r2) = (0.6, 0.35);
    let a = ellipsoid([0.0; 3], [r1; 3]).expect("sphere");
    let b = ellipsoid([0.0; 3], [r2; 3]).expect("sphere");
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut tally = Tally::default();
    for i in 0..12 {
        let kind = ALL_KINDS[i % 3];
        let (pa, pb) = draw_pair(&mut rng, &a, &b, kind);
        check_pair(&a, &pa, &b, &pb, &format!("spheres pair {i}"), &mut tally);
        let (c1, c2): (Point3, Point3) = (pa * Point3::origin(), pb * Point3::origin());
        let gap = (c2 - c1).norm() - r1 - r2;
        let n = distance(&a, &pa, &b, &pb, None, &NewtonParams::default());
        assert!((n.distance - gap.max(0.0)).abs() < 1e-6, "pair {i}: {} vs {gap}", n.distance);
        let gc = certify_growth(&a, &pa, &b, &pb).expect("certificate");
        let want = ((c2 - c1).norm() - r2).max(0.0).powi(2) / (r1 * r1);
        assert!((gc.value - want).abs() < 1e-6 * want.max(1.0), "pair {i}: {} vs {want}", gc.value);
    }
    assert!(tally.overlapping >= 1 && tally.near_touching >= 1, "{tally:?}");
}
