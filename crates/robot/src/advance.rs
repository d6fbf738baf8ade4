//! Motions certified by conservative advancement: a joint-space segment `q(t) = q₀ + t·Δq`,
//! `t ∈ [0, 1]`, proven free of the world and of self-collision, or its first contact parameter.
//!
//! ```text
//! first: the configuration q₀ checked (pairs whose links do not move keep their verdict throughout)
//! every moving pair p holds a proof: free (no closer than the padding) for every t up to u_p
//! a bound b of p's distance taken at q(t') proves it free up to u_p = t' + s_p, s_p the largest s
//! with m(s) ≤ b − padding, where
//!     m(s) = min(s·D, s·A + s²·B / 2, s·V + s²·G / 2)   for a link–world pair, the sum of the
//!            two links' for a self pair (counting only the joints below their common ancestor,
//!            which alone move them apart); D over the whole segment, A, B, V, G at q(t') for the
//!            geometry's bounding ball ([`crate::motion`])
//! t ← 0; every moving pair gets a cheap bound at q₀ (its ball gap, or its ball and box gaps)
//! loop:  take the pair p with the earliest u_p
//!          u_p ≥ 1                                      → the motion is free
//!          p's bound is loose (a gap, or a close sos bound): refine it at q(t), u_p ← the later
//!              ball / box gap → sos root bound → the meshes' distance (within a slack)
//!              a mesh bound ≤ padding + tolerance        → contact at t (within the tolerance)
//!          else t ← u_p: place the geometries at q(t); the pairs whose proofs end by t + ½·(last
//!              step) get new cheap bounds there (u ← the later of the old and the new end), the
//!              others keep theirs
//! ```
//!
//! No point of a geometry moves farther than `m(s)` from where it was at `q(t')` during
//! `[t', t' + s]`, for any `s` up to the segment's end (the motion bound, [`crate::motion`]), and a
//! geometry at distance `b` from the world cannot touch it before moving `b`; two links close by at
//! most the sum of their bounds, each measured in the frame of their nearest common ancestor (the
//! joints above it move both together). So a proof taken at one step holds at the later steps
//! too (it is carried, not taken again, until it runs out), the motion is free up to the earliest
//! `u_p`, and stepping there leaves no gap: there is no sampling resolution to choose (Schwarzer,
//! Saha and Latombe, IEEE T-RO 2005). A contact is reported at the first `t` where a pair's mesh
//! bound falls to `padding + tolerance`; the motion is free before it, so the true first contact
//! `t*` is not earlier than the reported one by more than the time it takes to close the
//! tolerance.
//!
//! **The meshes' searches** stop early in two ways, neither of which weakens the proof: at the
//! distance the pair cannot close before `t = 1` (a pair farther than that is free to the end),
//! and within a slack of 20 % of the way from `padding + tolerance` to the closest triangles found
//! (`crate::exact::Slack`): the bound is then `padding + tolerance + 0.8·(d − padding − tolerance)`,
//! `d` the distance of two triangles, and nothing unsearched is closer. A contact is only
//! reported from two triangles within `padding + tolerance`.
//!
//! [`MotionChecker::set_carried_bounds`] turns the carrying off: every moving pair is bounded again
//! at every step and the meshes are searched exactly, the reference the carried bounds are tested
//! against (`tests/motion.rs`).
//!
//! Continuous joints interpolate along the shorter way round (`Δq` wrapped into (−π, π]).

use crate::check::CheckOptions;
use crate::check::RobotChecker;
use crate::exact::Slack;
use crate::model::JointKind;
use crate::motion::{step, LinkMotion, MotionBounds};
use crate::{Error, Result};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::f64::consts::PI;
use sublevel_core::math::{Isometry3, Real};

/// Steps between two looks at a motion's deadline and cancellation ([`MotionChecker::set_deadline`]):
/// a step takes microseconds, so a stop is seen well within a millisecond.
pub const STOP_EVERY: usize = 16;

