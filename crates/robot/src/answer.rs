//! What a configuration check is asked ([`CheckOptions`]) and what it answers
//! ([`ConfigurationAnswer`]); the checks themselves are in [`crate::check`].

use crate::fidelity::Fidelity;
use sublevel_core::math::{Point3, Real};

/// What a check computes.
#[derive(Clone, Copy, Debug)]
pub struct CheckOptions {
    /// Padding added around every robot geometry (meters, ≥ 0): a pair closer than it collides.
    pub padding: Real,
    /// Whether the minimum robot–world distance is computed (else the world pairs stop at the
    /// first collision and far pairs are not solved).
    pub distance: bool,
    /// Whether self-collision pairs are checked.
    pub self_collision: bool,
    /// Whether the minimum distance's joint-space gradient is computed (with `distance`).
    pub gradient: bool,
}

impl Default for CheckOptions {
    fn default() -> Self {
        Self { padding: 0.0, distance: true, self_collision: true, gradient: false }
    }
}

/// The answer for one configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigurationAnswer {
    /// Whether the robot collides with the world or itself.
    pub collides: bool,
    /// Whether a robot geometry collides with a world object.
    pub world: bool,
    /// Whether two robot geometries of a checked self pair collide.
    pub self_collision: bool,
    /// Minimum robot–world distance (meters): the closest pair's mesh distance (module docs); 0
    /// when the robot collides with the world; +∞ with no world pair; NaN when not asked for.
    pub distance: Real,
    /// The world pair of `distance` (or the colliding one), as (geometry index, object index).
    pub pair: Option<(usize, usize)>,
    /// Witness points of `distance` on the robot and on the object (world frame, meters), when
    /// the robot is free of the world.
    pub witnesses: Option<(Point3, Point3)>,
    /// A colliding self pair, as geometry indices.
    pub self_pair: Option<(usize, usize)>,
    /// With [`CheckOptions::gradient`], when the robot is free of the world at a finite distance:
    /// ∂distance/∂q, one entry per configuration entry (meters per radian or per meter). The
    /// closest points' normal `n` (from the object's witness to the robot's) times the point
    /// Jacobian of the robot's witness ([`crate::RobotModel::point_jacobian`]): `∂d/∂q_k = n·∂x/∂q_k`,
    /// the derivative wherever the closest pair and its closest features do not switch.
    pub gradient: Option<Vec<Real>>,
    /// Whether every solve the answer rests on converged (pairs resolved on the mesh count as
    /// converged: the mesh test is exact).
    pub converged: bool,
    /// Pairs decided by their bounding balls.
    pub pairs_pruned: usize,
    /// Self pairs decided by the robot's clearance tables ([`crate::clearance`]), one lookup each.
    pub pairs_table: usize,
    /// Pairs decided by the links' sphere trees ([`crate::spheres`]), no solve.
    pub pairs_spheres: usize,
    /// Pairs proved colliding by the link meshes' inner balls ([`crate::inner`]), no mesh test.
    pub pairs_proved: usize,
    /// Pairs bounded by the sos bodies (one solve each).
    pub pairs_model: usize,
    /// Pairs resolved on the meshes.
    pub pairs_exact: usize,
    /// The model a collision rests on ([`crate::fidelity`]): [`Fidelity::Mesh`] when the
    /// verdict is the meshes' own — every free verdict at any level (a free pair is proven free
    /// by a shape containing the mesh), and a collision found on the meshes or proven by a
    /// contact proof — else the conservative level whose bodies came within the padding (the
    /// meshes may be free there: a possible false collision, never a miss).
    pub fidelity: Fidelity,
}

impl ConfigurationAnswer {
    /// The answer before any pair is checked: free, distance +∞ (NaN when `distance` is not asked
    /// for), converged, every count 0.
    pub(crate) fn start(distance: bool) -> Self {
        Self {
            collides: false,
            world: false,
            self_collision: false,
            distance: if distance { Real::INFINITY } else { Real::NAN },
            pair: None,
            witnesses: None,
            self_pair: None,
            gradient: None,
            converged: true,
            pairs_pruned: 0,
            pairs_table: 0,
            pairs_spheres: 0,
            pairs_proved: 0,
            pairs_model: 0,
            pairs_exact: 0,
            fidelity: Fidelity::Mesh,
        }
    }
}
