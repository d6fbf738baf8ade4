//! The stability suite: query configurations where collision methods are known to fail (tiny
//! gaps, exact tangency, deep / concentric overlap, containment, identical bodies, flat and needle
//! bodies, large coordinates, warm starts across huge pose jumps, rotations near 180°, bodies
//! scaled to 1 cm), each answered by [`certified_distance`] / [`certified_growth`] in
//! [`CertifyMode::Certify`] and classified against the level-0 SDP.
//!
//! # Classification of one query
//!
//! - **certified**: Newton converged and agrees with the SDP (agreement rule of
//!   [`sublevel_query::certified`]: |n − s| ≤ 1e-6·|s| or ≤ 1e-9 absolute, on the squared distance in m² and on
//!   d(p₁‖p₂));
//! - **flagged**: the answer was replaced by the SDP fallback (`source = SdpFallback`) and that
//!   answer is verified (`converged`);
//! - **unresolved**: anything else (the target is none).
//!
//! Used by the `sublevel-lab stability` report command and its test (`stability::tests`, run by
//! `cargo test -p sublevel-lab stability`).

use nalgebra::{Translation3, Unit};
use rand::{Rng, SeedableRng};
use sublevel_core::body::{ellipsoid, Body};
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_core::Result;
use sublevel_query::distance::{distance, DistanceWarmStart};
use sublevel_query::growth::{growth, GrowthWarmStart};
use sublevel_query::{
    certified::AGREEMENT_ABSOLUTE, certified_distance, certified_growth, AnswerSource, CertifyMode, CertifyParams,
};

/// One configuration: two posed bodies and optional warm starts.
#[derive(Clone, Debug)]
pub struct StabilityPair {
    /// Body A (p₁ of the growth query).
    pub a: Body,
    /// Pose of A.
    pub pose_a: Isometry3,
    /// Body B (p₂ of the growth query).
    pub b: Body,
    /// Pose of B.
    pub pose_b: Isometry3,
    /// Warm start of the distance query (from another pose), if any.
    pub warm_distance: Option<DistanceWarmStart>,
    /// Warm start of the growth query, if any.
    pub warm_growth: Option<GrowthWarmStart>,
}

/// A named family of configurations.
#[derive(Clone, Debug)]
pub struct StabilityCase {
    /// Short name, e.g. `gap 1e-9`.
    pub name: String,
    /// Its configurations.
    pub pairs: Vec<StabilityPair>,
}

/// The outcome of one case: counts over its queries (two per pair: distance and growth).
#[derive(Clone, Debug, Default)]
pub struct CaseReport {
    /// The case's name.
    pub name: String,
    /// Number of queries.
    pub n: usize,
    /// Queries whose Newton answer agrees with the SDP.
    pub certified: usize,
    /// Queries answered by a verified SDP fallback.
    pub flagged: usize,
    /// Queries neither certified nor flagged (descriptions in `failures`).
    pub unresolved: usize,
    /// Median Newton iterations over the queries.
    pub median_iterations: Real,
    /// Max |newton − sdp| / |sdp| over queries with |sdp| > 1e-6 (0 if none).
    pub max_relative_error: Real,
    /// Max |newton − sdp| over queries with |sdp| ≤ 1e-6 (objective units; 0 if none).
    pub max_absolute_error_near_zero: Real,
    /// One line per flagged or unresolved query.
    pub failures: Vec<String>,
}

impl CaseReport {
    /// Percentage of certified queries.
    pub fn certified_percent(&self) -> Real {
        100.0 * self.certified as Real / self.n.max(1) as Real
    }

    /// Percentage of flagged (fallback) queries.
    pub fn flagged_percent(&self) -> Real {
        100.0 * self.flagged as Real / self.n.max(1) as Real
    }
}

/// The gaps of the "gap" cases, in meters of translation beyond the touching position.
pub const GAPS: [Real; 5] = [1e-9, 1e-7, 1e-5, 1e-3, 1e-1];

