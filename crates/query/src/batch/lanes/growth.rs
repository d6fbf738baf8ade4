//! The growth measure's Newton runs on the lanes: four pairs of the growth-first path per pass.

use super::*;

/// The four lanes' pairs and Newton states of the growth measure's KKT system (see
/// [`solve_growth_on_lanes`]), one array entry per lane (as [`Lanes`]).
struct GrowthLanes {
    /// The lanes' pairs, step lengths, residuals, counters and maps of B.
    book: LaneBook,
    /// Accepted points (the lane's working frame) and multipliers.
    x: [[Real; 4]; 3],
    mu: [Real; 4],
    /// Newton steps from the accepted points.
    dx: [[Real; 4]; 3],
    dmu: [Real; 4],
    /// Each lane's working frame ([`working_frame`], as [`Lanes`]): its origin in A's frame,
    /// and A's map to its normalized coordinates there, u = k·x + c.
    o: [[Real; 4]; 3],
    ca: [[Real; 4]; 3],
}

impl GrowthLanes {
    /// Puts pair `k` into lane `i` in the working frame with origin `o` (A's frame; B posed as
    /// `bb` and A's normalized offset `ca` there), starting at `x0` (that frame).
    fn fill(&mut self, i: usize, k: usize, bb: &PosedBody<'_>, o: &Vector3, ca: &Vector3, x0: &Vector3) {
        self.book.fill(i, k, bb);
        for r in 0..3 {
            self.x[r][i] = x0[r];
            self.dx[r][i] = 0.0;
            self.o[r][i] = o[r];
            self.ca[r][i] = ca[r];
        }
        self.mu[i] = 0.0;
        self.dmu[i] = 0.0;
    }
}

