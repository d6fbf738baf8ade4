//! Motions certified by conservative advancement: a joint-space segment `q(t) = q₀ + t·Δq`,
//! `t ∈ [0, 1]`, proven free of the world and of self-collision, or its first contact parameter.
//!
//! ```text
//! first: the configuration q₀ checked (pairs whose links do not move keep their verdict throughout)
//! t ← 0
//! loop:  place the geometries at q(t); every moving pair p gets a cheap lower bound b_p of its
//!        distance (ball and box gaps) and the bound of how far it can close in a step of s:
//!            m_L(s) = min(s·D_L, s·A_L + s²·B_L / 2) for a link–world pair, m_a + m_b for a self pair
//!            (counting only the joints below the two links' common ancestor, which alone move them
//!            apart)
//!            D_L = Σ_j c_Lj |Δq_j| over the whole segment, A_L and B_L from the joint axes' distances
//!            to the link at q(t) ([`crate::motion`])
//!        take pairs by their step s_p (the largest s with m(s) ≤ b_p − padding), smallest first;
//!        refine the one taken
//!            ball / box gap → sos root bound → the meshes' exact distance
//!        until the smallest is exact: its ratio is the step Δt (every other pair's ratio is at
//!        least its lower bound's, hence at least Δt)
//!        the exact bound ≤ padding + tolerance            → contact at t (within the tolerance)
//!        t ← t + Δt;  t ≥ 1                                 → the motion is free
//! ```
//!
//! No point of link L moves farther than `m_L(Δt)` during a step (the motion bound,
//! [`crate::motion`]), and a geometry at distance `d_g` from the world cannot touch it before moving
//! `d_g`; two links close by at most `m_a + m_b`, each measured in the frame of their nearest common
//! ancestor (the joints above it move both together).
//! So each step is free, and the steps cover `[0, 1]` with no gap: there is no sampling
//! resolution to choose (Schwarzer, Saha and Latombe, IEEE T-RO 2005). A contact is reported at
//! the first `t` where a bound falls to `padding + tolerance`; the motion is free before it, so the
//! true first contact `t*` is not earlier than the reported one by more than the time it takes to
//! close the tolerance.
//!
//! Continuous joints interpolate along the shorter way round (`Δq` wrapped into (−π, π]).

use crate::check::CheckOptions;
use crate::check::RobotChecker;
use crate::model::JointKind;
use crate::motion::{step, LinkMotion, MotionBounds};
use crate::{Error, Result};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::f64::consts::PI;
use sublevel_core::math::{Isometry3, Real};

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

/// Checks joint-space motions of a robot among a world ([`crate::advance`]).
pub struct MotionChecker<'c, 'r> {
    checker: &'c mut RobotChecker<'r>,
    bounds: MotionBounds,
}

/// A world pair `(g, Some(o))` or self pair `(k, None)` of the refinement queue.
type PairKey = (usize, Option<usize>);

/// How a moving pair closes: a link against the world, or two links (with the number of moving
/// joints of each chain below their common ancestor, [`MotionBounds::below_common`]).
#[derive(Clone, Copy, Debug)]
enum Closing {
    World(usize),
    Pair((usize, usize), (usize, usize)),
}

