//! The parry3d-f64 peers of `sublevel-lab bench` and `chart`: GJK on the convex hulls of the two
//! meshes (cold, and warm from the previous closest-point difference), and the exact distance
//! between the triangle meshes, the ground truth of the error columns.

use sublevel_core::math::{Isometry3, Real};
use sublevel_core::{Error, Result};

/// A triangle mesh read from an OFF file: vertices (meters) and triangles (polygons fanned).
#[derive(Debug)]
pub struct OffMesh {
    /// Vertex positions.
    pub vertices: Vec<sublevel_core::math::Point3>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

/// Reads an OFF mesh with its faces (polygons are split into fans) with the fit's OFF parser
/// ([`sublevel_fit::mesh::parse_off_mesh`]: the same header and limit checks).
///
/// # Errors
/// [`Error::Io`] when unreadable; [`Error::InvalidArgument`] naming `mesh` (with the path) for
/// malformed text; [`Error::ResourceExhausted`] beyond the default vertex limit.
pub fn load_off_mesh(path: &std::path::Path) -> Result<OffMesh> {
    use sublevel_fit::mesh::{parse_off_mesh, DEFAULT_MAX_MESH_POINTS};
    let mesh = parse_off_mesh(&std::fs::read(path)?, DEFAULT_MAX_MESH_POINTS).map_err(|e| match e {
        Error::InvalidArgument { field, reason } => Error::invalid(field, format!("{}: {reason}", path.display())),
        other => other,
    })?;
    Ok(OffMesh { vertices: mesh.vertices, triangles: mesh.triangles })
}

fn parry_vec(p: &sublevel_core::math::Point3) -> parry3d_f64::math::Vector {
    parry3d_f64::math::Vector::new(p.x, p.y, p.z)
}

/// Our pose as parry's (glam) pose.
pub fn parry_pose(iso: &Isometry3) -> parry3d_f64::math::Pose {
    let q = iso.rotation.quaternion();
    let t = iso.translation.vector;
    parry3d_f64::math::Pose::from_parts(
        parry3d_f64::math::Vector::new(t.x, t.y, t.z),
        parry3d_f64::math::Rot3::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

/// The peer shapes of one pair: convex hulls (for GJK) and the triangle meshes (exact distance).
pub struct PeerShapes {
    /// Convex hull of A's points.
    pub hull_a: parry3d_f64::shape::ConvexPolyhedron,
    /// Convex hull of B's points.
    pub hull_b: parry3d_f64::shape::ConvexPolyhedron,
    /// A's triangle mesh.
    pub mesh_a: parry3d_f64::shape::TriMesh,
    /// B's triangle mesh.
    pub mesh_b: parry3d_f64::shape::TriMesh,
}

impl PeerShapes {
    /// Builds the hulls and meshes from two OFF meshes.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `mesh` when parry rejects a hull or a mesh.
    pub fn new(a: &OffMesh, b: &OffMesh) -> Result<Self> {
        let hull = |m: &OffMesh| {
            let pts: Vec<_> = m.vertices.iter().map(parry_vec).collect();
            parry3d_f64::shape::ConvexPolyhedron::from_convex_hull(&pts)
                .ok_or_else(|| Error::invalid("mesh", "parry could not build the convex hull"))
        };
        let tri = |m: &OffMesh| {
            parry3d_f64::shape::TriMesh::new(m.vertices.iter().map(parry_vec).collect(), m.triangles.clone())
                .map_err(|e| Error::invalid("mesh", format!("parry rejected the triangle mesh: {e:?}")))
        };
        Ok(Self { hull_a: hull(a)?, hull_b: hull(b)?, mesh_a: tri(a)?, mesh_b: tri(b)? })
    }

    /// Cold GJK distance between the hulls (`parry3d_f64::query::distance`).
    pub fn hull_distance(&self, pose_a: &Isometry3, pose_b: &Isometry3) -> Real {
        parry3d_f64::query::distance(&parry_pose(pose_a), &self.hull_a, &parry_pose(pose_b), &self.hull_b)
            .map_or(Real::NAN, |d| d.distance)
    }

    /// Warm GJK distance between the hulls: the simplex starts from `dir` (A's frame, the previous
    /// closest-point difference), which is updated.
    pub fn hull_distance_warm(
        &self,
        pose_a: &Isometry3,
        pose_b: &Isometry3,
        dir: &mut parry3d_f64::math::Vector,
    ) -> Real {
        use parry3d_f64::query::gjk::{self, CsoPoint, GJKResult, VoronoiSimplex};
        let pos12 = parry_pose(pose_a).inv_mul(&parry_pose(pose_b));
        let back = -pos12.translation;
        let n = if dir.length_squared() > 1e-24 {
            dir.normalize()
        } else if back.length_squared() > 1e-24 {
            back.normalize()
        } else {
            parry3d_f64::math::Vector::X
        };
        let mut simplex = VoronoiSimplex::new();
        simplex.reset(CsoPoint::from_shapes(&pos12, &self.hull_a, &self.hull_b, n));
        match gjk::closest_points(&pos12, &self.hull_a, &self.hull_b, Real::MAX, true, &mut simplex) {
            GJKResult::ClosestPoints(p1, p2, _) => {
                *dir = p1 - p2;
                dir.length()
            }
            _ => 0.0,
        }
    }

    /// Exact distance between the triangle meshes (the ground truth).
    pub fn mesh_distance(&self, pose_a: &Isometry3, pose_b: &Isometry3) -> Real {
        parry3d_f64::query::distance(&parry_pose(pose_a), &self.mesh_a, &parry_pose(pose_b), &self.mesh_b)
            .map_or(Real::NAN, |d| d.distance)
    }
}

/// Mean and max of |model − exact| over the poses where the exact distance is positive.
pub fn error_stats(model: &[Real], exact: &[Real]) -> (Real, Real) {
    let errs: Vec<Real> = model.iter().zip(exact).filter(|(_, e)| **e > 0.0).map(|(m, e)| (m - e).abs()).collect();
    if errs.is_empty() {
        return (Real::NAN, Real::NAN);
    }
    (errs.iter().sum::<Real>() / errs.len() as Real, errs.iter().cloned().fold(0.0, Real::max))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_stats_skip_overlapping_poses() {
        let (mean, max) = error_stats(&[0.9, 2.0, 0.0], &[1.0, 2.5, 0.0]);
        assert!((mean - 0.3).abs() < 1e-12 && (max - 0.5).abs() < 1e-12);
        assert!(error_stats(&[1.0], &[0.0]).0.is_nan());
    }

    #[test]
    fn off_mesh_fans_polygons() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quad.off");
        std::fs::write(&path, "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n").unwrap();
        let m = load_off_mesh(&path).unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        std::fs::write(&path, "OFF\n1 1 0\n0 0 0\n3 0 1 2\n").unwrap();
        assert!(load_off_mesh(&path).unwrap_err().to_string().contains("mesh"));
    }
}
