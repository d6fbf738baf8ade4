//! Batch solvers (issue 15): many cold distance queries between the same two bodies — one pair of
//! a planner's query across its candidate states, or one body pair of a scene check — solved
//! several pairs at a time, one pair per SIMD lane.
//!
//! ```text
//! queue of pairs ──► coarse stage, 8 f32 lanes (2d ≥ 4): per round, for 8 trial points at once
//!                      p_a, p_b at 8 points in single precision, gradients, Hessians, KKT
//!                      residuals and 8 × 8 KKT solves in 8-lane f32 arithmetic; until a lane's
//!                      residual is below 10⁻³ of the scale: its state handed to
//!                ──► fine stage, 4 f64 lanes (one pair each): per round, for the 4 trial points
//!                      p_a at 4 points, p_b at 4 points      SoaPoly: one pass per body
//!                      gradients, Hessians, KKT residuals    4-lane arithmetic
//!                      8 × 8 KKT solves (block elimination)  4-lane arithmetic
//!                    then per lane: accept the trial point or halve its step (backtracking on
//!                    the single-pair solver's merit, ‖KKT residual‖₂ with stationarity in units
//!                    of the smaller body's size), converged → answer, the lane takes the next pair
//!                    (2d = 8: a predicted last point checked at once without Hessians)
//! pairs without a separated start, and lanes that stall, reach the iteration cap or end near
//! contact ──► the single-pair solver's growth-first path, where its own separated run would hand
//! them (so they are not solved twice): its growth solve on 4 lanes too (4 × 4 KKT solves),
//! the overlapping answers from there, the rest (A's minimizer inside B, growth > 1, lanes that
//! fail) on the single-pair solver
//! ```
//!
//! Pairs with a body of degree 2d ≥ 4 run in two stages (2d = 2: the fine stage alone, see
//! `lanes::COARSE_MIN_DEGREE`). The **coarse stage** (`lanes::coarse`, fourteenth session) takes
//! eight pairs per pass: its lane arithmetic runs in eight-lane `f32` registers (the same
//! instructions as four-lane `f64` ones, twice the pairs) and its points are evaluated in single
//! precision ([`crate::poly::SoaPoly::eval8_rows_f32`]: the single-precision table's Horner sums,
//! two quantities of four points per eight-lane multiply–add, half the multiply–adds of the
//! double-precision kernel; p and ∇p from them by Euler's identity in double precision), until a
//! lane's residual is below 10⁻³ of the stationarity scale. The lane then hands its point,
//! multipliers and Newton step to the **fine stage** (four `f64` lanes, the double-precision
//! kernel), which goes on from that step's trial point to the same tolerance. The single-precision
//! kernel errs by at most 1.1·10⁻⁵ relative on the project's bodies (`kernel_timing` prints it),
//! so the coarse steps are Newton steps, and two or three double-precision steps finish a pair;
//! answers agree with the single-pair ones to the KKT tolerance (2·10⁻¹¹ m on the chair / human
//! poses). When the coarse queue runs dry the lanes still running hand off as they are and run
//! first in the fine stage, beside the others (one slow pair took 85 rounds alone otherwise); a
//! lane that ends the coarse stage otherwise (nonfinite, singular, stalled, at the cap) starts
//! again in the fine stage from its cold start, so single precision never decides a pair. The
//! coarse lanes hold their points as displacements from each pair's start points (fifteenth
//! session), so single precision does not depend on where the bodies sit in A's frame or on how
//! their sizes compare (a 100 m body against a 1.7 cm one, a body 1 km from its frame's origin:
//! see `lanes::coarse`).
//!
//! A pair's last point needs no Hessians: it is only checked. Where a fine-stage lane accepts a
//! point at a residual below 10⁻⁵ of the stationarity scale (`lanes::VERIFY_RESIDUAL`), Newton's
//! quadratic convergence puts its next trial point below the tolerance, so that point is checked
//! at once, for that lane alone, by the single-pair solver's value + gradient kernels
//! (`Lanes::verify`: 19 instead of 32 ns per point at 2d = 8), and the lane gives its answer and
//! takes the next pair; a trial point that fails the check (10 of about 1440 per 300-pair batch at
//! 2d = 8) is evaluated with its Hessians in the next round as before. On the chair / human poses
//! this took the fine stage from 171 to 100 rounds per batch at 2d = 8 (149 to 77 at 2d = 6) and
//! the batch's instructions down 6.7 % at 2d = 8 (callgrind). Only pairs with a body of 2d = 8
//! run the checks: below, the four-point kernel is cheap beside a check's scalar work
//! (`lanes::VERIFY_MIN_DEGREE`).
//!
//! History of the stages (`examples/cold_profile D 20 batch`, Intel Xeon, builds alternated in one
//! session): the twelfth session's coarse stage ran four pairs per pass with `f64` lane arithmetic
//! and took the batch's rate over single queries from 1.61–1.64 to 1.82–1.83× at 2d = 8 and from
//! 1.89–1.93 to 2.04–2.15× at 2d = 6 (instructions per pair 8740 → 7297 and 4600 → 4472); at
//! 2d = 2 and 4 it cost as much as it saved, so lower degrees ran the fine stage alone. On eight
//! `f32` lanes the stage pays from 2d = 4 (see `lanes::coarse` for the figures). Euler's
//! identity in `f32` instead of `f64` saved kernel work but its hand-offs cost the fine stage 8 %
//! more double-precision evaluations at 2d = 8 (the batch ran 5 % slower).
//!
//! The lanes run the single-pair solver's cold separated Newton run ([`distance`]: same start, same
//! KKT system, same line search and tolerance, same 30-iteration cap) with one difference: every
//! trial point is evaluated with its Hessians (the four-point kernel evaluates them at no extra
//! cost), so there are no chord steps. A converged lane's answer is therefore the single-pair
//! answer to the KKT tolerance (not to the bit); a KKT point with positive multipliers of this
//! convex program is its global minimizer either way. A lane that leaves without an answer goes on
//! where the single-pair solver's own run would fail over to, its growth-first path, instead of
//! the whole single-pair solver (which repeated the failed run: about 4 % of a 300-pair batch's
//! instructions at 2d = 6, callgrind).
//!
//! Measured on this project's machine (AMD EPYC Zen 3, 2 cores; `sublevel bench`, the 300 cold
//! chair / human poses, 22 of them overlapping, all poses one at a time and as one batch
//! alternated 20 times, medians, µs per pair): 1.63 → 0.94 at 2d = 6 (1.73× the single-query
//! rate), 1.34 → 0.72 at 2d = 4 (1.86×), 2.02 → 1.58 at 2d = 8 (1.28×: the four-point kernel gained
//! less there, 48 vs 55 ns per point from a table broadcast coefficient by coefficient). The pair
//! table ([`crate::poly::SoaPoly`], seventh session) lifted 2d = 8 to 1.50× (`examples/cold_profile
//! 8 15 batch`, medians of 8 runs alternated with the previous build, which gave 1.36×). Per
//! round of four lanes at 2d = 6: two kernel passes of about 88 ns and about 115 ns of lane
//! arithmetic; outside the rounds, the cold starts and the overlapping pairs on the single-pair
//! path (about a sixth of the batch's time) bound the gain.
//!
//! The cold starts are computed four pairs at a time too (eighth session): the posed interior
//! points, the bounding-sphere test and both bodies' support and radial look-ups (the nodes
//! gathered from the tables) in 4-lane arithmetic, the same starts as the single-pair solver's up
//! to rounding. The scalar starts were 18 % of a 2d = 6 batch's instructions and 30 % at 2d = 2
//! (callgrind, about 1050 instructions per pair); with the lanes, the instructions per pair of the
//! 300-pair batch fell 13 / 6.5 / 3.8 % at 2d = 2 / 6 / 8 (4233 → 3668, 5950 → 5565, 10165 →
//! 9778), and the batch's rate over the single queries rose from 1.99 / 1.97 / 1.82 / 1.42 to
//! 2.15 / 2.07 / 1.95 / 1.62 at 2d = 2 / 4 / 6 / 8 (medians of 10, the previous build alternated
//! three times in one run; `examples/cold_profile D 10 batch`).
//!
//! The overlapping pairs (22 of the 300) then took 12 % of a 2d = 6 batch's instructions and
//! 18 % at 2d = 2, each on the single-pair growth solver: their growth solves run on four lanes
//! too (`lanes::solve_growth_on_lanes`, the same start, KKT system, line search and tolerance
//! as the single-pair growth solve, Hessians at every trial point). Instructions per pair fell a
//! further 11 / 5.3 / 1.1 % at 2d = 2 / 6 / 8 (3668 → 3257, 5565 → 5270, 9778 → 9667), and the
//! rate over single queries, alternated three times in one run with both previous builds, went
//! 1.91 → 2.22 → 2.34 at 2d = 2, 1.92 → 2.18 → 2.50 at 2d = 4, 1.80 → 1.91 → 2.09 at 2d = 6 and
//! 1.51 → 1.54 → 1.74 at 2d = 8 (medians of three; the host was loaded, single queries varied
//! 1.1–3.1 µs between runs, so only the ratios within a run count).
//!
//! Three closures of the 4-lane cold starts had been compiled out of line, without the AVX target
//! features (about 280 instructions a call, 5 % of a 2d = 6 batch's instructions); as plain
//! inlined functions the instructions per pair fell a further 9 / 5.8 / 3.3 % (3257 → 2959,
//! 5270 → 4965, 9667 → 9349) and the rate over single queries went 2.55 → 3.16× at 2d = 2,
//! 2.35 → 2.68× at 2d = 4, 2.09 → 2.25× at 2d = 6 and 1.66 → 1.82× at 2d = 8 (the two builds
//! alternated three times, medians). The lanes' code therefore has no closures over `F4` values.
//! Building an 848-byte warm start per answer costs 8–40 % more time
//! (`cold_distances(…, true)`; it varies with the allocator's state), so the service's cold
//! queries, which keep none, ask for none.