/// Settings of [`MotionChecker::check_motion`].
#[derive(Clone, Copy, Debug)]
pub struct MotionOptions {
    /// Padding around every robot geometry (meters, ≥ 0).
    pub padding: Real,
    /// Contact tolerance (meters, > 0): a bound at or below `padding + tolerance` is a contact.
    pub tolerance: Real,
    /// Most steps one motion may take before it is answered undecided (≥ 1).
    pub max_steps: usize,
}

impl Default for MotionOptions {
    fn default() -> Self {
        Self { padding: 0.0, tolerance: 1e-3, max_steps: 100_000 }
    }
}

impl MotionOptions {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `padding` (negative or not finite), `tolerance` (not
    /// finite and > 0) or `max_steps` (0).
    pub fn validate(&self) -> Result<()> {
        if !(self.padding.is_finite() && self.padding >= 0.0) {
            return Err(Error::invalid("padding", format!("must be finite and ≥ 0 m, got {}", self.padding)));
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(Error::invalid("tolerance", format!("must be finite and > 0 m, got {}", self.tolerance)));
        }
        if self.max_steps == 0 {
            return Err(Error::invalid("max_steps", "must be ≥ 1"));
        }
        Ok(())
    }
}

/// The answer for one motion.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionAnswer {
    /// Whether the whole segment is proven free.
    pub valid: bool,
    /// Whether the answer is decided (false: `max_steps` was reached; then `valid` is false).
    pub decided: bool,
    /// The first contact parameter in [0, 1] (within the tolerance), when there is one.
    pub contact: Option<Real>,
    /// The configuration at `contact`.
    pub contact_q: Option<Vec<Real>>,
    /// The pair at `contact`: a geometry and a world object `(g, Some(o))`, or two geometries of a
    /// self pair `(a, None)` with `self_pair`.
    pub pair: Option<(usize, Option<usize>)>,
    /// The self pair at `contact`, as geometry indices.
    pub self_pair: Option<(usize, usize)>,
    /// Advancement steps taken (configurations bounded).
    pub steps: usize,
}

/// The meshes' searches' slack ([`crate::exact::Slack`], module docs): on the MotionBenchMaker
/// Panda's planned edges, 0.2 takes 10 % more steps than exact searches and a fifth less time.
const SLACK: Real = 0.2;

/// The pairs whose proofs end within this fraction of the last step past a new configuration get
/// new bounds there, with the ones that end there (module docs): a pair that would limit the next
/// step is bounded at once, not at a configuration of its own.
const WINDOW: Real = 0.5;

/// Checks joint-space motions of a robot among a world ([`crate::advance`]).
pub struct MotionChecker<'c, 'r> {
    checker: &'c mut RobotChecker<'r>,
    bounds: MotionBounds,
    /// Whether pairs carry their proofs across steps (the default; [`MotionChecker::set_carried_bounds`]).
    carry: bool,
    /// When a motion stops undecided, whatever its steps ([`MotionChecker::set_deadline`]).
    deadline: Option<std::time::Instant>,
    scratch: Scratch,
}

/// A motion's working space, kept between motions (no allocation per step).
#[derive(Default)]
struct Scratch {
    dq: Vec<Real>,
    q: Vec<Real>,
    speed: Vec<Real>,
    /// The pairs that move, with how they close.
    moving: Vec<(PairKey, Closing)>,
    /// Each moving pair's proof so far.
    proofs: Vec<Proof>,
    /// Each geometry's motion bound and the placement it was taken at.
    motion: Vec<(usize, LinkMotion)>,
    /// The moving pairs by the end of their proofs, earliest first.
    heap: BinaryHeap<Expiry>,
    /// Pairs taken off the heap for a new bound (scratch).
    renew: Vec<usize>,
}

/// A world pair `(g, Some(o))` or self pair `(k, None)`.
type PairKey = (usize, Option<usize>);

