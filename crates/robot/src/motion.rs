//! How far a link can move along a joint-space segment: the bound conservative advancement steps
//! with (Schwarzer, Saha and Latombe, *Adaptive dynamic collision checking for single and multiple
//! articulated robots in complex environments*, IEEE T-RO 2005, §III).
//!
//! A point `x` of link L moves with the configuration; along the segment `q(t) = q₀ + t·Δq`,
//! `t ∈ [0, 1]`,
//!
//! ```text
//! dx/dt = Σ_j  J_j(q) · Δq_j         one term per joint j on the chain from the root to L
//! |J_j| = |a_j × (x − o_j)| ≤ |x − o_j|      revolute / continuous j (axis a_j through o_j)
//! |J_j| = |a_j| = 1                          prismatic j
//! ```
//!
//! and `|x − o_j|` is bounded independently of the configuration by the chain's geometry: the
//! joint's own rotation leaves `o_j` (its child frame's origin) in place, every later joint k on the
//! chain moves the next frame by at most `|origin_k.translation|` (plus its travel `max|q_k|` for a
//! prismatic joint), and the point lies within the link's radius `r_L` of the link's origin:
//!
//! ```text
//! R_jL = Σ_{k after j on the chain to L} ( |t_k| + travel_k ) + r_L
//! |x(t) − x(0)| ≤ Σ_j  c_Lj · |Δq_j|,   c_Lj = R_jL (revolute) or 1 (prismatic)
//! ```
//!
//! A mimic joint following entry v with multiplier μ moves by `μ · Δq_v`, so it adds `|μ| · c` to
//! entry v's coefficient. The bound holds for every configuration, so it holds on every sub-segment
//! too: a step of length `Δt` moves no point of L farther than `Δt · Σ_j c_Lj |Δq_j|`.
//!
//! **At a configuration** the lever arms are usually much shorter than the chain's full reach `R_jL`
//! (an arm folded, or a link close to a joint's axis). Write a point of L in joint j's child frame
//! as `y`: `x − o_j = R_j · y`, and only the joints after j on the chain move `y`, at most
//! `E_jL = Σ_{k after j} c'_kL |Δq_k|` per unit of t (`c'_kL = R_kL`, or 1 for a prismatic k). The
//! distance of x from j's axis (the part of `y` across the axis) starts at most
//! `ρ_jL = min(dist(p_L, axis_j) + r_L, R_jL)` (p_L the link's origin at the step's start) and grows
//! at most at rate `E_jL`, so during a step of length s
//!
//! ```text
//! |dx/dt| ≤ A_L + s·B_L,   A_L = Σ_j |Δq_j| · (ρ_jL, or 1 prismatic),   B_L = Σ_{j revolute} |Δq_j| · E_jL
//! |x(t+s) − x(t)| ≤ s·A_L + s²·B_L / 2            and also ≤ s · Σ_j c_Lj |Δq_j|
//! ```
//!
//! ([`MotionBounds::at`]; mimic joints with their `|μ|`).
//!
//! **The rigid body's speed.** `A_L` adds the joints' speeds as if they all pushed the same way;
//! the velocity itself is a vector sum, `v_x = Σ_j u_j a_j × (x − o_j)` (`u_j = μ_j Δq_j`; `u_j a_j`
//! for a prismatic j), and for the points of a ball B(c, r) on the link
//! `|v_x| = |v_c + ω × (x − c)| ≤ |v_c| + |ω| r` (ω = Σ_{j revolute} u_j a_j). Its growth along the
//! step: with `Ω_j` the angular velocity of joint j's parent (`|Ω_j| ≤ W_j = Σ_{k before j, revolute}
//! |u_k|`), a revolute term changes at `u_j (Ω_j × (a_j × (x − o_j)) + a_j × w_j)` (Jacobi's identity;
//! `w_j` the velocity x gets from j and the joints after it, at most `S_j = Σ_{k from j on} c'_kL |u_k|`),
//! a prismatic one at `u_j Ω_j × a_j`, so every point's acceleration is at most
//!
//! ```text
//! G = Σ_{j revolute} |u_j| (W_j R_jL + S_j) + Σ_{j prismatic} |u_j| W_j
//! |x(t+s) − x(t)| ≤ s·V + s²·G / 2,   V = |v_c| + |ω| r at the step's start
//! ```
//!
//! On the MotionBenchMaker Panda's planned edges, at the configurations where conservative
//! advancement measured a link's distance on the meshes, V was 0.18–0.44 of `A_L` (deciles; median
//! 0.29), against 0.26 for the largest speed of the link mesh's vertices. [`MotionBounds::at_ball`] takes the
//! ball of a geometry (its lever arms `ρ` measured from the ball too), [`MotionBounds::at`] the
//! link's radius about its origin. A clearance d allows the step
//! `s = max(d / D_L, 2d / (A_L + √(A_L² + 2 B_L d)), 2d / (V + √(V² + 2 G d)))`, the largest of the
//! three bounds' ([`step`], [`LinkMotion::displacement`]).

