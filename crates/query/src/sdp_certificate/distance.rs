//! The distance certificate (module docs of [`super`], "Distance", "Block structure" and
//! "Conditioning"): `max γ` such that `‖x − y‖² − γ − τ(1 − p_a) − ξ(1 − p_b)` is sos in the six
//! variables w = (u, v) of the two bodies' normalized frames, solved once in the plain frames and,
//! by default, again in frames recentered at the first pass's witnesses.

use super::frame::BodyFrame;
use super::level0::{embed, solve_level0, unit_exponent, Level0Solution};
use super::verify::{radius_estimate, verify_level0};
use super::witness::{kernel_point, moments_first_order, world_point};
use super::CertificateParams;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Matrix3, Point3, Real, Vector3};
use sublevel_core::poly::gram::GramStructure;
use sublevel_core::poly::monomial::graded_exponents;
use sublevel_core::Result;

/// Level-0 SDP bound on the squared distance.
#[derive(Clone, Debug)]
pub struct DistanceCertificate {
    /// γ*: lower bound on the squared distance in m² (exact for sos-convex bodies); ≈ 0 (up to the
    /// solver tolerance, possibly slightly negative) when the bodies overlap.
    pub squared_distance: Real,
    /// √max(γ*, 0) in meters.
    pub distance: Real,
    /// Multiplier τ ≥ 0 of body A's constraint (m², the objective's units).
    pub tau: Real,
    /// Multiplier ξ ≥ 0 of body B's constraint (m²).
    pub xi: Real,
    /// Witness points (x*, y*) in world coordinates, recovered from the first-order moments of the
    /// dual (moment) solution; `None` when the moments are not finite or the recovered points violate
    /// their body's constraint by more than [`CertificateParams::witness_feasibility_tolerance`].
    pub witnesses: Option<(Point3, Point3)>,
    /// The same first-order moments mapped to world points without the feasibility filter (`None`
    /// only when not finite). For nonconvex bodies (paper §IV-A) they may lie outside their body;
    /// when both are feasible and ‖x − y‖² meets the bound, the lower bound is tight.
    pub moment_witnesses: Option<(Point3, Point3)>,
    /// Witness points from the kernel of the Gram matrix (paper §IV-A): the first Gram block has
    /// basis (1, u, v), and at a minimizer the certificate σ vanishes, so (1, u*, v*) spans its
    /// kernel; read off when that kernel is one-dimensional (`None` otherwise, e.g. for a pair with
    /// several minimizers). Unfiltered: for nonconvex bodies they may lie outside their body.
    pub kernel_witnesses: Option<(Point3, Point3)>,
    /// Clarabel's final status (`Solved` or `AlmostSolved`; other statuses are errors).
    pub solver_status: sublevel_core::conic::SdpStatus,
    /// Seconds inside Clarabel (both passes).
    pub solve_seconds: Real,
    /// Interior-point iterations (both passes).
    pub iterations: u32,
    /// Sides of the Gram blocks: `[7, C(3 + d, d), C(3 + d, d)]` for the block-structured form,
    /// `[C(6 + d, d)]` for the full 6-variable form (see [`CertificateParams::full_gram`]).
    pub gram_sizes: Vec<usize>,
    /// A-posteriori lower bound on the squared distance (m²) from the returned certificate:
    /// `squared_distance` when the Gram blocks, corrected so that the sos identity holds exactly,
    /// are PSD; otherwise lowered by |λ_min| times a bound on ‖z(w)‖² over the bodies (which uses
    /// estimates of their radii: careful, not rigorous). See the module docs.
    pub verified_squared_distance: Real,
    /// Max |coefficient residual| of the sos identity as returned (m²).
    pub residual: Real,
    /// Smallest eigenvalue over the corrected Gram blocks (m²; ≥ 0 means an exact sos certificate
    /// up to floating-point rounding).
    pub gram_min_eigenvalue: Real,
}

