//! The world pairs of a robot geometry and a point cloud ([`crate::cloud`]).

use super::RobotChecker;
use crate::answer::ConfigurationAnswer;
use crate::cloud::{cloud_lower_bound, geometry_against_cloud, CloudPair, PointCloud};
use crate::exact::PairOutcome;
use crate::world::WorldShape;
use sublevel_core::math::Real;

impl RobotChecker<'_> {
    /// [`RobotChecker::world_bound`] of robot geometry `g` and cloud object `o` at `level` 1 or
    /// 2: at 1 the nearest point to each of the geometry's sphere-tree balls of a few centimeters
    /// (a cloud has no sos model; [`cloud_lower_bound`]), at 2 the exact gap, or `cap` when every
    /// point ball is farther; and whether it is exact.
    pub(crate) fn cloud_bound(&self, g: usize, o: usize, cloud: &PointCloud, level: u8, cap: Real) -> (Real, bool) {
        let pose = self.world[o].pose.inv_mul(&self.poses[g]);
        let geometry = &self.robot.geometries[g];
        if level < 2 {
            return (cloud_lower_bound(geometry, &pose, cloud), false);
        }
        let gap = match geometry_against_cloud(geometry, &pose, cloud, 0.0, cap, &mut Vec::new()) {
            CloudPair::Touches { .. } => 0.0,
            CloudPair::Free { distance, .. } => distance,
            CloudPair::Apart => cap,
        };
        (gap, true)
    }

    /// World object `o`'s point cloud, for a cloud object.
    pub(crate) fn cloud(&self, o: usize) -> Option<&PointCloud> {
        match &self.world[o].shape {
            WorldShape::Points(c) => Some(c),
            _ => None,
        }
    }

    /// A world pair of a geometry and a point cloud ([`crate::cloud`]): `None` when every point
    /// ball is farther than `bound` (and the padding), else contact or the closest ball, with the
    /// geometry's closest point and the ball's as witnesses.
    pub(crate) fn cloud_pair(
        &self,
        g: usize,
        o: usize,
        cloud: &PointCloud,
        bound: Real,
        padding: Real,
        answer: &mut ConfigurationAnswer,
    ) -> Option<PairOutcome> {
        answer.pairs_exact += 1;
        let place = &self.world[o].pose;
        let pose = place.inv_mul(&self.poses[g]);
        let limit = bound.max(padding);
        match geometry_against_cloud(&self.robot.geometries[g], &pose, cloud, padding, limit, &mut Vec::new()) {
            CloudPair::Apart => None,
            CloudPair::Touches { .. } => Some(PairOutcome::Collides),
            CloudPair::Free { distance, index, x } => {
                let p = cloud.point(index);
                let toward = x - p;
                let y = p + toward * (cloud.radius() / toward.norm().max(Real::MIN_POSITIVE));
                let (x, y) = (place.transform_point(&x.into()), place.transform_point(&y.into()));
                Some(PairOutcome::Free { distance, witnesses: Some((x, y)) })
            }
        }
    }
}
