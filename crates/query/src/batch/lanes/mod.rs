//! The four-lane solver (x86-64 only: AVX2 + FMA registers, [`F4`] and [`F8`] lanes of
//! `sublevel-kernels`, made with the [`Avx2Fma`] proof that the solver runs with).

use super::super::distance::{
    clear_of_contact, distance_growth_first, finish, overlapping_answer, separated_answer, DistanceResult,
    DistanceWarmStart, KktOut,
};
use super::super::fast_eval::FastPosed;
use super::super::growth::GrowthWarmStart;
use super::super::newton::{frame_origin, merit_length, posed_in_frame, working_frame, NewtonParams, SolveStatus};
#[cfg(doc)]
use super::BatchSettings;
use crate::lane_algebra::*;
use sublevel_core::body::{Body, PosedBody};
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::poly::radial::RADIAL_GRID;
use sublevel_core::poly::support::SUPPORT_GRID;
use sublevel_core::poly::{RadialTable, SupportTable};
use sublevel_kernels::{Avx2Fma, Lane, LaneMask, F4, M4};

mod coarse;
mod growth;
mod starts;
use growth::solve_growth_on_lanes;
use starts::cold_starts;

/// [`super::cold_distances`] on the lanes (`cpu`: the proof that they may run), compiled for
/// AVX2 + FMA (the lane arithmetic becomes one instruction per operation).
pub(super) fn solve(
    cpu: Avx2Fma,
    a: &Body,
    b: &Body,
    poses: &[(Isometry3, Isometry3)],
    params: &NewtonParams,
    warm_starts: bool,
) -> Vec<DistanceResult> {
    cpu.run(
        #[inline(always)]
        || solve_on_lanes(cpu, a, b, poses, params, warm_starts),
    )
}

/// [`cold_starts`] compiled for AVX2 + FMA, for the tests (`cpu`: the proof that it may run).
#[cfg(test)]
pub(super) fn cold_starts_on_lanes(
    cpu: Avx2Fma,
    a: &Body,
    b: &Body,
    rels: &[Isometry3],
) -> Vec<Option<(Vector3, Vector3)>> {
    cpu.run(
        #[inline(always)]
        || cold_starts(cpu, a, b, rels),
    )
}

impl V3<F4> {
    /// Lane `i` as a vector.
    #[inline(always)]
    fn lane(a: &[[Real; 4]; 3], i: usize) -> Vector3 {
        Vector3::new(a[0][i], a[1][i], a[2][i])
    }

    /// The vectors of four lanes, coordinates by rows.
    #[inline(always)]
    fn load(cpu: Avx2Fma, v: &[[Real; 4]; 3]) -> Self {
        Self([F4::load(cpu, &v[0]), F4::load(cpu, &v[1]), F4::load(cpu, &v[2])])
    }

    /// The coordinates by rows.
    #[inline(always)]
    fn to_arrays(self) -> [[Real; 4]; 3] {
        [self.0[0].to_array(), self.0[1].to_array(), self.0[2].to_array()]
    }
}

/// The separated answer of a lane's converged run `out` (frame of body A, whose pose is
/// `pose_a`; `rel`: B's pose in A's frame): with its warm start, or sharing `empty`. Inlined:
/// out of line it would run without the AVX target features.
#[inline(always)]
fn lane_answer(
    pose_a: &Isometry3,
    rel: &Isometry3,
    out: KktOut,
    warm_starts: bool,
    empty: &std::sync::Arc<DistanceWarmStart>,
) -> DistanceResult {
    let iterations = out.iterations;
    if warm_starts {
        finish(pose_a, rel, out, iterations, false, &GrowthWarmStart::default(), None)
    } else {
        separated_answer(pose_a, &out, iterations, false, empty.clone())
    }
}

