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
//!              "report": {"seconds", "fitted", "cached", "notes"},
//!              "clearance": [{…}, …],                                     (crate::clearance)
//!              "integrity": "sha256:HEX"}
//! ```
//!
//! **Integrity.** A robot file is read as it was written or not at all. A geometry at a link and
//! index where the URDF has a `<collision>` element must be that element (same origin, primitive
//! dimensions, or mesh name and scale); elsewhere only exact primitives may be added by hand (a
//! collision model of spheres, say), never a halfspace; origins are unit quaternions within
//! ±1e6 m. `integrity` is the SHA-256 of every other byte of the file in its canonical JSON form
//! ([`RobotFile::digest`]): the meshes, the bodies, the clearance tables' cells and contacts, the
//! allowed pairs. It is required of a file holding what the checks cannot re-derive cheaply
//! (fitted meshes, clearance tables) and verified whenever present: a file edited after it was
//! written (a table overwritten, a mesh or a body changed, two links' geometries swapped) is
//! refused naming `integrity`, since the checks trust those bytes to answer "free". The digest
//! detects edits and corruption; it is not a signature: whoever can write a robot file can also
//! write a wrong one, as with a wrong URDF.
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
use crate::model::{CollisionGeometry, RobotModel};
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
    /// The meshes whose first fit failed numerically and that took the fallback path (the fit
    /// module's ladder: lower degrees, then the minimum-volume ellipsoid), each with the
    /// failures on the way.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fallbacks: Vec<String>,
    /// What was skipped in the SRDF, one line each naming its element
    /// ([`crate::srdf::Semantics::known_to`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Link pairs on one rigid body (joined by fixed joints) that the SRDF does not allow, left
    /// out of self-collision checking all the same ([`RobotModel::rigid_pairs`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rigid_pairs: Vec<[String; 2]>,
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
    /// `sha256:HEX`, the [`RobotFile::digest`] of every other field (module docs: Integrity).
    #[serde(default)]
    pub integrity: String,
}

/// The fields of a [`RobotFile`] that its digest covers, in file order.
#[derive(Serialize)]
struct Covered<'a> {
    format: &'a str,
    name: &'a str,
    urdf: &'a str,
    allowed_pairs: &'a [[String; 2]],
    geometries: &'a [GeometryFile],
    report: &'a RobotFitReport,
    clearance: &'a [ClearanceFile],
}

/// Feeds serialized bytes into a hash.
struct HashWriter(sha2::Sha256);

