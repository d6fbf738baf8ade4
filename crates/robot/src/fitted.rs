//! A robot fitted for collision queries: its URDF model, the link pairs its SRDF allows to touch,
//! and every link's collision geometry as an exact primitive or as a compound sos-convex body that
//! contains the link's mesh (paper §V), with the mesh kept for the exact stage of the checks.
//!
//! ```text
//! robot.json  {"format": "sublevel.robot.v1", "name", "urdf": <URDF text>,
//!              "allowed_pairs": [["panda_link0", "panda_link1"], …],      (SRDF disable_collisions)
//!              "geometries": [{"link", "index", "origin": {"translation", "rotation"},
//!                              "primitive": {…}                            (a URDF box, cylinder, …)
//!                           or "mesh": {"source", "sha256", "scale", "vertices", "triangles"},
//!                              "compound": {…}},                           (sublevel.compound.v1)
//!                             …],
//!              "report": {"seconds", "fitted", "cached", "notes"}}
//! ```
//!
//! A geometry's frame is its URDF `<collision><origin>` in its link's frame; a mesh is stored
//! scaled, in that frame, and its compound body is fitted to those vertices (every triangle inside
//! a leaf). [`FittedRobot::from_file`] validates everything a check relies on, naming the field.
//!
//! The checks read a compound body's **root** only (its sos bound; the mesh decides what the
//! bound cannot), so a robot is built with the root bodies alone — the leaves stay in the file —
//! and every mesh vertex is verified inside its root (`p ≤ 1 + 1e-9`): a convex root holding the
//! vertices holds the mesh, which is what makes the root's distance a lower bound of the mesh's.
//! Building the ~350 nodes of the Panda's trees took seconds of support tables nothing reads.

use crate::clearance::{ClearanceFile, ClearanceTable};
use crate::inner::InnerBalls;
use crate::model::RobotModel;
use crate::spheres::{SphereTree, DEFAULT_LEAF_RADIUS};
use crate::{Error, Result};
use nalgebra::{Quaternion, Translation3};
use serde::{Deserialize, Serialize};
use std::path::Path;
use sublevel_core::body::Body;
use sublevel_core::compound::{CompoundFile, COMPOUND_FORMAT};
use sublevel_core::math::{Isometry3, Point3, Real, UnitQuaternion, Vector3};
use sublevel_core::primitive::{Primitive, PrimitiveFile};

/// The `format` of a robot file.
pub const ROBOT_FORMAT: &str = "sublevel.robot.v1";

/// Most triangles one link mesh may hold in a robot file.
pub const MAX_MESH_TRIANGLES: usize = 2_000_000;

/// A pose in a robot file: translation in meters and a unit quaternion (w, x, y, z).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseFile {
    /// Translation, meters.
    pub translation: [Real; 3],
    /// Rotation as a unit quaternion (w, x, y, z); normalized on reading.
    pub rotation: [Real; 4],
}

impl PoseFile {
    /// The file form of `pose`.
    pub fn of(pose: &Isometry3) -> Self {
        let t = pose.translation.vector;
        let q = pose.rotation.quaternion();
        Self { translation: [t.x, t.y, t.z], rotation: [q.w, q.i, q.j, q.k] }
    }

    /// The pose, validated.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `field` when a number is not finite or the quaternion is
    /// zero.
    pub fn to_pose(&self, field: &str) -> Result<Isometry3> {
        let [w, x, y, z] = self.rotation;
        let norm = (w * w + x * x + y * y + z * z).sqrt();
        if self.translation.iter().chain(&self.rotation).any(|v| !v.is_finite()) || norm <= 1e-9 {
            return Err(Error::invalid(
                field,
                "translation and rotation must be finite, the rotation a nonzero quaternion (w, x, y, z)",
            ));
        }
        let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        let [tx, ty, tz] = self.translation;
        Ok(Isometry3::from_parts(Translation3::new(tx, ty, tz), q))
    }
}