use crate::model::{JointKind, JointValue, RobotModel};
use crate::{Error, Result};
use sublevel_core::math::{Isometry3, Real, Vector3};

/// Per-link coefficients of the motion bound (see the module docs): `coefficients[link][k]`
/// meters per radian (revolute, continuous) or meters per meter (prismatic) of configuration
/// entry k.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionBounds {
    coefficients: Vec<Vec<Real>>,
    /// Per link, the moving joints from it up to the root, nearest first.
    chains: Vec<Vec<ChainJoint>>,
    /// Per link, the radius about its origin that holds its geometry (meters).
    radius: Vec<Real>,
}

/// A moving joint on a link's chain (see the module docs).
#[derive(Clone, Debug, PartialEq)]
struct ChainJoint {
    /// The joint's index in [`RobotModel::joints`].
    joint: usize,
    /// The configuration entry it follows.
    variable: usize,
    /// `|μ|` for a mimic joint, else 1.
    gain: Real,
    /// `μ` for a mimic joint (its sign: which way it turns), else 1.
    multiplier: Real,
    /// Whether it is prismatic (a speed of `|Δq|`, no lever arm).
    prismatic: bool,
    /// `R_jL`: the chain's full reach from the joint to any point of the link (meters).
    reach: Real,
}

/// The bound of one link's motion from a configuration along a segment (see the module docs), per
/// unit of the segment's parameter t: a point moves at most
/// `min(s·full, s·linear + s²·quadratic / 2, s·speed + s²·growth / 2)` in a step of length s
/// ([`LinkMotion::displacement`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkMotion {
    /// `D_L = Σ_j c_Lj |Δq_j|`, the configuration-free bound (meters).
    pub full: Real,
    /// `A_L`, the speed at the step's start (meters).
    pub linear: Real,
    /// `B_L`, how fast that speed can grow (meters).
    pub quadratic: Real,
    /// `V`, the rigid body's speed at the step's start: its ball's center's velocity plus the
    /// angular velocity times the ball's radius (meters; +∞ where not measured).
    pub speed: Real,
    /// `G`, how fast that speed can grow: a bound of every point's acceleration (meters).
    pub growth: Real,
}

impl Default for LinkMotion {
    /// A link that does not move.
    fn default() -> Self {
        Self { full: 0.0, linear: 0.0, quadratic: 0.0, speed: Real::INFINITY, growth: 0.0 }
    }
}

impl LinkMotion {
    /// The sum of two links' bounds: of their relative motion (a self pair).
    pub fn plus(&self, other: &LinkMotion) -> LinkMotion {
        LinkMotion {
            full: self.full + other.full,
            linear: self.linear + other.linear,
            quadratic: self.quadratic + other.quadratic,
            speed: self.speed + other.speed,
            growth: self.growth + other.growth,
        }
    }

    /// Whether the link does not move.
    pub fn is_still(&self) -> bool {
        self.full <= 0.0
    }

    /// How far a point can move in a step of length `s` ≥ 0 (meters): the least of the three
    /// bounds.
    pub fn displacement(&self, s: Real) -> Real {
        (s * self.full)
            .min(s * self.linear + s * s * self.quadratic / 2.0)
            .min(s * self.speed + s * s * self.growth / 2.0)
    }
}

/// The longest step (in units of t) over which no point bounded by `motion` moves `clearance`
/// meters or more: `max(d / D, 2d / (A + √(A² + 2Bd)), 2d / (V + √(V² + 2Gd)))` (+∞ for a link
/// that does not move, 0 for `clearance ≤ 0`).
pub fn step(clearance: Real, motion: &LinkMotion) -> Real {
    if clearance <= 0.0 {
        return 0.0;
    }
    if motion.is_still() {
        return Real::INFINITY;
    }
    let coarse = clearance / motion.full;
    let quadratic = |a: Real, b: Real| {
        let fine = 2.0 * clearance / (a + (a * a + 2.0 * b * clearance).sqrt());
        if fine.is_finite() {
            fine
        } else {
            0.0
        }
    };
    coarse.max(quadratic(motion.linear, motion.quadratic)).max(quadratic(motion.speed, motion.growth))
}

