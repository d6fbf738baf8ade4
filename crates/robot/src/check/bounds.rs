//! Pair bounds of a placed configuration for conservative advancement ([`crate::advance`]): a
//! world or self pair's distance bounded from below at a chosen level (the ball and box gaps, the
//! sos root bodies, the meshes).

use super::{box_gap, exact_pair_within, parry_pose, root_shape, PairOutcome, RobotChecker, Slack};
use crate::fitted::LinkShape;
use crate::Result;
use sublevel_core::math::Real;
use sublevel_query::shape::shape_distance;

impl RobotChecker<'_> {
    /// A lower bound of the distance of robot geometry `g` and world object `o` as placed by
    /// [`RobotChecker::place`] (meters; 0 when they touch), and whether it is the meshes' (or an
    /// exact primitive's: a motion reports contacts only from these), at `level`:
    /// 0 the ball and box gaps, 1 the sos root bound (exact for a primitive link), 2 the meshes'
    /// distance, to within `slack` ([`Slack::bound`] of the distance of the closest triangles
    /// found) — or that bound of `cap` when the meshes are farther apart than `cap` (the search
    /// stops there).
    ///
    /// # Errors
    /// A query that fails outright.
    pub(crate) fn world_bound(&self, g: usize, o: usize, level: u8, cap: Real, slack: Slack) -> Result<(Real, bool)> {
        let primitive = self.both_primitive(g, o);
        match level {
            0 => Ok((self.world_gap(g, o).max(self.world_box_gap(g, o, Real::INFINITY)), false)),
            1 => match self.cloud(o) {
                Some(cloud) => Ok(self.cloud_bound(g, o, cloud, 1, cap)),
                None => Ok((self.sos_world_bound(g, o)?, primitive)),
            },
            _ => {
                if primitive {
                    return Ok((self.sos_world_bound(g, o)?, true));
                }
                if let Some(cloud) = self.cloud(o) {
                    return Ok(self.cloud_bound(g, o, cloud, 2, cap));
                }
                let (a, b) = (&self.robot_exact[g], &self.world_exact[o]);
                let pa = parry_pose(&(self.poses[g] * a.offset));
                let pb = parry_pose(&(self.world[o].pose * b.offset));
                Ok((
                    match exact_pair_within(
                        &pa,
                        a,
                        &pb,
                        b,
                        0.0,
                        cap,
                        &self.world_hints[g * self.world.len() + o],
                        slack,
                    )? {
                        PairOutcome::Collides => 0.0,
                        PairOutcome::Free { distance, .. } => slack.bound(distance.min(cap)),
                    },
                    true,
                ))
            }
        }
    }

    /// The ball gap of robot geometry `g` and world object `o` as placed: the cheapest lower
    /// bound of their distance (level 0 of [`RobotChecker::world_bound`] is at least this).
    pub(crate) fn world_ball_gap(&self, g: usize, o: usize) -> Real {
        self.world_gap(g, o)
    }

    /// The ball gap of checked self pair `k` as placed (level 0 of [`RobotChecker::self_bound`]
    /// is at least this).
    pub(crate) fn self_ball_gap(&self, k: usize) -> Real {
        let (a, b) = self.self_pairs[k];
        let (ga, gb) = (&self.robot.geometries[a], &self.robot.geometries[b]);
        (self.centers[a] - self.centers[b]).norm() - ga.sphere.1 - gb.sphere.1
    }

    /// As [`RobotChecker::world_bound`] for checked self pair `k` ([`RobotChecker::self_pairs`]).
    ///
    /// # Errors
    /// A query that fails outright.
    pub(crate) fn self_bound(&self, k: usize, level: u8, cap: Real, slack: Slack) -> Result<(Real, bool)> {
        let (a, b) = self.self_pairs[k];
        let (ga, gb) = (&self.robot.geometries[a], &self.robot.geometries[b]);
        let both_primitive = matches!((&ga.shape, &gb.shape), (LinkShape::Primitive(_), LinkShape::Primitive(_)));
        let (pa, pb) = (self.poses[a], self.poses[b]);
        match level {
            0 => {
                let gap = (self.centers[a] - self.centers[b]).norm() - ga.sphere.1 - gb.sphere.1;
                let box_gap = match (&self.boxes[a], &self.boxes[b]) {
                    (Some(x), Some(y)) => box_gap(x, y),
                    _ => Real::NEG_INFINITY,
                };
                Ok((gap.max(box_gap).max(self.table_bound(k)), false))
            }
            1 => {
                let d = shape_distance(root_shape(&ga.shape), &pa, root_shape(&gb.shape), &pb, None)?;
                let ok = d.status.converged() && !d.overlapping;
                Ok((if ok { d.distance.max(0.0) } else { 0.0 }, both_primitive && ok))
            }
            _ => {
                let (ea, eb) = (&self.robot_exact[a], &self.robot_exact[b]);
                let outcome = exact_pair_within(
                    &parry_pose(&(pa * ea.offset)),
                    ea,
                    &parry_pose(&(pb * eb.offset)),
                    eb,
                    0.0,
                    cap,
                    &self.self_hints[k],
                    slack,
                )?;
                Ok((
                    match outcome {
                        PairOutcome::Collides => 0.0,
                        PairOutcome::Free { distance, .. } => slack.bound(distance.min(cap)),
                    },
                    true,
                ))
            }
        }
    }
}