/// How a moving pair closes: a link against the world, or two links (with the number of moving
/// joints of each chain below their common ancestor, [`MotionBounds::below_common`]).
#[derive(Clone, Copy, Debug)]
enum Closing {
    World(usize),
    Pair((usize, usize), (usize, usize)),
}

/// What is proven of a moving pair: free (no closer than the padding) for every `t` up to
/// `until`, by a bound of `level` taken at placement `stamp` ([`crate::advance`]).
#[derive(Clone, Copy, Debug)]
struct Proof {
    until: Real,
    /// The distance bound taken at `stamp` (less the pair's link padding).
    bound: Real,
    level: u8,
    /// Whether the bound is the meshes' (within the slack) or an exact primitive's: contacts
    /// are reported from these alone.
    exact: bool,
    stamp: usize,
    /// Whether its last bound on the meshes was close (its next goes to the meshes at once).
    near: bool,
}

impl Proof {
    /// Whether the bound is good enough to step by: exact, or the sos root's and not within
    /// `refine_below` (only close pairs need the meshes).
    fn settled(&self, refine_below: Real) -> bool {
        self.exact || self.level >= 2 || (self.level == 1 && self.bound > refine_below)
    }
}

/// A moving pair on the heap: the earliest end of proof first.
#[derive(Clone, Copy, Debug)]
struct Expiry {
    until: Real,
    pair: usize,
}

impl PartialEq for Expiry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Expiry {}
impl PartialOrd for Expiry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Expiry {
    fn cmp(&self, other: &Self) -> Ordering {
        other.until.total_cmp(&self.until).then(other.pair.cmp(&self.pair))
    }
}

/// The settings of one motion the pair bounds need.
#[derive(Clone, Copy)]
struct Levels {
    padding: Real,
    threshold: Real,
    refine_below: Real,
    /// The meshes' searches' slack above the threshold ([`Slack`]).
    slack: Real,
}

impl<'c, 'r> MotionChecker<'c, 'r> {
    /// A motion checker over `checker`'s robot and world; the motion bounds take each link's
    /// radius from its geometries (the farthest point of their bounding balls from the link's
    /// origin).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `robot_id` (the robot of the request) when a geometry's
    /// bounding ball reaches no finite distance from its link's origin (a geometry placed beyond
    /// the coordinate range); otherwise as [`crate::RobotModel::motion_bounds`].
    pub fn new(checker: &'c mut RobotChecker<'r>) -> Result<Self> {
        let robot = checker.robot();
        let mut radius = vec![0.0; robot.model.links().len()];
        for g in &robot.geometries {
            let center = g.origin.transform_point(&g.sphere.0.into());
            let reach = center.coords.norm() + g.sphere.1;
            if !reach.is_finite() {
                let link = &robot.model.links()[g.link].name;
                return Err(Error::invalid(
                    "robot_id",
                    format!(
                        "the robot's geometry `{}` of link `{}` lies beyond the supported range (±1e6 m of its link's origin): its motions cannot be bounded",
                        sublevel_core::error::clip(&g.name),
                        sublevel_core::error::clip(link)
                    ),
                ));
            }
            radius[g.link] = Real::max(radius[g.link], reach);
        }
        let bounds = robot.model.motion_bounds(&radius)?;
        Ok(Self { checker, bounds, carry: true, deadline: None, scratch: Scratch::default() })
    }