use super::distance::{distance, DistanceResult};
use super::newton::NewtonParams;
use crate::body::Body;
use crate::math::Isometry3;

/// Fewest pairs worth the lanes: below this the batch answers pair by pair.
pub const MIN_LANE_BATCH: usize = 4;

/// Cold distance answers for the pairs `poses` (pose of `a`, pose of `b`; body frame → world) of
/// the bodies `a` and `b`, in order: the answers [`distance`] gives with no warm start, eight or
/// four pairs per SIMD pass (see the module docs). Pairs go through [`distance`] one by one when there are
/// fewer than [`MIN_LANE_BATCH`], when the CPU lacks AVX2 + FMA, or when a body has degree below 2.
///
/// With `warm_starts` false, the answers the lanes give share one empty warm start (an invalid
/// [`super::DistanceWarmStart`]: a query started from it runs cold) instead of one allocation
/// each: for callers that drop them (cold queries of a planner, scene checks). Measured on the
/// chair / human cold poses at 2d = 6 (`examples/cold_profile 6 20 batch`), the 848-byte warm
/// starts of a 300-pair batch add 8–40 % to its time (it varies with the allocator's state).
///
/// Never panics on valid bodies; each answer says whether it converged.
pub fn cold_distances(
    a: &Body,
    b: &Body,
    poses: &[(Isometry3, Isometry3)],
    params: &NewtonParams,
    warm_starts: bool,
) -> Vec<DistanceResult> {
    #[cfg(target_arch = "x86_64")]
    if poses.len() >= MIN_LANE_BATCH && a.degree() >= 2 && b.degree() >= 2 && crate::math::cpu_has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        return unsafe { lanes::lanes_avx2(a, b, poses, params, warm_starts) };
    }
    poses.iter().map(|(pa, pb)| distance(a, pa, b, pb, None, params)).collect()
}

/// The four-lane solver (x86-64 only: AVX2 + FMA registers).
#[cfg(target_arch = "x86_64")]
mod lanes {
    use super::super::distance::{
        clear_of_contact, distance_growth_first, finish, overlapping_answer, separated_answer, DistanceResult,
        DistanceWarmStart, KktOut, SPECULATIVE_ITERATIONS,
    };
    use super::super::fast_eval::FastPosed;
    use super::super::growth::GrowthWarmStart;
    use super::super::newton::{frame_origin, merit_length, posed_in_frame, working_frame, NewtonParams, SolveStatus};
    use crate::body::{Body, PosedBody};
    use crate::math::{Isometry3, Real, Vector3};
    use crate::poly::radial::RADIAL_GRID;
    use crate::poly::support::SUPPORT_GRID;
    use crate::poly::{RadialTable, SupportTable};
    use std::arch::x86_64::*;

