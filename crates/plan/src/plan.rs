//! One planning request answered: the request checked, the goals made configurations, the
//! search, the simplification and the certification, each timed (see the crate docs).

use crate::certify::{certify_path, CertifySettings};
use crate::rrt::{connect, Budget, SearchSettings, SearchStop};
use crate::simplify::{simplify, SimplifySettings};
use crate::space::{HaltonSampler, JointSpace};
use crate::validity::{CheckCounts, Validity};
use rand::{Rng, SeedableRng};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};
use sublevel_robot::ik::{IkSettings, IkSolver, PoseGoal};

/// The longest timeout of a plan.
pub const MAX_TIMEOUT: Duration = Duration::from_secs(3600);

/// The largest sampling resolution of the search's edges (samples per unit of joint distance):
/// 30 times VAMP's 32, far finer than any obstacle needs, and an edge across a 7-joint robot's
/// whole range still lists under 10⁵ samples.
pub const MAX_RESOLUTION: Real = 1000.0;

/// The largest contact tolerance of the certificates (meters).
pub const MAX_TOLERANCE: Real = 0.1;

/// The largest padding around the robot's geometries (meters).
pub const MAX_PADDING: Real = 1.0;

/// The most goal configurations a goal tree is rooted at, and the most a request may give.
pub const MAX_GOALS: usize = 64;

/// The most corner-cutting passes of the simplification.
pub const MAX_SMOOTHING_PASSES: usize = 8;

/// The most shortcut tries of the simplification.
pub const MAX_SHORTCUT_ATTEMPTS: usize = 1024;

/// Planner settings; [`PlanSettings::default`] gives the service's defaults.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanSettings {
    /// The time the whole plan may take: goals, search, simplification and certification
    /// (> 0; default 1 s).
    pub timeout: Duration,
    /// The seed of the sampler and of the simplification's random choices: the same request with
    /// the same seed on the same checker gives the same path (default 1).
    pub seed: u64,
    /// The longest step of an extension (joint-space distance, > 0; default 1.0).
    pub range: Real,
    /// Samples per unit of joint-space distance on the search's edges (> 0; default 32, VAMP's).
    pub resolution: Real,
    /// The chance that a round of the search draws a goal instead of a sample ([0, 1); default
    /// 0.05).
    pub goal_bias: Real,
    /// Padding around every robot geometry (meters, ≥ 0; default 0): the path keeps this clearance.
    pub padding: Real,
    /// Whether the path is simplified (default true).
    pub simplify: bool,
    /// Most shortcut tries of the simplification (default 16).
    pub shortcut_attempts: usize,
    /// Corner-cutting passes after the shortcuts (default 0: none).
    pub smoothing_passes: usize,
    /// Contact tolerance of the edges' certificates (meters, > 0; default 1 mm).
    pub tolerance: Real,
    /// Most goal configurations the goal tree is rooted at (≥ 1; default 8): the joint goals
    /// given first, then samples of a goal region or inverse kinematics solutions.
    pub max_goals: usize,
    /// Extra clearance the search and the simplification keep (meters, ≥ 0; default 2 mm) when
    /// the start and a goal have it, so that the path stays clear of the obstacles and its
    /// certificates take few steps; 0 when an end is closer (the certificates always use the
    /// padding alone).
    pub search_margin: Real,
    /// Whether the search keeps dynamic domains (default true; [`crate::rrt`]).
    pub dynamic_domain: bool,
    /// Whether the search lets a tree of at most half the other's size keep the turn (default true;
    /// [`crate::rrt`]).
    pub balance: bool,
}

impl Default for PlanSettings {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(1),
            seed: 1,
            range: 1.0,
            resolution: 32.0,
            goal_bias: 0.05,
            padding: 0.0,
            simplify: true,
            shortcut_attempts: 16,
            smoothing_passes: 0,
            tolerance: 1e-3,
            max_goals: 8,
            search_margin: 2e-3,
            dynamic_domain: true,
            balance: true,
        }
    }
}