/// A link mesh as stored in a robot file: scaled, in its geometry's frame (meters).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeshFile {
    /// The URDF's file name (`package://…`), for the reader.
    pub source: String,
    /// SHA-256 of the file's bytes (hex), the key of the fit cache with `scale` and the settings.
    pub sha256: String,
    /// The URDF's per-axis scale, already applied to `vertices`.
    pub scale: [Real; 3],
    /// Vertices, meters.
    pub vertices: Vec<[Real; 3]>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// One collision geometry of a robot file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GeometryFile {
    /// The link's URDF name.
    pub link: String,
    /// Which `<collision>` element of the link (0-based).
    pub index: usize,
    /// The geometry's frame in the link's frame.
    pub origin: PoseFile,
    /// An exact primitive (URDF box, cylinder, sphere, capsule).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub primitive: Option<PrimitiveFile>,
    /// A mesh (with `compound`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshFile>,
    /// The compound body containing `mesh` (a `sublevel.compound.v1` file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compound: Option<CompoundFile>,
}

/// What a robot fit did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RobotFitReport {
    /// Wall time of the fit, seconds.
    pub seconds: Real,
    /// Distinct meshes fitted.
    pub fitted: usize,
    /// Distinct meshes taken from the cache.
    pub cached: usize,
    /// Per mesh: leaves, worst leaf excess and the tolerance, and anything the reader should know.
    pub notes: Vec<String>,
}

/// A robot file (see the module docs).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RobotFile {
    /// Always [`ROBOT_FORMAT`].
    pub format: String,
    /// The robot's URDF name.
    pub name: String,
    /// The URDF text (collision geometry read from `geometries`, not from its mesh paths).
    pub urdf: String,
    /// Link pairs allowed to touch (the SRDF's `disable_collisions`).
    #[serde(default)]
    pub allowed_pairs: Vec<[String; 2]>,
    /// Every link's collision geometry.
    pub geometries: Vec<GeometryFile>,
    /// What the fit did.
    #[serde(default)]
    pub report: RobotFitReport,
    /// Clearance tables of self pairs moved by one or two joints ([`crate::clearance`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clearance: Vec<ClearanceFile>,
}

/// A link's collision geometry as the checks use it.
#[derive(Clone, Debug)]
pub enum LinkShape {
    /// An exact primitive.
    Primitive(Primitive),
    /// A mesh (geometry frame, meters) and the root body of the compound body containing it.
    Mesh {
        /// The compound body's root (geometry frame): it contains every leaf, hence every
        /// triangle (verified on every vertex when the robot is read).
        body: Box<Body>,
        /// Vertices, meters.
        vertices: Vec<Point3>,
        /// Triangles.
        triangles: Vec<[u32; 3]>,
        /// parry's triangle mesh of `vertices` and `triangles` with its BVH, built once when the
        /// robot is read (the exact stage of [`crate::check`]).
        exact: parry3d_f64::shape::SharedShape,
        /// The sphere tree (geometry frame): every point of every triangle inside a chain of its
        /// balls, built when the robot is read ([`crate::spheres`]); the checks' first stage.
        spheres: SphereTree,
        /// Balls inside the mesh's closed components (geometry frame), built when the robot is
        /// read ([`crate::inner`]): quick proofs of contact.
        inner: InnerBalls,
    },
}

/// One collision geometry of a [`FittedRobot`].
#[derive(Clone, Debug)]
pub struct RobotGeometry {
    /// Index of its link in [`RobotModel::links`].
    pub link: usize,
    /// `LINK` or `LINK#k` for a link's k-th geometry (k ≥ 1).
    pub name: String,
    /// Geometry frame → link frame.
    pub origin: Isometry3,
    /// The shape.
    pub shape: LinkShape,
    /// A ball containing the mesh or primitive: its center in the geometry frame and radius
    /// (meters); infinite for a halfspace.
    pub sphere: (Vector3, Real),
    /// The box containing the mesh or primitive, axis-aligned in the geometry frame: its center
    /// and half extents (meters); `None` for a halfspace.
    pub local_box: Option<(Vector3, Vector3)>,
}