    /// The configuration checker the motions are checked with (its robot, world and padding),
    /// for the single configurations a caller checks between motions.
    pub fn checker(&mut self) -> &mut RobotChecker<'r> {
        self.checker
    }

    /// The robot's motion bounds ([`crate::motion`]), as the advancement uses them.
    pub fn bounds(&self) -> &MotionBounds {
        &self.bounds
    }

    /// Turns carried bounds on (the default) or off. On, a pair keeps what it has proven — free
    /// up to some `t` — across steps, only the pairs whose proofs end within half the last step
    /// past the new configuration get new bounds there, and the meshes are searched with a slack
    /// (module docs); off, every moving pair gets a new bound at every step and the meshes'
    /// distances are exact (the reference the carried bounds are tested against). Either way
    /// every step is covered by a valid bound of every pair.
    pub fn set_carried_bounds(&mut self, on: bool) {
        self.carry = on;
    }

    /// Sets the instant past which a motion stops undecided (`decided = false`, `valid = false`,
    /// as at `max_steps`), and so does a motion inside a cancelled
    /// [`sublevel_core::cancel::cancellable`] scope: a planner's deadline reaches into a long
    /// certificate. Looked at every [`STOP_EVERY`] steps; `None` (the default) never stops early.
    pub fn set_deadline(&mut self, deadline: Option<std::time::Instant>) {
        self.deadline = deadline;
    }

    /// Whether the deadline has passed or the thread's cancellation scope is cancelled.
    fn stopped(&self) -> bool {
        self.deadline.is_some_and(|d| std::time::Instant::now() >= d) || sublevel_core::cancel::is_cancelled()
    }

    /// Checks the motion from `q0` to `q1` (radians, meters; continuous joints the shorter way)
    /// with the robot's root at `base`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `q0` / `q1` (length, finiteness), `padding`, `tolerance`
    /// or `max_steps`; the checks' errors.
    pub fn check_motion(
        &mut self,
        q0: &[Real],
        q1: &[Real],
        base: &Isometry3,
        options: &MotionOptions,
    ) -> Result<MotionAnswer> {
        let mut s = std::mem::take(&mut self.scratch);
        let answer = self.advance(&mut s, q0, q1, base, options);
        self.scratch = s;
        answer
    }

    fn advance(
        &mut self,
        s: &mut Scratch,
        q0: &[Real],
        q1: &[Real],
        base: &Isometry3,
        options: &MotionOptions,
    ) -> Result<MotionAnswer> {
        let model = &self.checker.robot().model;
        model.check_configuration("q0", q0)?;
        model.check_configuration("q1", q1)?;
        options.validate()?;
        s.dq.clear();
        s.dq.extend((0..model.dof()).map(|k| {
            let d = q1[k] - q0[k];
            if model.variable_joint(k).kind == JointKind::Continuous {
                let w = d.rem_euclid(2.0 * PI);
                if w > PI {
                    w - 2.0 * PI
                } else {
                    w
                }
            } else {
                d
            }
        }));
        s.speed.clear();
        s.speed.extend((0..model.links().len()).map(|l| self.bounds.displacement(l, &s.dq)));
        let robot = self.checker.robot();
        let mut answer = MotionAnswer {
            valid: false,
            decided: true,
            contact: None,
            contact_q: None,
            pair: None,
            self_pair: None,
            steps: 0,
        };
        let levels = Levels {
            padding: options.padding,
            threshold: options.padding + options.tolerance,
            // Bounds this close are taken on the meshes: a contact is never reported from a
            // loose bound.
            refine_below: options.padding + 10.0 * options.tolerance,
            slack: if self.carry { SLACK } else { 0.0 },
        };
        // The pairs that move, with their links (one for a world pair); the others keep q₀'s
        // verdict.
        s.moving.clear();
        for (g, geometry) in robot.geometries.iter().enumerate() {
            let link = geometry.link;
            if s.speed[link] > 0.0 {
                s.moving.extend(self.checker.world_pairs_of(g).iter().map(|&o| ((g, Some(o)), Closing::World(link))));
            }
        }
        for (k, &(a, b)) in self.checker.self_pairs().iter().enumerate() {
            let links = (robot.geometries[a].link, robot.geometries[b].link);
            let counts = self.bounds.below_common(links.0, links.1);
            if counts != (0, 0) && s.speed[links.0] + s.speed[links.1] > 0.0 {
                s.moving.push(((k, None), Closing::Pair(links, counts)));
            }
        }
        let first = self.checker.check(
            q0,
            base,
            &CheckOptions { padding: levels.threshold, distance: false, self_collision: true, gradient: false },
        )?;
        answer.steps = 1;
        if first.collides {
            answer.contact = Some(0.0);
            answer.contact_q = Some(q0.to_vec());
            answer.pair = first.pair.map(|(g, o)| (g, Some(o))).or(first.self_pair.map(|(a, _)| (a, None)));
            answer.self_pair = if first.world { None } else { first.self_pair };
            return Ok(answer);
        }
        if s.moving.is_empty() {
            answer.valid = true;
            return Ok(answer);
        }
        // Placement 0 is q₀, placed by its check.
        let (mut t, mut stamp): (Real, usize) = (0.0, 0);
        s.q.clear();
        s.q.extend_from_slice(q0);
        s.motion.clear();
        s.motion.resize(self.checker.robot().geometries.len(), (usize::MAX, LinkMotion::default()));
        s.proofs.clear();
        s.proofs.resize(
            s.moving.len(),
            Proof { until: 0.0, bound: 0.0, level: 0, exact: false, stamp: usize::MAX, near: false },
        );
        s.heap.clear();
        for i in 0..s.moving.len() {
            self.renew(s, i, t, stamp, &levels)?;
            s.heap.push(Expiry { until: s.proofs[i].until, pair: i });
        }
        loop {
            let Some(&top) = s.heap.peek() else { unreachable!("the moving pairs are never empty here") };
            if top.until >= 1.0 {
                // Every pair is proven free to the segment's end.
                answer.valid = true;
                return Ok(answer);
            }
            let i = top.pair;
            if !s.proofs[i].settled(levels.refine_below) {
                // The pair that ends the proofs soonest has only a loose bound: tighten it here.
                s.heap.pop();
                if self.renew(s, i, t, stamp, &levels)? {
                    answer.contact = Some(t);
                    answer.contact_q = Some(s.q.clone());
                    match s.moving[i].0 {
                        (g, Some(o)) => answer.pair = Some((g, Some(o))),
                        (k, None) => {
                            let pair = self.checker.self_pairs()[k];
                            answer.pair = Some((pair.0, None));
                            answer.self_pair = Some(pair);
                        }
                    }
                    return Ok(answer);
                }
                s.heap.push(Expiry { until: s.proofs[i].until, pair: i });
                continue;
            }
            // Every pair is free up to `top.until`: step there.
            if answer.steps >= options.max_steps || (answer.steps % STOP_EVERY == 1 && self.stopped()) {
                answer.decided = false;
                return Ok(answer);
            }
            answer.steps += 1;
            let last = top.until - t;
            t = top.until;
            stamp += 1;
            for (q, (a, d)) in s.q.iter_mut().zip(q0.iter().zip(&s.dq)) {
                *q = a + t * d;
            }
            self.checker.place(&s.q, base)?;
            // New bounds for the pairs whose proofs end here, and (carried) for those that
            // would end within another step like the last; the others keep theirs.
            let horizon = if self.carry { t + WINDOW * last } else { Real::INFINITY };
            s.renew.clear();
            while let Some(&e) = s.heap.peek() {
                if e.until > horizon {
                    break;
                }
                s.heap.pop();
                s.renew.push(e.pair);
            }
            for k in 0..s.renew.len() {
                let i = s.renew[k];
                self.renew(s, i, t, stamp, &levels)?;
                s.heap.push(Expiry { until: s.proofs[i].until, pair: i });
            }
        }
    }

    /// A new bound for moving pair `i` at placement `stamp` (parameter `t`): its cheap bound
    /// when its proof was taken at an earlier placement, else the next level; its proof then
    /// ends at the later of the old end and the new bound's. Returns whether the pair is in
    /// contact: a mesh bound within `padding + tolerance` (two triangles that close).
    fn renew(&mut self, s: &mut Scratch, i: usize, t: Real, stamp: usize, levels: &Levels) -> Result<bool> {
        let (pair, closing) = s.moving[i];
        let old = s.proofs[i];
        let checker = &*self.checker;
        let robot = checker.robot();
        let poses = checker.link_poses();
        let ball = |g: usize| (checker.geometry_center(g), robot.geometries[g].sphere.1);
        let m = match (closing, pair) {
            (Closing::World(l), (g, _)) => {
                if s.motion[g].0 != stamp {
                    s.motion[g] = (stamp, self.bounds.at_ball(&robot.model, l, poses, &s.dq, ball(g)));
                }
                s.motion[g].1
            }
            (Closing::Pair(links, counts), (k, _)) => {
                let (a, b) = checker.self_pairs()[k];
                self.bounds.relative_balls(&robot.model, links, counts, poses, &s.dq, (ball(a), ball(b)))
            }
        };
        // The meshes' search stops where the pair cannot close the distance before the end.
        let cap = levels.padding + m.displacement(1.0 - t) * (1.0 + 1e-9) + 1e-12;
        let cap = if cap > levels.threshold {
            levels.threshold + (cap - levels.threshold) / (1.0 - levels.slack)
        } else {
            levels.refine_below
        };
        let fresh = old.stamp == stamp;
        let mut level = if fresh { old.level + 1 } else { 0 };
        if fresh && level == 1 && old.near {
            // Close at its last steps: the sos bound would be too.
            level = 2;
        }
        let cheap = if level == 0 {
            // The ball gap alone, when it lasts to the end.
            let gap = match pair {
                (g, Some(o)) => self.checker.world_ball_gap(g, o) - self.checker.world_extra(g),
                (k, None) => self.checker.self_ball_gap(k) - self.checker.self_extra(k),
            };
            (t + step(gap - levels.padding, &m) >= 1.0).then_some((gap, false))
        } else {
            None
        };
        let (mut bound, mut exact) = match cheap {
            Some(b) => b,
            None => self.bound(pair, level, cap, levels)?,
        };
        if fresh {
            if !exact && level == 1 && bound <= levels.refine_below {
                // Close by the sos bound: on to the meshes at once.
                level = 2;
                (bound, exact) = self.bound(pair, 2, cap, levels)?;
            } else if !exact {
                bound = bound.max(old.bound);
            }
        }
        let near = if level == 2 { bound <= 2.0 * levels.refine_below } else { old.near && level == 0 };
        let until = t + step(bound - levels.padding, &m);
        let until = if self.carry && old.stamp != usize::MAX { until.max(old.until) } else { until };
        s.proofs[i] = Proof { until, bound, level, exact, stamp, near };
        Ok(exact && bound <= levels.threshold)
    }

    /// A pair's bound at `level` ([`RobotChecker::world_bound`], [`RobotChecker::self_bound`]).
    /// Less the pair's link padding ([`RobotChecker::set_link_padding`]): a lower bound of the
    /// distance of the padded shapes, compared with the options' padding like any bound.
    fn bound(&self, pair: (usize, Option<usize>), level: u8, cap: Real, levels: &Levels) -> Result<(Real, bool)> {
        let ((bound, exact), extra) = match pair {
            (g, Some(o)) => {
                let extra = self.checker.world_extra(g);
                let slack = Slack { fraction: levels.slack, floor: levels.threshold + extra };
                (self.checker.world_bound(g, o, level, cap + extra, slack)?, extra)
            }
            (k, None) => {
                let extra = self.checker.self_extra(k);
                let slack = Slack { fraction: levels.slack, floor: levels.threshold + extra };
                (self.checker.self_bound(k, level, cap + extra, slack)?, extra)
            }
        };
        Ok((bound - extra, exact))
    }
}
