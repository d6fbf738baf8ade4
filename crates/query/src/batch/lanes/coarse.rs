//! The distance batch's coarse stage on eight single-precision lanes: the early Newton steps of
//! eight pairs per pass, their lane arithmetic in eight-lane `f32` registers ([`F8`]: the same
//! instructions as the fine stage's four-lane `f64` ones, twice the pairs) and their points
//! evaluated in single precision ([`sublevel_core::poly::SoaPoly::eval8_rows_f32`], one
//! eight-point pass per body).
//!
//! The steps are the single-pair solver's (same start, KKT system, least-squares multipliers at
//! the start, backtracking on the same merit, iteration cap) until a lane's merit is below
//! [`BatchSettings::coarse_residual`] of its scale; it then hands its point, multipliers and
//! Newton step to the fine stage (double precision, four lanes). In single precision the residuals
//! carry relative errors of about 10⁻⁵ (the kernel's) and the steps a little more, far below the
//! hand-off level, so the steps are Newton steps to that accuracy. A lane that ends otherwise (a
//! nonfinite residual, a singular system, the cap, [`NewtonParams::line_search_steps`] rejected
//! trial points in a row) hands nothing: its pair starts again from its cold start in the fine
//! stage, where the double-precision lanes decide it as they would without this stage (none did
//! on the chair / human poses at any degree).
//!
//! **Per-lane origins**: each lane holds its points as displacements from its start points x₀ on A
//! and y₀ on B, with x₀ − y₀ and each body's normalized coordinates at its start point computed in
//! double precision when the lane is filled. Single precision is then relative to how far the
//! points move from their starts (at most about the bodies' sizes), not to where the bodies sit in
//! A's frame. With the points in A's frame, a small body far from A's frame origin would have
//! normalized coordinates off by up to 10⁻³: the residuals would never reach the hand-off level,
//! and the lanes would run to the line search's limit before starting again in double precision
//! (`cold_profile D N scales` times the batch on such pairs: the chair / human pair rescaled and
//! moved). The single-pair solver and the fine stage work in double precision in A's frame.
//!
//! On the chair / human cold poses the stage takes 0.04 more Newton iterations per pair than the
//! fine stage alone (single-precision arithmetic near the hand-off) and makes the batch faster
//! from 2d = 4 on ([`BatchSettings::coarse_min_degree`]); docs/performance.md has the batch's
//! rates.

use super::{kkt_round, merit_length, Handoff, KktRound, NewtonParams, Stage, EMPTY};
#[cfg(doc)]
use crate::batch::BatchSettings;
use crate::lane_algebra::{congruence, mat_mul, mat_t_mul, M3, S3, V3};
use sublevel_core::body::{Body, PosedBody};
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::poly::SoaPoly;
use sublevel_kernels::{Avx2Fma, Lane, LaneMask, F8, M8};

/// Lanes of the coarse stage.
const L: usize = 8;

/// p, ∇p and ∇²p at eight points (normalized coordinates), one lane per point.
struct Eval8 {
    value: F8,
    gradient: V3<F8>,
    hessian: S3<F8>,
}

/// `p` at the eight points `u` in single precision ([`SoaPoly::eval8_rows_f32`]).
#[inline(always)]
fn eval8(p: &SoaPoly, u: V3<F8>) -> Eval8 {
    let cpu = u.0[0].cpu();
    let e = p.eval8_rows_f32(&u.to_arrays32());
    let h = &e.hessian;
    Eval8 {
        value: F8::load(cpu, &e.value),
        gradient: V3::load32(cpu, &e.gradient),
        hessian: h.each_ref().map(
            #[inline(always)]
            |row| F8::load(cpu, row),
        ),
    }
}

impl V3<F8> {
    /// The vectors of eight lanes, coordinates by rows.
    #[inline(always)]
    fn load32(cpu: Avx2Fma, v: &[[f32; 8]; 3]) -> Self {
        Self([F8::load(cpu, &v[0]), F8::load(cpu, &v[1]), F8::load(cpu, &v[2])])
    }

    /// The coordinates by rows.
    #[inline(always)]
    fn to_arrays32(self) -> [[f32; 8]; 3] {
        [self.0[0].to_array(), self.0[1].to_array(), self.0[2].to_array()]
    }
}

