use super::identities::evaluate;
use super::*;
use sublevel_core::conic::SdpStatus;
use sublevel_core::math::{Real, Vector3};
use sublevel_core::poly::gram::{triangle_len, GramStructure};
use sublevel_core::poly::monomial::{basis_len, graded_exponents3};
use sublevel_core::poly::Polynomial;
use sublevel_core::Error;

/// Coefficients of yᵀ∇²p y (p given by its graded-lex coefficients `c`) and of wᵀGw, both
/// indexed by six-variable exponents (x1, x2, x3, y1, y2, y3): the first directly from the
/// derivative formula, the second through an independent `GramStructure` expansion.
fn hessian_and_gram_coefficients(d: usize, c: &[Real], g: &nalgebra::DMatrix<Real>) -> Vec<(Real, Real)> {
    let full = graded_exponents3(2 * d);
    let low = graded_exponents3(d - 1);
    let mut half6 = Vec::new();
    for k in 0..3 {
        for e in &low {
            let mut v = vec![e[0], e[1], e[2], 0, 0, 0];
            v[3 + k] = 1;
            half6.push(v);
        }
    }
    let gs = GramStructure::with_half_basis(6, half6, 2 * d);
    let rhs6 = gs.polynomial_of(g);
    let mut out = Vec::new();
    for k in 0..3 {
        for l in k..3 {
            for beta in &graded_exponents3(2 * d - 2) {
                let mut lhs = 0.0;
                for (ci, a) in full.iter().enumerate() {
                    let ok = if k == l { a[k] >= 2 } else { a[k] >= 1 && a[l] >= 1 };
                    if !ok {
                        continue;
                    }
                    let mut bb = *a;
                    bb[k] -= 1;
                    bb[l] -= 1;
                    if bb != *beta {
                        continue;
                    }
                    let f = if k == l { (a[k] as f64) * (a[k] as f64 - 1.0) } else { 2.0 * a[k] as f64 * a[l] as f64 };
                    lhs += f * c[ci];
                }
                let mut e6 = vec![beta[0], beta[1], beta[2], 0, 0, 0];
                e6[3 + k] += 1;
                e6[3 + l] += 1;
                out.push((lhs, rhs6[gs.index_of[&e6]]));
            }
        }
    }
    out
}

/// The sos-convexity identities are built into G's affine image: for arbitrary c and
/// arbitrary free columns of G, the G returned by `convexity_gram` satisfies
/// coeff(yᵀ∇²p y) = coeff(wᵀGw) for every monomial, checked against an independent expansion
/// through `GramStructure` in six variables (x, y); the free columns reappear as entries of G.
#[test]
fn gram_image_satisfies_the_sos_convexity_identities() {
    for d in 1..=3 {
        let prob = GramProgram::log_det_p(d, &[]).unwrap();
        let l = basis_len(3, 2 * d);
        let mut x = vec![0.0; prob.num_vars];
        for (k, v) in x.iter_mut().enumerate().skip(prob.col_c) {
            *v = (k as f64 * 0.618_034).fract() - 0.5; // distinct values
        }
        let c = x[prob.col_c..prob.col_c + l].to_vec();
        let g = prob.convexity_gram(&x);
        let mut checked = 0;
        for (lhs, rhs) in hessian_and_gram_coefficients(d, &c, &g) {
            assert!((lhs - rhs).abs() < 1e-12 * (1.0 + lhs.abs()), "d = {d}: {lhs} vs {rhs}");
            checked += 1;
        }
        assert_eq!(checked, 6 * basis_len(3, 2 * d - 2));
        // Every free column is an entry of svec(G), each used once.
        let svec = evaluate(&prob.gram_image, &x);
        let free: Vec<Real> = x[prob.col_g..].to_vec();
        for v in &free {
            assert_eq!(svec.iter().filter(|s| *s == v).count(), 1, "d = {d}: free value {v}");
        }
        assert_eq!(prob.num_vars - prob.col_g, triangle_len(prob.convexity_gram_size) - checked);
    }
}