/// Builds the cases from `bodies` (sos-convex, any degrees; pairs cycle through consecutive
/// bodies), `pairs_per_case` configurations per case, and `seed` for the random directions and
/// rotations. `extra` bodies (e.g. degree 8) give one more case, "degree 8 gaps", when non-empty.
///
/// # Errors
/// [`sublevel_core::Error::InvalidArgument`] naming `bodies` when fewer than one is given.
pub fn stability_cases(
    bodies: &[Body],
    extra: &[Body],
    pairs_per_case: usize,
    seed: u64,
) -> Result<Vec<StabilityCase>> {
    if bodies.is_empty() {
        return Err(sublevel_core::Error::invalid("bodies", "at least one body is needed"));
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let pick = |k: usize| (&bodies[k % bodies.len()], &bodies[(k + 1) % bodies.len()]);
    let mut cases = Vec::new();

    // Gaps and tangency along random directions.
    let touch: Vec<Touching> = (0..pairs_per_case).map(|k| touching_pairs(&mut rng, bodies, k)).collect();
    for gap in GAPS.iter().rev().chain(std::iter::once(&0.0)) {
        let name = if *gap == 0.0 { "tangent (gap 0)".to_string() } else { format!("gap {gap:.0e}") };
        cases.push(StabilityCase { name, pairs: touch.iter().map(|t| t.at(t.s_touch + gap)).collect() });
    }
    cases.push(StabilityCase {
        name: "deep overlap".into(),
        pairs: touch.iter().map(|t| t.at(0.3 * t.s_touch)).collect(),
    });
    cases.push(StabilityCase { name: "concentric".into(), pairs: touch.iter().map(|t| t.at(0.0)).collect() });

    // A small sphere inside each body (both orders).
    let mut inside = Vec::new();
    for k in 0..pairs_per_case {
        let (a, _) = pick(k);
        let pose_a = random_pose(&mut rng, 0.5);
        let c = pose_a * a.interior_point();
        let small = ellipsoid([0.0; 3], [0.05 * a.scale(); 3])?;
        let pose_s = Isometry3::from_parts(Translation3::from(c.coords), random_rotation(&mut rng));
        let pair = |a: &Body, pa: Isometry3, b: &Body, pb: Isometry3| StabilityPair {
            a: a.clone(),
            pose_a: pa,
            b: b.clone(),
            pose_b: pb,
            warm_distance: None,
            warm_growth: None,
        };
        inside.push(pair(a, pose_a, &small, pose_s));
        inside.push(pair(&small, pose_s, a, pose_a));
    }
    cases.push(StabilityCase { name: "one inside the other".into(), pairs: inside });

    // Identical bodies at identical poses.
    let identical = (0..pairs_per_case)
        .map(|k| {
            let (a, _) = pick(k);
            let pose = random_pose(&mut rng, 0.5);
            StabilityPair {
                a: a.clone(),
                pose_a: pose,
                b: a.clone(),
                pose_b: pose,
                warm_distance: None,
                warm_growth: None,
            }
        })
        .collect();
    cases.push(StabilityCase { name: "identical, same pose".into(), pairs: identical });

    // Flat slabs and needles (closed-form thin ellipsoids, axis ratio 1e-3) against the bodies.
    let slab = ellipsoid([0.0; 3], [1.0, 1.0, 1e-3])?;
    let needle = ellipsoid([0.0; 3], [1.0, 1e-3, 1e-3])?;
    let thin: Vec<Body> = vec![slab, needle];
    for (name, gap) in [("slab/needle gap 1e-3", 1e-3), ("slab/needle overlap", -1.0)] {
        let pairs = (0..pairs_per_case)
            .map(|k| {
                let t = touching_pairs(&mut rng, &[thin[k % 2].clone(), bodies[k % bodies.len()].clone()], 0);
                t.at(if gap < 0.0 { 0.5 * t.s_touch } else { t.s_touch + gap })
            })
            .collect();
        cases.push(StabilityCase { name: name.into(), pairs });
    }

    // Coordinates offset by 1e4 m: the gap-1e-3 configurations moved rigidly.
    let offset = Isometry3::translation(1e4, -1e4, 1e4);
    cases.push(StabilityCase {
        name: "offset 1e4 m, gap 1e-3".into(),
        pairs: touch
            .iter()
            .map(|t| {
                let mut p = t.at(t.s_touch + 1e-3);
                p.pose_a = offset * p.pose_a;
                p.pose_b = offset * p.pose_b;
                p
            })
            .collect(),
    });

    // Warm starts from a far-away pose (50 m away, rotated) carried to a near-touching pose.
    cases.push(StabilityCase {
        name: "warm start across a huge jump".into(),
        pairs: touch
            .iter()
            .map(|t| {
                let mut near = t.at(t.s_touch + 1e-3);
                let far_b = Isometry3::from_parts(Translation3::new(50.0, -30.0, 20.0), random_rotation(&mut rng))
                    * near.pose_b;
                let np = Default::default();
                let d = distance(&near.a, &near.pose_a, &near.b, &far_b, None, &np);
                let g = growth(&near.a, &near.pose_a, &near.b, &far_b, None, &np);
                near.warm_distance = Some(*d.warm_start);
                near.warm_growth = Some(*g.warm_start);
                near
            })
            .collect(),
    });

    // Rotations of B near 180° (about a random axis), placed 1e-3 beyond touching.
    let mut flips = Vec::new();
    for (k, angle) in [std::f64::consts::PI - 1e-6, std::f64::consts::PI, std::f64::consts::PI - 1e-12]
        .into_iter()
        .cycle()
        .take(pairs_per_case.max(3))
        .enumerate()
    {
        let (a, b) = pick(k);
        let axis = Unit::new_normalize(random_direction(&mut rng));
        let t = Touching::new(
            a,
            &random_pose(&mut rng, 0.5),
            b,
            UnitQuaternion::from_axis_angle(&axis, angle),
            random_direction(&mut rng),
        );
        flips.push(t.at(t.s_touch + 1e-3));
    }
    cases.push(StabilityCase { name: "rotation near 180°".into(), pairs: flips });

    if !extra.is_empty() {
        let pairs = (0..pairs_per_case)
            .flat_map(|k| {
                let t = touching_pairs(&mut rng, extra, k);
                [t.at(t.s_touch + 1e-3), t.at(t.s_touch + 1e-7), t.at(0.5 * t.s_touch)]
            })
            .collect();
        cases.push(StabilityCase { name: "degree 8 (gaps 1e-3, 1e-7, overlap)".into(), pairs });
    }

    // The bodies scaled to 1 cm (a gripper's finger, a small part): gaps 1e-3 and 1e-7 of their
    // size, and overlap. The solvers' line search measures stationarity in units of the smaller
    // body's size, so these runs are the unit-size ones in other units.
    let small = bodies
        .iter()
        .map(|b| {
            let c = b.center() * 0.01;
            Body::new(b.polynomial().clone(), [c.x, c.y, c.z], 0.01 * b.scale(), Default::default())
        })
        .collect::<Result<Vec<Body>>>()?;
    let pairs = (0..pairs_per_case)
        .flat_map(|k| {
            let t = touching_pairs(&mut rng, &small, k);
            let size = t.a.scale().min(t.b.scale());
            [t.at(t.s_touch + 1e-3 * size), t.at(t.s_touch + 1e-7 * size), t.at(0.5 * t.s_touch)]
        })
        .collect();
    cases.push(StabilityCase { name: "1 cm bodies (gaps 1e-3, 1e-7 of size, overlap)".into(), pairs });
    Ok(cases)
}

/// Runs every query of `case` (distance A–B and growth d(A‖B) per pair) in
/// [`CertifyMode::Certify`] and classifies it (module docs).
pub fn run_case(case: &StabilityCase, params: &CertifyParams) -> CaseReport {
    let mut rep = CaseReport { name: case.name.clone(), ..Default::default() };
    let mut iterations = Vec::new();
    for (k, p) in case.pairs.iter().enumerate() {
        let d = certified_distance(
            &p.a,
            &p.pose_a,
            &p.b,
            &p.pose_b,
            p.warm_distance.as_ref(),
            params,
            CertifyMode::Certify,
        );
        let n2 = d.result.distance * d.result.distance;
        let g =
            certified_growth(&p.a, &p.pose_a, &p.b, &p.pose_b, p.warm_growth.as_ref(), params, CertifyMode::Certify);
        let entries = [
            ("distance²", d.source, d.converged, d.certificate.clone(), n2, d.result.iterations, d.result.status),
            (
                "growth",
                g.source,
                g.converged,
                g.certificate.clone(),
                g.result.value,
                g.result.iterations,
                g.result.status,
            ),
        ];
        for (what, source, converged, cert, value, iters, status) in entries {
            rep.n += 1;
            iterations.push(iters as Real);
            let agrees = cert.as_ref().is_some_and(|c| c.agrees);
            if let Some(c) = &cert {
                // Newton's own value: for fallbacks the certificate's gap was measured before the swap.
                let newton_err = c.relative_gap * c.bound.abs().max(AGREEMENT_ABSOLUTE);
                if c.bound.abs() > 1e-6 {
                    rep.max_relative_error = rep.max_relative_error.max(newton_err / c.bound.abs());
                } else {
                    rep.max_absolute_error_near_zero = rep.max_absolute_error_near_zero.max(newton_err);
                }
            }
            match source {
                AnswerSource::Newton if agrees => rep.certified += 1,
                AnswerSource::SdpFallback if converged => {
                    rep.flagged += 1;
                    rep.failures.push(format!(
                        "{}: pair {k} {what}: Newton {status:?} value {}, replaced by the SDP ({})",
                        case.name,
                        cert.as_ref().and_then(|c| c.newton_value).map_or("-".into(), |v| format!("{v:.10e}")),
                        cert.as_ref().map_or("-".into(), |c| format!(
                            "bound {:.10e}, verified {:.10e}, gap {:.1e}",
                            c.bound, c.verified_bound, c.relative_gap
                        ))
                    ));
                }
                _ => {
                    rep.unresolved += 1;
                    rep.failures.push(format!(
                        "{}: pair {k} {what}: UNRESOLVED source {source:?} converged {converged} status {status:?} value {value:.6e} certificate {cert:?}",
                        case.name
                    ));
                }
            }
        }
    }
    iterations.sort_by(|a, b| a.total_cmp(b));
    rep.median_iterations = match iterations.len() {
        0 => 0.0,
        n if n % 2 == 1 => iterations[n / 2],
        n => 0.5 * (iterations[n / 2 - 1] + iterations[n / 2]),
    };
    rep
}

/// A touching configuration of `set[k]` and `set[k + 1]` (cyclic) with random poses and direction.
fn touching_pairs(rng: &mut rand_chacha::ChaCha8Rng, set: &[Body], k: usize) -> Touching {
    let (a, b) = (&set[k % set.len()], &set[(k + 1) % set.len()]);
    let pose_a = random_pose(rng, 0.5);
    let rot_b = random_rotation(rng);
    let dir = random_direction(rng);
    Touching::new(a, &pose_a, b, rot_b, dir)
}

/// B placed along a ray from A's interior point: B's interior point at `c_a + s·dir` with rotation
/// `rot_b`; `s_touch` is where the two bodies touch (bisection on d(p_A‖p_B) = 1).
struct Touching {
    a: Body,
    pose_a: Isometry3,
    b: Body,
    rot_b: UnitQuaternion,
    origin: Vector3,
    dir: Vector3,
    s_touch: Real,
}

impl Touching {
    fn new(a: &Body, pose_a: &Isometry3, b: &Body, rot_b: UnitQuaternion, dir: Vector3) -> Self {
        let origin = (pose_a * a.interior_point()).coords;
        let mut t = Touching { a: a.clone(), pose_a: *pose_a, b: b.clone(), rot_b, origin, dir, s_touch: 0.0 };
        let separated =
            |t: &Touching, s: Real| growth(&t.a, &t.pose_a, &t.b, &t.pose_b(s), None, &Default::default()).value > 1.0;
        let (mut lo, mut hi) = (0.0, a.scale() + b.scale());
        while !separated(&t, hi) && hi < 1e6 {
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if separated(&t, mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        t.s_touch = hi;
        t
    }

    fn pose_b(&self, s: Real) -> Isometry3 {
        let c = self.origin + self.dir * s;
        let cb = self.rot_b * self.b.interior_point().coords;
        Isometry3::from_parts(Translation3::from(c - cb), self.rot_b)
    }

    fn at(&self, s: Real) -> StabilityPair {
        StabilityPair {
            a: self.a.clone(),
            pose_a: self.pose_a,
            b: self.b.clone(),
            pose_b: self.pose_b(s),
            warm_distance: None,
            warm_growth: None,
        }
    }
}

fn random_direction(rng: &mut rand_chacha::ChaCha8Rng) -> Vector3 {
    loop {
        let v = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

fn random_rotation(rng: &mut rand_chacha::ChaCha8Rng) -> UnitQuaternion {
    let axis = Unit::new_normalize(random_direction(rng));
    UnitQuaternion::from_axis_angle(&axis, rng.random_range(0.0..std::f64::consts::PI))
}

fn random_pose(rng: &mut rand_chacha::ChaCha8Rng, spread: Real) -> Isometry3 {
    let t = random_direction(rng) * rng.random_range(0.0..spread);
    Isometry3::from_parts(Translation3::from(t), random_rotation(rng))
}