impl MotionBounds {
    /// An upper bound of how far any point of link `link` moves when the configuration moves
    /// linearly by `dq` (one entry per configuration entry; radians or meters; for a continuous
    /// joint the angle actually turned), meters.
    ///
    /// # Panics
    /// Never for `dq` of the robot's length; a shorter `dq` bounds only its entries.
    pub fn displacement(&self, link: usize, dq: &[Real]) -> Real {
        self.coefficients[link].iter().zip(dq).map(|(c, d)| c * d.abs()).sum()
    }

    /// The coefficients of link `link`, one per configuration entry.
    pub fn coefficients(&self, link: usize) -> &[Real] {
        &self.coefficients[link]
    }

    /// The bound of link `link`'s motion from the configuration whose link poses are `poses`
    /// ([`RobotModel::forward_kinematics`]) along `dq` (see the module docs).
    ///
    /// # Panics
    /// Never for `poses` and `dq` of the robot's lengths.
    pub fn at(&self, model: &RobotModel, link: usize, poses: &[Isometry3], dq: &[Real]) -> LinkMotion {
        self.below(model, link, self.chains[link].len(), poses, dq, None)
    }

    /// As [`MotionBounds::at`] for the points of link `link` within the ball of center `center`
    /// (world frame, at the configuration of `poses`) and radius `radius` (meters): a geometry
    /// of the link, whose ball lies within the link's radius of its origin. Its lever arms and
    /// its speed are measured from the ball, not from the link's origin.
    pub fn at_ball(
        &self,
        model: &RobotModel,
        link: usize,
        poses: &[Isometry3],
        dq: &[Real],
        (center, radius): (&Vector3, Real),
    ) -> LinkMotion {
        self.below(model, link, self.chains[link].len(), poses, dq, Some((center, radius)))
    }

    /// The moving joints of link `a`'s and link `b`'s chains below their nearest common ancestor
    /// (the joints above it move both links together, leaving their distance unchanged): how many
    /// of each chain's first entries [`MotionBounds::relative`] counts.
    pub fn below_common(&self, a: usize, b: usize) -> (usize, usize) {
        let (ca, cb) = (&self.chains[a], &self.chains[b]);
        let shared = ca.iter().rev().zip(cb.iter().rev()).take_while(|(x, y)| x.joint == y.joint).count();
        (ca.len() - shared, cb.len() - shared)
    }

    /// The bound of how fast links `a` and `b` can close from the configuration of `poses` along
    /// `dq`: the motion of each in the frame of their nearest common ancestor (`counts` from
    /// [`MotionBounds::below_common`]), summed.
    pub fn relative(
        &self,
        model: &RobotModel,
        (a, b): (usize, usize),
        counts: (usize, usize),
        poses: &[Isometry3],
        dq: &[Real],
    ) -> LinkMotion {
        self.below(model, a, counts.0, poses, dq, None).plus(&self.below(model, b, counts.1, poses, dq, None))
    }

    /// As [`MotionBounds::relative`] for the points of links `a` and `b` within the balls
    /// `balls` (as in [`MotionBounds::at_ball`]).
    #[allow(clippy::too_many_arguments)]
    pub fn relative_balls(
        &self,
        model: &RobotModel,
        (a, b): (usize, usize),
        counts: (usize, usize),
        poses: &[Isometry3],
        dq: &[Real],
        balls: ((&Vector3, Real), (&Vector3, Real)),
    ) -> LinkMotion {
        self.below(model, a, counts.0, poses, dq, Some(balls.0)).plus(&self.below(
            model,
            b,
            counts.1,
            poses,
            dq,
            Some(balls.1),
        ))
    }