impl PlanSettings {
    /// Checks the settings: every one that sizes the work is bounded ([`MAX_TIMEOUT`],
    /// [`MAX_RESOLUTION`], [`MAX_GOALS`], [`MAX_SMOOTHING_PASSES`], [`MAX_SHORTCUT_ATTEMPTS`]),
    /// and the lengths are physical ([`MAX_TOLERANCE`], [`MAX_PADDING`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the setting out of its range (`timeout`, `range`,
    /// `resolution`, `goal_bias`, `padding`, `tolerance`, `max_goals`, `smoothing_passes`,
    /// `shortcut_attempts`, `search_margin`).
    pub fn validate(&self) -> Result<()> {
        let positive = |field: &str, v: Real, unit: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(
                    field,
                    format!("must be finite and > 0{unit}, got {}", sublevel_core::error::show_real(v)),
                ))
            }
        };
        let at_most = |field: &str, v: Real, max: Real, unit: &str| {
            if v <= max {
                Ok(())
            } else {
                Err(Error::invalid(
                    field,
                    format!("must be at most {max}{unit}, got {}", sublevel_core::error::show_real(v)),
                ))
            }
        };
        if self.timeout.is_zero() {
            return Err(Error::invalid("timeout", "must be > 0 s: a plan needs time to check its ends"));
        }
        if self.timeout > MAX_TIMEOUT {
            return Err(Error::invalid(
                "timeout",
                format!("must be at most {} s, got {} s", MAX_TIMEOUT.as_secs(), self.timeout.as_secs_f64()),
            ));
        }
        positive("range", self.range, "")?;
        positive("resolution", self.resolution, " samples per unit of joint distance")?;
        // The samples of one edge are listed before they are checked: bounded with the resolution.
        at_most("resolution", self.resolution, MAX_RESOLUTION, " samples per unit of joint distance")?;
        positive("tolerance", self.tolerance, " m")?;
        at_most("tolerance", self.tolerance, MAX_TOLERANCE, " m")?;
        if !(self.goal_bias.is_finite() && (0.0..1.0).contains(&self.goal_bias)) {
            return Err(Error::invalid(
                "goal_bias",
                format!("must be in [0, 1), got {}", sublevel_core::error::show_real(self.goal_bias)),
            ));
        }
        if !(self.padding.is_finite() && self.padding >= 0.0) {
            return Err(Error::invalid(
                "padding",
                format!("must be finite and ≥ 0 m, got {}", sublevel_core::error::show_real(self.padding)),
            ));
        }
        at_most("padding", self.padding, MAX_PADDING, " m")?;
        if !(1..=MAX_GOALS).contains(&self.max_goals) {
            return Err(Error::invalid("max_goals", format!("must be in [1, {MAX_GOALS}], got {}", self.max_goals)));
        }
        if self.smoothing_passes > MAX_SMOOTHING_PASSES {
            return Err(Error::invalid(
                "smoothing_passes",
                format!("must be at most {MAX_SMOOTHING_PASSES}, got {}", self.smoothing_passes),
            ));
        }
        if self.shortcut_attempts > MAX_SHORTCUT_ATTEMPTS {
            return Err(Error::invalid(
                "shortcut_attempts",
                format!("must be at most {MAX_SHORTCUT_ATTEMPTS}, got {}", self.shortcut_attempts),
            ));
        }
        if !(self.search_margin.is_finite() && self.search_margin >= 0.0) {
            return Err(Error::invalid(
                "search_margin",
                format!("must be finite and ≥ 0 m, got {}", self.search_margin),
            ));
        }
        Ok(())
    }
}

/// A goal region in joint space: every entry within its tolerances of a center (MoveIt's joint
/// constraints).
#[derive(Clone, Debug, PartialEq)]
pub struct JointRegion {
    /// The center configuration.
    pub center: Vec<Real>,
    /// How far below the center each entry may be (≥ 0, radians or meters).
    pub below: Vec<Real>,
    /// How far above the center each entry may be (≥ 0).
    pub above: Vec<Real>,
}

/// How the plan ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PlanStatus {
    /// A path, every edge certified.
    Solved,
    /// The deadline passed before a path was found, or before every edge of the path found was
    /// certified (then the path is returned, uncertified).
    TimedOut,
    /// The start configuration collides: the pair, in words.
    StartInCollision(String),
    /// Every goal configuration collides: the first's pair, in words.
    GoalInCollision(String),
    /// No goal configuration exists (inverse kinematics found none): why, in words.
    GoalUnreachable(String),
    /// The plan was cancelled.
    Cancelled,
}

/// Time spent in each stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanTiming {
    /// Checking the ends and making the goal configurations.
    pub goals: Duration,
    /// The RRT-Connect search.
    pub search: Duration,
    /// The simplification.
    pub simplify: Duration,
    /// The certification and the repairs.
    pub certify: Duration,
}