/// A robot fitted for collision queries (module docs).
#[derive(Clone, Debug)]
pub struct FittedRobot {
    /// The kinematic model.
    pub model: RobotModel,
    /// Every collision geometry, grouped by link in URDF order.
    pub geometries: Vec<RobotGeometry>,
    /// Link pairs allowed to touch (SRDF).
    pub allowed_pairs: Vec<[String; 2]>,
    /// Link pairs self-collision checks test (both have geometry, not allowed), as link indices.
    pub self_pairs: Vec<(usize, usize)>,
    /// The file this robot was read from or is saved as.
    pub file: RobotFile,
    /// The clearance tables of `file`, validated ([`crate::clearance`]).
    pub clearance: Vec<ClearanceTable>,
}

/// The axis-aligned box of points: its center and half extents (zeros for no points).
pub fn bounding_box(points: &[Point3]) -> (Vector3, Vector3) {
    let Some(first) = points.first() else { return (Vector3::zeros(), Vector3::zeros()) };
    let (mut lo, mut hi) = (first.coords, first.coords);
    for p in points {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    ((lo + hi) * 0.5, (hi - lo) * 0.5)
}

/// The ball around points: the center of their bounding box and the largest distance to it.
pub fn bounding_ball(points: &[Point3]) -> (Vector3, Real) {
    if points.is_empty() {
        return (Vector3::zeros(), 0.0);
    }
    let mut lo = points[0].coords;
    let mut hi = lo;
    for p in points {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    let c = (lo + hi) * 0.5;
    let r = points.iter().map(|p| (p.coords - c).norm()).fold(0.0, Real::max);
    (c, r)
}

impl FittedRobot {
    /// Validates a robot file into a robot.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the field: `format`, `urdf` (as
    /// [`RobotModel::from_urdf_str`]), `allowed_pairs[k]` (a link the robot lacks),
    /// `geometries[k].link`, `.origin`, `.primitive`, `.mesh` (an index out of range, a
    /// non-finite vertex, too many triangles), `.compound` (its format, root index and root body, and a mesh vertex outside the root), or a
    /// geometry with neither a primitive nor a mesh and its compound body.
    pub fn from_file(file: RobotFile) -> Result<Self> {
        if file.format != ROBOT_FORMAT {
            return Err(Error::invalid(
                "format",
                format!("expected {ROBOT_FORMAT:?}, got {:?}", sublevel_core::error::clip(&file.format)),
            ));
        }
        let model = RobotModel::from_urdf_str(&file.urdf)?;
        let disabled: Vec<crate::srdf::DisabledPair> = file
            .allowed_pairs
            .iter()
            .map(|[a, b]| crate::srdf::DisabledPair { link1: a.clone(), link2: b.clone(), reason: String::new() })
            .collect();
        let self_pairs =
            model.self_collision_pairs(&disabled).map_err(|e| rename(e, "srdf.disable_collisions", "allowed_pairs"))?;
        let mut geometries = Vec::with_capacity(file.geometries.len());
        for (k, g) in file.geometries.iter().enumerate() {
            let field = format!("geometries[{k}]");
            let link = model
                .link_index(&g.link)
                .ok_or_else(|| Error::invalid(format!("{field}.link"), "names a link the URDF does not have"))?;
            let origin = g.origin.to_pose(&format!("{field}.origin"))?;
            let name = if g.index == 0 { g.link.clone() } else { format!("{}#{}", g.link, g.index) };
            let (shape, sphere, local_box) = match (&g.primitive, &g.mesh, &g.compound) {
                (Some(p), None, None) => {
                    let p = Primitive::from_file(p).map_err(|e| prefix(e, &format!("{field}.primitive")))?;
                    let local_box = p.local_half_extents().map(|h| (Vector3::zeros(), h));
                    (LinkShape::Primitive(p), (Vector3::zeros(), p.bounding_radius()), local_box)
                }
                (None, Some(m), Some(c)) => {
                    let (vertices, triangles) = mesh_of(&format!("{field}.mesh"), m)?;
                    let body = root_body(&format!("{field}.compound"), c, &vertices)?;
                    let sphere = bounding_ball(&vertices);
                    let local_box = Some(bounding_box(&vertices));
                    let exact = exact_trimesh(&format!("{field}.mesh"), &vertices, &triangles)?;
                    let spheres = SphereTree::build(&vertices, &triangles, DEFAULT_LEAF_RADIUS);
                    if let Some(i) = vertices.iter().position(|v| !spheres.covers(&v.coords)) {
                        return Err(Error::Numerical(format!(
                            "{field}.mesh: vertex {i} lies outside the mesh's sphere tree"
                        )));
                    }
                    let inner = InnerBalls::build(&vertices, &triangles);
                    let shape = LinkShape::Mesh { body: Box::new(body), vertices, triangles, exact, spheres, inner };
                    (shape, sphere, local_box)
                }
                _ => {
                    return Err(Error::invalid(
                        field,
                        "needs either `primitive`, or `mesh` with its `compound` body (and not both)",
                    ))
                }
            };
            geometries.push(RobotGeometry { link, name, origin, shape, sphere, local_box });
        }
        let mut robot = Self {
            model,
            geometries,
            allowed_pairs: file.allowed_pairs.clone(),
            self_pairs,
            file,
            clearance: Vec::new(),
        };
        let tables = std::mem::take(&mut robot.file.clearance);
        robot.with_clearance(tables)
    }

    /// The robot with `tables` as its clearance tables (replacing any it had; saved with it).
    ///
    /// # Errors
    /// As [`crate::clearance`]'s validation: [`Error::InvalidArgument`] naming `clearance[k]` and
    /// the field.
    pub fn with_clearance(mut self, tables: Vec<ClearanceFile>) -> Result<Self> {
        self.clearance = crate::clearance::load_tables(&self, &tables)?;
        self.file.clearance = tables;
        Ok(self)
    }

    /// Reads and validates a robot file.
    ///
    /// # Errors
    /// [`Error::Io`], [`Error::Json`], or as [`FittedRobot::from_file`].
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display())))?;
        Self::from_json(&text)
    }

    /// Parses and validates the JSON text of a robot file.
    ///
    /// # Errors
    /// [`Error::Json`], or as [`FittedRobot::from_file`].
    pub fn from_json(text: &str) -> Result<Self> {
        Self::from_file(serde_json::from_str(text)?)
    }

    /// Writes the robot file (compact JSON).
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::Json`].
    pub fn save(&self, path: &Path) -> Result<()> {
        std::fs::write(path, serde_json::to_string(&self.file)?)?;
        Ok(())
    }

    /// Attaches an object to link `link` (a grasped object): an exact primitive at `origin` in the
    /// link's frame, moving with the link and checked like it — against the world, and against
    /// the links the link itself is checked against (its allowed pairs are the object's too). Its
    /// name is `name`; it is kept in memory only (not written by [`FittedRobot::save`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `link` when the robot has no such link, `origin` when the
    /// pose is not finite, or `primitive` for a halfspace (an attached object is bounded).
    pub fn attach(&mut self, link: &str, name: &str, primitive: Primitive, origin: Isometry3) -> Result<usize> {
        let index = self.model.link_index(link).ok_or_else(|| {
            Error::invalid("link", format!("`{}` is not a link of the robot", sublevel_core::error::clip(link)))
        })?;
        if origin.to_homogeneous().iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("origin", "must be finite"));
        }
        let Some(half) = primitive.local_half_extents() else {
            return Err(Error::invalid("primitive", "a halfspace cannot be attached: attached objects are bounded"));
        };
        self.geometries.push(RobotGeometry {
            link: index,
            name: name.to_owned(),
            origin,
            shape: LinkShape::Primitive(primitive),
            sphere: (Vector3::zeros(), primitive.bounding_radius()),
            local_box: Some((Vector3::zeros(), half)),
        });
        Ok(self.geometries.len() - 1)
    }

    /// The geometries of link `link`.
    pub fn link_geometries(&self, link: usize) -> impl Iterator<Item = (usize, &RobotGeometry)> + '_ {
        self.geometries.iter().enumerate().filter(move |(_, g)| g.link == link)
    }
}

/// An error's field prefixed by `prefix` (`prefix.field`).
fn prefix(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidArgument { field, reason } => {
            Error::InvalidArgument { field: format!("{prefix}.{field}"), reason }
        }
        other => other,
    }
}

/// An error's field with `from` replaced by `to`.
fn rename(e: Error, from: &str, to: &str) -> Error {
    match e {
        Error::InvalidArgument { field, reason } => {
            Error::InvalidArgument { field: field.replacen(from, to, 1), reason }
        }
        other => other,
    }
}

/// Slack of the containment check of a mesh's vertices in its root body (`p ≤ 1 + slack`).
const ROOT_SLACK: Real = 1e-9;

/// The root body of a compound file, validated, with every vertex verified inside it.
fn root_body(field: &str, c: &CompoundFile, vertices: &[Point3]) -> Result<Body> {
    if c.format != COMPOUND_FORMAT {
        return Err(Error::invalid(format!("{field}.format"), format!("must be {COMPOUND_FORMAT:?}")));
    }
    let node = c.nodes.get(c.root).ok_or_else(|| {
        Error::invalid(format!("{field}.root"), format!("{} is not a node index (0..{})", c.root, c.nodes.len()))
    })?;
    let body = Body::from_file(node.body.clone()).map_err(|e| prefix(e, &format!("{field}.nodes[{}].body", c.root)))?;
    if let Some((i, p)) =
        vertices.iter().map(|v| body.value_at(v)).enumerate().find(|(_, p)| p.is_nan() || *p > 1.0 + ROOT_SLACK)
    {
        return Err(Error::invalid(
            format!("{field}.nodes[{}]", c.root),
            format!("mesh vertex {i} lies outside the root body (p = {p}): the body does not contain its mesh"),
        ));
    }
    Ok(body)
}

/// A stored mesh, validated ([`validate_mesh`]).
fn mesh_of(field: &str, m: &MeshFile) -> Result<(Vec<Point3>, Vec<[u32; 3]>)> {
    let vertices: Vec<Point3> = m.vertices.iter().map(|v| Point3::new(v[0], v[1], v[2])).collect();
    validate_mesh(field, &vertices, &m.triangles)?;
    Ok((vertices, m.triangles.clone()))
}

/// The field name `name` under `prefix` (`prefix.name`, or `name` alone for an empty prefix).
fn under(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_owned()
    } else {
        format!("{prefix}.{name}")
    }
}

/// Checks a triangle mesh as the robot checks take it: 1 to [`MAX_MESH_TRIANGLES`] triangles,
/// every vertex finite and within ±1e6 m, every index naming a vertex.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `PREFIX.triangles`, `PREFIX.vertices[k]` or
/// `PREFIX.triangles[k]` (the bare names for an empty prefix).
pub(crate) fn validate_mesh(prefix: &str, vertices: &[Point3], triangles: &[[u32; 3]]) -> Result<()> {
    if triangles.is_empty() || triangles.len() > MAX_MESH_TRIANGLES {
        return Err(Error::invalid(
            under(prefix, "triangles"),
            format!("must hold 1 to {MAX_MESH_TRIANGLES} triangles, got {}", triangles.len()),
        ));
    }
    if let Some(i) = vertices.iter().position(|v| v.iter().any(|c| !c.is_finite() || c.abs() > 1e6)) {
        return Err(Error::invalid(under(prefix, &format!("vertices[{i}]")), "must be finite, within ±1e6 m"));
    }
    if let Some(i) = triangles.iter().position(|t| t.iter().any(|&v| v as usize >= vertices.len())) {
        return Err(Error::invalid(
            under(prefix, &format!("triangles[{i}]")),
            format!("names a vertex beyond the {} vertices", vertices.len()),
        ));
    }
    Ok(())
}

/// parry's triangle mesh (its BVH built) of a validated mesh, for the exact stage.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field` when parry refuses the mesh.
pub(crate) fn exact_trimesh(
    field: &str,
    vertices: &[Point3],
    triangles: &[[u32; 3]],
) -> Result<parry3d_f64::shape::SharedShape> {
    let points = vertices.iter().map(|p| parry3d_f64::math::Vector::new(p.x, p.y, p.z)).collect();
    parry3d_f64::shape::SharedShape::trimesh(points, triangles.to_vec())
        .map_err(|e| Error::invalid(field, format!("not a valid triangle mesh: {e:?}")))
}
