//! The world a robot is checked in: named objects, each an exact primitive, a triangle mesh, a
//! point cloud ([`crate::cloud`]) or a sos-convex body (a cloud's cluster,
//! [`crate::cloud::bodies`]), placed in the world frame.
//!
//! A mesh object is exact the way a link mesh is: its triangles decide contact (parry's BVH, as
//! coal and FCL decide it). It may carry a sos-convex body that contains it — the root of the
//! compound body it was fitted to (paper §V) — which then gives the cheap lower bound of the
//! checks' model stage; without one, pairs go from the ball and box gaps straight to the
//! triangles.
//!
//! A body object is its own exact shape: the convex set {p ≤ 1}. Its sos bound is the body
//! itself, and the exact stage gives it to parry as a support map ([`body_shape`]), so a link
//! mesh meets it triangle by triangle, as it meets a primitive.

mod body_shape;

pub(crate) use body_shape::{closest_points, intersection_test};

use crate::cloud::PointCloud;
use crate::fitted::{bounding_ball, bounding_box, exact_trimesh, validate_mesh};
use crate::{Error, Result};
use std::sync::Arc;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::primitive::Primitive;

/// An object of the world: a shape placed in the world frame.
#[derive(Clone, Debug)]
pub struct WorldObject {
    /// Its name (a MoveIt collision object's id, with `#k` for its k-th shape, k ≥ 1).
    pub name: String,
    /// The shape, in its own frame.
    pub shape: WorldShape,
    /// Shape frame → world.
    pub pose: Isometry3,
}

impl WorldObject {
    /// An exact primitive named `name` at `pose`.
    pub fn primitive(name: impl Into<String>, primitive: Primitive, pose: Isometry3) -> Self {
        Self { name: name.into(), shape: WorldShape::Primitive(primitive), pose }
    }

    /// A triangle mesh named `name` at `pose`.
    pub fn mesh(name: impl Into<String>, mesh: Arc<WorldMesh>, pose: Isometry3) -> Self {
        Self { name: name.into(), shape: WorldShape::Mesh(mesh), pose }
    }

    /// A point cloud named `name`, its points mapped into the world by `pose`.
    pub fn points(name: impl Into<String>, cloud: Arc<PointCloud>, pose: Isometry3) -> Self {
        Self { name: name.into(), shape: WorldShape::Points(cloud), pose }
    }

    /// A sos-convex body named `name` at `pose`.
    pub fn body(name: impl Into<String>, body: Arc<WorldBody>, pose: Isometry3) -> Self {
        Self { name: name.into(), shape: WorldShape::Body(body), pose }
    }

    /// The primitive, for a primitive object.
    pub fn as_primitive(&self) -> Option<&Primitive> {
        match &self.shape {
            WorldShape::Primitive(p) => Some(p),
            _ => None,
        }
    }
}

/// The shape of a [`WorldObject`].
#[derive(Clone, Debug)]
pub enum WorldShape {
    /// An exact primitive (box, sphere, cylinder, capsule, halfspace).
    Primitive(Primitive),
    /// A triangle mesh, shared by the objects that place it.
    Mesh(Arc<WorldMesh>),
    /// A point cloud: a ball of the cloud's noise radius about every point ([`crate::cloud`]).
    Points(Arc<PointCloud>),
    /// A convex sos body, its own exact shape (module docs).
    Body(Arc<WorldBody>),
}

impl WorldShape {
    /// The shape's kind: the primitive's (`box`, `sphere`, …) or `mesh`.
    pub fn kind(&self) -> &'static str {
        match self {
            WorldShape::Primitive(p) => p.kind(),
            WorldShape::Mesh(_) => "mesh",
            WorldShape::Points(_) => "points",
            WorldShape::Body(_) => "body",
        }
    }

    /// A ball containing the shape in its own frame: center and radius (meters; infinite for a
    /// halfspace, −1 for a cloud without points).
    pub fn ball(&self) -> (Vector3, Real) {
        match self {
            WorldShape::Primitive(p) => (Vector3::zeros(), p.bounding_radius()),
            WorldShape::Mesh(m) => m.ball,
            WorldShape::Points(c) => c.ball(),
            WorldShape::Body(b) => b.ball,
        }
    }

    /// The axis-aligned box containing the shape in its own frame: center and half extents
    /// (meters); `None` for a halfspace.
    pub fn local_box(&self) -> Option<(Vector3, Vector3)> {
        match self {
            WorldShape::Primitive(p) => p.local_half_extents().map(|h| (Vector3::zeros(), h)),
            WorldShape::Mesh(m) => Some(m.local_box),
            WorldShape::Points(c) => Some(c.local_box()),
            WorldShape::Body(b) => Some(b.local_box),
        }
    }
}

