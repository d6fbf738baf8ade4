//! Point-cloud obstacles: the points a depth camera or a lidar saw, each a ball of the sensor's
//! noise radius, in a k-d tree (kiddo) for the checks' radius queries.
//!
//! ```text
//! frame     float32 x, y, z in the sensor frame (a PointCloud2's layout), or a depth image
//!           deprojected through the pinhole intrinsics ([`depth`])
//! filter    holes (NaN, ±∞, zero depth) dropped · range crop · workspace crop (world box) ·
//!           voxel grid (one point per occupied voxel: the mean of its points) · statistical
//!           outliers (mean distance to k neighbours beyond mean + α·σ) · self filter (points
//!           within a padding of the robot at its joint positions)          [`filter`]
//! obstacle  {x : |x − p_i| ≤ r} for every kept point p_i, r the noise radius
//! ```
//!
//! **Contact.** A robot geometry meets the cloud within padding `s` when some point's ball comes
//! within `s` of it: `dist(p_i, G) ≤ r + s`, with `G` a primitive's solid and a link mesh's
//! triangles (a mesh checker's contact, as coal and FCL decide it, and as the mesh obstacles of
//! [`crate::world`]). The checks find the points near a geometry by radius queries about its
//! sphere tree's balls ([`crate::spheres`]): a ball with no point within its radius plus `r + s`
//! is free, a point within `r + s` less the radius of a node's ball proves contact, and the
//! points left are measured against the mesh exactly (parry's point projection). The verdicts
//! are a brute-force pass's over every point ball (tested).

pub mod bodies;
pub mod depth;
pub mod filter;
mod grid;

pub use grid::{GRID_CELL, GRID_REACH};
pub mod render;

use crate::fitted::{bounding_ball, bounding_box, LinkShape, RobotGeometry};
use crate::spheres::MAX_DEPTH;
use crate::{Error, Result};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};

/// Most points a cloud obstacle keeps after filtering; a frame that leaves more is refused
/// (`ResourceExhausted` naming `points`). A point costs about 48 bytes (its coordinates and the
/// tree's copy), so a cloud stays under about 50 MB; a 2 cm voxel grid leaves a 640 × 480 frame
/// some 10–40 thousand points.
pub const MAX_CLOUD_POINTS: usize = 1_000_000;

/// Largest noise radius a cloud may state (meters).
pub const MAX_NOISE_RADIUS: Real = 1.0;

/// A point-cloud obstacle (module docs): points in the cloud's own frame (meters), each the
/// center of a ball of radius [`PointCloud::radius`], in a k-d tree.
pub struct PointCloud {
    points: Vec<[Real; 3]>,
    radius: Real,
    tree: ImmutableKdTree<Real, 3>,
    /// Lower bounds of the distance to the points, cell by cell: most radius queries end here.
    grid: grid::GapGrid,
    /// Ball containing every point ball (own frame): center, radius; radius −1 when empty.
    ball: (Vector3, Real),
    /// Box containing every point ball (own frame): center, half extents.
    local_box: (Vector3, Vector3),
}

impl std::fmt::Debug for PointCloud {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointCloud").field("points", &self.points.len()).field("radius", &self.radius).finish()
    }
}