    mod coarse;
    mod simd;
    use simd::*;

    /// [`super::cold_distances`] on the lanes, compiled for AVX2 + FMA (the 4-lane arithmetic below becomes
    /// one instruction per operation).
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn lanes_avx2(
        a: &Body,
        b: &Body,
        poses: &[(Isometry3, Isometry3)],
        params: &NewtonParams,
        warm_starts: bool,
    ) -> Vec<DistanceResult> {
        solve_on_lanes(a, b, poses, params, warm_starts)
    }

    /// [`cold_starts`] compiled for AVX2 + FMA, for the tests.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(test)]
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn cold_starts_avx2(a: &Body, b: &Body, rels: &[Isometry3]) -> Vec<Option<(Vector3, Vector3)>> {
        cold_starts(a, b, rels)
    }

    /// Cells per cube-face side of both tables the cold starts read ([`RADIAL_GRID`] =
    /// [`SUPPORT_GRID`]: one cell computation serves both look-ups of a direction).
    const GRID: usize = RADIAL_GRID;
    const _: () = assert!(RADIAL_GRID == SUPPORT_GRID);
    /// Nodes per face side, and per face.
    const NODES: usize = GRID + 1;
    const FACE_NODES: usize = NODES * NODES;

    /// `fx` where `on_x`, else `fy` where `on_y`, else `fz`, per lane.
    #[inline(always)]
    fn select3(on_x: M4, on_y: M4, fx: F4, fy: F4, fz: F4) -> F4 {
        F4::select(on_x, fx, F4::select(on_y, fy, fz))
    }

    /// The cube-map cells of four directions (one per lane): [`crate::poly::radial`]'s face
    /// coordinates and bilinear interpolation, per lane.
    struct CubeCells {
        /// Flat node index `face · (G + 1)² + j · (G + 1) + i` of each cell's first node.
        k: __m128i,
        /// The direction's position within its cell (interpolation weights along a and b).
        ta: F4,
        tb: F4,
        /// Lanes whose direction is nonzero and finite (the others read node 0 and are marked).
        ok: M4,
    }

    impl CubeCells {
        /// The cells of the directions `v` (any nonzero length): the face of the largest |vᵢ|
        /// (faces +x, −x, +y, −y, +z, −z, ties to the earlier axis), face coordinates the other two
        /// components in cyclic order over its modulus (the scalar look-ups' rules and arithmetic).
        #[inline(always)]
        fn new(v: V3) -> Self {
            let [x, y, z] = v.0;
            let (ax, ay, az) = (x.abs(), y.abs(), z.abs());
            let (zero, one) = (F4::splat(0.0), F4::splat(1.0));
            let on_x = ay.le(ax).and(az.le(ax));
            let on_y = on_x.not().and(az.le(ay));
            let major = select3(on_x, on_y, ax, ay, az);
            let sign = select3(on_x, on_y, x, y, z).lt(zero);
            let face = select3(on_x, on_y, zero, F4::splat(2.0), F4::splat(4.0)) + F4::select(sign, one, zero);
            let (a, b) = (select3(on_x, on_y, y, z, x) / major, select3(on_x, on_y, z, x, y) / major);
            let ok = a.finite().and(b.finite());
            let half = F4::splat(0.5 * GRID as Real);
            let fa = F4::select(ok, (a + one) * half, zero);
            let fb = F4::select(ok, (b + one) * half, zero);
            let last = F4::splat((GRID - 1) as Real);
            let (i, j) = (fa.floor().max(zero).min(last), fb.floor().max(zero).min(last));
            let k = face.mul_add(F4::splat(FACE_NODES as Real), j.mul_add(F4::splat(NODES as Real), i));
            // SAFETY: see [`F4`]'s docs; `k` holds small nonnegative integers (exact conversion).
            let k = unsafe { _mm256_cvtpd_epi32(k.0) };
            Self { k, ta: fa - i, tb: fb - j, ok }
        }

        /// `table[k + offset]` per lane, from the flat table `base` (`stride` reals per node).
        ///
        /// # Safety
        /// `base` points at 6·(G + 1)² nodes of `stride` reals; `offset` < `stride`·(G + 2).
        #[inline(always)]
        unsafe fn gather(&self, base: *const Real, stride: i32, offset: usize) -> F4 {
            // SAFETY: the node indices are below 6·(G + 1)² − (G + 2) (face ≤ 5, i, j ≤ G − 1), so
            // with the offset every read stays in the table (the caller's contract).
            unsafe {
                let k = _mm_mullo_epi32(self.k, _mm_set1_epi32(stride));
                F4(_mm256_i32gather_pd::<8>(base.add(offset), k))
            }
        }

        /// Bilinear interpolation of the four nodes around each direction, of the node quantity at
        /// `coordinate` of `stride`-real nodes ([`crate::poly::RadialTable::radius`]'s arithmetic).
        ///
        /// # Safety
        /// As [`Self::gather`], with `coordinate` < `stride`.
        #[inline(always)]
        unsafe fn interpolate(&self, base: *const Real, stride: usize, coordinate: usize) -> F4 {
            // SAFETY: offsets below stride·(G + 2) (the caller's contract).
            let (s, c) = (stride as i32, coordinate);
            let [n00, n01, n10, n11] = unsafe {
                [
                    self.gather(base, s, c),
                    self.gather(base, s, stride + c),
                    self.gather(base, s, stride * NODES + c),
                    self.gather(base, s, stride * (NODES + 1) + c),
                ]
            };
            let low = n00 + (n01 - n00) * self.ta;
            let high = n10 + (n11 - n10) * self.ta;
            low + (high - low) * self.tb
        }

        /// The radial table's radius per lane (0 where the direction is not `ok`).
        #[inline(always)]
        fn radius(&self, table: &RadialTable) -> F4 {
            // SAFETY: `nodes` is 6·(G + 1)² reals (one per node), coordinate 0 of stride 1.
            let r = unsafe { self.interpolate(table.nodes().as_ptr().cast(), 1, 0) };
            F4::select(self.ok, r, F4::splat(0.0))
        }