/// The eight lanes' pairs and Newton states, one array entry per lane (plain arrays: a lane is
/// refilled by scalar stores, read back as registers in the next round).
struct Lanes8 {
    /// Index of each lane's pair in the batch, or [`EMPTY`].
    job: [usize; L],
    /// Step lengths of the next trial points, the merit ([`KktRound`]) at the accepted points, 1 where the
    /// trial point is the lane's start, Newton steps taken and trial points rejected since the last.
    alpha: [f32; L],
    r0: [f32; L],
    start: [f32; L],
    steps: [f32; L],
    rejected: [f32; L],
    /// The lane's origins (frame of body A, double precision): its start points x₀ on A and
    /// y₀ on B. The lanes hold x − x₀ and y − y₀, so single precision is relative to how far the
    /// points move from their starts, not to where the bodies sit in A's frame (see
    /// [`coarse_stage8`]).
    oa: [[Real; L]; 3],
    ob: [[Real; L]; 3],
    /// x₀ − y₀, and A's normalized coordinates (x₀ − c_a)/s_a at x₀.
    d0: [[f32; L]; 3],
    ca: [[f32; L]; 3],
    /// Body B's map to its normalized coordinates from y − y₀: u = M (y − y₀) + c with
    /// c = M y₀ + c_b (frame of body A), M row-major.
    mb: [[f32; L]; 9],
    cb: [[f32; L]; 3],
    /// Accepted points (x − x₀, y − y₀), multipliers, and the Newton steps from them.
    x: [[f32; L]; 3],
    y: [[f32; L]; 3],
    lam: [[f32; L]; 2],
    dx: [[f32; L]; 3],
    dy: [[f32; L]; 3],
    dl: [[f32; L]; 2],
}

impl Lanes8 {
    /// Eight empty lanes.
    fn new() -> Self {
        Self {
            job: [EMPTY; L],
            alpha: [0.0; L],
            r0: [0.0; L],
            start: [0.0; L],
            steps: [0.0; L],
            rejected: [0.0; L],
            oa: [[0.0; L]; 3],
            ob: [[0.0; L]; 3],
            d0: [[0.0; L]; 3],
            ca: [[0.0; L]; 3],
            mb: [[0.0; L]; 9],
            cb: [[0.0; L]; 3],
            x: [[0.0; L]; 3],
            y: [[0.0; L]; 3],
            lam: [[0.0; L]; 2],
            dx: [[0.0; L]; 3],
            dy: [[0.0; L]; 3],
            dl: [[0.0; L]; 2],
        }
    }

    /// Gives lane `i` pair `k` (A unposed as `ba`, B posed as `bb` in A's frame) at its start
    /// (x0, y0), which becomes the lane's origins.
    #[inline(always)]
    fn fill(&mut self, i: usize, k: usize, ba: &PosedBody<'_>, bb: &PosedBody<'_>, x0: &Vector3, y0: &Vector3) {
        self.job[i] = k;
        let (m, c, ua0) = (bb.linear(), bb.to_normalized(y0), ba.to_normalized(x0));
        for r in 0..3 {
            self.cb[r][i] = c[r] as f32;
            for col in 0..3 {
                self.mb[3 * r + col][i] = m[(r, col)] as f32;
            }
            self.oa[r][i] = x0[r];
            self.ob[r][i] = y0[r];
            self.d0[r][i] = (x0[r] - y0[r]) as f32;
            self.ca[r][i] = ua0[r] as f32;
            self.x[r][i] = 0.0;
            self.y[r][i] = 0.0;
            self.dx[r][i] = 0.0;
            self.dy[r][i] = 0.0;
        }
        self.lam[0][i] = 0.0;
        self.lam[1][i] = 0.0;
        self.dl[0][i] = 0.0;
        self.dl[1][i] = 0.0;
        self.alpha[i] = 0.0;
        self.steps[i] = 0.0;
        self.rejected[i] = 0.0;
        self.start[i] = 1.0;
    }

    /// The lanes holding a pair.
    #[inline(always)]
    fn live(&self, cpu: Avx2Fma) -> M8 {
        M8::from_bools(cpu, self.job.map(|k| k != EMPTY))
    }

