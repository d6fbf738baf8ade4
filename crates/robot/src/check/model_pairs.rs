//! Pairs near contact at a conservative level of the fidelity dial ([`crate::fidelity`]): the
//! level's bodies, which contain the link meshes, decide a pair the gaps and tables left; a pair
//! they do not show clear of the padding collides.

use super::{root_shape, RobotChecker};
use crate::answer::ConfigurationAnswer;
use crate::exact::PairOutcome;
use crate::fidelity::Fidelity;
use crate::fitted::{FittedRobot, LinkShape};
use crate::spheres::{Sphere, SphereTree, TreeAnswer};
use crate::world::WorldShape;
use crate::Result;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_query::shape::shape_distance;

/// The sphere model of `robot` at `tolerance` (meters): per geometry, the balls of its sphere
/// tree's cut for the lanes (empty past [`super::MAX_CUT_BALLS`] balls, and for a primitive),
/// and which nodes the cut holds (the descents' leaves). A node is small enough when its ball
/// reaches at most `tolerance` past the mesh: radius plus its center's distance to the mesh
/// (parry's point projection), so that every point of the ball is within `tolerance` of it.
pub(super) fn sphere_model(robot: &FittedRobot, tolerance: Real) -> (Vec<Vec<Sphere>>, Vec<Vec<bool>>) {
    use parry3d_f64::query::PointQuery;
    robot
        .geometries
        .iter()
        .map(|g| {
            let LinkShape::Mesh { spheres, exact, .. } = &g.shape else { return (Vec::new(), Vec::new()) };
            let mesh = exact.as_trimesh();
            let reach = |n: u32| {
                let s = &spheres.nodes[n as usize].sphere;
                if s.radius <= tolerance / 2.0 {
                    return true;
                }
                let Some(mesh) = mesh.filter(|_| s.radius <= tolerance) else { return false };
                let c = s.center;
                let p = mesh.project_local_point(parry3d_f64::math::Vector::new(c.x, c.y, c.z), false).point;
                s.radius + (Vector3::new(p.x, p.y, p.z) - c).norm() <= tolerance
            };
            let cut = spheres.cut_by(usize::MAX, reach);
            let mut leaves = vec![false; spheres.nodes.len()];
            for &n in &cut {
                leaves[n as usize] = true;
            }
            let balls = if cut.len() <= super::MAX_CUT_BALLS {
                cut.iter().map(|&n| spheres.nodes[n as usize].sphere).collect()
            } else {
                Vec::new()
            };
            (balls, leaves)
        })
        .unzip()
}