/// What both solvers' lanes keep besides their Newton iterates, one array entry per lane: plain
/// arrays, so that a lane is refilled by scalar stores that have long retired when the next
/// round loads them into registers.
struct LaneBook {
    /// Index of each lane's pair in the batch, or [`EMPTY`].
    job: [usize; 4],
    /// Step lengths of the next trial points.
    alpha: [Real; 4],
    /// The line search's merit at the accepted points (‖KKT residual‖₂, stationarity in units
    /// of [`merit_length`]).
    r0: [Real; 4],
    /// 1 where the lane's trial point is its start (accepted as it is, multipliers by least
    /// squares), else 0.
    start: [Real; 4],
    /// Newton steps taken, and trial points rejected since the last step (small integers).
    steps: [Real; 4],
    rejected: [Real; 4],
    /// Body B's map to its normalized coordinates u = M y + c (frame of body A), M row-major.
    mb: [[Real; 4]; 9],
    cb: [[Real; 4]; 3],
}

impl LaneBook {
    /// Four empty lanes.
    fn new() -> Self {
        Self {
            job: [EMPTY; 4],
            alpha: [0.0; 4],
            r0: [0.0; 4],
            start: [0.0; 4],
            steps: [0.0; 4],
            rejected: [0.0; 4],
            mb: [[0.0; 4]; 9],
            cb: [[0.0; 4]; 3],
        }
    }

    /// Gives lane `i` pair `k` (B posed as `bb` in A's frame), at its start.
    #[inline(always)]
    fn fill(&mut self, i: usize, k: usize, bb: &PosedBody<'_>) {
        self.job[i] = k;
        let (m, c) = (bb.linear(), bb.to_normalized(&Vector3::zeros()));
        for r in 0..3 {
            self.cb[r][i] = c[r];
            for col in 0..3 {
                self.mb[3 * r + col][i] = m[(r, col)];
            }
        }
        self.alpha[i] = 0.0;
        self.steps[i] = 0.0;
        self.rejected[i] = 0.0;
        self.start[i] = 1.0;
    }

    /// Whether every lane is empty.
    fn is_empty(&self) -> bool {
        self.job == [EMPTY; 4]
    }

    /// The lanes' maps of B as 4-lane registers (M, c).
    #[inline(always)]
    fn map(&self, cpu: Avx2Fma) -> (M3<F4>, V3<F4>) {
        let m = &self.mb;
        let mb = [
            F4::load(cpu, &m[0]),
            F4::load(cpu, &m[1]),
            F4::load(cpu, &m[2]),
            F4::load(cpu, &m[3]),
            F4::load(cpu, &m[4]),
            F4::load(cpu, &m[5]),
            F4::load(cpu, &m[6]),
            F4::load(cpu, &m[7]),
            F4::load(cpu, &m[8]),
        ];
        (mb, V3::load(cpu, &self.cb))
    }

    /// The lanes holding a pair.
    #[inline(always)]
    fn live(&self, cpu: Avx2Fma) -> M4 {
        let job = &self.job;
        M4::from_bools(cpu, [job[0] != EMPTY, job[1] != EMPTY, job[2] != EMPTY, job[3] != EMPTY])
    }

    /// The bookkeeping of a round: where a trial point was `accepted` (its residual `r1`), a
    /// step counted, the residual kept and the next step length `first`; where a live lane's was
    /// not, a rejection counted and the step halved. Returns the lanes done (accepted and `ends`
    /// — stationary, nonfinite or unsolvable — or at the iteration `cap`), the bits of the lanes
    /// that leave (done, or `stall` rejected trial points in a row: the single-pair line search's
    /// limit, [`NewtonParams::line_search_steps`]) and the steps taken before this round.
    #[inline(always)]
    fn advance(&mut self, accepted: M4, r1: F4, first: F4, ends: M4, cap: F4, stall: F4) -> (M4, u32, F4) {
        let cpu = r1.cpu();
        let (zero, one) = (F4::splat(cpu, 0.0), F4::splat(cpu, 1.0));
        let live = self.live(cpu);
        self.r0 = F4::select(accepted, r1, F4::load(cpu, &self.r0)).to_array();
        self.alpha = F4::select(accepted, first, F4::load(cpu, &self.alpha) * F4::splat(cpu, 0.5)).to_array();
        let rejected = F4::select(accepted, zero, F4::load(cpu, &self.rejected) + one);
        self.rejected = rejected.to_array();
        let before = F4::load(cpu, &self.steps);
        let done = accepted.and(ends.or(cap.le(before)));
        let stalled = live.and(accepted.not()).and(stall.le(rejected));
        self.steps = (before + F4::select(accepted, one, zero)).to_array();
        self.start = [0.0; 4];
        (done, done.or(stalled).bits(), before)
    }
}