impl std::io::Write for HashWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        sha2::Digest::update(&mut self.0, buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl RobotFile {
    /// `sha256:HEX`: SHA-256 of the file's canonical JSON (compact, fields in declaration order,
    /// numbers as serde_json writes them) without its `integrity` field. Parsing and writing a
    /// file again gives the same digest.
    ///
    /// # Errors
    /// [`Error::Json`] when a field cannot be serialized.
    pub fn digest(&self) -> Result<String> {
        let covered = Covered {
            format: &self.format,
            name: &self.name,
            urdf: &self.urdf,
            allowed_pairs: &self.allowed_pairs,
            geometries: &self.geometries,
            report: &self.report,
            clearance: &self.clearance,
        };
        let mut w = HashWriter(<sha2::Sha256 as sha2::Digest>::new());
        serde_json::to_writer(&mut w, &covered)?;
        let hash = sha2::Digest::finalize(w.0);
        Ok(format!("sha256:{}", hash.iter().map(|b| format!("{b:02x}")).collect::<String>()))
    }

    /// Sets `integrity` to the file's [`RobotFile::digest`]: done by whatever writes a robot
    /// file (the fit, [`FittedRobot::with_clearance`]).
    ///
    /// # Errors
    /// As [`RobotFile::digest`].
    pub fn seal(&mut self) -> Result<()> {
        self.integrity = self.digest()?;
        Ok(())
    }
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
    /// geometry with neither a primitive nor a mesh and its compound body; `geometries` or
    /// `geometries[k]…` for a geometry that is not the URDF's collision element at its place;
    /// `integrity` for a file changed after it was written (module docs);
    /// [`Error::ResourceExhausted`] for a robot over a [`crate::limits`] limit.
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
        crate::limits::check_self_pairs(&model, &file.allowed_pairs)?;
        if file.clearance.len() > crate::limits::MAX_CLEARANCE_TABLES {
            return Err(crate::limits::exceeded(
                "clearance tables",
                file.clearance.len(),
                crate::limits::MAX_CLEARANCE_TABLES,
            ));
        }
        let urdf_elements: std::collections::HashMap<(&str, usize), &CollisionGeometry> = model
            .links()
            .iter()
            .flat_map(|l| l.collision.iter().enumerate().map(move |(k, c)| ((l.name.as_str(), k), c)))
            .collect();
        let mut placed = std::collections::HashSet::new();
        let mut geometries = Vec::with_capacity(file.geometries.len());
        for (k, g) in file.geometries.iter().enumerate() {
            let field = format!("geometries[{k}]");
            let link = model
                .link_index(&g.link)
                .ok_or_else(|| Error::invalid(format!("{field}.link"), "names a link the URDF does not have"))?;
            let origin = g.origin.to_pose(&format!("{field}.origin"))?;
            if !placed.insert((g.link.as_str(), g.index)) {
                return Err(Error::invalid(
                    format!("{field}.index"),
                    format!("link `{}` collision {} is given twice", sublevel_core::error::clip(&g.link), g.index),
                ));
            }
            match urdf_elements.get(&(g.link.as_str(), g.index)) {
                Some(c) => matches_urdf(&field, g, c)?,
                None if g.mesh.is_some() => {
                    return Err(Error::invalid(
                        format!("{field}.mesh"),
                        format!(
                            "link `{}` has no collision element {} in the URDF: a mesh geometry is the URDF's",
                            sublevel_core::error::clip(&g.link),
                            g.index
                        ),
                    ))
                }
                None => {}
            }
            check_origin(&format!("{field}.origin"), &g.origin)?;
            if matches!(g.primitive, Some(PrimitiveFile::Halfspace { .. })) {
                return Err(Error::invalid(
                    format!("{field}.primitive"),
                    "a halfspace is no link geometry (it has no bounded extent); it belongs to the world",
                ));
            }
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
        robot.clearance = crate::clearance::load_tables(&robot, &robot.file.clearance)?;
        let derived = robot.file.geometries.iter().any(|g| g.mesh.is_some() || g.compound.is_some())
            || !robot.file.clearance.is_empty();
        if robot.file.integrity.is_empty() && derived {
            return Err(Error::invalid(
                "integrity",
                "missing: a robot file with fitted meshes or clearance tables carries the SHA-256 of its contents, \
                 as `sublevel robot fit` writes it",
            ));
        }
        if !robot.file.integrity.is_empty() && robot.file.digest()? != robot.file.integrity {
            return Err(Error::invalid(
                "integrity",
                "the file's contents do not match its SHA-256: it was changed after it was written \
                 (fit the robot again, or `sublevel robot tables` to rebuild its tables)",
            ));
        }
        Ok(robot)
    }

    /// The robot with `tables` as its clearance tables (replacing any it had; saved with it, the
    /// file sealed again: [`RobotFile::seal`]).
    ///
    /// # Errors
    /// As [`crate::clearance`]'s validation: [`Error::InvalidArgument`] naming `clearance[k]` and
    /// the field.
    pub fn with_clearance(mut self, tables: Vec<ClearanceFile>) -> Result<Self> {
        if tables.len() > crate::limits::MAX_CLEARANCE_TABLES {
            return Err(crate::limits::exceeded("clearance tables", tables.len(), crate::limits::MAX_CLEARANCE_TABLES));
        }
        self.clearance = crate::clearance::load_tables(&self, &tables)?;
        self.file.clearance = tables;
        self.file.seal()?;
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

/// Checks a geometry's origin: translation within ±1e6 m, rotation a unit quaternion (within 1e-6).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field`.
fn check_origin(field: &str, o: &PoseFile) -> Result<()> {
    let norm = o.rotation.iter().map(|v| v * v).sum::<Real>().sqrt();
    let near = o.translation.iter().all(|v| v.abs() <= sublevel_core::math::MAX_COORDINATE);
    let unit = (norm - 1.0).abs() <= 1e-6;
    if !(near && unit) {
        return Err(Error::invalid(
            field,
            format!(
                "translation {:?} must lie within ±1e6 m and rotation {:?} be a unit quaternion (w, x, y, z)",
                o.translation, o.rotation
            ),
        ));
    }
    Ok(())
}

/// Checks that a file's geometry is the URDF's `<collision>` element of its link and index: the
/// same origin (within 1e-9 m and 1e-9 in the quaternion, either sign), the same primitive, or a
/// mesh of the same name and scale with a SHA-256 in hex.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field.origin`, `.primitive` or `.mesh`.
fn matches_urdf(field: &str, g: &GeometryFile, c: &CollisionGeometry) -> Result<()> {
    let (origin, primitive, mesh) = match c {
        CollisionGeometry::Box { origin, size } => (origin, Some(PrimitiveFile::Box { size: *size }), None),
        CollisionGeometry::Sphere { origin, radius } => (origin, Some(PrimitiveFile::Sphere { radius: *radius }), None),
        CollisionGeometry::Cylinder { origin, radius, length } => {
            (origin, Some(PrimitiveFile::Cylinder { radius: *radius, height: *length }), None)
        }
        CollisionGeometry::Capsule { origin, radius, length } => {
            (origin, Some(PrimitiveFile::Capsule { radius: *radius, height: *length }), None)
        }
        CollisionGeometry::Mesh { origin, filename, scale } => (origin, None, Some((filename, scale))),
    };
    let want = PoseFile::of(origin);
    let close = |a: &[Real], b: &[Real]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9);
    let negated = want.rotation.map(|v| -v);
    if !close(&g.origin.translation, &want.translation)
        || !(close(&g.origin.rotation, &want.rotation) || close(&g.origin.rotation, &negated))
    {
        return Err(Error::invalid(
            format!("{field}.origin"),
            format!("differs from the URDF's collision origin {want:?}"),
        ));
    }
    match (primitive, mesh) {
        (Some(p), _) if g.primitive.as_ref() != Some(&p) || g.mesh.is_some() => Err(Error::invalid(
            format!("{field}.primitive"),
            format!("the URDF's collision element is the primitive {p:?}"),
        )),
        (None, Some((filename, scale))) => {
            let Some(m) = &g.mesh else {
                return Err(Error::invalid(format!("{field}.mesh"), "the URDF's collision element is a mesh"));
            };
            if &m.source != filename || m.scale != *scale {
                return Err(Error::invalid(
                    format!("{field}.mesh"),
                    format!("the URDF's collision element is mesh `{filename}` at scale {scale:?}"),
                ));
            }
            if m.sha256.len() != 64 || !m.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err(Error::invalid(format!("{field}.mesh.sha256"), "must be 64 hexadecimal digits"));
            }
            Ok(())
        }
        _ => Ok(()),
    }
}