    /// The bound of link `link`'s motion from the first `count` moving joints of its chain alone
    /// (all of them: its motion in the world; the joints below an ancestor: its motion in that
    /// ancestor's frame, where the distance from each of those joints' axes is the same), for the
    /// points within `ball` (center in the world frame, radius), or within the link's radius of
    /// its origin.
    ///
    /// The speed bound (module docs): with `u_j` joint j's rate (`μ·Δq`), `Ω_j` the angular
    /// velocity of its parent (the counted joints nearer the root) and `r_j = x − o_j`, a
    /// revolute term of the velocity `u_j a_j × r_j` changes at
    /// `u_j (Ω_j × (a_j × r_j) + a_j × w_j)` (Jacobi's identity; `w_j` the velocity of x from
    /// joint j and the joints after it), a prismatic term `u_j a_j` at `u_j Ω_j × a_j`, so every
    /// point's acceleration is at most `G = Σ_rev |u_j| (W_j R_j + S_j) + Σ_prism |u_j| W_j`
    /// (`W_j = Σ_{k before j, revolute} |u_k|`, `S_j = Σ_{k from j on} |u_k| c'_k`), and its
    /// speed at the step's start is at most `|v_c| + |ω| r` (a rigid body: `v_x = v_c + ω × (x − c)`).
    fn below(
        &self,
        model: &RobotModel,
        link: usize,
        count: usize,
        poses: &[Isometry3],
        dq: &[Real],
        ball: Option<(&Vector3, Real)>,
    ) -> LinkMotion {
        let joints = model.joints();
        let (center, radius) = ball.unwrap_or((&poses[link].translation.vector, self.radius[link]));
        let chain = &self.chains[link][..count];
        let turning: Real = chain.iter().filter(|c| !c.prismatic).map(|c| c.gain * dq[c.variable].abs()).sum();
        let (mut linear, mut quadratic, mut after) = (0.0, 0.0, 0.0);
        // Revolute rates counted so far (nearest first): W_j = turning − this, after joint j.
        let (mut turned, mut growth) = (0.0, 0.0);
        let (mut velocity, mut omega) = (Vector3::zeros(), Vector3::zeros());
        for c in chain {
            let rate = c.gain * dq[c.variable].abs();
            let u = c.multiplier * dq[c.variable];
            let frame = &poses[joints[c.joint].child];
            let axis = frame.rotation * joints[c.joint].axis;
            if c.prismatic {
                linear += rate;
                after += rate;
                velocity += axis * u;
                growth += rate * (turning - turned);
                continue;
            }
            let offset = center - frame.translation.vector;
            let across = (offset - axis * offset.dot(&axis)).norm();
            linear += rate * (across + radius).min(c.reach);
            quadratic += rate * after;
            after += rate * c.reach;
            turned += rate;
            velocity += axis.cross(&offset) * u;
            omega += axis * u;
            growth += rate * ((turning - turned) * c.reach + after);
        }
        // `after` is now Σ c'|Δq| over the counted joints: the configuration-free bound.
        let speed = velocity.norm() + omega.norm() * radius;
        LinkMotion { full: after, linear, quadratic, speed, growth }
    }
}

impl RobotModel {
    /// The motion-bound coefficients of every link (see the module docs), given each link's
    /// radius: the largest distance from the link's origin to a point of its collision geometry
    /// (meters, one per [`RobotModel::links`]; 0 for a link without geometry).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `link_radius` when it does not have one entry per link, or
    /// `link_radius[k]` for a negative or non-finite radius.
    pub fn motion_bounds(&self, link_radius: &[Real]) -> Result<MotionBounds> {
        let links = self.links();
        if link_radius.len() != links.len() {
            return Err(Error::invalid(
                "link_radius",
                format!("{} radii for {} links", link_radius.len(), links.len()),
            ));
        }
        if let Some(k) = link_radius.iter().position(|r| !(r.is_finite() && *r >= 0.0)) {
            return Err(Error::invalid(format!("link_radius[{k}]"), "must be a finite radius ≥ 0 meters"));
        }
        let joints = self.joints();
        let mut coefficients = vec![vec![0.0; self.dof()]; links.len()];
        let mut chains = vec![Vec::new(); links.len()];
        for ((l, row), chain) in coefficients.iter_mut().enumerate().zip(&mut chains) {
            // Walk from the link up to the root; `reach` is R_jL for the joint reached so far
            // (the terms of the joints below it plus the link's radius).
            let mut reach = link_radius[l];
            let mut at = links[l].parent_joint;
            while let Some(j) = at {
                let joint = &joints[j];
                let (source, gain) = match joint.value {
                    JointValue::Fixed => (None, 0.0),
                    JointValue::Variable(k) => (Some(k), 1.0),
                    JointValue::Mimic { variable, multiplier, .. } => (Some(variable), multiplier),
                };
                if let Some(k) = source {
                    let (multiplier, gain) = (gain, gain.abs());
                    let prismatic = joint.kind == JointKind::Prismatic;
                    row[k] += gain * if prismatic { 1.0 } else { reach };
                    if gain > 0.0 {
                        chain.push(ChainJoint { joint: j, variable: k, gain, multiplier, prismatic, reach });
                    }
                }
                // Joint j itself lies below the next joint up the chain.
                let travel = match (joint.kind, joint.limits) {
                    (JointKind::Prismatic, Some((lo, hi))) => lo.abs().max(hi.abs()),
                    _ => 0.0,
                };
                reach += joint.origin.translation.vector.norm() + travel;
                at = links[joint.parent].parent_joint;
            }
        }
        Ok(MotionBounds { coefficients, chains, radius: link_radius.to_vec() })
    }
}