/// The linear part of body A's map to its normalized coordinates, u = k·x + c with
/// k = 1/scale, in every lane: (k, k²).
#[inline(always)]
fn scale_map(cpu: Avx2Fma, a: &Body) -> (F4, F4) {
    let k = 1.0 / a.scale();
    (F4::splat(cpu, k), F4::splat(cpu, k * k))
}

/// The offset c = −(center − o)/scale of body A's map to its normalized coordinates in a
/// working frame with origin `o` (A's frame; [`working_frame`]).
#[inline(always)]
fn offset_map(a: &Body, o: &Vector3) -> Vector3 {
    -(a.center() - o) * (1.0 / a.scale())
}

/// No pair in the lane.
const EMPTY: usize = usize::MAX;

/// The four lanes' pairs and Newton states (see the module docs), one array entry per lane:
/// plain arrays, so that a lane is refilled by scalar stores that have long retired when the
/// next round loads the arrays into registers.
struct Lanes {
    /// The lanes' pairs, step lengths, residuals, counters and maps of B.
    book: LaneBook,
    /// Accepted points (frame of body A) and multipliers.
    x: [[Real; 4]; 3],
    y: [[Real; 4]; 3],
    lam: [[Real; 4]; 2],
    /// Newton steps from the accepted points.
    dx: [[Real; 4]; 3],
    dy: [[Real; 4]; 3],
    dl: [[Real; 4]; 2],
    /// Pose of B relative to A (pose_a⁻¹ · pose_b).
    rel: [Isometry3; 4],
    /// Each lane's working frame ([`working_frame`]): its origin `o` in A's frame (zero unless
    /// the pair's coordinates could exceed `shift_ratio` times the smaller body's size; the
    /// lane's points are relative to it), and the offset of A's normalized map there
    /// ([`offset_map`]).
    o: [[Real; 4]; 3],
    ca: [[Real; 4]; 3],
    /// [`NewtonParams::frame_shift_ratio`].
    shift_ratio: Real,
}

impl Lanes {
    /// Sets lane `i`'s working frame for pair `k` (relative pose `rel`): its origin and A's
    /// center in it, and B's map; returns the origin (A's frame). A's own frame (the common
    /// case) sets the lane exactly as without a working frame.
    #[inline(always)]
    fn frame(&mut self, i: usize, k: usize, a: &Body, b: &Body, rel: &Isometry3) -> Vector3 {
        let (o, bb) = posed_in_frame(b, rel, frame_origin(a, b, rel, self.shift_ratio));
        self.book.fill(i, k, &bb);
        let c = offset_map(a, &o);
        for r in 0..3 {
            self.o[r][i] = o[r];
            self.ca[r][i] = c[r];
        }
        self.rel[i] = *rel;
        o
    }

    /// Lane `i`'s working-frame origin (A's frame).
    fn origin(&self, i: usize) -> Vector3 {
        Vector3::new(self.o[0][i], self.o[1][i], self.o[2][i])
    }

    /// Puts pair `k` with the relative pose `rel` into lane `i`, starting at (x0, y0) (A's
    /// frame).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn fill(&mut self, i: usize, k: usize, a: &Body, b: &Body, rel: &Isometry3, x0: &Vector3, y0: &Vector3) {
        let o = self.frame(i, k, a, b, rel);
        for r in 0..3 {
            self.x[r][i] = x0[r] - o[r];
            self.y[r][i] = y0[r] - o[r];
            self.dx[r][i] = 0.0;
            self.dy[r][i] = 0.0;
        }
        self.dl[0][i] = 0.0;
        self.dl[1][i] = 0.0;
    }
}

