//! What a planner asks of a collision checker: whether a configuration is free, whether a
//! straight joint-space segment is free at a sampling resolution (the search's edges), and
//! whether a segment is *proven* free (the returned path's edges, certified).
//!
//! [`RobotValidity`] answers all three for a fitted robot among a world: states by
//! [`sublevel_robot::RobotChecker::check`] (the verdict alone, no distance), sampled edges in
//! rakes of [`sublevel_robot::BLOCK`] samples spread along the edge
//! ([`sublevel_robot::rake_order`], [`sublevel_robot::RobotChecker::any_collision`]), certified
//! edges by conservative advancement ([`sublevel_robot::MotionChecker::check_motion`]). Other
//! checkers sample their edges one configuration at a time, as OMPL's discrete motion validator
//! orders them ([`sampled_edge_free`]).

use crate::space::JointSpace;
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::Result;
use sublevel_robot::{rake_order, CheckOptions, MotionChecker, MotionOptions, RobotModel, BLOCK};

/// The answer of a certified edge check.
#[derive(Clone, Debug, PartialEq)]
pub enum Certificate {
    /// The whole segment is proven free at the padding.
    Free,
    /// The first contact (within the tolerance) at this segment parameter in [0, 1].
    Contact(Real),
    /// The check ran out of steps before deciding.
    Undecided,
}

/// Counts of the checks a plan made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CheckCounts {
    /// Configurations checked (alone or as an edge's samples).
    pub states: usize,
    /// Edges checked by sampling (their samples count in `states`).
    pub edges: usize,
    /// Edges checked by conservative advancement.
    pub edges_certified: usize,
    /// Advancement steps of the certified edges (configurations bounded).
    pub advancement_steps: usize,
}

/// A collision checker for planners (module docs).
pub trait Validity {
    /// The space the configurations live in.
    fn space(&self) -> &JointSpace;

    /// Whether configuration `q` is free.
    ///
    /// # Errors
    /// The checker's errors (a malformed configuration names its field).
    fn state_free(&mut self, q: &[Real]) -> Result<bool>;

    /// Whether the segment from `a` to `b` is free at `resolution` samples per unit of joint
    /// distance: `b` and the interior samples are checked (`a` is known free), ordered so that a
    /// collision anywhere is met early (the default: one at a time in [`sample_order`]; a checker
    /// may take the same samples in another order, or several at once, for the same verdict).
    ///
    /// # Errors
    /// As [`Validity::state_free`].
    fn edge_free(&mut self, a: &[Real], b: &[Real], resolution: Real) -> Result<bool> {
        sampled_edge_free(self, a, b, resolution)
    }

    /// Whether the segment from `a` to `b` is proven free at the checker's padding, with
    /// contacts reported within `tolerance` meters.
    ///
    /// # Errors
    /// As [`Validity::state_free`].
    fn certify(&mut self, a: &[Real], b: &[Real], tolerance: Real) -> Result<Certificate>;

    /// Whether every configuration within `tube[k]` of the segment from `a` to `b` in every entry
    /// k (radians or meters, ≥ 0) is proven free at the checker's padding, with contacts
    /// reported within `tolerance` meters: a blend of a timed trajectory lies in such a tube
    /// around its chords ([`crate::trajectory::certify_blends`]). The default proves the
    /// segment alone when the tube is empty (every entry 0) and answers
    /// [`Certificate::Undecided`] otherwise.
    ///
    /// # Errors
    /// As [`Validity::state_free`].
    fn certify_tube(&mut self, a: &[Real], b: &[Real], tube: &[Real], tolerance: Real) -> Result<Certificate> {
        if tube.iter().all(|&w| w == 0.0) {
            self.certify(a, b, tolerance)
        } else {
            Ok(Certificate::Undecided)
        }
    }