impl PointCloud {
    /// A cloud of `points` (own frame, meters), each a ball of `radius` meters (the sensor's
    /// noise radius, ≥ 0). No points is a valid cloud that nothing meets.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `radius` (negative, not finite, or above
    /// [`MAX_NOISE_RADIUS`]) or `points[k]` (a coordinate not finite or beyond ±1e6 m);
    /// [`Error::ResourceExhausted`] naming `points` past [`MAX_CLOUD_POINTS`].
    pub fn new(points: Vec<[Real; 3]>, radius: Real) -> Result<Self> {
        if !(radius.is_finite() && (0.0..=MAX_NOISE_RADIUS).contains(&radius)) {
            return Err(Error::invalid(
                "radius",
                format!(
                    "must be finite, in [0, {MAX_NOISE_RADIUS}] m, got {}",
                    sublevel_core::error::show_real(radius)
                ),
            ));
        }
        if points.len() > MAX_CLOUD_POINTS {
            return Err(Error::ResourceExhausted(format!(
                "points: {} points after filtering, more than the {MAX_CLOUD_POINTS} a cloud obstacle may keep \
                 (about 48 bytes each); set a voxel filter or a workspace crop",
                points.len()
            )));
        }
        let limit = sublevel_core::math::MAX_COORDINATE;
        if let Some(k) = points.iter().position(|p| p.iter().any(|v| !(v.is_finite() && v.abs() <= limit))) {
            return Err(Error::invalid(
                format!("points[{k}]"),
                format!("{:?} must be finite and within ±{limit:e} m", points[k]),
            ));
        }
        let tree = ImmutableKdTree::new_from_slice(&points)
            .map_err(|e| Error::invalid("points", format!("the k-d tree could not be built: {e:?}")))?;
        let (ball, local_box) = if points.is_empty() {
            ((Vector3::zeros(), -1.0), (Vector3::zeros(), Vector3::zeros()))
        } else {
            let p: Vec<Point3> = points.iter().map(|v| Point3::new(v[0], v[1], v[2])).collect();
            let (c, r) = bounding_ball(&p);
            let (bc, h) = bounding_box(&p);
            ((c, r + radius), (bc, h.add_scalar(radius)))
        };
        let grid = grid::GapGrid::build(&points);
        Ok(Self { points, radius, tree, grid, ball, local_box })
    }

    /// The points (own frame, meters).
    pub fn points(&self) -> &[[Real; 3]] {
        &self.points
    }

    /// Point `i` (own frame, meters).
    pub fn point(&self, i: usize) -> Vector3 {
        Vector3::from(self.points[i])
    }

    /// The noise radius: every point is a ball of this radius (meters).
    pub fn radius(&self) -> Real {
        self.radius
    }

    /// How many points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// A ball containing every point ball (own frame): center and radius (meters); radius −1 for
    /// an empty cloud.
    pub fn ball(&self) -> (Vector3, Real) {
        self.ball
    }

    /// The axis-aligned box containing every point ball (own frame): center and half extents.
    pub fn local_box(&self) -> (Vector3, Vector3) {
        self.local_box
    }

    /// Bytes the cloud holds (points and tree), for the memory limits.
    pub fn memory_bytes(&self) -> usize {
        // The tree keeps a copy of the coordinates and an index per point.
        self.points.len() * (2 * std::mem::size_of::<[Real; 3]>() + 8)
            + self.grid.memory_bytes()
            + std::mem::size_of::<Self>()
    }

    /// Whether some point lies within `distance` of `center` (own frame, meters): `|p − c| ≤ d`.
    pub fn any_within(&self, center: &Vector3, distance: Real) -> bool {
        if self.points.is_empty() || distance < 0.0 {
            return false;
        }
        if let Some(found) = self.grid.any_within(&self.points, center, distance) {
            return found;
        }
        if self.grid.clear(center, distance) {
            return false;
        }
        let nearest =
            self.tree.query(&[center.x, center.y, center.z]).nearest_one::<SquaredEuclidean<Real>>().execute();
        nearest.distance <= distance * distance
    }

    /// Whether the cloud's gap grid alone shows that no point lies within `distance` of `center`
    /// (false: it cannot tell; [`PointCloud::any_within`] then asks the tree).
    #[inline]
    pub(crate) fn clear_by_grid(&self, center: &Vector3, distance: Real) -> bool {
        self.grid.clear(center, distance)
    }

    /// The nearest point to `center` (own frame): its index and distance (meters); `None` when
    /// empty.
    pub fn nearest(&self, center: &Vector3) -> Option<(usize, Real)> {
        if self.points.is_empty() {
            return None;
        }
        let n = self.tree.query(&[center.x, center.y, center.z]).nearest_one::<SquaredEuclidean<Real>>().execute();
        Some((n.item as usize, n.distance.sqrt()))
    }

    /// Appends to `out` the indices of the points within `distance` of `center` (own frame,
    /// meters), unsorted.
    pub fn within(&self, center: &Vector3, distance: Real, out: &mut Vec<usize>) {
        if self.points.is_empty()
            || distance < 0.0
            || self.grid.within(&self.points, center, distance, out)
            || self.grid.clear(center, distance)
        {
            return;
        }
        let found = self
            .tree
            .query(&[center.x, center.y, center.z])
            .within::<SquaredEuclidean<Real>>(distance * distance)
            .unsorted()
            .execute();
        out.extend(found.iter().map(|n| n.item as usize));
    }
}