        /// The support table's interpolated support point per lane (normalized units; meaningless
        /// where the direction is not `ok`).
        #[inline(always)]
        fn support(&self, table: &SupportTable) -> V3 {
            let base: *const Real = table.nodes().as_ptr().cast();
            // SAFETY: `nodes` is 6·(G + 1)² points of three reals; coordinates 0–2 of stride 3.
            unsafe { V3([self.interpolate(base, 3, 0), self.interpolate(base, 3, 1), self.interpolate(base, 3, 2)]) }
        }
    }

    /// The fraction min(r / ‖du‖, 1) of the way from a body's interior point towards a target
    /// whose direction in the body's normalized frame is `du`, for the radial table's radius `r`
    /// there (0 where ‖du‖ is 0 or not a number: [`PosedBody::boundary_towards`]'s rule, per lane).
    #[inline(always)]
    fn reach(r: F4, du: V3) -> F4 {
        let n = du.dot(du).sqrt();
        F4::select(F4::splat(0.0).lt(n), (r / n).min(F4::splat(1.0)), F4::splat(0.0))
    }

    /// The rotation matrix (row-major) of unit quaternions (w, x, y, z) per lane.
    #[inline(always)]
    fn rotation_matrix(w: F4, x: F4, y: F4, z: F4) -> M3 {
        let (one, two) = (F4::splat(1.0), F4::splat(2.0));
        let (xx, yy, zz) = (x * x, y * y, z * z);
        let (xy, xz, yz, wx, wy, wz) = (x * y, x * z, y * z, w * x, w * y, w * z);
        [
            one - two * (yy + zz),
            two * (xy - wz),
            two * (xz + wy),
            two * (xy + wz),
            one - two * (xx + zz),
            two * (yz - wx),
            two * (xz - wy),
            two * (yz + wx),
            one - two * (xx + yy),
        ]
    }