/// With relaxation c, p = −c(‖u‖²)ᵈ with the free entries of G at 0 gives G = 0
/// (yᵀ∇²(p + c q)y = 0 = wᵀ0w), p = 0 gives the Gram matrix of c·yᵀ∇²q y (independent
/// expansion), and q's coefficients evaluate to (‖u‖²)ᵈ.
#[test]
fn relaxed_identities_move_c_q_into_the_gram_image() {
    for d in 1..=4 {
        let q = norm_power_coefficients(d);
        let poly = Polynomial::from_coefficients(2 * d, q.clone()).unwrap();
        let u = Vector3::new(0.3, -0.7, 1.1);
        assert!((poly.value(&u) - u.norm_squared().powi(d as i32)).abs() < 1e-12);
        let spec = ProblemSpec { convexity_relaxation: 2.5, ..ProblemSpec::log_det_p(d) };
        let prob = GramProgram::build(&spec, Containment::Points(&[])).unwrap();
        let mut x = vec![0.0; prob.num_vars];
        for (k, v) in q.iter().enumerate() {
            x[prob.col_c + k] = -2.5 * v;
        }
        let g = prob.convexity_gram(&x);
        assert!(g.amax() < 1e-12, "d = {d}: |G| = {}", g.amax());
        if d <= 3 {
            let g0 = prob.convexity_gram(&vec![0.0; prob.num_vars]);
            assert!(g0.amax() > 1.0);
            let cq: Vec<Real> = q.iter().map(|v| 2.5 * v).collect();
            for (lhs, rhs) in hessian_and_gram_coefficients(d, &cq, &g0) {
                assert!((lhs - rhs).abs() < 1e-12 * (1.0 + lhs.abs()), "d = {d}: {lhs} vs {rhs}");
            }
        }
    }
    let bad = ProblemSpec { matrix: ObjectiveMatrix::H, convexity_relaxation: 1.0, ..ProblemSpec::log_det_p(2) };
    assert!(matches!(
        GramProgram::build(&bad, Containment::Points(&[])),
        Err(Error::InvalidArgument { field, .. }) if field == "convexity_relaxation"
    ));
}

#[test]
fn every_status_is_mapped() {
    assert_eq!(usable_status(SdpStatus::Solved, "fit").unwrap(), SdpStatus::Solved);
    assert_eq!(usable_status(SdpStatus::AlmostSolved, "fit").unwrap(), SdpStatus::AlmostSolved);
    for s in SdpStatus::ALL.into_iter().filter(|s| !s.is_usable()) {
        let e = usable_status(s, "fit").unwrap_err();
        assert!(matches!(e, Error::Numerical(_)));
        assert!(e.to_string().contains(s.as_str()), "{e}");
        // The text form reads back as the same value.
        assert_eq!(SdpStatus::parse(s.as_str()), s);
    }
    assert_eq!(SdpStatus::parse("a status from elsewhere"), SdpStatus::Unknown);
    assert_eq!(SdpStatus::parse(""), SdpStatus::NotRun);
    let json = serde_json::to_string(&SdpStatus::ClosedForm).unwrap();
    assert_eq!(json, "\"closed_form\"");
    assert_eq!(serde_json::from_str::<SdpStatus>(&json).unwrap(), SdpStatus::ClosedForm);
}