    /// Whether every configuration within `tube[k]` of `center` in every entry k (a box,
    /// radians or meters, ≥ 0) is proven free at the checker's padding: one check of `center`
    /// with the padding grown by what the box can move the links. The default proves the box
    /// only when it is a point (every entry 0).
    ///
    /// # Errors
    /// As [`Validity::state_free`].
    fn box_free(&mut self, center: &[Real], tube: &[Real]) -> Result<bool> {
        if tube.iter().all(|&w| w == 0.0) {
            self.state_free(center)
        } else {
            Ok(false)
        }
    }

    /// The counts of the checks made so far.
    fn counts(&self) -> CheckCounts;

    /// Why `q` collides, in words (the colliding pair), or `None` when it is free.
    ///
    /// # Errors
    /// As [`Validity::state_free`].
    fn collision(&mut self, q: &[Real]) -> Result<Option<String>>;

    /// Sets the extra clearance (meters, ≥ 0) that [`Validity::state_free`] and the sampled edges
    /// ask for on top of the padding, while the certificates keep the padding alone (a checker
    /// with no notion of clearance ignores it).
    fn set_search_margin(&mut self, _margin: Real) {}

    /// The robot's kinematic model and base pose, for pose goals (inverse kinematics); `None` for
    /// a checker with no robot behind it.
    fn kinematics(&mut self) -> Option<(&RobotModel, Isometry3)> {
        None
    }

    /// Sets the instant past which the checker's long answers stop early, conservatively: a
    /// sampled edge not yet proven colliding answers "not free" and a certificate
    /// [`Certificate::Undecided`], so that the planner sees its deadline within one block of
    /// samples (or a few advancement steps) rather than at the end of an edge of any length. A
    /// checker whose answers are all short ignores it; `None` never stops early.
    fn set_deadline(&mut self, _deadline: Option<Instant>) {}
}

/// The sampled edge test of [`Validity::edge_free`]: the samples of `a → b` at `resolution` per
/// unit of joint distance, `b` first, in [`sample_order`], each by [`Validity::state_free`].
///
/// # Errors
/// As [`Validity::state_free`].
pub fn sampled_edge_free<V: Validity + ?Sized>(
    checker: &mut V,
    a: &[Real],
    b: &[Real],
    resolution: Real,
) -> Result<bool> {
    let n = ((checker.space().distance(a, b) * resolution).ceil() as usize).max(1);
    let mut q = Vec::with_capacity(a.len());
    for i in sample_order(n) {
        checker.space().interpolate(a, b, i as Real / n as Real, &mut q);
        if !checker.state_free(&q)? {
            return Ok(false);
        }
    }
    Ok(true)
}

/// `1..=n` in the order OMPL's discrete motion validator checks a segment's samples: the end
/// first, then each next index halving the largest gap left.
pub fn sample_order(n: usize) -> Vec<usize> {
    let mut order = vec![n];
    let mut seen = vec![false; n + 1];
    seen[n] = true;
    let mut step = n;
    while step > 1 {
        step = step.div_ceil(2);
        for k in (step..n).step_by(step) {
            if !std::mem::replace(&mut seen[k], true) {
                order.push(k);
            }
        }
    }
    order.extend((1..n).filter(|&k| !seen[k]));
    order
}

/// A fitted robot among a world, as a planner's checker (module docs).
pub struct RobotValidity<'c, 'r> {
    motion: MotionChecker<'c, 'r>,
    space: JointSpace,
    base: Isometry3,
    padding: Real,
    margin: Real,
    max_steps: usize,
    /// Past it, edges answer "not free" and certificates undecided ([`Validity::set_deadline`]).
    deadline: Option<Instant>,
    counts: CheckCounts,
    /// The samples of one rake, row by row (reused).
    block: Vec<Real>,
    /// One sample (reused).
    sample: Vec<Real>,
}

impl<'c, 'r> RobotValidity<'c, 'r> {
    /// The checker of `motion`'s robot and world with the robot's root at `base`, every geometry
    /// padded by `padding` meters (≥ 0; on top of the checker's link padding).
    pub fn new(mut motion: MotionChecker<'c, 'r>, base: Isometry3, padding: Real) -> Self {
        let space = JointSpace::of(&motion.checker().robot().model);
        Self {
            motion,
            space,
            base,
            padding,
            margin: 0.0,
            max_steps: 100_000,
            deadline: None,
            counts: CheckCounts::default(),
            block: Vec::new(),
            sample: Vec::new(),
        }
    }
}