/// The answer to a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanOutcome {
    /// How the plan ended.
    pub status: PlanStatus,
    /// The path, start first (empty with no path); rows of configuration entries (radians,
    /// meters).
    pub path: Vec<Vec<Real>>,
    /// Its joint-space length (0 with no path).
    pub length: Real,
    /// Whether every edge of the path is proven free (conservative advancement).
    pub certified: bool,
    /// The edges (`path[i] → path[i+1]`) left unproven.
    pub unproven: Vec<usize>,
    /// Which of the goal configurations the path reaches.
    pub goal: Option<Vec<Real>>,
    /// Time per stage.
    pub timing: PlanTiming,
    /// Checks made.
    pub counts: CheckCounts,
    /// Nodes of the search's two trees.
    pub nodes: usize,
    /// Edges the certification repaired.
    pub repaired: usize,
}

impl PlanOutcome {
    /// The outcome of a plan whose time ran out before it found anything: TIMED_OUT, no path, no
    /// check made.
    pub fn timed_out() -> Self {
        Self {
            status: PlanStatus::TimedOut,
            path: Vec::new(),
            length: 0.0,
            certified: false,
            unproven: Vec::new(),
            goal: None,
            timing: PlanTiming::default(),
            counts: CheckCounts::default(),
            nodes: 0,
            repaired: 0,
        }
    }
}

/// What a plan is asked for.
#[derive(Clone, Debug, PartialEq)]
pub enum Goal {
    /// One or more goal configurations: the path reaches one of them.
    Configurations(Vec<Vec<Real>>),
    /// Any configuration of a joint region: its center first, then samples inside it.
    Region(JointRegion),
    /// A link at a pose: goal configurations by inverse kinematics ([`sublevel_robot::ik`]),
    /// seeded with the start, each checked for collision; the checker must have a robot
    /// ([`Validity::kinematics`]).
    Pose(PoseGoal),
}

/// Checks a configuration against `space`: its length, finite entries, inside the bounds of
/// every entry that does not wrap.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field` (the length) or `field[k]`.
pub fn check_configuration(space: &JointSpace, field: &str, q: &[Real]) -> Result<()> {
    if q.len() != space.dof() {
        return Err(Error::invalid(
            field,
            format!("has {} entries, the robot {} joint variables", q.len(), space.dof()),
        ));
    }
    for (k, (&v, &(lo, hi))) in q.iter().zip(&space.bounds).enumerate() {
        if !v.is_finite() {
            return Err(Error::invalid(format!("{field}[{k}]"), format!("must be finite, got {v}")));
        }
        if !space.wraps[k] && !(lo..=hi).contains(&v) {
            return Err(Error::invalid(
                format!("{field}[{k}]"),
                format!("{v} is outside the joint's limits [{lo}, {hi}]"),
            ));
        }
    }
    Ok(())
}

/// Plans from `start` to `goal` on `checker` (the crate docs); `cancel` stops it early. Goal
/// configurations beyond those given (region samples) are drawn from the seed, so the answer is
/// reproducible.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `start`, `goal...` or a setting; the checker's errors.
pub fn plan(
    checker: &mut dyn Validity,
    start: &[Real],
    goal: &Goal,
    settings: &PlanSettings,
    cancel: &AtomicBool,
) -> Result<PlanOutcome> {
    settings.validate()?;
    let clock = Instant::now();
    let deadline = clock + settings.timeout;
    checker.set_deadline(Some(deadline));
    let answer = plan_within(checker, start, goal, settings, cancel, clock, deadline);
    checker.set_deadline(None);
    answer
}