/// A pair in the refinement queue: smallest ratio first.
struct Queued {
    ratio: Real,
    bound: Real,
    level: u8,
    exact: bool,
    /// How fast the pair can close (the bound of its links' relative motion).
    motion: LinkMotion,
    /// A world pair `(g, Some(o))` or self pair `(k, None)`.
    pair: (usize, Option<usize>),
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.ratio.total_cmp(&other.ratio) == Ordering::Equal
    }
}
impl Eq for Queued {}
impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Queued {
    fn cmp(&self, other: &Self) -> Ordering {
        other.ratio.total_cmp(&self.ratio)
    }
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
        Ok(Self { checker, bounds })
    }

    /// The configuration checker the motions are checked with (its robot, world and padding),
    /// for the single configurations a caller checks between motions.
    pub fn checker(&mut self) -> &mut RobotChecker<'r> {
        self.checker
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
        let model = &self.checker.robot().model;
        model.check_configuration("q0", q0)?;
        model.check_configuration("q1", q1)?;
        options.validate()?;
        let dq: Vec<Real> = (0..model.dof())
            .map(|k| {
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
            })
            .collect();
        let speed: Vec<Real> = (0..model.links().len()).map(|l| self.bounds.displacement(l, &dq)).collect();
        let links = model.links().len();
        let geometries: Vec<usize> = self.checker.robot().geometries.iter().map(|g| g.link).collect();
        let self_pairs = self.checker.self_pairs().to_vec();
        let mut answer = MotionAnswer {
            valid: false,
            decided: true,
            contact: None,
            contact_q: None,
            pair: None,
            self_pair: None,
            steps: 0,
        };
        let threshold = options.padding + options.tolerance;
        // Bounds this close are taken on the meshes: a contact is never reported from a loose
        // bound.
        let refine_below = options.padding + 10.0 * options.tolerance;
        // The pairs that move, with their links (one for a world pair); the others keep q₀'s
        // verdict.
        let mut moving: Vec<(PairKey, Closing)> = Vec::new();
        for (g, &link) in geometries.iter().enumerate() {
            if speed[link] > 0.0 {
                moving.extend(self.checker.world_pairs_of(g).iter().map(|&o| ((g, Some(o)), Closing::World(link))));
            }
        }
        for (k, &(a, b)) in self_pairs.iter().enumerate() {
            let links = (geometries[a], geometries[b]);
            let counts = self.bounds.below_common(links.0, links.1);
            if counts != (0, 0) && speed[links.0] + speed[links.1] > 0.0 {
                moving.push(((k, None), Closing::Pair(links, counts)));
            }
        }
        let mut motion = vec![LinkMotion::default(); links];
        let first = self.checker.check(
            q0,
            base,
            &CheckOptions { padding: threshold, distance: false, self_collision: true, gradient: false },
        )?;
        answer.steps = 1;
        if first.collides {
            answer.contact = Some(0.0);
            answer.contact_q = Some(q0.to_vec());
            answer.pair = first.pair.map(|(g, o)| (g, Some(o))).or(first.self_pair.map(|(a, _)| (a, None)));
            answer.self_pair = if first.world { None } else { first.self_pair };
            return Ok(answer);
        }
        if moving.is_empty() {
            answer.valid = true;
            return Ok(answer);
        }
        let mut t: Real = 0.0;
        let mut q = q0.to_vec();
        let mut heap = BinaryHeap::with_capacity(moving.len());
        loop {
            // Step t ends here: advance to it (q₀ was checked above).
            if t > 0.0 {
                answer.steps += 1;
            }
            for k in 0..q.len() {
                q[k] = q0[k] + t * dq[k];
            }
            self.checker.place(&q, base)?;
            let model = &self.checker.robot().model;
            for (l, m) in motion.iter_mut().enumerate() {
                *m = if speed[l] > 0.0 {
                    self.bounds.at(model, l, self.checker.link_poses(), &dq)
                } else {
                    LinkMotion::default()
                };
            }
            heap.clear();
            for &(pair, closing) in &moving {
                let m = match closing {
                    Closing::World(l) => motion[l],
                    Closing::Pair(links, counts) => {
                        self.bounds.relative(model, links, counts, self.checker.link_poses(), &dq)
                    }
                };
                let (bound, exact) = self.bound(pair, 0)?;
                heap.push(Queued { ratio: step(bound - options.padding, &m), bound, level: 0, exact, motion: m, pair });
            }
            let limiting = loop {
                let Some(mut top) = heap.pop() else { break None };
                // A bound is good enough for a step once it is the sos root's and not close: only
                // pairs within `refine_below` need the meshes.
                if top.exact || top.level >= 2 || (top.level == 1 && top.bound > refine_below) {
                    break Some(top);
                }
                // Refine: the sos bound, then the meshes (at once where the sos bound is close).
                top.level += 1;
                let (bound, exact) = self.bound(top.pair, top.level)?;
                let (bound, exact) = if !exact && top.level == 1 && bound <= refine_below {
                    top.level = 2;
                    self.bound(top.pair, 2)?
                } else {
                    (bound.max(top.bound), exact)
                };
                top.bound = bound;
                top.exact = exact;
                top.ratio = step(bound - options.padding, &top.motion);
                heap.push(top);
            };
            let Some(limit) = limiting else {
                answer.valid = true;
                return Ok(answer);
            };
            if limit.bound <= threshold {
                answer.contact = Some(t);
                answer.contact_q = Some(q);
                match limit.pair {
                    (g, Some(o)) => answer.pair = Some((g, Some(o))),
                    (k, None) => {
                        answer.pair = Some((self_pairs[k].0, None));
                        answer.self_pair = Some(self_pairs[k]);
                    }
                }
                return Ok(answer);
            }
            if t >= 1.0 {
                answer.valid = true;
                return Ok(answer);
            }
            if answer.steps >= options.max_steps {
                answer.decided = false;
                return Ok(answer);
            }
            t = (t + limit.ratio).min(1.0);
        }
    }

    /// A pair's bound at `level` ([`RobotChecker::world_bound`], [`RobotChecker::self_bound`]).
    /// Less the pair's link padding ([`RobotChecker::set_link_padding`]): a lower bound of the
    /// distance of the padded shapes, compared with the options' padding like any bound.
    fn bound(&self, pair: (usize, Option<usize>), level: u8) -> Result<(Real, bool)> {
        let ((bound, exact), extra) = match pair {
            (g, Some(o)) => (self.checker.world_bound(g, o, level)?, self.checker.world_extra(g)),
            (k, None) => (self.checker.self_bound(k, level)?, self.checker.self_extra(k)),
        };
        Ok((bound - extra, exact))
    }
}