impl RobotValidity<'_, '_> {
    /// `2 · max_L D_L(tube)`: how much closer any two geometries, or a geometry and the world,
    /// can come within a joint-space box of half-widths `tube` (meters).
    fn inflation(&mut self, tube: &[Real]) -> Real {
        let links = self.motion.checker().robot().model.links().len();
        let bounds = self.motion.bounds();
        2.0 * (0..links).map(|l| bounds.displacement(l, tube)).fold(0.0, Real::max)
    }

    /// Holds every configuration entry not in `moving` at its value in `at` (the start): the plan
    /// moves only the `moving` joints, as MoveIt plans only its planning group's
    /// ([`JointSpace::hold`]).
    pub fn hold_all_but(&mut self, moving: &[bool], at: &[Real]) {
        for (k, (&m, &v)) in moving.iter().zip(at).enumerate() {
            if !m {
                self.space.hold(k, v);
            }
        }
    }

    /// Whether the deadline has passed or the thread's cancellation scope is cancelled.
    fn stopped(&self) -> bool {
        self.deadline.is_some_and(|d| Instant::now() >= d) || sublevel_core::cancel::is_cancelled()
    }
}

impl Validity for RobotValidity<'_, '_> {
    fn space(&self) -> &JointSpace {
        &self.space
    }

    fn state_free(&mut self, q: &[Real]) -> Result<bool> {
        self.counts.states += 1;
        let padding = self.padding + self.margin;
        let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
        Ok(!self.motion.checker().check(q, &self.base, &options)?.collides)
    }

    /// The samples of [`sampled_edge_free`] (the same configurations: `n = max(1, ⌈distance ·
    /// resolution⌉)`, t = i / n for i = 1..=n, made by [`JointSpace::interpolate`], so continuous
    /// joints take the shorter way round), checked in rakes: blocks of [`BLOCK`] samples in
    /// [`rake_order`], each by [`sublevel_robot::RobotChecker::any_collision`] at the padding
    /// plus the search margin, stopping at the first block that holds a colliding sample. The
    /// verdict is the one-at-a-time check's; only the order of the samples differs (the first
    /// block already spans the whole edge). The samples are made here rather than by
    /// [`sublevel_robot::RobotChecker::rake_motion`], whose linear interpolation would take a
    /// continuous joint the long way round. `counts.states` grows by every sample of the blocks
    /// checked (a colliding block's in full).
    ///
    /// # Errors
    /// [`sublevel_core::Error::InvalidArgument`] naming `start` / `end` (a length other than the
    /// robot's entries, a value that is not finite); the checker's errors.
    ///
    /// Past the deadline ([`Validity::set_deadline`]) or in a cancelled
    /// [`sublevel_core::cancel::cancellable`] scope, the edge answers "not free" before its next
    /// block: an edge of 10⁵ samples never outlives its plan.
    fn edge_free(&mut self, a: &[Real], b: &[Real], resolution: Real) -> Result<bool> {
        self.counts.edges += 1;
        let model = &self.motion.checker().robot().model;
        model.check_configuration("start", a)?;
        model.check_configuration("end", b)?;
        let n = ((self.space.distance(a, b) * resolution).ceil() as usize).max(1);
        let padding = self.padding + self.margin;
        for rake in rake_order(n, BLOCK).chunks(BLOCK) {
            if self.stopped() {
                return Ok(false);
            }
            self.block.clear();
            for &i in rake {
                self.space.interpolate(a, b, i as Real / n as Real, &mut self.sample);
                self.block.extend_from_slice(&self.sample);
            }
            self.counts.states += rake.len();
            if self.motion.checker().any_collision(&self.block, &self.base, padding)? {
                return Ok(false);
            }
        }
        Ok(true)
    }

