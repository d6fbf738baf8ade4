//! Distances to a mesh's surface: the one-sided Hausdorff excess of a body over the mesh.
//!
//! ```text
//! excess(S, M) = max_k d(b_k, ∂M),   b_k ∈ ∂S boundary samples (rays from S's interior point,
//!                                     fit::containment::boundary_points), d = distance to the
//!                                     nearest mesh triangle (parry's TriMesh point projection)
//! ```
//!
//! A sampled lower estimate of the one-sided Hausdorff distance `sup_{x ∈ ∂S} d(x, M)`: how far
//! the body's surface reaches beyond the mesh, in meters. The distance is unsigned (meshes need
//! not be closed), so a boundary point inside a closed mesh counts by its distance to the
//! surface too.

use crate::{Error, Result};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real};

/// Boundary samples per node used for the excess by default.
pub const DEFAULT_EXCESS_SAMPLES: usize = 1000;

/// A triangle mesh with a bounding volume hierarchy, for point–surface distances (meters).
pub struct MeshSurface {
    mesh: TriMesh,
}

impl MeshSurface {
    /// Builds the hierarchy of `triangles` (indices into `vertices`, meters).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `mesh` when parry refuses the mesh (no triangles, an
    /// index out of range).
    pub fn new(vertices: &[Point3], triangles: &[[u32; 3]]) -> Result<Self> {
        // parry panics on an index out of range: refuse it first.
        if let Some(k) = triangles.iter().position(|t| t.iter().any(|&i| i as usize >= vertices.len())) {
            return Err(Error::invalid(
                "mesh",
                format!("triangle {k} names a vertex beyond the {} vertices", vertices.len()),
            ));
        }
        let v: Vec<PVec> = vertices.iter().map(|p| PVec::new(p.x, p.y, p.z)).collect();
        let mesh = TriMesh::new(v, triangles.to_vec()).map_err(|e| Error::invalid("mesh", format!("{e:?}")))?;
        Ok(Self { mesh })
    }

    /// Distance (meters) from `x` to the nearest point of any triangle.
    pub fn distance(&self, x: &Point3) -> Real {
        self.mesh.distance_to_local_point(PVec::new(x.x, x.y, x.z), false)
    }

    /// The sampled one-sided Hausdorff excess of `body` (its own frame = the mesh's) over the
    /// mesh, with `samples` boundary points (see the module docs), meters.
    ///
    /// # Errors
    /// [`Error::Numerical`] when the body's boundary cannot be sampled (not coercive).
    pub fn excess(&self, body: &Body, samples: usize) -> Result<Real> {
        let pts = crate::containment::boundary_points(body, &Isometry3::identity(), samples)?;
        Ok(pts.iter().map(|x| self.distance(x)).fold(0.0, Real::max))
    }
}