impl Lanes {
    /// Lane `i`'s trial point at step length 1 from its accepted point, checked by value +
    /// gradient evaluations of both bodies (the single-pair kernels, double precision): the
    /// point, its multipliers and ∞-norm KKT residual as a converged run's end
    /// (`iterations` Newton steps) when it is stationary (the single-pair solver's test:
    /// ‖r‖∞ ≤ `tolerance`·(1 + 2‖x − y‖)), else `None` (the lane goes on as it was).
    #[inline(always)]
    fn verify(&self, cpu: Avx2Fma, i: usize, a: &Body, b: &Body, iterations: usize, tolerance: Real) -> Option<KktOut> {
        let lane = |v: &[[Real; 4]; 3], d: &[[Real; 4]; 3]| {
            Vector3::new(v[0][i] + d[0][i], v[1][i] + d[1][i], v[2][i] + d[2][i])
        };
        let (x, y) = (lane(&self.x, &self.dx), lane(&self.y, &self.dy));
        let lam = [self.lam[0][i] + self.dl[0][i], self.lam[1][i] + self.dl[1][i]];
        let (book, k) = (&self.book, 1.0 / a.scale());
        let center = a.center() - self.origin(i);
        let m = nalgebra::Matrix3::from_fn(|r, c| book.mb[3 * r + c][i]);
        let ub = m * y + Vector3::new(book.cb[0][i], book.cb[1][i], book.cb[2][i]);
        let (va, ga) = a.fast_polynomial().value_gradient_avx2(cpu, &((x - center) * k));
        let (vb, gb) = b.fast_polynomial().value_gradient_avx2(cpu, &ub);
        let d2 = (x - y) * 2.0;
        let (ra, rb) = (ga * (k * lam[0]) + d2, m.tr_mul(&gb) * lam[1] - d2);
        let residual = ra.amax().max(rb.amax()).max((va - 1.0).abs()).max((vb - 1.0).abs());
        let stationary = residual <= tolerance * (1.0 + 2.0 * (x - y).norm());
        stationary.then_some(KktOut { x, y, lam, status: SolveStatus::Converged, iterations, residual })
    }

    /// [`Self::verify`] for the lanes set in `verify` (Newton steps taken so far: `steps`): a
    /// lane whose trial point is stationary leaves, with its answer in `answers` when both
    /// multipliers are positive and the bodies clear of contact (else the single-pair solver
    /// decides, as for the lanes that end in a round). Compiled apart from the rounds (not
    /// inlined, its body compiled for AVX2 + FMA by `cpu`): inlined, its scalar code makes the
    /// rounds spill registers.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn verify_lanes(
        &mut self,
        cpu: Avx2Fma,
        verify: u32,
        steps: &[Real; 4],
        a: &Body,
        b: &Body,
        poses: &[(Isometry3, Isometry3)],
        params: &NewtonParams,
        warm_starts: bool,
        answers: &mut [Option<DistanceResult>],
        empty: &std::sync::Arc<DistanceWarmStart>,
    ) {
        cpu.run(
            #[inline(always)]
            || {
                for i in (0..4).filter(|i| verify & (1 << i) != 0) {
                    let Some(out) = self.verify(cpu, i, a, b, steps[i] as usize + 1, params.kkt_tolerance) else {
                        continue;
                    };
                    let k = self.book.job[i];
                    self.book.job[i] = EMPTY;
                    if out.lam[0] > 0.0 && out.lam[1] > 0.0 && clear_of_contact(&out.x, &out.y, a, b) {
                        let out = out.moved(&self.origin(i));
                        answers[k] = Some(lane_answer(&poses[k].0, &self.rel[i], out, warm_starts, empty));
                    }
                }
            },
        )
    }
}