    fn certify(&mut self, a: &[Real], b: &[Real], tolerance: Real) -> Result<Certificate> {
        self.counts.edges_certified += 1;
        let options = MotionOptions { padding: self.padding, tolerance, max_steps: self.max_steps };
        self.motion.set_deadline(self.deadline);
        let answer = self.motion.check_motion(a, b, &self.base, &options)?;
        self.counts.advancement_steps += answer.steps;
        Ok(match (answer.valid, answer.decided, answer.contact) {
            (true, _, _) => Certificate::Free,
            (false, true, Some(t)) => Certificate::Contact(t),
            _ => Certificate::Undecided,
        })
    }

    /// The segment certified with every geometry padded by `2 · max_L D_L(tube)` more, `D_L` the
    /// configuration-free motion bound of link L ([`sublevel_robot::MotionBounds::displacement`]):
    /// no point of a link is farther than `D_L(tube)` from where it is at the nearest
    /// configuration of the segment, so a world pair closes by at most one link's bound and a
    /// self pair by two.
    fn certify_tube(&mut self, a: &[Real], b: &[Real], tube: &[Real], tolerance: Real) -> Result<Certificate> {
        let model = &self.motion.checker().robot().model;
        if tube.len() != model.dof() {
            return Err(sublevel_core::Error::invalid(
                "tube",
                format!("{} values for {} configuration entries", tube.len(), model.dof()),
            ));
        }
        let inflation = self.inflation(tube);
        let padding = self.padding;
        self.padding = padding + inflation;
        let answer = self.certify(a, b, tolerance);
        self.padding = padding;
        answer
    }

    /// `center` checked with every geometry padded by `2 · max_L D_L(tube)` more (as
    /// [`Validity::certify_tube`]): no configuration of the box moves a link farther than
    /// `D_L(tube)` from where it is at `center`.
    fn box_free(&mut self, center: &[Real], tube: &[Real]) -> Result<bool> {
        let model = &self.motion.checker().robot().model;
        if tube.len() != model.dof() {
            return Err(sublevel_core::Error::invalid(
                "tube",
                format!("{} values for {} configuration entries", tube.len(), model.dof()),
            ));
        }
        self.counts.states += 1;
        let padding = self.padding + self.inflation(tube);
        let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
        Ok(!self.motion.checker().check(center, &self.base, &options)?.collides)
    }

    fn counts(&self) -> CheckCounts {
        self.counts
    }

    fn collision(&mut self, q: &[Real]) -> Result<Option<String>> {
        let options = CheckOptions { padding: self.padding, distance: false, self_collision: true, gradient: false };
        let checker = self.motion.checker();
        let answer = checker.check(q, &self.base, &options)?;
        if !answer.collides {
            return Ok(None);
        }
        let robot = checker.robot();
        let geometry = |g: usize| {
            let geometry = &robot.geometries[g];
            format!("link `{}` (geometry `{}`)", robot.model.links()[geometry.link].name, geometry.name)
        };
        Ok(Some(match (answer.pair, answer.self_pair) {
            (Some((g, o)), _) if answer.world => {
                format!("{} collides with object `{}`", geometry(g), checker.world()[o].name)
            }
            (_, Some((a, b))) => format!("{} collides with {}", geometry(a), geometry(b)),
            _ => "the robot collides".to_string(),
        }))
    }

    fn set_search_margin(&mut self, margin: Real) {
        self.margin = margin;
    }

    fn set_deadline(&mut self, deadline: Option<Instant>) {
        self.deadline = deadline;
    }

    fn kinematics(&mut self) -> Option<(&RobotModel, Isometry3)> {
        let base = self.base;
        Some((&self.motion.checker().robot().model, base))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_order_visits_every_index_once_end_first_then_halving() {
        for n in 1..200 {
            let order = sample_order(n);
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (1..=n).collect::<Vec<_>>(), "n = {n}");
            assert_eq!(order[0], n);
        }
        assert_eq!(sample_order(8), vec![8, 4, 2, 6, 1, 3, 5, 7]);
    }
}