/// What a radius search of one robot geometry against a cloud found ([`geometry_against_cloud`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum CloudPair {
    /// Every point ball is farther than the limit from the geometry.
    Apart,
    /// Point `index`'s ball comes within the padding of the geometry.
    Touches {
        /// The point's index.
        index: usize,
    },
    /// The closest point ball is `distance` away (padding < distance ≤ limit): point `index`,
    /// and `x`, the geometry's closest point (cloud frame).
    Free {
        /// Gap between the geometry and the point's ball (meters).
        distance: Real,
        /// The point's index.
        index: usize,
        /// The geometry's point closest to it (cloud frame).
        x: Vector3,
    },
}

/// Distance from `y` (geometry frame) to a robot geometry: a primitive's solid (0 inside) or a
/// link mesh's triangles (parry's point projection), and the closest point (geometry frame).
pub(crate) fn point_to_geometry(shape: &LinkShape, y: &Vector3) -> (Real, Vector3) {
    match shape {
        LinkShape::Primitive(p) => {
            if crate::spheres::primitive_signed_distance(p, y) <= 0.0 {
                return (0.0, *y);
            }
            let (d, x) = p.closest_boundary_point(y);
            (d.max(0.0), x)
        }
        LinkShape::Mesh { exact, .. } => {
            let q = parry3d_f64::math::Vector::new(y.x, y.y, y.z);
            let proj = exact.project_local_point(q, false);
            let x = Vector3::new(proj.point.x, proj.point.y, proj.point.z);
            ((x - y).norm(), x)
        }
    }
}

/// One robot geometry (`shape`, with its bounding ball `sphere` and box `local_box` in the
/// geometry frame; `pose` maps the geometry frame into the cloud's) against `cloud`: contact
/// within `padding` (≥ 0), else the closest point ball when it lies within `limit` (≥ padding;
/// `limit == padding` asks for a verdict only, which stops at the first contact). Candidates
/// come from one radius query about the bounding ball; each is dropped by the box bound or
/// measured exactly ([`point_to_geometry`]). `scratch` holds the candidates.
pub(crate) fn geometry_against_cloud(
    geometry: &RobotGeometry,
    pose: &Isometry3,
    cloud: &PointCloud,
    padding: Real,
    limit: Real,
    scratch: &mut Vec<usize>,
) -> CloudPair {
    let r = cloud.radius();
    if limit <= padding {
        if let LinkShape::Mesh { spheres, .. } = &geometry.shape {
            if !spheres.nodes.is_empty() {
                return tree_against_cloud(geometry, spheres, pose, cloud, padding, scratch);
            }
        }
    }
    let (center, radius) = geometry.sphere;
    let reach = r + limit;
    let c = pose.transform_point(&center.into()).coords;
    let mut best: Option<(Real, usize, Vector3)> = None;
    let mut reach = reach;
    if limit > padding {
        // A distance is asked for: the point nearest the ball's center gives an upper bound of
        // it, and no point farther from the center than that bound plus the radii can do better.
        let Some((i, d)) = cloud.nearest(&c) else { return CloudPair::Apart };
        if d - radius - r > limit {
            return CloudPair::Apart;
        }
        let y = pose.inverse_transform_point(&cloud.point(i).into()).coords;
        let (d, x) = point_to_geometry(&geometry.shape, &y);
        if d - r <= padding {
            return CloudPair::Touches { index: i };
        }
        if d - r <= limit {
            best = Some((d - r, i, x));
            reach = d;
        }
    }
    scratch.clear();
    cloud.within(&c, radius + reach, scratch);
    for &i in scratch.iter() {
        let y = pose.inverse_transform_point(&cloud.point(i).into()).coords;
        if let Some((bc, h)) = &geometry.local_box {
            let out = ((y - bc).abs() - h).map(|v| v.max(0.0)).norm();
            if out > reach {
                continue;
            }
        }
        let (d, x) = point_to_geometry(&geometry.shape, &y);
        let gap = d - r;
        if gap <= padding {
            return CloudPair::Touches { index: i };
        }
        if gap <= limit && best.is_none_or(|b| gap < b.0) {
            best = Some((gap, i, x));
        }
    }
    match best {
        Some((distance, index, x)) => CloudPair::Free { distance, index, x: pose.transform_point(&x.into()).coords },
        None => CloudPair::Apart,
    }
}

