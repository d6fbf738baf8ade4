//! Configuration checks in blocks: many configurations at once, the first stages in SIMD lanes
//! (four f64 lanes on a CPU with AVX2 and FMA, one lane elsewhere, the same code).
//!
//! ```text
//! block of W configurations, entry k of lane i at q[k·W + i]
//!   forward kinematics in lanes: the joints compiled once per checker into a flat program
//!     (origin as a signed permutation or a rotation, then a turn about ±x/±y/±z, a turn about
//!      any axis, or a slide), sin / cos in lanes (Cody–Waite reduction, Taylor to r¹⁸)
//!   world pairs, per geometry g and object o, over the lanes still open:
//!     ball of g against o's world box (or a mesh object's ball)          > padding → free
//!     ball of g against o in closed form (box, sphere, cylinder, capsule, halfspace)
//!     the 16 balls of g's sphere-tree cut, each against o in closed form  > padding → free
//!     an inner ball of g's closed mesh meeting o, o reaching outside the
//!       mesh's bounding ball                                              → collides (proof)
//!     otherwise the pair is left pending for that lane
//!   self pairs (a, b): the two balls, the pair's clearance table per lane, the two cuts ball
//!     against ball, the inner-ball proof of two closed meshes; otherwise pending
//! a lane with no pending pair is answered from the lanes; a lane with pending pairs is placed
//!   alone and only those pairs go through the single path's stages (trees, proofs, sos bound,
//!   meshes), the pairs the lanes decided are not checked again
//! ```
//!
//! **Exact as the single path.** A bound calls a pair free only when balls that contain the
//! link mesh (the sphere tree's nodes hold every triangle; a geometry's ball holds the whole
//! geometry) clear the padding, and a proof calls it colliding only as
//! [`crate::inner`]'s proofs do, so a lane's verdict is the meshes' verdict, the one
//! [`RobotChecker::check`] gives. The lanes' poses differ from the single path's by rounding
//! (about 1e-15 m per meter of reach: `tests` compares them to 1e-12 on the Panda and a robot
//! with every joint kind); every bound must clear the padding, and every proof hold, by an
//! inflation of 1e-9 m per meter of the robot's reach and of the base's distance from the world
//! origin, far above that rounding. Configurations with an entry beyond 1e5 (radians or meters)
//! and robots of more than 64 entries are checked alone.
//!
//! **What it buys** (the MotionBenchMaker Panda labels, `sublevel-lab robot-labels`): about
//! 70 % of the configurations are decided in the lanes, and the block path's mean is about 1.4×
//! the single path's; the others are the ones within a few centimeters of contact, where only the
//! trees and the meshes can tell, and they keep most of the single path's cost (docs/robots.md).

use super::RobotChecker;
use crate::answer::{CheckOptions, ConfigurationAnswer};
use crate::fidelity::Fidelity;
use crate::{Error, Result};
use kernel::{BlockInput, Decided, Scratch};
use lanes::{Lanes, MAX_ANGLE};
use sublevel_core::math::{Isometry3, Real};

mod kernel;
mod lanes;
mod plan;

pub(crate) use plan::BlockPlan;

/// The configurations of one [`RobotChecker::check_block`] call and how to check them.
#[derive(Clone, Copy)]
struct Job<'a> {
    /// n × dof reals, validated.
    configs: &'a [Real],
    base: &'a Isometry3,
    options: &'a CheckOptions,
    /// Whether the answers end at the first colliding configuration.
    stop: bool,
    /// Whether the answers may end at any colliding configuration (the first a block's lanes
    /// prove colliding, before the single path for the lanes before it).
    any: bool,
}

/// The answer of a configuration the lanes decided, among `pairs` checked pairs.
fn decided_answer(d: &Decided, pairs: usize, fidelity: Fidelity) -> ConfigurationAnswer {
    let mut a = ConfigurationAnswer::start(false);
    if d.conservative {
        a.fidelity = fidelity;
    }
    a.world = d.world.is_some();
    a.pair = d.world;
    a.self_collision = d.self_pair.is_some();
    a.self_pair = d.self_pair;
    a.collides = a.world || a.self_collision;
    a.pairs_table = d.tables;
    a.pairs_proved = d.proved;
    a.pairs_pruned = pairs.saturating_sub(d.tables + d.proved);

    a
}

/// `e` with its field under `prefix` (`prefix.field`).
fn prefixed(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidArgument { field, reason } => {
            Error::InvalidArgument { field: format!("{prefix}.{field}"), reason }
        }
        other => other,
    }
}

