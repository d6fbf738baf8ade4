//! Self pairs of a configuration check: the stages of [`RobotChecker`]'s module docs for two
//! geometries of the robot, with the clearance tables ([`crate::clearance`]) first.

use super::{root_shape, RobotChecker};
use crate::answer::{CheckOptions, ConfigurationAnswer};
use crate::exact::{box_gap_past, exact_collides, parry_pose, triangles_touch};
use crate::fitted::LinkShape;
use crate::inner::links_touch;
use crate::spheres::SphereTree;
use crate::Result;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::primitive::Primitive;
use sublevel_query::shape::shape_distance;

impl RobotChecker<'_> {
    /// Self pair `k`'s clearance-table bound at the configuration placed (−∞ without a table).
    pub(super) fn table_bound(&self, k: usize) -> Real {
        self.self_tables[k].map_or(Real::NEG_INFINITY, |t| self.robot.clearance[t].lower_bound(&self.q))
    }

    /// Self pair `k` by its clearance table at the configuration placed: `Some(false)` when the
    /// table's bound exceeds `padding` (free), `Some(true)` when the triangle pair the table
    /// stored for the cell touches within it (collides: parry's triangle test, as on the meshes),
    /// `None` when the table cannot tell (or there is none).
    fn table_verdict(&self, k: usize, padding: Real) -> Option<bool> {
        let table = &self.robot.clearance[self.self_tables[k]?];
        let (cell, bound) = table.lookup(&self.q)?;
        if bound > padding {
            return Some(false);
        }
        let (a, b) = self.self_pairs[k];
        let mesh = |g: usize| match &self.robot.geometries[g].shape {
            LinkShape::Mesh { exact, .. } => exact.as_trimesh(),
            LinkShape::Primitive(_) => None,
        };
        let (ma, mb, pair) = (mesh(a)?, mesh(b)?, table.contact(cell)?);
        let (pa, pb) = (parry_pose(&self.poses[a]), parry_pose(&self.poses[b]));
        triangles_touch(ma, &pa, mb, &pb, padding, pair).then_some(true)
    }

    /// Whether the sphere trees prove self pair (`a`, `b`) farther apart than `padding`: a dual
    /// descent of two meshes' trees, or a mesh's tree against a primitive; `false` for two
    /// primitives.
    fn self_spheres_apart(&self, a: usize, b: usize, padding: Real) -> bool {
        let (ga, gb) = (&self.robot.geometries[a], &self.robot.geometries[b]);
        let (pa, pb) = (&self.poses[a], &self.poses[b]);
        match (&ga.shape, &gb.shape) {
            (LinkShape::Mesh { spheres: sa, .. }, LinkShape::Mesh { spheres: sb, .. }) => {
                let rel = pa.inv_mul(pb);
                sa.apart_from_tree(sb, rel.rotation.to_rotation_matrix().matrix(), &rel.translation.vector, padding)
            }
            (LinkShape::Mesh { spheres, .. }, LinkShape::Primitive(p)) => {
                tree_apart_from_primitive(spheres, pa, p, pb, padding)
            }
            (LinkShape::Primitive(p), LinkShape::Mesh { spheres, .. }) => {
                tree_apart_from_primitive(spheres, pb, p, pa, padding)
            }
            _ => false,
        }
    }

    /// The self pairs of the configuration placed, in two passes: the cheap stages (ball and box
    /// gaps, the clearance table, the contact proofs) over every pair first, so that a colliding
    /// configuration is decided by the first proof found anywhere, then the sphere trees, the
    /// sos bound and the meshes for the pairs left.
    /// Only the pairs `only` (indices of checked self pairs, increasing) when given.
    pub(super) fn self_check(
        &mut self,
        options: &CheckOptions,
        answer: &mut ConfigurationAnswer,
        only: Option<&[usize]>,
    ) -> Result<()> {
        let mut pending = std::mem::take(&mut self.pending);
        pending.clear();
        let result = self.self_check_passes(options, answer, &mut pending, only);
        self.pending = pending;
        result
    }

    fn self_check_passes(
        &self,
        options: &CheckOptions,
        answer: &mut ConfigurationAnswer,
        pending: &mut Vec<usize>,
        only: Option<&[usize]>,
    ) -> Result<()> {
        for k in 0..self.self_pairs.len() {
            if only.is_some_and(|o| o.binary_search(&k).is_err()) {
                continue;
            }
            let (a, b) = self.self_pairs[k];
            let padding = options.padding + self.pad[a] + self.pad[b];
            let (ga, gb) = (&self.robot.geometries[a], &self.robot.geometries[b]);
            let gap = (self.centers[a] - self.centers[b]).norm() - ga.sphere.1 - gb.sphere.1;
            let box_gap = || match (&self.boxes[a], &self.boxes[b]) {
                (Some(x), Some(y)) => box_gap_past(x, y, padding),
                _ => Real::NEG_INFINITY,
            };
            if gap > padding || box_gap() > padding {
                answer.pairs_pruned += 1;
                continue;
            }
            match self.table_verdict(k, padding) {
                Some(false) => {
                    answer.pairs_table += 1;
                    continue;
                }
                Some(true) => {
                    answer.pairs_table += 1;
                    answer.self_collision = true;
                    answer.self_pair = Some((a, b));
                    return Ok(());
                }
                None => {}
            }
            pending.push(k);
        }
        if !self.fidelity.is_mesh() {
            for &k in pending.iter() {
                let (a, b) = self.self_pairs[k];
                let padding = options.padding + self.pad[a] + self.pad[b];
                let collides = match self.model_self_pair(k, padding, answer)? {
                    Some(collides) => collides,
                    None => self.exact_self_collides(k, padding, answer)?,
                };
                if collides {
                    answer.self_collision = true;
                    answer.self_pair = Some((a, b));
                    return Ok(());
                }
            }
            return Ok(());
        }
        if self.sphere_stage {
            let before = pending.len();
            pending.retain(|&k| {
                let (a, b) = self.self_pairs[k];
                !self.self_spheres_apart(a, b, options.padding + self.pad[a] + self.pad[b])
            });
            answer.pairs_spheres += before - pending.len();
        }
        if self.contact_proofs {
            for &k in pending.iter() {
                let (a, b) = self.self_pairs[k];
                let (ga, gb) = (&self.robot.geometries[a], &self.robot.geometries[b]);
                if links_touch(&ga.shape, &self.poses[a], &gb.shape, &self.poses[b]) {
                    answer.pairs_proved += 1;
                    answer.self_collision = true;
                    answer.self_pair = Some((a, b));
                    return Ok(());
                }
            }
        }
        for &k in pending.iter() {
            let (a, b) = self.self_pairs[k];
            let padding = options.padding + self.pad[a] + self.pad[b];
            let (ga, gb) = (&self.robot.geometries[a], &self.robot.geometries[b]);
            answer.pairs_model += 1;
            let (pa, pb) = (&self.poses[a], &self.poses[b]);
            let d = shape_distance(root_shape(&ga.shape), pa, root_shape(&gb.shape), pb, None)?;
            let free = d.status.converged() && !d.overlapping && d.distance > padding;
            if free {
                continue;
            }
            if self.exact_self_collides(k, padding, answer)? {
                answer.self_collision = true;
                answer.self_pair = Some((a, b));
                return Ok(());
            }
        }
        Ok(())
    }

    /// Whether self pair `k`'s meshes (or primitives) come within `padding` (exact).
    fn exact_self_collides(&self, k: usize, padding: Real, answer: &mut ConfigurationAnswer) -> Result<bool> {
        let (a, b) = self.self_pairs[k];
        answer.pairs_exact += 1;
        let (ea, eb) = (&self.robot_exact[a], &self.robot_exact[b]);
        let (pa, pb) = (parry_pose(&(self.poses[a] * ea.offset)), parry_pose(&(self.poses[b] * eb.offset)));
        exact_collides(&pa, ea, &pb, eb, padding, &self.self_hints[k])
    }
}

/// Whether the sphere tree `tree` (posed by `pose`) shows the primitive `p` (posed by `pose_p`)
/// farther than `threshold` from every triangle.
fn tree_apart_from_primitive(
    tree: &SphereTree,
    pose: &Isometry3,
    p: &Primitive,
    pose_p: &Isometry3,
    threshold: Real,
) -> bool {
    // Ball centers straight into the primitive's frame: one rotation matrix per pair.
    let rel = pose_p.inv_mul(pose);
    tree.apart_from_primitive(rel.rotation.to_rotation_matrix().matrix(), &rel.translation.vector, p, threshold)
}