/// Certifies the distance between body `a` under `pose_a` and body `b` under `pose_b` (paper
/// eq. "distance.lasserre", level 0) with [`CertificateParams::default`].
///
/// # Errors
/// [`sublevel_core::Error::Numerical`] when Clarabel returns no usable solution.
pub fn certify_distance(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Result<DistanceCertificate> {
    certify_distance_with_params(a, pose_a, b, pose_b, &CertificateParams::default())
}

/// [`certify_distance`] with explicit solver settings.
///
/// Builds the Gram form described in the module docs (block-structured by default), maximizes γ
/// (by default twice, the second pass recentered at the first pass's witnesses: module docs,
/// "Conditioning"), recovers the witnesses from the moments and checks the certificate a
/// posteriori.
///
/// # Errors
/// [`sublevel_core::Error::InvalidArgument`] naming `params.tolerance` / `params.max_iterations`;
/// [`sublevel_core::Error::Numerical`] naming Clarabel's status when it is neither `Solved` nor
/// `AlmostSolved`.
pub fn certify_distance_with_params(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    params: &CertificateParams,
) -> Result<DistanceCertificate> {
    params.validate()?;
    let plain = (BodyFrame::identity(), BodyFrame::identity(), a.scale().max(b.scale()));
    let (mut seconds, mut iterations) = (0.0, 0);
    let (frame_a, frame_b, len) = if params.recenter {
        // Pass 1 in the bodies' own normalized frames, loose tolerance, to locate the witnesses.
        let loose = CertificateParams { tolerance: params.tolerance.max(params.presolve_tolerance), ..*params };
        match solve_distance_in(a, pose_a, b, pose_b, &plain, &loose) {
            Ok(first) => {
                seconds += first.sol.sol.solve_seconds;
                iterations += first.sol.sol.iterations;
                match first.witnesses_normalized {
                    Some((u, v)) => {
                        let rho = params.recenter_scale * a.scale().min(b.scale());
                        (
                            BodyFrame { origin: u, scale: rho / a.scale() },
                            BodyFrame { origin: v, scale: rho / b.scale() },
                            rho,
                        )
                    }
                    None => plain,
                }
            }
            Err(_) => plain,
        }
    } else {
        plain
    };
    let frames = (frame_a, frame_b, len);
    let run = solve_distance_in(a, pose_a, b, pose_b, &frames, params)?;
    seconds += run.sol.sol.solve_seconds;
    iterations += run.sol.sol.iterations;
    // ‖w_a‖ ≤ (R_a + ‖u_o‖)/κ_a on body a, likewise for b (module docs, "A-posteriori check").
    let ba = (radius_estimate(a) + frame_a.origin.norm()) / frame_a.scale;
    let bb = (radius_estimate(b) + frame_b.origin.norm()) / frame_b.scale;
    let d = a.degree().max(b.degree()) / 2;
    let powers = |r2: Real| (0..=d).map(|k| r2.powi(k as i32)).sum::<Real>();
    let z_bounds: Vec<Real> = if params.full_gram {
        vec![powers(ba * ba + bb * bb)]
    } else {
        vec![1.0 + ba * ba + bb * bb, powers(ba * ba), powers(bb * bb)]
    };
    let constraints = [run.pa.as_slice(), run.pb.as_slice()];
    let check = verify_level0(&run.blocks, &run.objective, &constraints, &run.sol, &z_bounds);
    let sol = &run.sol.sol;
    let len2 = len * len;
    let gamma = sol.x[run.sol.gamma] * len2;
    let witnesses = run.witnesses_normalized.map(|(u, v)| (world_point(a, pose_a, &u), world_point(b, pose_b, &v)));
    let moment_witnesses =
        run.moments_normalized.map(|(u, v)| (world_point(a, pose_a, &u), world_point(b, pose_b, &v)));
    let kernel_witnesses = run.kernel_normalized.map(|(u, v)| (world_point(a, pose_a, &u), world_point(b, pose_b, &v)));
    Ok(DistanceCertificate {
        squared_distance: gamma,
        distance: gamma.max(0.0).sqrt(),
        tau: sol.x[run.sol.multipliers[0]] * len2,
        xi: sol.x[run.sol.multipliers[1]] * len2,
        witnesses,
        moment_witnesses,
        kernel_witnesses,
        solver_status: sol.status.into(),
        solve_seconds: seconds,
        iterations,
        gram_sizes: run.blocks.iter().map(GramStructure::size).collect(),
        verified_squared_distance: check.bound * len2,
        residual: check.residual * len2,
        gram_min_eigenvalue: check.min_eigenvalue * len2,
    })
}

/// One solved distance program with its data.
struct DistanceRun {
    blocks: Vec<GramStructure>,
    objective: Vec<Real>,
    pa: Vec<Real>,
    pb: Vec<Real>,
    sol: Level0Solution,
    /// Moment-recovered witnesses in the bodies' normalized coordinates, if finite and feasible.
    witnesses_normalized: Option<(Vector3, Vector3)>,
    /// The same moments without the feasibility filter, if finite.
    moments_normalized: Option<(Vector3, Vector3)>,
    /// Witnesses from the kernel of the first Gram block (paper §IV-A), unfiltered, if the kernel
    /// is one-dimensional.
    kernel_normalized: Option<(Vector3, Vector3)>,
}

/// Solves the distance program with body a's variables in `frames.0`, body b's in `frames.1`, and
/// the objective divided by `frames.2`² (meters²).
fn solve_distance_in(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    frames: &(BodyFrame, BodyFrame, Real),
    params: &CertificateParams,
) -> Result<DistanceRun> {
    let (fa, fb, len) = *frames;
    let d = a.degree().max(b.degree()) / 2;
    let blocks = if params.full_gram {
        vec![GramStructure::new(6, d)]
    } else {
        // (1, u, v) for the quadratic part; z_d(u) and z_d(v) for each body's own polynomial.
        let pad = |e: &Vec<u8>, offset: usize| {
            let mut out = vec![0u8; 6];
            out[offset..offset + 3].copy_from_slice(e);
            out
        };
        let half3 = graded_exponents(3, d);
        vec![
            GramStructure::with_half_basis(6, graded_exponents(6, 1), 2 * d),
            GramStructure::with_half_basis(6, half3.iter().map(|e| pad(e, 0)).collect(), 2 * d),
            GramStructure::with_half_basis(6, half3.iter().map(|e| pad(e, 3)).collect(), 2 * d),
        ]
    };
    let gram = &blocks[0];
    let ra = *pose_a.rotation.to_rotation_matrix().matrix();
    let rb = *pose_b.rotation.to_rotation_matrix().matrix();
    // x = R_a(c_a + s_a(u_o + κ_a w_a)) + t_a, likewise y; x − y = δ + M w, everything divided by L.
    let xa0 = ra * (a.center() + fa.origin * a.scale()) + pose_a.translation.vector;
    let xb0 = rb * (b.center() + fb.origin * b.scale()) + pose_b.translation.vector;
    let delta = (xa0 - xb0) / len;
    let mut m = nalgebra::Matrix3x6::<Real>::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(ra * (a.scale() * fa.scale / len)));
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(rb * (-b.scale() * fb.scale / len)));
    let g = m.transpose() * m;
    let lin = m.transpose() * delta;

    let nf = gram.full_basis.len();
    let mut objective = vec![0.0; nf];
    objective[0] = delta.norm_squared();
    for i in 0..6 {
        objective[gram.index_of[&unit_exponent(6, &[i])]] += 2.0 * lin[i];
        for j in i..6 {
            let w = if i == j { 1.0 } else { 2.0 };
            objective[gram.index_of[&unit_exponent(6, &[i, j])]] += w * g[(i, j)];
        }
    }
    let compose =
        |body: &Body, f: &BodyFrame| body.polynomial().compose_affine(&(Matrix3::identity() * f.scale), &f.origin);
    let pa = embed(&compose(a, &fa), gram, 0);
    let pb = embed(&compose(b, &fb), gram, 3);
    let sol = solve_level0(&blocks, &objective, &[pa.as_slice(), pb.as_slice()], params)?;
    let moments_normalized = moments_first_order(&blocks[0], &sol, 6).map(|w| {
        let u = fa.origin + Vector3::new(w[0], w[1], w[2]) * fa.scale;
        let v = fb.origin + Vector3::new(w[3], w[4], w[5]) * fb.scale;
        (u, v)
    });
    let witnesses_normalized = moments_normalized.filter(|(u, v)| {
        a.polynomial().value(u) <= 1.0 + params.witness_feasibility_tolerance
            && b.polynomial().value(v) <= 1.0 + params.witness_feasibility_tolerance
    });
    let kernel_normalized = kernel_point(&blocks[0], &sol, 6, params.kernel_relative_eigenvalue).map(|w| {
        let u = fa.origin + Vector3::new(w[0], w[1], w[2]) * fa.scale;
        let v = fb.origin + Vector3::new(w[3], w[4], w[5]) * fb.scale;
        (u, v)
    });
    Ok(DistanceRun { blocks, objective, pa, pb, sol, witnesses_normalized, moments_normalized, kernel_normalized })
}