    /// Lane `i`'s state as a [`Handoff`] (its residual raised by `noise`
    /// ([`BatchSettings::coarse_noise`]) times the merit's scale 1 + 2‖x − y‖/L, L = `len`
    /// ([`merit_length`])).
    #[inline(always)]
    fn handoff(&self, i: usize, len: Real, noise: Real) -> Handoff {
        let x = std::array::from_fn(|r| self.oa[r][i] + Real::from(self.x[r][i]));
        let y = std::array::from_fn(|r| self.ob[r][i] + Real::from(self.y[r][i]));
        let gap = Vector3::from(x) - Vector3::from(y);
        Handoff {
            x,
            y,
            lam: [self.lam[0][i].into(), self.lam[1][i].into()],
            dx: std::array::from_fn(|r| self.dx[r][i]),
            dy: std::array::from_fn(|r| self.dy[r][i]),
            dl: [self.dl[0][i], self.dl[1][i]],
            r0: (Real::from(self.r0[i]) + noise * (1.0 + 2.0 * gap.norm() / len)) as f32,
            alpha: self.alpha[i],
            steps: self.steps[i] as u16,
            rejected: self.rejected[i] as u16,
        }
    }
}

/// Runs the coarse stage on eight lanes for every pair of the batch with a separated start
/// (`starts`, frame of body A; `rels`: B's pose in A's frame) and records where each stands in
/// `stage`: [`Stage::Resume`] for a hand-off, [`Stage::Drained`] for a lane still running when
/// the queue ran dry, [`Stage::Cold`] for a pair the fine stage takes from its start (no start,
/// or the coarse run ended without a hand-off). The iteration cap, line-search limit and hand-off
/// thresholds come from `params` (the speculative run's cap, [`BatchSettings`]). Compiled apart
/// from the fine stage (not inlined into it), for AVX2 + FMA (`cpu`: the proof that it may run).
#[inline(never)]
pub(super) fn coarse_stage8(
    cpu: Avx2Fma,
    a: &Body,
    b: &Body,
    rels: &[Isometry3],
    starts: &[Option<(Vector3, Vector3)>],
    params: &NewtonParams,
    stage: &mut [Stage],
) {
    cpu.run(
        #[inline(always)]
        || {
            let (soa_a, soa_b) = (a.soa_polynomial(), b.soa_polynomial());
            let cap = F8::splat(cpu, params.max_iterations.min(params.speculative_iterations) as Real);
            let stall = F8::splat(cpu, params.line_search_steps as Real);
            let noise = params.batch.coarse_noise;
            let (zero, one) = (F8::splat(cpu, 0.0), F8::splat(cpu, 1.0));
            let ka = 1.0 / a.scale();
            let (ka8, ka2) = (F8::splat(cpu, ka), F8::splat(cpu, ka * ka));
            let ba = PosedBody::unposed(a);
            let near_level = F8::splat(cpu, params.batch.coarse_residual);
            // The merit's length L and its weight 1/L² ([`merit_length`]).
            let len = merit_length(a, b);
            let (w2, two_over_len) = (F8::splat(cpu, 1.0 / (len * len)), F8::splat(cpu, 2.0 / len));
            let armijo = F8::splat(cpu, -1e-4);
            let tiny = F8::splat(cpu, F8::TINY);
            let mut lanes = Lanes8::new();
            let mut next = 0;
            loop {
                for i in 0..L {
                    while lanes.job[i] == EMPTY && next < rels.len() {
                        let k = next;
                        next += 1;
                        if let Some((x0, y0)) = &starts[k] {
                            lanes.fill(i, k, &ba, &PosedBody::new(b, &rels[k]), x0, y0);
                        }
                    }
                }
                let live = lanes.live(cpu);
                if live.bits() == 0 {
                    break;
                }
                // When the queue runs dry the lanes still running go on in the fine stage, first in its
                // queue (no lane waits for the slowest one).
                if next >= rels.len() && live.bits() != 0xff {
                    for i in 0..L {
                        let k = lanes.job[i];
                        if k != EMPTY {
                            stage[k] = if lanes.start[i] != 0.0 {
                                Stage::Cold
                            } else {
                                Stage::Drained(lanes.handoff(i, len, noise))
                            };
                        }
                    }
                    break;
                }
                let (x, y) = (V3::load32(cpu, &lanes.x), V3::load32(cpu, &lanes.y));
                let lam = [F8::load(cpu, &lanes.lam[0]), F8::load(cpu, &lanes.lam[1])];
                let (dx, dy) = (V3::load32(cpu, &lanes.dx), V3::load32(cpu, &lanes.dy));
                let dl = [F8::load(cpu, &lanes.dl[0]), F8::load(cpu, &lanes.dl[1])];
                let (al, r0) = (F8::load(cpu, &lanes.alpha), F8::load(cpu, &lanes.r0));
                let start = zero.lt(F8::load(cpu, &lanes.start));
                let m = &lanes.mb;
                let mb: M3<F8> = [
                    F8::load(cpu, &m[0]),
                    F8::load(cpu, &m[1]),
                    F8::load(cpu, &m[2]),
                    F8::load(cpu, &m[3]),
                    F8::load(cpu, &m[4]),
                    F8::load(cpu, &m[5]),
                    F8::load(cpu, &m[6]),
                    F8::load(cpu, &m[7]),
                    F8::load(cpu, &m[8]),
                ];
                let cb = V3::load32(cpu, &lanes.cb);
                let xt = dx.mul_add(al, x);
                let yt = dy.mul_add(al, y);
                let lt = [dl[0].mul_add(al, lam[0]), dl[1].mul_add(al, lam[1])];
                let ea = eval8(soa_a, xt.mul_add(ka8, V3::load32(cpu, &lanes.ca)));
                let eb = eval8(soa_b, mat_mul(&mb, yt).add(cb));
                let ga = ea.gradient.scale(ka8);
                let gb = mat_t_mul(&mb, eb.gradient);
                let h = &ea.hessian;
                let ha: S3<F8> = [h[0] * ka2, h[1] * ka2, h[2] * ka2, h[3] * ka2, h[4] * ka2, h[5] * ka2];
                let hb = congruence(&mb, &eb.hessian);
                let KktRound { lt, dist, r1, step, .. } = kkt_round(
                    xt.add(V3::load32(cpu, &lanes.d0)),
                    yt,
                    lt,
                    start,
                    tiny,
                    w2,
                    [ga, gb],
                    [ea.value, eb.value],
                    [&ha, &hb],
                );
                let (sdx, sdy, sdl, solved) = step;
                // Accepted trial points: the start, or a decrease of the merit (Armijo).
                let finite = r1.finite();
                let decrease = r1.le(armijo.mul_add(al, one) * r0).and(finite);
                let accepted = start.or(decrease).and(live);
                lanes.x = V3::select(accepted, xt, x).to_arrays32();
                lanes.y = V3::select(accepted, yt, y).to_arrays32();
                lanes.lam =
                    [F8::select(accepted, lt[0], lam[0]).to_array(), F8::select(accepted, lt[1], lam[1]).to_array()];
                lanes.dx = V3::select(accepted, sdx, dx).to_arrays32();
                lanes.dy = V3::select(accepted, sdy, dy).to_arrays32();
                lanes.dl =
                    [F8::select(accepted, sdl[0], dl[0]).to_array(), F8::select(accepted, sdl[1], dl[1]).to_array()];
                // The bookkeeping: a step counted where accepted, else a rejection and the step halved.
                let near = r1.le(near_level * dist.mul_add(two_over_len, one));
                let ends = near.or(finite.not()).or(solved.not());
                lanes.r0 = F8::select(accepted, r1, r0).to_array();
                lanes.alpha = F8::select(accepted, one, al * F8::splat(cpu, 0.5)).to_array();
                let rejected = F8::select(accepted, zero, F8::load(cpu, &lanes.rejected) + one);
                lanes.rejected = rejected.to_array();
                let before = F8::load(cpu, &lanes.steps);
                lanes.steps = (before + F8::select(accepted, one, zero)).to_array();
                lanes.start = [0.0; L];
                let done = accepted.and(ends.or(cap.le(before)));
                let stalled = live.and(accepted.not()).and(stall.le(rejected));
                let leave = done.or(stalled).bits();
                if leave == 0 {
                    continue;
                }
                // Hand-offs (accepted near the answer, with a step from there); the other lanes that
                // leave start again in the fine stage.
                let handoff = done.and(near).and(solved).and(finite).bits();
                for i in (0..L).filter(|i| leave & (1 << i) != 0) {
                    let k = lanes.job[i];
                    lanes.job[i] = EMPTY;
                    stage[k] =
                        if handoff & (1 << i) != 0 { Stage::Resume(lanes.handoff(i, len, noise)) } else { Stage::Cold };
                }
            }
        },
    )
}