impl RobotChecker<'_> {
    /// Checks configurations given row by row in `configs` (n × dof reals, radians / meters, dof
    /// = [`crate::RobotModel::dof`]) with the robot's root at `base`, and appends one answer per
    /// configuration to `out`, in order (module docs). The verdicts are [`RobotChecker::check`]'s;
    /// with `options.distance`, or with the sphere stage or the contact proofs off, every
    /// configuration is checked alone. With `stop_at_first_collision` the answers end with the
    /// first colliding configuration. A configuration the lanes decide gets the counts of the
    /// lanes: every pair not proved colliding counts as pruned.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `configurations` (a length that is not a multiple of
    /// dof), `configurations[i].q[k]` (not finite) or `padding`, before any configuration is
    /// checked; [`Error::Numerical`] as [`RobotChecker::check`] (`out` then holds the answers
    /// before the configuration that failed).
    pub fn check_block(
        &mut self,
        configs: &[Real],
        base: &Isometry3,
        options: &CheckOptions,
        stop_at_first_collision: bool,
        out: &mut Vec<ConfigurationAnswer>,
    ) -> Result<()> {
        let job = Job { configs, base, options, stop: stop_at_first_collision, any: false };
        self.run_job(&job, out)
    }

    /// Whether any configuration of `configs` (n × dof reals, as
    /// [`RobotChecker::check_block`]) collides within `padding` (meters) with the world or
    /// itself: [`RobotChecker::first_collision`]'s `is_some()`, answered as soon as the lanes
    /// prove one configuration colliding, without the single path for the others of its block.
    ///
    /// # Errors
    /// As [`RobotChecker::check_block`].
    pub fn any_collision(&mut self, configs: &[Real], base: &Isometry3, padding: Real) -> Result<bool> {
        let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
        let mut out = Vec::new();
        self.run_job(&Job { configs, base, options: &options, stop: true, any: true }, &mut out)?;
        Ok(out.iter().any(|a| a.collides))
    }

    /// How many configurations the block path has checked since the checker was made, and how
    /// many of them its lanes left to the single path's stages (sphere trees, proofs, sos bound,
    /// meshes) because a pair came within a few centimeters of contact: the share that sets a
    /// workload's cost per configuration (module docs).
    pub fn block_counts(&self) -> (u64, u64) {
        self.block_counts
    }

    /// [`RobotChecker::check_block`] for `job`.
    fn run_job(&mut self, job: &Job<'_>, out: &mut Vec<ConfigurationAnswer>) -> Result<()> {
        let Job { configs, base, options, stop: stop_at_first_collision, .. } = *job;
        if !(options.padding.is_finite() && options.padding >= 0.0) {
            return Err(Error::invalid("padding", format!("must be finite and ≥ 0 m, got {}", options.padding)));
        }
        let dof = self.robot.model.dof();
        if configs.is_empty() {
            return Ok(());
        }
        if dof == 0 || !configs.len().is_multiple_of(dof) {
            return Err(Error::invalid(
                "configurations",
                format!("holds {} reals, not a multiple of the robot's {dof} entries", configs.len()),
            ));
        }
        for (i, q) in configs.chunks_exact(dof).enumerate() {
            self.robot.model.check_configuration("q", q).map_err(|e| prefixed(e, &format!("configurations[{i}]")))?;
        }
        if options.distance || !self.sphere_stage || !self.contact_proofs || dof > kernel::MAX_DOF {
            for (i, q) in configs.chunks_exact(dof).enumerate() {
                let answer = self.check(q, base, options).map_err(|e| prefixed(e, &format!("configurations[{i}]")))?;
                let collides = answer.collides;
                out.push(answer);
                if stop_at_first_collision && collides {
                    break;
                }
            }
            return Ok(());
        }
        let plan = match self.block.take() {
            Some(plan) => plan,
            None => Box::new(BlockPlan::new(self)),
        };
        let result = self.blocks_dispatch(&plan, job, out);
        self.block = Some(plan);
        result
    }

    /// [`RobotChecker::blocks`] in four f64 lanes on a CPU with AVX2 and FMA, else one lane.
    fn blocks_dispatch(&mut self, plan: &BlockPlan, job: &Job<'_>, out: &mut Vec<ConfigurationAnswer>) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if let Some(cpu) = sublevel_kernels::Avx2Fma::detect() {
            return cpu.run(
                #[inline(always)]
                || self.blocks::<sublevel_kernels::F4>(cpu, plan, job, out),
            );
        }
        self.blocks::<sublevel_kernels::Scalar<false>>((), plan, job, out)
    }

    /// The block path of [`RobotChecker::check_block`] in lanes `L` (configurations validated).
    #[inline(always)]
    fn blocks<L: Lanes>(
        &mut self,
        cpu: L::Cpu,
        plan: &BlockPlan,
        job: &Job<'_>,
        out: &mut Vec<ConfigurationAnswer>,
    ) -> Result<()> {
        let Job { configs, base, options, stop, any } = *job;
        let z = L::splat(cpu, 0.0);
        let w = L::WIDTH;
        let dof = self.robot.model.dof();
        let mut scratch = Scratch::new(z, plan);
        let eps = plan.inflation(base);
        let base_rows = plan::pose_rows(base);
        let mut soa = vec![0.0; dof * w];
        let (mut world_left, mut self_left) = (Vec::new(), Vec::new());
        let mut verdicts = [None; 8];
        let pairs = self.world_pairs.iter().map(Vec::len).sum::<usize>()
            + if options.self_collision { self.self_pairs.len() } else { 0 };
        for (b, block) in configs.chunks(dof * w).enumerate() {
            let n = block.len() / dof;
            let lane_q = |lane: usize| &block[lane.min(n - 1) * dof..(lane.min(n - 1) + 1) * dof];
            let mut rows: [&[Real]; 8] = [&[]; 8];
            for (lane, row) in rows.iter_mut().enumerate().take(w) {
                *row = lane_q(lane);
            }
            let mut lanes = 0u32;
            for (lane, q) in rows.iter().enumerate().take(w) {
                if lane < n && q.iter().all(|v| v.abs() <= MAX_ANGLE) {
                    lanes |= 1 << lane;
                }
                for (k, v) in q.iter().enumerate() {
                    soa[k * w + lane] = *v;
                }
            }
            if lanes != 0 {
                let input = BlockInput {
                    q: &soa,
                    configs: &rows[..w],
                    base: base_rows,
                    padding: options.padding,
                    eps,
                    pad: &self.pad,
                    world_pairs: &self.world_pairs,
                    self_pairs: &self.self_pairs,
                    self_collision: options.self_collision,
                    proofs: self.fidelity.is_mesh(),
                    conclusive: matches!(self.fidelity, Fidelity::Spheres { .. }),
                    lanes,
                };
                let (tables, clearance) = (&self.self_tables, &self.robot.clearance);
                let table = |k: usize, lane: usize| {
                    tables[k].map_or(Real::NEG_INFINITY, |t| clearance[t].lower_bound(input.configs[lane]))
                };
                kernel::decide(z, plan, &input, &table, &mut scratch, &mut verdicts);
            } else {
                verdicts = [None; 8];
            }
            if any {
                let proved = verdicts.iter().take(n).flatten().find(|d| d.world.is_some() || d.self_pair.is_some());
                if let Some(d) = proved {
                    out.push(decided_answer(d, pairs, self.fidelity));
                    return Ok(());
                }
            }
            for (lane, verdict) in verdicts.iter().enumerate().take(n) {
                self.block_counts.0 += 1;
                let answer = match verdict {
                    Some(d) if !d.pending => decided_answer(d, pairs, self.fidelity),
                    Some(d) => {
                        self.block_counts.1 += 1;
                        world_left.clear();
                        world_left.extend(scratch.pending_world.iter().filter(|p| p.0 == lane).map(|p| (p.1, p.2)));
                        self_left.clear();
                        self_left.extend(scratch.pending_self.iter().filter(|p| p.0 == lane).map(|p| p.1));
                        self.check_left(rows[lane], base, options, d, &world_left, &self_left, pairs)
                            .map_err(|e| prefixed(e, &format!("configurations[{}]", b * w + lane)))?
                    }
                    None => {
                        self.block_counts.1 += 1;
                        self.check(rows[lane], base, options)
                            .map_err(|e| prefixed(e, &format!("configurations[{}]", b * w + lane)))?
                    }
                };
                let collides = answer.collides;
                out.push(answer);
                if stop && collides {
                    return Ok(());
                }
            }
        }
        Ok(())
    }

    /// The answer at `q` of a lane the kernel left pairs of: the world pairs `world` and the self
    /// pairs `selfs` (indices, increasing) through the single path's stages, the rest as `d`
    /// decided.
    #[allow(clippy::too_many_arguments)]
    fn check_left(
        &mut self,
        q: &[Real],
        base: &Isometry3,
        options: &CheckOptions,
        d: &Decided,
        world: &[(usize, usize)],
        selfs: &[usize],
        pairs: usize,
    ) -> Result<ConfigurationAnswer> {
        self.place(q, base)?;
        let mut answer = decided_answer(d, pairs, self.fidelity);
        answer.pairs_pruned = pairs.saturating_sub(d.tables + d.proved + world.len() + selfs.len());
        if d.world.is_none() && !world.is_empty() {
            self.world_check(options, &mut answer, Some(world))?;
        }
        if options.self_collision && d.self_pair.is_none() && !selfs.is_empty() {
            self.self_check(options, &mut answer, Some(selfs))?;
        }
        answer.collides = answer.world || answer.self_collision;
        Ok(answer)
    }

    /// The index of the first configuration of `configs` (n × dof reals, as
    /// [`RobotChecker::check_block`]) that collides within `padding` (meters) with the world or
    /// itself, or `None` when all are free: the verdict of a sampled motion (a rake).
    ///
    /// # Errors
    /// As [`RobotChecker::check_block`].
    pub fn first_collision(&mut self, configs: &[Real], base: &Isometry3, padding: Real) -> Result<Option<usize>> {
        let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
        let mut out = Vec::new();
        self.check_block(configs, base, &options, true, &mut out)?;
        Ok(out.iter().position(|a| a.collides))
    }
}