impl RobotChecker<'_> {
    /// Sets the level of the checks that follow ([`crate::fidelity`]): [`Fidelity::Mesh`] (the
    /// default) answers the meshes' verdicts and distances; a conservative level calls a pair
    /// free only when its bodies, which contain the meshes, clear the padding, and colliding
    /// otherwise. At [`Fidelity::Spheres`] the model is each mesh geometry's sphere tree cut
    /// where every ball reaches at most `tolerance` past the mesh (its radius plus its center's
    /// distance to the mesh, at most twice its radius): the single path descends it no deeper,
    /// and the block path's lanes test the whole cut where it has at most [`super::MAX_CUT_BALLS`]
    /// balls (a pair left within the padding then collides without the single path). Motions
    /// ([`crate::MotionChecker`]) start with a check at the level and advance on the meshes'
    /// bounds.
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] naming `fidelity.tolerance` out of range (nothing changes).
    pub fn set_fidelity(&mut self, fidelity: Fidelity) -> Result<()> {
        fidelity.validate("fidelity")?;
        if fidelity == self.fidelity {
            return Ok(());
        }
        let previous =
            (self.fidelity, std::mem::take(&mut self.cuts), std::mem::take(&mut self.model_leaves), self.block.take());
        if let Some((level, cuts, leaves, block)) = self.stash.replace(previous) {
            if level == fidelity {
                (self.fidelity, self.cuts, self.model_leaves, self.block) = (level, cuts, leaves, block);
                return Ok(());
            }
        }
        (self.cuts, self.model_leaves) = match fidelity {
            Fidelity::Spheres { tolerance } => sphere_model(self.robot, tolerance),
            _ => (Vec::new(), Vec::new()),
        };
        self.fidelity = fidelity;
        self.block = None;
        Ok(())
    }

    /// The level of the checks ([`RobotChecker::set_fidelity`]).
    pub fn fidelity(&self) -> Fidelity {
        self.fidelity
    }

    /// At [`Fidelity::Spheres`], the balls of geometry `g`'s cut the lanes test as its model
    /// (its frame; empty for a primitive geometry, a cut of more than [`super::MAX_CUT_BALLS`] balls,
    /// or at another level).
    pub fn sphere_cut(&self, g: usize) -> &[Sphere] {
        self.cuts.get(g).map_or(&[], Vec::as_slice)
    }

    /// Whether node `n` of geometry `g`'s sphere tree is a leaf of the checker's sphere model
    /// (always false at other levels: the whole tree).
    fn model_leaf(&self, g: usize, n: u32) -> bool {
        self.model_leaves.get(g).is_some_and(|l| l[n as usize])
    }

    /// World pair (`g`, `o`) at the checker's conservative level: `None` when the level's
    /// bodies are at least `bound` apart and farther than `padding`, a free outcome with the
    /// level's distance (a lower bound of the meshes') when they are nearer than `bound` but
    /// clear of the padding, else a collision (`answer.fidelity` set to the level whose bodies
    /// came within the padding). Sphere cuts decide a mesh link against a primitive at
    /// [`Fidelity::Spheres`]; the root bodies decide the rest; a pair with no body (a mesh
    /// obstacle without one, a point cloud) or a solve that did not converge is decided on the
    /// meshes, exactly.
    pub(super) fn model_world_pair(
        &self,
        g: usize,
        o: usize,
        bound: Real,
        padding: Real,
        answer: &mut ConfigurationAnswer,
    ) -> Result<Option<PairOutcome>> {
        let geometry = &self.robot.geometries[g];
        let obj = &self.world[o];
        let leaf = |n: u32| self.model_leaf(g, n);
        if let (LinkShape::Mesh { spheres, .. }, WorldShape::Primitive(p)) = (&geometry.shape, &obj.shape) {
            if !spheres.nodes.is_empty() {
                let rel = obj.pose.inv_mul(&self.poses[g]);
                let (r, t) = (rel.rotation.to_rotation_matrix().into_inner(), rel.translation.vector);
                answer.pairs_spheres += 1;
                if spheres.against_primitive_to(&r, &t, p, bound, Real::NEG_INFINITY, leaf) == TreeAnswer::Apart {
                    return Ok(None);
                }
                if let Fidelity::Spheres { .. } = self.fidelity {
                    let gap = if bound <= padding {
                        Real::NEG_INFINITY
                    } else {
                        spheres.lower_bound_to_primitive(&r, &t, p, leaf, bound)
                    };
                    return Ok(self.model_outcome(gap, padding, bound, None, answer));
                }
            }
        }
        let shape = match self.world_sos_shape(o) {
            Some(shape) if self.cloud(o).is_none() && !self.both_primitive(g, o) => shape,
            _ => return self.world_pair(g, o, bound, padding, answer),
        };
        answer.pairs_model += 1;
        let d = shape_distance(root_shape(&geometry.shape), &self.poses[g], shape, &obj.pose, None)?;
        if !d.status.converged() {
            return self.world_pair(g, o, bound, padding, answer);
        }
        let gap = if d.overlapping { Real::NEG_INFINITY } else { d.distance };
        Ok(self.model_outcome(gap, padding, bound, Some((d.witness_a, d.witness_b)), answer))
    }

    /// A pair whose level model is `gap` apart: free past `bound` (`None`), free with the gap
    /// as its distance, or a collision at the checker's level.
    fn model_outcome(
        &self,
        gap: Real,
        padding: Real,
        bound: Real,
        witnesses: Option<(sublevel_core::math::Point3, sublevel_core::math::Point3)>,
        answer: &mut ConfigurationAnswer,
    ) -> Option<PairOutcome> {
        if gap > padding {
            return (gap < bound).then_some(PairOutcome::Free { distance: gap, witnesses });
        }
        answer.fidelity = if witnesses.is_some() { Fidelity::Bodies } else { self.fidelity };
        Some(PairOutcome::Collides)
    }

    /// Self pair `k` at the checker's conservative level: `Some(true)` when the level's bodies
    /// come within `padding` (collides, `answer.fidelity` set), `Some(false)` when they clear
    /// it, `None` when the meshes must decide (a solve that did not converge).
    pub(super) fn model_self_pair(
        &self,
        k: usize,
        padding: Real,
        answer: &mut ConfigurationAnswer,
    ) -> Result<Option<bool>> {
        let (a, b) = self.self_pairs[k];
        let (ga, gb) = (&self.robot.geometries[a], &self.robot.geometries[b]);
        let (pa, pb) = (&self.poses[a], &self.poses[b]);
        let apart = |tree: &SphereTree, g: usize, p: &Primitive, pose_p: &Isometry3| {
            let rel = pose_p.inv_mul(&self.poses[g]);
            let (r, t) = (rel.rotation.to_rotation_matrix().into_inner(), rel.translation.vector);
            let leaf = |n: u32| self.model_leaf(g, n);
            tree.against_primitive_to(&r, &t, p, padding, Real::NEG_INFINITY, leaf) == TreeAnswer::Apart
        };
        let spheres = match (&ga.shape, &gb.shape) {
            (LinkShape::Mesh { spheres: sa, .. }, LinkShape::Mesh { spheres: sb, .. }) => {
                let rel = pa.inv_mul(pb);
                let (r, t) = (rel.rotation.to_rotation_matrix().into_inner(), rel.translation.vector);
                let leaves = (|n: u32| self.model_leaf(a, n), |n: u32| self.model_leaf(b, n));
                Some(sa.apart_from_tree_to(sb, &r, &t, padding, leaves))
            }
            (LinkShape::Mesh { spheres, .. }, LinkShape::Primitive(p)) => Some(apart(spheres, a, p, pb)),
            (LinkShape::Primitive(p), LinkShape::Mesh { spheres, .. }) => Some(apart(spheres, b, p, pa)),
            _ => None,
        };
        if let Some(apart) = spheres {
            answer.pairs_spheres += 1;
            if apart {
                return Ok(Some(false));
            }
            if let Fidelity::Spheres { .. } = self.fidelity {
                answer.fidelity = self.fidelity;
                return Ok(Some(true));
            }
        }
        answer.pairs_model += 1;
        let d = shape_distance(root_shape(&ga.shape), pa, root_shape(&gb.shape), pb, None)?;
        if !d.status.converged() {
            return Ok(None);
        }
        let collides = d.overlapping || d.distance <= padding;
        let exact = matches!((&ga.shape, &gb.shape), (LinkShape::Primitive(_), LinkShape::Primitive(_)));
        if collides && !exact {
            answer.fidelity = Fidelity::Bodies;
        }
        Ok(Some(collides))
    }
}