    /// The cold starts of the pairs whose relative poses (B in A's frame) are `rels`: the start
    /// [`cold_start`] gives each (the same tests and choices, at the same points up to rounding),
    /// computed four pairs at a time: the posed interior points, the bounding-sphere test, both
    /// bodies' support and radial look-ups (one cube-map cell per body and lane, gathered nodes) in
    /// 4-lane arithmetic; only the overlap tests of pairs whose spheres meet (two polynomial values,
    /// at points mapped on the lanes) stay scalar.
    #[inline(always)]
    fn cold_starts(a: &Body, b: &Body, rels: &[Isometry3]) -> Vec<Option<(Vector3, Vector3)>> {
        let ba = PosedBody::unposed(a);
        let ca = ba.interior_point();
        let ca4 = V3::splat(&ca);
        let quadric = a.degree() <= 2 || b.degree() <= 2;
        let spheres = match (a.bounding_sphere(), b.bounding_sphere()) {
            (Some((c1, r1)), Some((c2, r2))) => Some((V3::splat(&ba.to_world(&c1.coords)), c2.coords, r1 + r2)),
            _ => None,
        };
        let (sa, sb) = (F4::splat(a.scale()), F4::splat(b.scale()));
        let (center_a, center_b) = (V3::splat(&a.center()), V3::splat(&b.center()));
        let (inv_sa, neg_inv_sb) = (F4::splat(1.0 / a.scale()), F4::splat(-1.0 / b.scale()));
        let interior_b = b.interior_point().coords;
        let mut out = Vec::with_capacity(rels.len());
        for chunk in rels.chunks(4) {
            // The chunk's poses by lanes (a short chunk repeats its last pose).
            let (mut q, mut t) = ([[0.0; 4]; 4], [[0.0; 4]; 3]);
            for i in 0..4 {
                let rel = &chunk[i.min(chunk.len() - 1)];
                let r = rel.rotation.quaternion();
                (q[0][i], q[1][i], q[2][i], q[3][i]) = (r.w, r.i, r.j, r.k);
                for (c, row) in t.iter_mut().enumerate() {
                    row[i] = rel.translation.vector[c];
                }
            }
            // No closures here: one compiled out of line loses the AVX target features (measured: each
            // of these was a call of about 280 instructions, 5 % of a 2d = 6 batch).
            let rot = rotation_matrix(F4::load(&q[0]), F4::load(&q[1]), F4::load(&q[2]), F4::load(&q[3]));
            let t4 = V3::load(&t);
            let cb = mat_mul(&rot, V3::splat(&interior_b)).add(t4);
            let apart = match &spheres {
                Some((c1, c2, rsum)) => {
                    let d = c1.sub(mat_mul(&rot, V3::splat(c2)).add(t4));
                    F4::splat(rsum * rsum).lt(d.dot(d))
                }
                None => M4::default(),
            };
            // The directions of the look-ups in each body's normalized frame: A's towards B, B's
            // towards A (A·n for the world direction n = ±(cb − ca)).
            let axis = cb.sub(ca4);
            let (du_a, du_b) = (axis.scale(inv_sa), mat_t_mul(&rot, axis).scale(neg_inv_sb));
            let (cells_a, cells_b) = (CubeCells::new(du_a), CubeCells::new(du_b));
            let xs = cells_a.support(a.support_table()).mul_add(sa, center_a);
            let ys = mat_mul(&rot, cells_b.support(b.support_table()).mul_add(sb, center_b)).add(t4);
            let supports = cells_a.ok.and(cells_b.ok);
            let facing = if quadric { M4::default() } else { apart.and(supports) };
            // Facing lanes: one bisector refinement (`distance::bisector_start`), the support
            // points for n = (y − x)/‖y − x‖ + axis/‖axis‖ where they are closer to each other.
            let (xs, ys) = if facing.bits() != 0 {
                let d = ys.sub(xs);
                let dd = d.dot(d);
                let one = F4::splat(1.0);
                let n = d.scale(one / dd.sqrt()).add(axis.scale(one / axis.dot(axis).sqrt()));
                let (du_a, du_b) = (n.scale(inv_sa), mat_t_mul(&rot, n).scale(neg_inv_sb));
                let (cells_a, cells_b) = (CubeCells::new(du_a), CubeCells::new(du_b));
                let xr = cells_a.support(a.support_table()).mul_add(sa, center_a);
                let yr = mat_mul(&rot, cells_b.support(b.support_table()).mul_add(sb, center_b)).add(t4);
                let dr = yr.sub(xr);
                let closer = facing.and(cells_a.ok).and(cells_b.ok).and(dr.dot(dr).lt(dd));
                (V3::select(closer, xr, xs), V3::select(closer, yr, ys))
            } else {
                (xs, ys)
            };
            let (xs, ys, cb_lanes) = (xs.to_arrays(), ys.to_arrays(), cb.to_arrays());
            let (mut x0, mut y0, mut order, mut use_supports) = (xs, ys, 0, 0);
            if facing.bits() != 0b1111 {
                // The radial boundary points on the segment between the interior points.
                let x0v = axis.mul_add(reach(cells_a.radius(a.radial_table()), du_a), ca4);
                let y0v = axis.mul_add(-reach(cells_b.radius(b.radial_table()), du_b), cb);
                let (ex, ey) = (x0v.sub(ca4), y0v.sub(ca4));
                order = apart.or(ex.dot(ex).lt(ey.dot(ey))).bits();
                let (gs, g0) = (V3::load(&ys).sub(V3::load(&xs)), y0v.sub(x0v));
                use_supports = supports.and(gs.dot(gs).lt(g0.dot(g0))).bits();
                (x0, y0) = (x0v.to_arrays(), y0v.to_arrays());
            }
            // Each interior point in the other body's normalized coordinates (the overlap tests).
            let ca_in_b = mat_t_mul(&rot, ca4.sub(t4)).sub(center_b).scale(-neg_inv_sb).to_arrays();
            let cb_in_a = V3::load(&cb_lanes).sub(center_a).scale(inv_sa).to_arrays();
            let (facing, apart) = (facing.bits(), apart.bits());
            for i in 0..chunk.len() {
                let bit = 1 << i;
                let start = if facing & bit != 0 || use_supports & bit != 0 {
                    (V3::lane(&xs, i), V3::lane(&ys, i))
                } else {
                    (V3::lane(&x0, i), V3::lane(&y0, i))
                };
                let separated = facing & bit != 0
                    || (order & bit != 0
                        && (apart & bit != 0 || {
                            // Spheres that meet: separated along the segment only when each interior
                            // point lies outside the other body.
                            b.fast_polynomial().value(&V3::lane(&ca_in_b, i)) > 1.0
                                && a.fast_polynomial().value(&V3::lane(&cb_in_a, i)) > 1.0
                        }));
                out.push(separated.then_some(start));
            }
        }
        out
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

    /// Fewest pairs left without an answer worth the growth lanes (below, the single-pair solver):
    /// as for the distance lanes ([`super::MIN_LANE_BATCH`]), a round costs two four-point passes
    /// (about 88 ns at 2d = 6) whatever the lanes hold, against two one-point evaluations (about
    /// 32 ns each) per pair on the single-pair solver, so fewer than three live lanes lose.
    const MIN_GROWTH_LANES: usize = super::MIN_LANE_BATCH;

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
        fn map(&self) -> (M3, V3) {
            let m = &self.mb;
            let mb = [
                F4::load(&m[0]),
                F4::load(&m[1]),
                F4::load(&m[2]),
                F4::load(&m[3]),
                F4::load(&m[4]),
                F4::load(&m[5]),
                F4::load(&m[6]),
                F4::load(&m[7]),
                F4::load(&m[8]),
            ];
            (mb, V3::load(&self.cb))
        }

        /// The lanes holding a pair.
        #[inline(always)]
        fn live(&self) -> M4 {
            let job = &self.job;
            M4::from_bools([job[0] != EMPTY, job[1] != EMPTY, job[2] != EMPTY, job[3] != EMPTY])
        }

        /// The bookkeeping of a round: where a trial point was `accepted` (its residual `r1`), a
        /// step counted, the residual kept and the next step length `first`; where a live lane's was
        /// not, a rejection counted and the step halved. Returns the lanes done (accepted and `ends`
        /// — stationary, nonfinite or unsolvable — or at the iteration `cap`), the bits of the lanes
        /// that leave (done, or 40 rejected trial points in a row: the single-pair line search's
        /// limit) and the steps taken before this round.
        #[inline(always)]
        fn advance(&mut self, accepted: M4, r1: F4, first: F4, ends: M4, cap: F4) -> (M4, u32, F4) {
            let (zero, one) = (F4::splat(0.0), F4::splat(1.0));
            let live = self.live();
            self.r0 = F4::select(accepted, r1, F4::load(&self.r0)).to_array();
            self.alpha = F4::select(accepted, first, F4::load(&self.alpha) * F4::splat(0.5)).to_array();
            let rejected = F4::select(accepted, zero, F4::load(&self.rejected) + one);
            self.rejected = rejected.to_array();
            let before = F4::load(&self.steps);
            let done = accepted.and(ends.or(cap.le(before)));
            let stalled = live.and(accepted.not()).and(F4::splat(40.0).le(rejected));
            self.steps = (before + F4::select(accepted, one, zero)).to_array();
            self.start = [0.0; 4];
            (done, done.or(stalled).bits(), before)
        }
    }

    /// The linear part of body A's map to its normalized coordinates, u = k·x + c with
    /// k = 1/scale, in every lane: (k, k²).
    #[inline(always)]
    fn scale_map(a: &Body) -> (F4, F4) {
        let k = 1.0 / a.scale();
        (F4::splat(k), F4::splat(k * k))
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
        /// the pair's coordinates could exceed 10³ of the smaller body's size; the lane's points
        /// are relative to it), and the offset of A's normalized map there ([`offset_map`]).
        o: [[Real; 4]; 3],
        ca: [[Real; 4]; 3],
    }