/// [`plan`] once its settings are checked and its checker knows the deadline.
fn plan_within(
    checker: &mut dyn Validity,
    start: &[Real],
    goal: &Goal,
    settings: &PlanSettings,
    cancel: &AtomicBool,
    clock: Instant,
    deadline: Instant,
) -> Result<PlanOutcome> {
    let space = checker.space().clone();
    check_configuration(&space, "start", start)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(settings.seed);
    let ik = match goal {
        Goal::Pose(pose) => {
            let (model, base) = checker
                .kinematics()
                .ok_or_else(|| Error::invalid("goal.pose", "this checker has no robot: pose goals need one"))?;
            pose.validate(model)?;
            Some((model.clone(), base))
        }
        _ => None,
    };
    let candidates = match (goal, &ik) {
        (Goal::Pose(pose), Some((model, base))) => {
            // Restarts until the deadline rather than a fixed few: where most solutions collide
            // (a hand inside a cage), free ones are rare, not absent.
            let ik = IkSettings { random_seeds: POSE_GOAL_RESTARTS, ..IkSettings::default() };
            let mut solver = IkSolver::new(model, base, pose, &[start.to_vec()], &ik)?;
            solver.set_deadline(deadline);
            pose_candidates(checker, &mut solver, settings.max_goals, deadline, &mut rng)?
        }
        _ => goal_candidates(&space, goal, settings.max_goals, &mut rng)?,
    };
    let mut outcome = PlanOutcome::timed_out();
    let finish = |mut o: PlanOutcome, checker: &dyn Validity| {
        o.counts = checker.counts();
        o
    };
    if let Some(why) = checker.collision(start)? {
        outcome.status = PlanStatus::StartInCollision(why);
        outcome.timing.goals = clock.elapsed();
        return Ok(finish(outcome, checker));
    }
    // Every candidate is checked, and the first `max_goals` free ones kept: colliding goals
    // given first never hide a free one behind them.
    let mut goals = Vec::new();
    let mut first_collision = None;
    for q in candidates {
        if goals.len() == settings.max_goals {
            break;
        }
        match checker.collision(&q)? {
            None => goals.push(q),
            Some(why) => {
                first_collision.get_or_insert(why);
            }
        }
    }
    outcome.timing.goals = clock.elapsed();
    if goals.is_empty() {
        outcome.status = match first_collision {
            Some(why) => PlanStatus::GoalInCollision(why),
            None => PlanStatus::GoalUnreachable(
                "inverse kinematics found no configuration within the pose goal's tolerances (the start and \
                 random restarts tried)"
                    .into(),
            ),
        };
        return Ok(finish(outcome, checker));
    }
    plan_to(checker, start, goals, settings, &mut rng, deadline, cancel, outcome).map(|o| finish(o, checker))
}

/// The search, simplification and certification from a free `start` to free `goals`.
#[allow(clippy::too_many_arguments)]
fn plan_to(
    checker: &mut dyn Validity,
    start: &[Real],
    goals: Vec<Vec<Real>>,
    settings: &PlanSettings,
    rng: &mut impl Rng,
    deadline: Instant,
    cancel: &AtomicBool,
    mut outcome: PlanOutcome,
) -> Result<PlanOutcome> {
    let search = SearchSettings {
        range: settings.range,
        resolution: settings.resolution,
        goal_bias: settings.goal_bias,
        dynamic_domain: settings.dynamic_domain,
        balance: settings.balance,
    };
    // The margin when the start and some goal keep it (only those goals then), else none.
    let mut goals = goals;
    if settings.search_margin > 0.0 {
        checker.set_search_margin(settings.search_margin);
        let mut kept = Vec::new();
        if checker.state_free(start)? {
            for g in &goals {
                if checker.state_free(g)? {
                    kept.push(g.clone());
                }
            }
        }
        if kept.is_empty() {
            checker.set_search_margin(0.0);
        } else {
            goals = kept;
        }
    }
    let mut sampler = HaltonSampler::new(start.len(), rng);
    let clock = Instant::now();
    let budget = Budget { deadline, cancel };
    let found = connect(checker, start, &goals, &search, &mut sampler, rng, budget)?;
    outcome.timing.search = clock.elapsed();
    let found = match found {
        Ok(found) => found,
        Err(SearchStop::Deadline) => {
            checker.set_search_margin(0.0);
            return Ok(outcome);
        }
        Err(SearchStop::Cancelled) => {
            checker.set_search_margin(0.0);
            outcome.status = PlanStatus::Cancelled;
            return Ok(outcome);
        }
    };
    outcome.nodes = found.nodes;
    outcome.goal = Some(goals[found.goal].clone());
    let mut path = found.path;
    if settings.simplify {
        let clock = Instant::now();
        let s = SimplifySettings {
            resolution: settings.resolution,
            shortcut_attempts: settings.shortcut_attempts,
            smoothing_passes: settings.smoothing_passes,
        };
        path = simplify(checker, path, &s, rng, deadline)?;
        outcome.timing.simplify = clock.elapsed();
    }
    checker.set_search_margin(0.0);
    let clock = Instant::now();
    let c = CertifySettings { tolerance: settings.tolerance, max_depth: 4, search };
    let certified = certify_path(checker, &path, &c, rng, budget)?;
    outcome.timing.certify = clock.elapsed();
    outcome.certified = certified.unproven.is_empty();
    outcome.status = if outcome.certified {
        PlanStatus::Solved
    } else if cancel.load(std::sync::atomic::Ordering::Relaxed) {
        PlanStatus::Cancelled
    } else {
        PlanStatus::TimedOut
    };
    outcome.unproven = certified.unproven;
    outcome.repaired = certified.repaired;
    outcome.length = checker.space().length(&certified.path);
    outcome.path = certified.path;
    Ok(outcome)
}