/// The dd and sdd cones of G − εI (paper §VI) against the psd cone, on one cloud in normalized
/// coordinates at 2d = 4 and 6: the feasible sets nest (dd ⊂ sdd ⊂ psd), so the maximized log det P
/// falls from psd to sdd to dd (to the solver's tolerance); every solution's G, read back from the
/// program's affine image, has λ_min ≥ ε − 1e-7 (p sos-convex); the dd solution satisfies
/// Gᵢᵢ − ε ≥ Σⱼ|Gᵢⱼ| entry by entry in the program's basis, and each sdd 2 × 2 block read from
/// the auxiliary columns is psd and the blocks sum to G − εI (all to 1e-6, the solver's
/// feasibility residual on entries of order 1e-6 to 1).
#[test]
fn dd_and_sdd_cones_nest_inside_the_psd_cone() {
    use rand::{Rng, SeedableRng};
    use sublevel_core::poly::gram::triangle_index;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let points: Vec<Vector3> = (0..80)
        .map(|_| {
            let v = Vector3::new(
                rng.random::<Real>() * 2.0 - 1.0,
                rng.random::<Real>() - 0.5,
                rng.random::<Real>() * 1.6 - 0.8,
            );
            v * 0.9
        })
        .collect();
    let settings = SolverSettings {
        tolerance: 1e-8,
        max_iterations: 200,
        linear_solver: KktSolver::default(),
        threads: 1,
        iterative_refinement: true,
    };
    for d in [2, 3] {
        let mut objectives = Vec::new();
        for cone in ConvexityCone::ALL {
            let spec = ProblemSpec { convexity_cone: cone, ..ProblemSpec::log_det_p(d) };
            let program = GramProgram::build(&spec, Containment::Points(&points)).unwrap();
            let raw = program.solve_with_retry(&settings, None, &mut |_, _| {}).unwrap();
            assert!(matches!(raw.status, SdpStatus::Solved), "2d = {}, {}: {:?}", 2 * d, cone.name(), raw.status);
            let m = program.convexity_gram_size;
            let g = program.convexity_gram(&raw.x);
            let lambda = g.clone().symmetric_eigenvalues().min();
            assert!(lambda >= CONVEXITY_FLOOR - 1e-7, "2d = {}, {}: λ_min {lambda}", 2 * d, cone.name());
            // G in the program's (scaled) basis, off-diagonals unpacked from √2 × Gᵢⱼ.
            let packed = evaluate(&program.gram_image, &raw.x);
            let entry = |i: usize, j: usize| {
                let (i, j) = (i.min(j), i.max(j));
                let v = packed[triangle_index(i, j)];
                if i == j {
                    v
                } else {
                    v / std::f64::consts::SQRT_2
                }
            };
            match cone {
                ConvexityCone::Dd => {
                    for i in 0..m {
                        let off: Real = (0..m).filter(|&j| j != i).map(|j| entry(i, j).abs()).sum();
                        assert!(entry(i, i) - CONVEXITY_FLOOR >= off - 1e-6, "row {i}: {} < {off}", entry(i, i));
                    }
                }
                ConvexityCone::Sdd => {
                    // The auxiliary (a, c) pairs follow every other column, pair by pair.
                    let first = program.num_vars - m * (m - 1);
                    let mut diagonal = vec![0.0; m];
                    let mut pair = 0;
                    for j in 0..m {
                        for i in 0..j {
                            let (a, c) = (raw.x[first + 2 * pair], raw.x[first + 2 * pair + 1]);
                            pair += 1;
                            let b = entry(i, j);
                            assert!(a >= -1e-7 && c >= -1e-7 && a * c - b * b >= -1e-7, "block ({i}, {j})");
                            diagonal[i] += a;
                            diagonal[j] += c;
                        }
                    }
                    for (i, s) in diagonal.iter().enumerate() {
                        assert!((entry(i, i) - CONVEXITY_FLOOR - s).abs() <= 1e-6, "diagonal {i}");
                    }
                }
                ConvexityCone::Psd => {}
            }
            objectives.push(raw.certificate.primal_objective);
        }
        let [psd, sdd, dd] = objectives[..] else { unreachable!() };
        assert!(psd >= sdd - 1e-5 && sdd >= dd - 1e-5, "2d = {}: log det P {psd}, {sdd}, {dd}", 2 * d);
        assert!(psd > dd, "2d = {}: the dd cone should cost some log det: {psd} against {dd}", 2 * d);
    }
    let bad =
        ProblemSpec { matrix: ObjectiveMatrix::H, convexity_cone: ConvexityCone::Sdd, ..ProblemSpec::log_det_p(2) };
    assert!(matches!(
        GramProgram::build(&bad, Containment::Points(&points)),
        Err(Error::InvalidArgument { field, .. }) if field == "convexity_cone"
    ));
}