/// Radius of the sphere-tree balls [`cloud_lower_bound`] measures from (meters).
const BOUND_BALL: Real = 0.05;

/// A lower bound of the gap between a robot geometry (`pose`: geometry frame → the cloud's) and
/// the cloud's point balls (meters, ≥ 0): the nearest point to each ball of the geometry's
/// sphere tree no larger than [`BOUND_BALL`] (the tree's leaves where larger), less the ball's
/// radius and the noise radius; for a primitive, its bounding ball's. Some twenty nearest-point
/// queries on a Panda link, against the hundreds of exact point distances of
/// [`geometry_against_cloud`]: conservative advancement takes this first.
pub(crate) fn cloud_lower_bound(geometry: &RobotGeometry, pose: &Isometry3, cloud: &PointCloud) -> Real {
    let r = cloud.radius();
    let gap = |center: &Vector3, radius: Real| match cloud.nearest(&pose.transform_point(&(*center).into()).coords) {
        Some((_, d)) => d - radius - r,
        None => Real::INFINITY,
    };
    let best = match &geometry.shape {
        LinkShape::Mesh { spheres, .. } if !spheres.nodes.is_empty() => {
            let mut best = Real::INFINITY;
            // A fixed stack: a descent holds at most one sibling per level.
            let (mut stack, mut len) = ([0u32; MAX_DEPTH + 2], 1);
            while len > 0 {
                len -= 1;
                let node = &spheres.nodes[stack[len] as usize];
                if node.sphere.radius > BOUND_BALL && node.children != 0 {
                    stack[len] = node.children;
                    stack[len + 1] = node.children + 1;
                    len += 2;
                } else {
                    best = best.min(gap(&node.sphere.center, node.sphere.radius));
                }
            }
            best
        }
        _ => gap(&geometry.sphere.0, geometry.sphere.1),
    };
    best.max(0.0)
}

/// A link mesh's verdict against a cloud by its sphere tree ([`crate::spheres`]): a node whose
/// ball has no point within its radius plus `r + padding` is free with everything below it; a
/// point within `r + padding` less a node's radius of its center meets the piece of triangle the
/// node holds (contact); a leaf neither decides measures its nearby points against the mesh.
fn tree_against_cloud(
    geometry: &RobotGeometry,
    spheres: &crate::spheres::SphereTree,
    pose: &Isometry3,
    cloud: &PointCloud,
    padding: Real,
    scratch: &mut Vec<usize>,
) -> CloudPair {
    let r = cloud.radius();
    let touch = r + padding;
    let (mut stack, mut len) = ([0u32; MAX_DEPTH + 2], 1);
    while len > 0 {
        len -= 1;
        let node = &spheres.nodes[stack[len] as usize];
        let c = pose.transform_point(&node.sphere.center.into()).coords;
        let rho = node.sphere.radius;
        if !cloud.any_within(&c, rho + touch) {
            continue;
        }
        if touch > rho {
            scratch.clear();
            cloud.within(&c, touch - rho, scratch);
            if let Some(&index) = scratch.first() {
                return CloudPair::Touches { index };
            }
        }
        if node.children != 0 {
            stack[len] = node.children;
            stack[len + 1] = node.children + 1;
            len += 2;
            continue;
        }
        scratch.clear();
        cloud.within(&c, rho + touch, scratch);
        for &i in scratch.iter() {
            let y = pose.inverse_transform_point(&cloud.point(i).into()).coords;
            if point_to_geometry(&geometry.shape, &y).0 - r <= padding {
                return CloudPair::Touches { index: i };
            }
        }
    }
    CloudPair::Apart
}