/// A lane's Newton state where its coarse stage ends ([`BatchSettings::coarse_residual`]): the accepted point
/// (frame of body A), its multipliers, the Newton step from it, its merit ([`KktRound::r1`]) and the
/// steps taken; the fine stage goes on from its trial point at step length 1.
#[derive(Clone, Copy)]
struct Handoff {
    x: [Real; 3],
    y: [Real; 3],
    lam: [Real; 2],
    /// The step, its length so far and the residual in single precision: computed from
    /// single-precision evaluations, they carry no more digits (a smaller record).
    dx: [f32; 3],
    dy: [f32; 3],
    dl: [f32; 2],
    r0: f32,
    alpha: f32,
    /// Newton steps taken and trial points rejected since the last one (small integers).
    steps: u16,
    rejected: u16,
}

/// Where a pair stands between the two stages of [`solve_on_lanes`].
#[derive(Clone, Copy)]
enum Stage {
    /// Starts the fine stage from its cold start: not in a lane of the coarse stage (no
    /// separated start), taken out before its first evaluation, or ended there without a
    /// hand-off (nonfinite, singular, stalled or at the cap in single precision; the
    /// double-precision lanes then decide it as they would without the coarse stage).
    Cold,
    /// Goes on from where the coarse stage left it.
    Resume(Handoff),
    /// The same, for a pair the coarse stage took out of its lane when its queue ran dry (first
    /// in the fine stage's queue).
    Drained(Handoff),
}

impl Lanes {
    /// Puts pair `k` (relative pose `rel`, B posed as `bb`) into lane `i` where its coarse stage
    /// left it (`h`): the next trial point is its Newton step from there at the step length it
    /// had reached.
    #[inline(always)]
    fn resume(&mut self, i: usize, k: usize, a: &Body, b: &Body, rel: &Isometry3, h: &Handoff) {
        let o = self.frame(i, k, a, b, rel);
        self.book.start[i] = 0.0;
        self.book.alpha[i] = h.alpha.into();
        self.book.rejected[i] = h.rejected.into();
        self.book.r0[i] = h.r0.into();
        self.book.steps[i] = h.steps.into();
        for r in 0..3 {
            self.x[r][i] = h.x[r] - o[r];
            self.y[r][i] = h.y[r] - o[r];
            self.dx[r][i] = h.dx[r].into();
            self.dy[r][i] = h.dy[r].into();
        }
        self.lam[0][i] = h.lam[0];
        self.lam[1][i] = h.lam[1];
        self.dl[0][i] = h.dl[0].into();
        self.dl[1][i] = h.dl[1].into();
    }
}

/// The distance KKT system at the lanes' trial points (frame of body A) and its Newton step,
/// shared by the fine stage (four `f64` lanes) and the coarse one (eight `f32` lanes).
struct KktRound<F: Lane> {
    /// The multipliers (least squares where the lane is at its start, else as given).
    lt: [F; 2],
    /// ‖x − y‖.
    dist: F,
    /// Stationarity residuals 2(x − y) + λa∇p_a, −2(x − y) + λb∇p_b, constraints p − 1.
    ra: V3<F>,
    rb: V3<F>,
    cva: F,
    cvb: F,
    /// The line search's merit ‖(r_a/L, r_b/L, p_a − 1, p_b − 1)‖₂ ([`merit_length`]).
    r1: F,
    /// The Newton step (dx, dy, [dλa, dλb]) and the lanes where it exists ([`solve_kkt8`]).
    step: (V3<F>, V3<F>, [F; 2], F::Mask),
}