/// Random restarts of the inverse kinematics of a pose goal (each about 0.2 ms on the Panda; the
/// plan's deadline stops them first).
const POSE_GOAL_RESTARTS: usize = 5000;

/// Descents after the first free solution of a pose goal that look for more.
const POSE_GOAL_MORE: usize = 32;

/// Inverse kinematics solutions of a pose goal, at most `max` (the free ones first: a colliding
/// solution is kept only while no free one is found, for the status to name its pair).
fn pose_candidates(
    checker: &mut dyn Validity,
    solver: &mut IkSolver<'_>,
    max: usize,
    deadline: Instant,
    rng: &mut impl Rng,
) -> Result<Vec<Vec<Real>>> {
    let (mut free, mut colliding, mut first_free) = (Vec::new(), None, None);
    while free.len() < max && Instant::now() < deadline {
        // Once a free solution is known, a few more descents look for others, not thousands.
        if first_free.is_some_and(|at: usize| solver.attempts() > at + POSE_GOAL_MORE) {
            break;
        }
        let Some(solution) = solver.next_solution(rng) else { break };
        if checker.state_free(&solution.q)? {
            free.push(solution.q);
            first_free.get_or_insert(solver.attempts());
        } else {
            colliding.get_or_insert(solution.q);
        }
    }
    if free.is_empty() {
        return Ok(colliding.into_iter().collect());
    }
    Ok(free)
}

/// The goal configurations to try, checked against the space: every one given (at most
/// [`MAX_GOALS`]; the plan keeps the first `max_goals` free ones), or a region's center then
/// samples inside it (`max_goals` in all).
fn goal_candidates(space: &JointSpace, goal: &Goal, max_goals: usize, rng: &mut impl Rng) -> Result<Vec<Vec<Real>>> {
    match goal {
        Goal::Configurations(qs) => {
            if qs.is_empty() {
                return Err(Error::invalid("goal", "needs at least one goal configuration"));
            }
            if qs.len() > MAX_GOALS {
                return Err(Error::invalid(
                    "goal.configurations",
                    format!("at most {MAX_GOALS} goal configurations, got {}", qs.len()),
                ));
            }
            for (k, q) in qs.iter().enumerate() {
                check_configuration(space, &format!("goal.configurations[{k}]"), q)?;
            }
            Ok(qs.clone())
        }
        Goal::Pose(_) => Err(Error::invalid("goal.pose", "this checker has no robot: pose goals need one")),
        Goal::Region(r) => {
            check_configuration(space, "goal.center", &r.center)?;
            for (field, t) in [("goal.below", &r.below), ("goal.above", &r.above)] {
                if t.len() != space.dof() {
                    return Err(Error::invalid(field, format!("has {} entries, the robot {}", t.len(), space.dof())));
                }
                if let Some(k) = t.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                    return Err(Error::invalid(
                        format!("{field}[{k}]"),
                        format!("must be finite and ≥ 0, got {}", t[k]),
                    ));
                }
            }
            let mut out = vec![r.center.clone()];
            let wide = r.below.iter().zip(&r.above).any(|(b, a)| b + a > 1e-9);
            while wide && out.len() < max_goals {
                let q = (0..space.dof())
                    .map(|k| {
                        let (lo, hi) = space.bounds[k];
                        let (a, b) = (r.center[k] - r.below[k], r.center[k] + r.above[k]);
                        let (a, b) = if space.wraps[k] { (a, b) } else { (a.max(lo), b.min(hi)) };
                        if b > a {
                            rng.random_range(a..=b)
                        } else {
                            a
                        }
                    })
                    .collect();
                out.push(q);
            }
            Ok(out)
        }
    }
}