/// A triangle mesh obstacle, validated, with its BVH built once (see the module docs).
#[derive(Clone, Debug)]
pub struct WorldMesh {
    vertices: Vec<Point3>,
    triangles: Vec<[u32; 3]>,
    body: Option<Body>,
    pub(crate) exact: parry3d_f64::shape::SharedShape,
    ball: (Vector3, Real),
    local_box: (Vector3, Vector3),
}

/// Slack of the containment check of a mesh's vertices in its body (`p ≤ 1 + slack`).
const CONTAINMENT_SLACK: Real = 1e-9;

impl WorldMesh {
    /// A mesh of `vertices` (its own frame, meters) and `triangles` (indices into `vertices`),
    /// with `body`, when given, a sos-convex body containing it (the root of the compound body
    /// fitted to it), verified on every vertex.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `triangles` (none, more than 2 000 000, or not a valid
    /// triangle mesh), `triangles[k]` (an index beyond the vertices), `vertices[k]` (not finite or
    /// beyond ±1e6 m) or `body` (a vertex outside it).
    pub fn new(vertices: Vec<Point3>, triangles: Vec<[u32; 3]>, body: Option<Body>) -> Result<Self> {
        validate_mesh("", &vertices, &triangles)?;
        if let Some(body) = &body {
            if let Some((i, p)) = vertices
                .iter()
                .map(|v| body.value_at(v))
                .enumerate()
                .find(|(_, p)| p.is_nan() || *p > 1.0 + CONTAINMENT_SLACK)
            {
                return Err(Error::invalid(
                    "body",
                    format!("mesh vertex {i} lies outside the body (p = {p}): the body does not contain the mesh"),
                ));
            }
        }
        let exact = exact_trimesh("triangles", &vertices, &triangles)?;
        let ball = bounding_ball(&vertices);
        let local_box = bounding_box(&vertices);
        Ok(Self { vertices, triangles, body, exact, ball, local_box })
    }

    /// The vertices (own frame, meters).
    pub fn vertices(&self) -> &[Point3] {
        &self.vertices
    }

    /// The triangles, as indices into [`WorldMesh::vertices`].
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The sos-convex body containing the mesh, when it has one.
    pub fn body(&self) -> Option<&Body> {
        self.body.as_ref()
    }
}

/// A convex sos body obstacle with its parry shape, built once (see the module docs).
#[derive(Clone, Debug)]
pub struct WorldBody {
    body: Arc<Body>,
    pub(crate) exact: parry3d_f64::shape::SharedShape,
    ball: (Vector3, Real),
    local_box: (Vector3, Vector3),
}

impl WorldBody {
    /// The obstacle {x : p(x) ≤ 1} of a convex `body` (its own frame, meters).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `body` for a nonconvex body (it has no certified
    /// bounding box or support bound, and the exact stage needs a convex set).
    pub fn new(body: Arc<Body>) -> Result<Self> {
        let nonconvex = || Error::invalid("body", "is not convex: a body obstacle must be a convex sublevel set");
        let (c, h) = body.bounding_box().ok_or_else(nonconvex)?;
        let (sc, r) = body.bounding_sphere().ok_or_else(nonconvex)?;
        let shape = body_shape::BodyShape::new(body.clone()).ok_or_else(nonconvex)?;
        Ok(Self {
            body,
            exact: parry3d_f64::shape::SharedShape(Arc::new(shape)),
            ball: (sc.coords, r),
            local_box: (c.coords, h),
        })
    }

    /// The body.
    pub fn body(&self) -> &Body {
        &self.body
    }

    /// The shared body.
    pub fn shared(&self) -> &Arc<Body> {
        &self.body
    }

    /// Whether every piece of a link's sphere tree, posed in the body's frame by `rel`, is
    /// farther than `threshold` (meters) from the body: each node dropped by the gap between its
    /// center and the body's supporting plane normal to the direction from the body's center, with
    /// the certified upper bound of the body's support function ([`Body::support_upper`]).
    pub(crate) fn tree_apart(&self, spheres: &crate::spheres::SphereTree, rel: &Isometry3, threshold: Real) -> bool {
        let body = &self.body;
        let lower = |x: &Vector3| {
            let d = x - body.center();
            let n = d.norm();
            if !(n > 0.0 && n.is_finite()) {
                return 0.0;
            }
            let u = d / n;
            body.support_upper(&u).map_or(0.0, |h| u.dot(x) - h)
        };
        spheres.apart_by(rel.rotation.to_rotation_matrix().matrix(), &rel.translation.vector, threshold, lower)
    }
}