/// What a sampled motion check found ([`RobotChecker::rake_motion`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RakeAnswer {
    /// The parameter t ∈ (0, 1] of a colliding sample (the smallest of the first block that
    /// held one), or `None` when every sample is free.
    pub collision: Option<Real>,
    /// Samples checked.
    pub samples: usize,
}

/// The samples `1..=n` of a segment in rake order for blocks of `lanes`: block j holds the
/// samples j + 1, j + 1 + s, j + 1 + 2s, … (s = ⌈n / lanes⌉), spread evenly along the segment,
/// so the first block already looks at every part of it (VAMP's rakes, Thomason et al., ICRA
/// 2024). Every index once.
pub fn rake_order(n: usize, lanes: usize) -> Vec<usize> {
    let s = n.div_ceil(lanes.max(1)).max(1);
    (0..s).flat_map(|j| (0..lanes.max(1)).map(move |k| j + 1 + k * s)).filter(|&i| i <= n).collect()
}

impl RobotChecker<'_> {
    /// The sampled check of the joint-space segment `a → b` (radians / meters, linear
    /// interpolation): `n = max(1, ⌈‖b − a‖ · resolution⌉)` samples at t = i / n, i = 1..=n (`a`
    /// is not checked), taken in rakes ([`rake_order`]) block by block, stopping at the first
    /// block with a colliding sample (within `padding` meters). VAMP checks its edges at
    /// resolution 32; a sampled check can miss a collision between samples, which conservative
    /// advancement ([`crate::MotionChecker`]) cannot.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `start` / `end` (wrong length, not finite),
    /// `resolution` (not finite or ≤ 0) or `padding`.
    pub fn rake_motion(
        &mut self,
        a: &[Real],
        b: &[Real],
        resolution: Real,
        base: &Isometry3,
        padding: Real,
    ) -> Result<RakeAnswer> {
        let model = &self.robot.model;
        model.check_configuration("start", a)?;
        model.check_configuration("end", b)?;
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(Error::invalid("resolution", format!("must be finite and > 0, got {resolution}")));
        }
        let length = a.iter().zip(b).map(|(x, y)| (y - x) * (y - x)).sum::<Real>().sqrt();
        let n = ((length * resolution).ceil() as usize).max(1);
        let lanes = BLOCK;
        let order = rake_order(n, lanes);
        let mut block = Vec::with_capacity(lanes * a.len());
        let mut samples = 0;
        for chunk in order.chunks(lanes) {
            block.clear();
            for &i in chunk {
                let t = i as Real / n as Real;
                block.extend(a.iter().zip(b).map(|(x, y)| x + t * (y - x)));
            }
            samples += chunk.len();
            let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
            let mut out = Vec::with_capacity(chunk.len());
            self.check_block(&block, base, &options, false, &mut out)?;
            let hit = chunk.iter().zip(&out).filter(|(_, a)| a.collides).map(|(&i, _)| i).min();
            if let Some(i) = hit {
                return Ok(RakeAnswer { collision: Some(i as Real / n as Real), samples });
            }
        }
        Ok(RakeAnswer { collision: None, samples })
    }
}

/// Configurations per block of the rakes (two AVX registers of four f64 lanes).
pub const BLOCK: usize = 8;