/// The brute-force reference of the cloud checks: the smallest gap (meters, 0 on contact) between
/// a robot geometry placed by `link_poses` ([`crate::RobotModel::forward_kinematics`]) and the
/// ball of radius `radius` about any of `points` (world frame), by parry's distance between the
/// ball and the geometry's exact shape (a link mesh's triangles, a primitive's solid), over every
/// pair whose bounding balls come within `reach` (∞ when none does). It shares nothing with the
/// checks but the shapes, and costs a parry query per point near each geometry: for tests and
/// benchmarks.
pub fn reference_gap(
    robot: &crate::FittedRobot,
    link_poses: &[Isometry3],
    points: &[[Real; 3]],
    radius: Real,
    reach: Real,
) -> Real {
    let ball = parry3d_f64::shape::Ball::new(radius.max(1e-12));
    let mut best = Real::INFINITY;
    for g in &robot.geometries {
        let pose = link_poses[g.link] * g.origin;
        let c = pose.transform_point(&g.sphere.0.into()).coords;
        let exact = crate::check::exact_shape(g);
        let placed = crate::exact::parry_pose(&(pose * exact.offset));
        for p in points {
            let v = Vector3::from(*p);
            if (v - c).norm() > g.sphere.1 + radius + reach {
                continue;
            }
            let at = crate::exact::parry_pose(&Isometry3::translation(v.x, v.y, v.z));
            let Ok(d) = parry3d_f64::query::distance(&placed, exact.shape.as_ref(), &at, &ball) else {
                return 0.0;
            };
            // A zero radius is a point: parry's tiny ball stands for it.
            best = best.min(if radius == 0.0 { d.distance + 1e-12 } else { d.distance });
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_cloud(n: usize, seed: u64) -> Vec<[Real; 3]> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..n).map(|_| [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(0.0..1.0)]).collect()
    }

    #[test]
    fn radius_queries_equal_brute_force() {
        let points = random_cloud(5000, 1);
        let cloud = PointCloud::new(points.clone(), 0.01).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(2);
        let mut found = Vec::new();
        for _ in 0..200 {
            let c = Vector3::new(rng.random_range(-1.2..1.2), rng.random_range(-1.2..1.2), rng.random_range(-0.2..1.2));
            let d = rng.random_range(0.0..0.2);
            let brute: Vec<usize> = (0..points.len()).filter(|&i| (Vector3::from(points[i]) - c).norm() <= d).collect();
            found.clear();
            cloud.within(&c, d, &mut found);
            found.sort_unstable();
            assert_eq!(found, brute);
            assert_eq!(cloud.any_within(&c, d), !brute.is_empty());
            let best = points.iter().map(|p| (Vector3::from(*p) - c).norm()).fold(Real::INFINITY, Real::min);
            assert!((cloud.nearest(&c).unwrap().1 - best).abs() < 1e-12);
        }
    }

    #[test]
    fn bounds_hold_every_point_ball() {
        let points = random_cloud(1000, 3);
        let cloud = PointCloud::new(points.clone(), 0.02).unwrap();
        let (c, r) = cloud.ball();
        let (bc, h) = cloud.local_box();
        for p in &points {
            let p = Vector3::from(*p);
            assert!((p - c).norm() + 0.02 <= r + 1e-12);
            assert!(((p - bc).abs() + Vector3::repeat(0.02) - h).max() <= 1e-12);
        }
    }

    #[test]
    fn bad_clouds_name_the_field() {
        let err = |r: Result<PointCloud>| r.unwrap_err().to_string();
        assert!(err(PointCloud::new(vec![[0.0, Real::NAN, 0.0]], 0.01)).contains("points[0]"));
        assert!(err(PointCloud::new(vec![[0.0; 3]], -0.1)).contains("radius"));
        assert!(err(PointCloud::new(vec![[0.0; 3]], 2.0)).contains("radius"));
        assert!(err(PointCloud::new(vec![[0.0; 3]; MAX_CLOUD_POINTS + 1], 0.01)).contains("points"));
        let empty = PointCloud::new(Vec::new(), 0.01).unwrap();
        assert!(
            empty.is_empty()
                && !empty.any_within(&Vector3::zeros(), 10.0)
                && empty.nearest(&Vector3::zeros()).is_none()
        );
    }
}