    impl Lanes {
        /// Sets lane `i`'s working frame for pair `k` (relative pose `rel`): its origin and A's
        /// center in it, and B's map; returns the origin (A's frame). A's own frame (the common
        /// case) sets the lane exactly as without a working frame.
        #[inline(always)]
        fn frame(&mut self, i: usize, k: usize, a: &Body, b: &Body, rel: &Isometry3) -> Vector3 {
            let (o, bb) = posed_in_frame(b, rel, frame_origin(a, b, rel));
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
        fn verify(&self, i: usize, a: &Body, b: &Body, iterations: usize, tolerance: Real) -> Option<KktOut> {
            let lane = |v: &[[Real; 4]; 3], d: &[[Real; 4]; 3]| {
                Vector3::new(v[0][i] + d[0][i], v[1][i] + d[1][i], v[2][i] + d[2][i])
            };
            let (x, y) = (lane(&self.x, &self.dx), lane(&self.y, &self.dy));
            let lam = [self.lam[0][i] + self.dl[0][i], self.lam[1][i] + self.dl[1][i]];
            let (book, k) = (&self.book, 1.0 / a.scale());
            let center = a.center() - self.origin(i);
            let m = nalgebra::Matrix3::from_fn(|r, c| book.mb[3 * r + c][i]);
            let ub = m * y + Vector3::new(book.cb[0][i], book.cb[1][i], book.cb[2][i]);
            // SAFETY: the lanes run only on CPUs with AVX2 and FMA (`lanes_avx2`).
            let ((va, ga), (vb, gb)) = unsafe {
                (
                    a.fast_polynomial().value_gradient_avx2(&((x - center) * k)),
                    b.fast_polynomial().value_gradient_avx2(&ub),
                )
            };
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
        /// inlined): inlined, its scalar code made the rounds spill (4 % more instructions per
        /// batch at 2d = 2, callgrind).
        ///
        /// # Safety
        /// The CPU must support AVX2 and FMA.
        #[allow(clippy::too_many_arguments)]
        #[target_feature(enable = "avx2,fma")]
        #[inline(never)]
        unsafe fn verify_lanes(
            &mut self,
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
            for i in (0..4).filter(|i| verify & (1 << i) != 0) {
                let Some(out) = self.verify(i, a, b, steps[i] as usize + 1, params.kkt_tolerance) else {
                    continue;
                };
                let k = self.book.job[i];
                self.book.job[i] = EMPTY;
                if out.lam[0] > 0.0 && out.lam[1] > 0.0 && clear_of_contact(&out.x, &out.y, a, b) {
                    let out = out.moved(&self.origin(i));
                    answers[k] = Some(lane_answer(&poses[k].0, &self.rel[i], out, warm_starts, empty));
                }
            }
        }
    }

    /// A lane's Newton state where its coarse stage ends ([`COARSE_RESIDUAL`]): the accepted point
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

    /// Merit ([`KktRound::r1`]) relative to its scale 1 + 2‖x − y‖/L below which a lane leaves the
    /// coarse stage (single precision, [`coarse`]) for the fine one (double precision): the `f32`
    /// kernel's relative errors on the project's bodies are at most 2.4·10⁻⁵ (2d = 8, value,
    /// gradient and Hessian; 10⁻⁷–10⁻⁶ at 2d ≤ 6), 40 times below this, so the coarse steps are
    /// Newton steps to that accuracy, and from a residual of 10⁻³ two or three double-precision
    /// steps reach the tolerance. (Hand-offs at 3·10⁻³ and 3·10⁻⁴ ran as fast on eight lanes.)
    const COARSE_RESIDUAL: Real = 1e-3;

    /// Bound on the error of a coarse-stage merit relative to its scale 1 + 2‖x − y‖/L: 4 times the
    /// `f32` kernel's largest relative error on the project's bodies (2.4·10⁻⁵ at 2d = 8), which
    /// scales terms of size 2‖x − y‖. Without it a pair that starts at its answer (spheres: the
    /// radial start is exact) compares its double-precision residuals with a single-precision one
    /// at the rounding level, and its line search stalls.
    const COARSE_NOISE: Real = 1e-4;

    /// Least degree 2d of the higher-degree body of a pair for which the batch runs the coarse
    /// stage. At 2d = 2 the single-precision kernel saves less than the stage's bookkeeping costs
    /// (6.4 % more instructions per batch, callgrind; `examples/cold_profile 2 20 batch` 2.66
    /// against 2.75× the single-query rate, alternated five times); at 2d = 4 the instructions are
    /// the same and the eight lanes make the batch faster (2.56 against 2.44×).
    const COARSE_MIN_DEGREE: usize = 4;

    /// Least degree 2d of the higher-degree body of a pair for which the fine stage checks predicted
    /// last points by value + gradient evaluations ([`Lanes::verify`]). Below it the four-point
    /// kernel is cheap beside a check's scalar work: `examples/cold_profile D 20 batch`, with and
    /// without the checks alternated, gave 2.00–2.05 against 1.96–1.98× the single-query rate at
    /// 2d = 8, the same at 2d = 6 (2.26–2.34 against 2.29–2.38×), and less at 2d = 4 (2.53–2.57
    /// against 2.63–2.70×) and 2d = 2 (2.50–2.58 against 2.76–2.81×).
    const VERIFY_MIN_DEGREE: usize = 8;

    /// Merit relative to its scale 1 + 2‖x − y‖/L at an accepted point below which the fine
    /// stage checks the next trial point by value + gradient evaluations ([`Lanes::verify`]):
    /// Newton's quadratic convergence then lands below the tolerance. Measured on the chair /
    /// human poses at 2d = 8 (callgrind, instructions per batch): 5·10⁻⁶, 10⁻⁵ and 3·10⁻⁵ the
    /// same (−6.7 %; 10 or 15 of about 1440 checks fail), 2·10⁻⁶ less (the first fine step's
    /// residual, about 10⁻⁵ at 2d = 8, is then never checked early).
    const VERIFY_RESIDUAL: Real = 1e-5;

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
        let (one, two) = (F::splat(1.0), F::splat(2.0));
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
    fn load6(h: &[[Real; 4]; 6], k: F4) -> S3 {
        [
            F4::load(&h[0]) * k,
            F4::load(&h[1]) * k,
            F4::load(&h[2]) * k,
            F4::load(&h[3]) * k,
            F4::load(&h[4]) * k,
            F4::load(&h[5]) * k,
        ]
    }

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
    fn solve_growth_on_lanes(
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
        let cap = F4::splat(params.max_iterations as Real);
        let tolerance = F4::splat(params.kkt_tolerance);
        let (zero, one, half) = (F4::splat(0.0), F4::splat(1.0), F4::splat(0.5));
        let (ka4, ka2) = scale_map(a);
        let len = merit_length(a, b);
        let l2 = F4::splat(len * len);
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
                    let (o, ba, bb) = working_frame(a, b, &rels[k]);
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
            let x = V3::load(&lanes.x);
            let mu = F4::load(&lanes.mu);
            let dx = V3::load(&lanes.dx);
            let dmu = F4::load(&lanes.dmu);
            let book = &lanes.book;
            let (al, r0, start) = (F4::load(&book.alpha), F4::load(&book.r0), zero.lt(F4::load(&book.start)));
            let (mb, cb) = book.map();
            let xt = dx.mul_add(al, x);
            let mut mt = dmu.mul_add(al, mu);
            let ua = xt.mul_add(ka4, V3::load(&lanes.ca));
            let ub = mat_mul(&mb, xt).add(cb);
            let ea = soa_a.eval4_rows(&ua.to_arrays());
            let eb = soa_b.eval4_rows(&ub.to_arrays());
            let gf = V3::load(&ea.gradient).scale(ka4);
            let gg = mat_t_mul(&mb, V3::load(&eb.gradient));
            // Least-squares multipliers at a start (the single-pair solver's initial multiplier).
            if start.bits() != 0 {
                let tiny = F4::splat(Real::MIN_POSITIVE);
                let (nf, ng) = (gf.dot(gf), gg.dot(gg));
                let ls = -gf.dot(gg) / ng.max(tiny);
                let fallback = nf.sqrt() / ng.sqrt().max(tiny);
                mt = F4::select(start, F4::select(ls.finite().and(zero.lt(ls)), ls, fallback), mt);
            }
            let r = gg.mul_add(mt, gf);
            let c = F4::load(&eb.value) - one;
            // The single-pair solver's merit ‖(L·r, c)‖₂ ([`merit_length`]).
            let r1 = r.dot(r).mul_add(l2, c * c).sqrt();
            let norm_inf = abs_max(r).max(c.abs());
            let stationary = norm_inf.le(tolerance * (one + abs_max(gf)));
            // The Newton steps from the trial points (taken where a trial point is accepted).
            let hf = load6(&ea.hessian, ka2);
            let hg = congruence(&mb, &load6(&eb.hessian, one));
            let w: S3 = [
                hg[0].mul_add(mt, hf[0]),
                hg[1].mul_add(mt, hf[1]),
                hg[2].mul_add(mt, hf[2]),
                hg[3].mul_add(mt, hf[3]),
                hg[4].mul_add(mt, hf[4]),
                hg[5].mul_add(mt, hf[5]),
            ];
            let (sdx, sdmu, solved) = solve_kkt4(&w, gg, r, c);
            let decrease = r1.le((F4::splat(-1e-4) * al + one) * r0).and(r1.finite());
            let accepted = start.or(decrease).and(lanes.book.live());
            lanes.x = V3::select(accepted, xt, x).to_arrays();
            lanes.mu = F4::select(accepted, mt, mu).to_array();
            lanes.dx = V3::select(accepted, sdx, dx).to_arrays();
            lanes.dmu = F4::select(accepted, sdmu, dmu).to_array();
            // A cold run keeps μ ≥ μ/2 per step (the KKT points with μ < 0 are not the answer).
            let halved = zero.lt(mt).and((mt + sdmu).lt(half * mt));
            let first = F4::select(halved, half * mt / -sdmu, one);
            let ends = stationary.or(r1.finite().not()).or(solved.not());
            let (done, leave, steps) = lanes.book.advance(accepted, r1, first, ends, cap);
            if leave == 0 {
                continue;
            }
            // The overlapping answers: a KKT point with μ > 0 (the minimizer) and p_a ≤ 1 there.
            let answer = done.and(stationary).and(r1.finite()).and(zero.lt(mt)).and(F4::load(&ea.value).le(one)).bits();
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
                    let local = rel.inverse_transform_point(&crate::math::Point3::from(x)).coords;
                    let growth = GrowthWarmStart::after(None, local, mt[i], true, rel.inverse());
                    std::sync::Arc::new(DistanceWarmStart { growth, ..Default::default() })
                } else {
                    empty.clone()
                };
                let p = poses[k].0 * crate::math::Point3::from(x);
                let iterations = steps[i] as usize;
                answers[k] =
                    Some(overlapping_answer(p, SolveStatus::Converged, iterations, norm_inf[i], false, warm_start));
            }
        }
    }

    #[inline(always)]
    fn solve_on_lanes(
        a: &Body,
        b: &Body,
        poses: &[(Isometry3, Isometry3)],
        params: &NewtonParams,
        warm_starts: bool,
    ) -> Vec<DistanceResult> {
        let (soa_a, soa_b) = (a.soa_polynomial(), b.soa_polynomial());
        let mut answers: Vec<Option<DistanceResult>> = vec![None; poses.len()];
        let cap = F4::splat(params.max_iterations.min(SPECULATIVE_ITERATIONS) as Real);
        let tolerance = F4::splat(params.kkt_tolerance);
        // Checks of predicted last points only where they pay (see `VERIFY_MIN_DEGREE`).
        let verify_level = F4::splat(VERIFY_RESIDUAL);
        // The merit's length L and its weight 1/L² ([`merit_length`]).
        let len = merit_length(a, b);
        let (w2, two_over_len) = (F4::splat(1.0 / (len * len)), F4::splat(2.0 / len));
        let verifying = a.degree().max(b.degree()) >= VERIFY_MIN_DEGREE;
        let (zero, one, two) = (F4::splat(0.0), F4::splat(1.0), F4::splat(2.0));
        let (ka4, ka2) = scale_map(a);
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
        };
        let empty = std::sync::Arc::new(DistanceWarmStart::default());
        let rels: Vec<Isometry3> = poses.iter().map(|(pa, pb)| pa.inv_mul(pb)).collect();
        let starts = cold_starts(a, b, &rels);
        // The coarse stage (eight single-precision lanes; none below `COARSE_MIN_DEGREE`: every pair
        // cold, in order) records where each pair stands; the fine stage's queue is the pairs it
        // drained and the cold ones (the slow ones first: they run beside the others; pairs without
        // a start are skipped by the refill), then the others.
        let (stage, queue) = if a.degree().max(b.degree()) >= COARSE_MIN_DEGREE {
            let mut stage = vec![Stage::Cold; poses.len()];
            let cap = params.max_iterations.min(SPECULATIVE_ITERATIONS);
            // SAFETY: the lanes run only on CPUs with AVX2 and FMA (`lanes_avx2`).
            unsafe { coarse::coarse_stage8(a, b, &rels, &starts, cap, &mut stage) };
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
            let (x, y) = (V3::load(&lanes.x), V3::load(&lanes.y));
            let lam = [F4::load(&lanes.lam[0]), F4::load(&lanes.lam[1])];
            let (dx, dy) = (V3::load(&lanes.dx), V3::load(&lanes.dy));
            let dl = [F4::load(&lanes.dl[0]), F4::load(&lanes.dl[1])];
            let book = &lanes.book;
            let (al, r0, start) = (F4::load(&book.alpha), F4::load(&book.r0), zero.lt(F4::load(&book.start)));
            let (mb, cb) = book.map();
            let xt = dx.mul_add(al, x);
            let yt = dy.mul_add(al, y);
            let lt = [dl[0].mul_add(al, lam[0]), dl[1].mul_add(al, lam[1])];
            let ua = xt.mul_add(ka4, V3::load(&lanes.ca));
            let ub = mat_mul(&mb, yt).add(cb);
            let (ea, eb) = (soa_a.eval4_rows(&ua.to_arrays()), soa_b.eval4_rows(&ub.to_arrays()));
            let ga = V3::load(&ea.gradient).scale(ka4);
            let gb = mat_t_mul(&mb, V3::load(&eb.gradient));
            let (va, vb) = (F4::load(&ea.value), F4::load(&eb.value));
            let (ha, hb) = (load6(&ea.hessian, ka2), congruence(&mb, &load6(&eb.hessian, one)));
            let tiny = F4::splat(Real::MIN_POSITIVE);
            let KktRound { lt, dist, ra, rb, cva, cvb, r1, step } =
                kkt_round(xt, yt, lt, start, tiny, w2, [ga, gb], [va, vb], [&ha, &hb]);
            let (sdx, sdy, sdl, solved) = step;
            let norm_inf = abs_max(ra).max(abs_max(rb)).max(cva.abs().max(cvb.abs()));
            // Accepted trial points: the start, or a decrease of the merit (Armijo).
            let decrease = r1.le((F4::splat(-1e-4) * al + one) * r0).and(r1.finite());
            let accepted = start.or(decrease).and(lanes.book.live());
            let scale = dist.mul_add(two, one);
            let stationary = norm_inf.le(tolerance * scale);
            lanes.x = V3::select(accepted, xt, x).to_arrays();
            lanes.y = V3::select(accepted, yt, y).to_arrays();
            lanes.lam =
                [F4::select(accepted, lt[0], lam[0]).to_array(), F4::select(accepted, lt[1], lam[1]).to_array()];
            lanes.dx = V3::select(accepted, sdx, dx).to_arrays();
            lanes.dy = V3::select(accepted, sdy, dy).to_arrays();
            lanes.dl = [F4::select(accepted, sdl[0], dl[0]).to_array(), F4::select(accepted, sdl[1], dl[1]).to_array()];
            // Lanes that leave: stationary (the answer, or the single-pair solver when a multiplier
            // is not positive), a nonfinite residual, a singular system, the iteration cap, or 40
            // rejected trial points in a row (the single-pair line search's limit).
            let ends = stationary.or(r1.finite().not()).or(solved.not());
            // Lanes whose next trial point is predicted to be their answer (accepted here at a
            // residual whose Newton step, converging quadratically, lands below the tolerance, and
            // not done): that point is checked now, one lane at a time, by value + gradient
            // evaluations (no Hessians, which a last point does not need), instead of in the next
            // round's pass.
            let level = verify_level * dist.mul_add(two_over_len, one);
            let last = if verifying { accepted.and(solved).and(r1.le(level)) } else { M4::default() };
            let (done, leave, steps) = lanes.book.advance(accepted, r1, one, ends, cap);
            let verify = last.and(done.not()).bits();
            if leave | verify == 0 {
                continue;
            }
            let (norm_inf, steps) = (norm_inf.to_array(), steps.to_array());
            if verify != 0 {
                // SAFETY: the lanes run only on CPUs with AVX2 and FMA (`lanes_avx2`).
                unsafe { lanes.verify_lanes(verify, &steps, a, b, poses, params, warm_starts, &mut answers, &empty) };
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
        if queue.len() >= MIN_GROWTH_LANES {
            solve_growth_on_lanes(a, b, poses, &rels, &queue, params, warm_starts, &mut answers, &empty);
        }
        answers
            .into_iter()
            .zip(poses)
            .map(|(r, (pa, pb))| r.unwrap_or_else(|| distance_growth_first(a, pa, b, pb, params)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::ellipsoid;
    use crate::math::{Real, UnitQuaternion, Vector3};
    use crate::query::test_bodies::random_body;
    use rand::{Rng, SeedableRng};

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
                let gap = (pa * crate::math::Point3::new(0.1, 0.0, 0.0)
                    - pb * crate::math::Point3::new(0.0, -0.1, 0.0))
                .norm()
                    - 0.8;
                assert!(d.status.converged(), "{d:?}");
                assert!((d.distance - gap.max(0.0)).abs() < 1e-9, "{} vs {gap}", d.distance);
                assert_eq!(d.overlapping, gap <= 0.0);
                overlapping += usize::from(d.overlapping);
                let (ca, cb) =
                    (pa * crate::math::Point3::new(0.1, 0.0, 0.0), pb * crate::math::Point3::new(0.0, -0.1, 0.0));
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
                (
                    "2 mm against 1 m",
                    rescaled(&unit_a, 0.003, zero),
                    unit_b.clone(),
                    poses(40, 2.5, 100 + degree as u64),
                ),
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
                    assert!(
                        gap <= 1e-9 * (1.0 + s.distance),
                        "2d = {degree}, {name}: {} vs {}",
                        d.distance,
                        s.distance
                    );
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
        if !crate::math::cpu_has_avx2_fma() {
            return;
        }
        use super::super::distance::cold_start;
        use crate::body::PosedBody;
        for degree in [2, 4, 6, 8] {
            let (a, b) = (random_body(degree, 21), random_body(degree, 22));
            let rels: Vec<Isometry3> =
                poses(203, 1.2, 30 + degree as u64).iter().map(|(pa, pb)| pa.inv_mul(pb)).collect();
            // SAFETY: the CPU supports AVX2 and FMA (checked above).
            let lanes = unsafe { lanes::cold_starts_avx2(&a, &b, &rels) };
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
}
