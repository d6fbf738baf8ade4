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

use crate::model::{JointKind, JointValue, RobotModel};
use crate::{Error, Result};
use sublevel_core::math::Real;

/// Per-link coefficients of the motion bound (see the module docs): `coefficients[link][k]`
/// meters per radian (revolute, continuous) or meters per meter (prismatic) of configuration
/// entry k.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionBounds {
    coefficients: Vec<Vec<Real>>,
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
        for (l, row) in coefficients.iter_mut().enumerate() {
            // Walk from the link up to the root; `reach` is R_jL for the joint reached so far
            // (the terms of the joints below it plus the link's radius).
            let mut reach = link_radius[l];
            let mut at = links[l].parent_joint;
            while let Some(j) = at {
                let joint = &joints[j];
                let (source, gain) = match joint.value {
                    JointValue::Fixed => (None, 0.0),
                    JointValue::Variable(k) => (Some(k), 1.0),
                    JointValue::Mimic { variable, multiplier, .. } => (Some(variable), multiplier.abs()),
                };
                if let Some(k) = source {
                    row[k] += gain * if joint.kind == JointKind::Prismatic { 1.0 } else { reach };
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
        Ok(MotionBounds { coefficients })
    }
}