/// [`KktRound`] at the trial points `xt`, `yt` with multipliers `lt` (replaced by the
/// single-pair solver's least-squares multipliers in the lanes of `start`; `tiny` the least
/// squared gradient norm they divide by), from both bodies' gradients `g`, values `v` and
/// Hessians `h` there (frame of body A); `w2` = 1/L² weighs stationarity in the merit, as the
/// single-pair solver's ([`merit_length`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn kkt_round<F: Lane>(
    xt: V3<F>,
    yt: V3<F>,
    mut lt: [F; 2],
    start: F::Mask,
    tiny: F,
    w2: F,
    [ga, gb]: [V3<F>; 2],
    [va, vb]: [F; 2],
    [ha, hb]: [&S3<F>; 2],
) -> KktRound<F> {
    let (one, two) = (tiny.constant(1.0), tiny.constant(2.0));
    let diff = xt.sub(yt);
    let dist = diff.dot(diff).sqrt();
    // Least-squares multipliers at a start (the single-pair solver's initial multipliers).
    if start.bits() != 0 {
        let (na, nb) = (ga.dot(ga), gb.dot(gb));
        let la = -(two * diff.dot(ga)) / na.max(tiny);
        let lb = two * diff.dot(gb) / nb.max(tiny);
        lt = [
            F::select(start, positive_multiplier(la, na, dist), lt[0]),
            F::select(start, positive_multiplier(lb, nb, dist), lt[1]),
        ];
    }
    let d2 = diff.scale(two);
    let ra = ga.mul_add(lt[0], d2);
    let rb = gb.mul_add(lt[1], d2.neg());
    let (cva, cvb) = (va - one, vb - one);
    let r1 = (ra.dot(ra) + rb.dot(rb)).mul_add(w2, cva.mul_add(cva, cvb * cvb)).sqrt();
    // The Newton steps from the trial points (taken where a trial point is accepted).
    let (wa, wb) = (shifted(ha, lt[0], two), shifted(hb, lt[1], two));
    let step = solve_kkt8(&wa, &wb, ga, gb, ra, rb, cva, cvb);
    KktRound { lt, dist, ra, rb, cva, cvb, r1, step }
}

#[inline(always)]
fn load6(h: &[[Real; 4]; 6], k: F4) -> S3<F4> {
    let cpu = k.cpu();
    [
        F4::load(cpu, &h[0]) * k,
        F4::load(cpu, &h[1]) * k,
        F4::load(cpu, &h[2]) * k,
        F4::load(cpu, &h[3]) * k,
        F4::load(cpu, &h[4]) * k,
        F4::load(cpu, &h[5]) * k,
    ]
}