/// The overlap test of the single-pair solver's growth-first path ([`distance_growth_first`]:
/// the growth measure d(p_a‖p_b) = min p_a(x) s.t. p_b(x) ≤ 1, paper §IV-B) for the pairs
/// `queue` of the batch, four per SIMD pass, as [`solve_on_lanes`] runs the separated distance:
/// the single-pair cold start (A's minimizer inside B is left to the single-pair solver; else
/// B's boundary towards A's interior point, or the support point of B facing −∇p_a there when
/// p_a is lower at it), the same KKT system, line search (backtracking on its merit, the
/// multiplier kept at least halved per step), tolerance and iteration cap, with the Hessians
/// at every trial point (no chord steps). A lane that converges with μ > 0 and
/// p_a(x) ≤ 1 gives the overlapping answer (the growth minimizer as both witnesses); every
/// other pair stays `None` for the single-pair solver.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_growth_on_lanes(
    cpu: Avx2Fma,
    a: &Body,
    b: &Body,
    poses: &[(Isometry3, Isometry3)],
    rels: &[Isometry3],
    queue: &[usize],
    params: &NewtonParams,
    warm_starts: bool,
    answers: &mut [Option<DistanceResult>],
    empty: &std::sync::Arc<DistanceWarmStart>,
) {
    let (soa_a, soa_b) = (a.soa_polynomial(), b.soa_polynomial());
    let cap = F4::splat(cpu, params.max_iterations as Real);
    let stall = F4::splat(cpu, params.line_search_steps as Real);
    let tolerance = F4::splat(cpu, params.kkt_tolerance);
    let (zero, one, half) = (F4::splat(cpu, 0.0), F4::splat(cpu, 1.0), F4::splat(cpu, 0.5));
    let (ka4, ka2) = scale_map(cpu, a);
    let len = merit_length(a, b);
    let l2 = F4::splat(cpu, len * len);
    let c1 = PosedBody::unposed(a).interior_point();
    let mut lanes = GrowthLanes {
        book: LaneBook::new(),
        x: [[0.0; 4]; 3],
        mu: [0.0; 4],
        dx: [[0.0; 4]; 3],
        dmu: [0.0; 4],
        o: [[0.0; 4]; 3],
        ca: [[0.0; 4]; 3],
    };
    let mut next = 0usize;
    loop {
        for i in 0..4 {
            while lanes.book.job[i] == EMPTY && next < queue.len() {
                let k = queue[next];
                next += 1;
                let (o, ba, bb) = working_frame(a, b, &rels[k], params);
                let c1 = c1 - o;
                // A's minimizer inside B (the inactive constraint) is the single-pair solver's.
                if FastPosed::new(&bb).value(&c1) <= 1.0 {
                    continue;
                }
                let fa = FastPosed::new(&ba);
                let x0 = bb.boundary_towards(&c1);
                let (v0, g1) = fa.value_gradient(&x0);
                let x0 = bb.support(&-g1).filter(|x| fa.value(x) < v0).unwrap_or(x0);
                lanes.fill(i, k, &bb, &o, &offset_map(a, &o), &x0);
            }
        }
        if lanes.book.is_empty() {
            break;
        }
        let x = V3::load(cpu, &lanes.x);
        let mu = F4::load(cpu, &lanes.mu);
        let dx = V3::load(cpu, &lanes.dx);
        let dmu = F4::load(cpu, &lanes.dmu);
        let book = &lanes.book;
        let (al, r0, start) =
            (F4::load(cpu, &book.alpha), F4::load(cpu, &book.r0), zero.lt(F4::load(cpu, &book.start)));
        let (mb, cb) = book.map(cpu);
        let xt = dx.mul_add(al, x);
        let mut mt = dmu.mul_add(al, mu);
        let ua = xt.mul_add(ka4, V3::load(cpu, &lanes.ca));
        let ub = mat_mul(&mb, xt).add(cb);
        let ea = soa_a.eval4_rows(&ua.to_arrays());
        let eb = soa_b.eval4_rows(&ub.to_arrays());
        let gf = V3::load(cpu, &ea.gradient).scale(ka4);
        let gg = mat_t_mul(&mb, V3::load(cpu, &eb.gradient));
        // Least-squares multipliers at a start (the single-pair solver's initial multiplier).
        if start.bits() != 0 {
            let tiny = F4::splat(cpu, Real::MIN_POSITIVE);
            let (nf, ng) = (gf.dot(gf), gg.dot(gg));
            let ls = -gf.dot(gg) / ng.max(tiny);
            let fallback = nf.sqrt() / ng.sqrt().max(tiny);
            mt = F4::select(start, F4::select(ls.finite().and(zero.lt(ls)), ls, fallback), mt);
        }
        let r = gg.mul_add(mt, gf);
        let c = F4::load(cpu, &eb.value) - one;
        // The single-pair solver's merit ‖(L·r, c)‖₂ ([`merit_length`]).
        let r1 = r.dot(r).mul_add(l2, c * c).sqrt();
        let norm_inf = abs_max(r).max(c.abs());
        let stationary = norm_inf.le(tolerance * (one + abs_max(gf)));
        // The Newton steps from the trial points (taken where a trial point is accepted).
        let hf = load6(&ea.hessian, ka2);
        let hg = congruence(&mb, &load6(&eb.hessian, one));
        let w: S3<F4> = [
            hg[0].mul_add(mt, hf[0]),
            hg[1].mul_add(mt, hf[1]),
            hg[2].mul_add(mt, hf[2]),
            hg[3].mul_add(mt, hf[3]),
            hg[4].mul_add(mt, hf[4]),
            hg[5].mul_add(mt, hf[5]),
        ];
        let (sdx, sdmu, solved) = solve_kkt4(&w, gg, r, c);
        let decrease = r1.le((F4::splat(cpu, -1e-4) * al + one) * r0).and(r1.finite());
        let accepted = start.or(decrease).and(lanes.book.live(cpu));
        lanes.x = V3::select(accepted, xt, x).to_arrays();
        lanes.mu = F4::select(accepted, mt, mu).to_array();
        lanes.dx = V3::select(accepted, sdx, dx).to_arrays();
        lanes.dmu = F4::select(accepted, sdmu, dmu).to_array();
        // A cold run keeps μ ≥ μ/2 per step (the KKT points with μ < 0 are not the answer).
        let halved = zero.lt(mt).and((mt + sdmu).lt(half * mt));
        let first = F4::select(halved, half * mt / -sdmu, one);
        let ends = stationary.or(r1.finite().not()).or(solved.not());
        let (done, leave, steps) = lanes.book.advance(accepted, r1, first, ends, cap, stall);
        if leave == 0 {
            continue;
        }
        // The overlapping answers: a KKT point with μ > 0 (the minimizer) and p_a ≤ 1 there.
        let answer =
            done.and(stationary).and(r1.finite()).and(zero.lt(mt)).and(F4::load(cpu, &ea.value).le(one)).bits();
        let (norm_inf, steps, mt) = (norm_inf.to_array(), steps.to_array(), mt.to_array());
        for i in (0..4).filter(|i| leave & (1 << i) != 0) {
            let k = lanes.book.job[i];
            lanes.book.job[i] = EMPTY;
            if answer & (1 << i) == 0 {
                continue;
            }
            let x = V3::lane(&lanes.x, i) + V3::lane(&lanes.o, i);
            let warm_start = if warm_starts {
                let rel = &rels[k];
                let local = rel.inverse_transform_point(&sublevel_core::math::Point3::from(x)).coords;
                let growth = GrowthWarmStart::after(None, local, mt[i], true, rel.inverse());
                std::sync::Arc::new(DistanceWarmStart { growth, ..Default::default() })
            } else {
                empty.clone()
            };
            let p = poses[k].0 * sublevel_core::math::Point3::from(x);
            let iterations = steps[i] as usize;
            answers[k] =
                Some(overlapping_answer(p, SolveStatus::Converged, iterations, norm_inf[i], false, warm_start));
        }
    }
}