#[inline(always)]
fn solve_on_lanes(
    cpu: Avx2Fma,
    a: &Body,
    b: &Body,
    poses: &[(Isometry3, Isometry3)],
    params: &NewtonParams,
    warm_starts: bool,
) -> Vec<DistanceResult> {
    let (soa_a, soa_b) = (a.soa_polynomial(), b.soa_polynomial());
    let mut answers: Vec<Option<DistanceResult>> = vec![None; poses.len()];
    let batch = &params.batch;
    let cap = F4::splat(cpu, params.max_iterations.min(params.speculative_iterations) as Real);
    let stall = F4::splat(cpu, params.line_search_steps as Real);
    let tolerance = F4::splat(cpu, params.kkt_tolerance);
    // Checks of predicted last points only where they pay (see `BatchSettings::verify_min_degree`).
    let verify_level = F4::splat(cpu, batch.verify_residual);
    // The merit's length L and its weight 1/L² ([`merit_length`]).
    let len = merit_length(a, b);
    let (w2, two_over_len) = (F4::splat(cpu, 1.0 / (len * len)), F4::splat(cpu, 2.0 / len));
    let verifying = a.degree().max(b.degree()) >= batch.verify_min_degree;
    let (zero, one, two) = (F4::splat(cpu, 0.0), F4::splat(cpu, 1.0), F4::splat(cpu, 2.0));
    let (ka4, ka2) = scale_map(cpu, a);
    let mut lanes = Lanes {
        book: LaneBook::new(),
        x: [[0.0; 4]; 3],
        y: [[0.0; 4]; 3],
        lam: [[0.0; 4]; 2],
        dx: [[0.0; 4]; 3],
        dy: [[0.0; 4]; 3],
        dl: [[0.0; 4]; 2],
        rel: [Isometry3::identity(); 4],
        o: [[0.0; 4]; 3],
        ca: [[0.0; 4]; 3],
        shift_ratio: params.frame_shift_ratio,
    };
    let empty = std::sync::Arc::new(DistanceWarmStart::default());
    let rels: Vec<Isometry3> = poses.iter().map(|(pa, pb)| pa.inv_mul(pb)).collect();
    let starts = cold_starts(cpu, a, b, &rels);
    // The coarse stage (eight single-precision lanes; none below `coarse_min_degree`: every pair
    // cold, in order) records where each pair stands; the fine stage's queue is the pairs it
    // drained and the cold ones (the slow ones first: they run beside the others; pairs without
    // a start are skipped by the refill), then the others.
    let (stage, queue) = if a.degree().max(b.degree()) >= batch.coarse_min_degree {
        let mut stage = vec![Stage::Cold; poses.len()];
        coarse::coarse_stage8(cpu, a, b, &rels, &starts, params, &mut stage);
        let first = |s: &Stage| matches!(s, Stage::Drained(_) | Stage::Cold);
        let mut queue: Vec<usize> = (0..poses.len()).filter(|&k| first(&stage[k])).collect();
        queue.extend((0..poses.len()).filter(|&k| matches!(stage[k], Stage::Resume(_))));
        (stage, queue)
    } else {
        (Vec::new(), (0..poses.len()).collect())
    };
    let mut next = 0;
    loop {
        // Refill the empty lanes from the queue; a pair without a separated start is left to the
        // single-pair solver.
        for i in 0..4 {
            while lanes.book.job[i] == EMPTY && next < queue.len() {
                let k = queue[next];
                next += 1;
                if let Some((x0, y0)) = &starts[k] {
                    match stage.get(k) {
                        Some(Stage::Resume(h) | Stage::Drained(h)) => lanes.resume(i, k, a, b, &rels[k], h),
                        _ => lanes.fill(i, k, a, b, &rels[k], x0, y0),
                    }
                }
            }
        }
        if lanes.book.is_empty() {
            break;
        }
        // The trial points of the four lanes, evaluated in one pass per body.
        let (x, y) = (V3::load(cpu, &lanes.x), V3::load(cpu, &lanes.y));
        let lam = [F4::load(cpu, &lanes.lam[0]), F4::load(cpu, &lanes.lam[1])];
        let (dx, dy) = (V3::load(cpu, &lanes.dx), V3::load(cpu, &lanes.dy));
        let dl = [F4::load(cpu, &lanes.dl[0]), F4::load(cpu, &lanes.dl[1])];
        let book = &lanes.book;
        let (al, r0, start) =
            (F4::load(cpu, &book.alpha), F4::load(cpu, &book.r0), zero.lt(F4::load(cpu, &book.start)));
        let (mb, cb) = book.map(cpu);
        let xt = dx.mul_add(al, x);
        let yt = dy.mul_add(al, y);
        let lt = [dl[0].mul_add(al, lam[0]), dl[1].mul_add(al, lam[1])];
        let ua = xt.mul_add(ka4, V3::load(cpu, &lanes.ca));
        let ub = mat_mul(&mb, yt).add(cb);
        let (ea, eb) = (soa_a.eval4_rows(&ua.to_arrays()), soa_b.eval4_rows(&ub.to_arrays()));
        let ga = V3::load(cpu, &ea.gradient).scale(ka4);
        let gb = mat_t_mul(&mb, V3::load(cpu, &eb.gradient));
        let (va, vb) = (F4::load(cpu, &ea.value), F4::load(cpu, &eb.value));
        let (ha, hb) = (load6(&ea.hessian, ka2), congruence(&mb, &load6(&eb.hessian, one)));
        let tiny = F4::splat(cpu, Real::MIN_POSITIVE);
        let KktRound { lt, dist, ra, rb, cva, cvb, r1, step } =
            kkt_round(xt, yt, lt, start, tiny, w2, [ga, gb], [va, vb], [&ha, &hb]);
        let (sdx, sdy, sdl, solved) = step;
        let norm_inf = abs_max(ra).max(abs_max(rb)).max(cva.abs().max(cvb.abs()));
        // Accepted trial points: the start, or a decrease of the merit (Armijo).
        let decrease = r1.le((F4::splat(cpu, -1e-4) * al + one) * r0).and(r1.finite());
        let accepted = start.or(decrease).and(lanes.book.live(cpu));
        let scale = dist.mul_add(two, one);
        let stationary = norm_inf.le(tolerance * scale);
        lanes.x = V3::select(accepted, xt, x).to_arrays();
        lanes.y = V3::select(accepted, yt, y).to_arrays();
        lanes.lam = [F4::select(accepted, lt[0], lam[0]).to_array(), F4::select(accepted, lt[1], lam[1]).to_array()];
        lanes.dx = V3::select(accepted, sdx, dx).to_arrays();
        lanes.dy = V3::select(accepted, sdy, dy).to_arrays();
        lanes.dl = [F4::select(accepted, sdl[0], dl[0]).to_array(), F4::select(accepted, sdl[1], dl[1]).to_array()];
        // Lanes that leave: stationary (the answer, or the single-pair solver when a multiplier
        // is not positive), a nonfinite residual, a singular system, the iteration cap, or `stall`
        // rejected trial points in a row (the single-pair line search's limit).
        let ends = stationary.or(r1.finite().not()).or(solved.not());
        // Lanes whose next trial point is predicted to be their answer (accepted here at a
        // residual whose Newton step, converging quadratically, lands below the tolerance, and
        // not done): that point is checked now, one lane at a time, by value + gradient
        // evaluations (no Hessians, which a last point does not need), instead of in the next
        // round's pass.
        let level = verify_level * dist.mul_add(two_over_len, one);
        let last = if verifying { accepted.and(solved).and(r1.le(level)) } else { F4::none(cpu) };
        let (done, leave, steps) = lanes.book.advance(accepted, r1, one, ends, cap, stall);
        let verify = last.and(done.not()).bits();
        if leave | verify == 0 {
            continue;
        }
        let (norm_inf, steps) = (norm_inf.to_array(), steps.to_array());
        if verify != 0 {
            lanes.verify_lanes(cpu, verify, &steps, a, b, poses, params, warm_starts, &mut answers, &empty);
        }
        let answer = done.and(stationary).and(r1.finite()).bits();
        for i in (0..4).filter(|i| leave & (1 << i) != 0) {
            let k = lanes.book.job[i];
            lanes.book.job[i] = EMPTY;
            let x = Vector3::new(lanes.x[0][i], lanes.x[1][i], lanes.x[2][i]);
            let y = Vector3::new(lanes.y[0][i], lanes.y[1][i], lanes.y[2][i]);
            let lam = [lanes.lam[0][i], lanes.lam[1][i]];
            // The answer when stationary with positive multipliers and clear of contact; otherwise
            // the single-pair solver decides (growth test, barrier path).
            if answer & (1 << i) == 0 || !(lam[0] > 0.0 && lam[1] > 0.0 && clear_of_contact(&x, &y, a, b)) {
                continue;
            }
            let iterations = steps[i] as usize;
            let out = KktOut { x, y, lam, status: SolveStatus::Converged, iterations, residual: norm_inf[i] };
            let out = out.moved(&lanes.origin(i));
            answers[k] = Some(lane_answer(&poses[k].0, &lanes.rel[i], out, warm_starts, &empty));
        }
    }
    // The pairs without a separated start, and those the lanes left: the single-pair solver's
    // growth-first path (which is where its own separated run, the same as the lane's, would
    // hand them), its growth solve on the lanes first.
    let queue: Vec<usize> = (0..poses.len()).filter(|&k| answers[k].is_none()).collect();
    if queue.len() >= batch.min_growth_lanes {
        solve_growth_on_lanes(cpu, a, b, poses, &rels, &queue, params, warm_starts, &mut answers, &empty);
    }
    answers
        .into_iter()
        .zip(poses)
        .map(|(r, (pa, pb))| r.unwrap_or_else(|| distance_growth_first(a, pa, b, pb, params)))
        .collect()
}
