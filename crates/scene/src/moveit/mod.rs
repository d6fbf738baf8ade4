//! MoveIt planning scenes: `moveit_msgs/PlanningScene` messages read from YAML or JSON (as
//! `rosmsg`/`rostopic echo`, MoveIt's scene exports and the MotionBenchMaker problem sets write
//! them) into typed, validated [`PlanningScene`]s: the world's collision objects with their
//! shapes placed in the planning frame, the allowed-collision matrix and the robot state.
//!
//! The YAML is parsed by `serde-saphyr`: a maintained, pure-Rust YAML 1.2 deserializer (no
//! `unsafe`, no libyaml) that is panic-free on malformed input and enforces a resource budget
//! (events, nesting depth, alias expansion), which matters for a scene that arrives over the
//! network (`ImportScene`); JSON is YAML 1.2 and goes through the same path. `serde_yaml` is
//! archived and its forks either keep `unsafe-libyaml` or lack the budget.
//!
//! The budget is proportional to the text ([`YamlBudget::for_text`]): a text of n bytes may
//! produce at most 3n + [`YAML_BUDGET_BASE`] parser events and nodes, and replay (or keep for
//! replay) at most n + [`YAML_BUDGET_BASE`] events through anchors and aliases. A text without
//! aliases never comes near it — every node costs at least one byte of text — so no scene is
//! refused for its size (the object count is bounded separately: `max_objects` of
//! [`PlanningScene::from_yaml_with_limit`]); an alias "billion laughs" is refused after at most
//! n + [`YAML_BUDGET_BASE`] replayed events, that is after memory in proportion to its text
//! (a 516-byte bomb: under 5 000 events, not the parser's default million).
//!
//! Message conventions followed (ROS `shape_msgs`, `geometry_msgs`, `moveit_msgs`):
//!
//! - a pose's `position` is `{x, y, z}` or `[x, y, z]` (meters), its `orientation` `{x, y, z, w}` or
//!   `[x, y, z, w]` (ROS order, w last). An all-zero quaternion (a message's default) is the
//!   identity; a quaternion whose norm is within [`QUATERNION_NORM_SLACK`] of 1 is normalized, as
//!   MoveIt does; anything else is refused;
//! - `SolidPrimitive.type` is a name (`box`, `sphere`, `cylinder`, `cone`) or the message's code
//!   (1 box, 2 sphere, 3 cylinder, 4 cone); `dimensions` are box `[x, y, z]` full side lengths,
//!   sphere `[radius]`, cylinder and cone `[height, radius]`, centered at the shape's pose with the
//!   axis along z;
//! - a collision object's `pose` (MoveIt ≥ 1.1) places the object in its header's frame and its
//!   `primitive_poses` / `mesh_poses` / `plane_poses` are relative to it; without `pose` they are
//!   in the header's frame directly;
//! - `operation` is ADD (0, the default) or APPEND (3, adds shapes to an object of the same id);
//!   REMOVE and MOVE only make sense in a scene diff and are refused;
//! - the allowed-collision matrix's `entry_values` are rows of booleans, as nested lists or as
//!   `AllowedCollisionEntry` messages (`{enabled: [...]}`).
//!
//! Every error is [`Error::InvalidArgument`] naming the field by its path, e.g.
//! `world.collision_objects[3].primitives[0].dimensions`.

use crate::{Error, Result, StoredPose, MAX_NAME_BYTES};
pub(crate) use budget::parse_yaml;
use budget::{bounded_objects, with_object_limit};
pub use budget::{YamlBudget, YAML_BUDGET_BASE};
use serde::Deserialize;
use sublevel_core::math::{pose_from_parts, Isometry3, Real, MAX_COORDINATE};

/// How far a quaternion's norm may be from 1 and still be normalized (hand-written scenes round
/// `√½` to 0.707).
pub const QUATERNION_NORM_SLACK: Real = 1e-3;

/// Most collision objects, shapes or mesh vertices one scene may hold (each bounded separately;
/// a caller bounds the objects lower with [`PlanningScene::from_yaml_with_limit`]).
pub const MAX_SCENE_ITEMS: usize = 1_000_000;

/// The instance name of shape `k` of an object with id `id` and `shapes` shapes: the id alone
/// for an object of one shape, else `id#k` ([`ImportPlan`] and [`world_objects`] name them so).
pub(crate) fn instance_name(id: &str, shapes: usize, k: usize) -> String {
    if shapes > 1 {
        format!("{id}#{k}")
    } else {
        id.to_owned()
    }
}

/// A shape of a collision object, in its own frame (meters; centered at the origin, axis along z
/// where it has one).
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A box of full side lengths `size` (x, y, z).
    Box {
        /// Full side lengths, meters.
        size: [Real; 3],
    },
    /// A ball.
    Sphere {
        /// Radius, meters.
        radius: Real,
    },
    /// A cylinder along z, from −height/2 to height/2.
    Cylinder {
        /// Full height, meters.
        height: Real,
        /// Radius, meters.
        radius: Real,
    },
    /// A cone along z, its base disc at z = −height/2 and its apex at z = height/2.
    Cone {
        /// Full height, meters.
        height: Real,
        /// Radius of the base, meters.
        radius: Real,
    },
    /// A triangle mesh.
    Mesh {
        /// Vertices, meters.
        vertices: Vec<[Real; 3]>,
        /// Triangles as vertex indices.
        triangles: Vec<[u32; 3]>,
    },
    /// The plane `normal · x + offset = 0` (`normal` a unit vector; MoveIt's `Plane.coef`
    /// divided by the norm of its first three coefficients).
    Plane {
        /// Unit normal.
        normal: [Real; 3],
        /// Offset, meters.
        offset: Real,
    },
}

/// A shape placed in the scene: its pose maps the shape's frame into the object's header frame
/// (the object's `pose` composed with the shape's own pose).
#[derive(Clone, Debug, PartialEq)]
pub struct PlacedShape {
    /// The shape.
    pub shape: Shape,
    /// Shape frame → the object's header frame.
    pub pose: Isometry3,
}

/// A collision object of the world.
#[derive(Clone, Debug, PartialEq)]
pub struct CollisionObject {
    /// Its id (kept as the instance name on import).
    pub id: String,
    /// The frame its poses are given in (`header.frame_id`; empty when absent).
    pub frame_id: String,
    /// Its shapes: primitives first, then meshes, then planes, each in message order.
    pub shapes: Vec<PlacedShape>,
}

/// The allowed-collision matrix: which pairs of names (robot links, object ids) may touch.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct AllowedCollisionMatrix {
    /// The names of the rows and columns.
    pub names: Vec<String>,
    /// `allowed[i][j]`: contacts between `names[i]` and `names[j]` are allowed (square, as given).
    pub allowed: Vec<Vec<bool>>,
    /// Names with a default entry, and whether their contacts with everything are allowed.
    pub defaults: Vec<(String, bool)>,
}

impl AllowedCollisionMatrix {
    /// Whether contacts between `a` and `b` are allowed: the matrix entry when both are named,
    /// else a default entry of either (allowed if either's default allows), else false.
    pub fn allowed(&self, a: &str, b: &str) -> bool {
        let index = |n: &str| self.names.iter().position(|m| m == n);
        if let (Some(i), Some(j)) = (index(a), index(b)) {
            return self.allowed[i][j];
        }
        self.defaults.iter().any(|(n, allowed)| *allowed && (n == a || n == b))
    }
}

/// A validated MoveIt planning scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlanningScene {
    /// The scene's `name` (empty when absent).
    pub name: String,
    /// The world's collision objects, in message order (APPEND operations merged).
    pub objects: Vec<CollisionObject>,
    /// The allowed-collision matrix, when the scene has one.
    pub allowed_collision: Option<AllowedCollisionMatrix>,
    /// The robot state's joint positions by name (radians or meters), in message order.
    pub joint_positions: Vec<(String, Real)>,
}

impl PlanningScene {
    /// Reads a `moveit_msgs/PlanningScene` from YAML or JSON bytes (see the module docs), with
    /// at most [`MAX_SCENE_ITEMS`] collision objects.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `scene` for bytes that are not a YAML mapping of the
    /// message (with the parser's line and column) or that breach the parser's budget
    /// ([`YamlBudget::for_text`]), or the path of the first field that does not validate.
    pub fn from_yaml(bytes: &[u8]) -> Result<Self> {
        Self::from_yaml_with_limit(bytes, MAX_SCENE_ITEMS)
    }

    /// [`PlanningScene::from_yaml`] with at most `max_objects` collision objects (entries of
    /// `world.collision_objects`, APPENDs counted): the parser stops at the first object past it,
    /// before any object is validated.
    ///
    /// # Errors
    /// As [`PlanningScene::from_yaml`]; [`Error::ResourceExhausted`] naming
    /// `world.collision_objects` and the limit for more objects.
    pub fn from_yaml_with_limit(bytes: &[u8], max_objects: usize) -> Result<Self> {
        let raw: RawScene = with_object_limit(max_objects, || parse_yaml("scene", bytes))?;
        raw.validate()
    }

    /// Reads a `moveit_msgs/PlanningScene` from JSON bytes with a JSON parser (exact JSON error
    /// positions); the same message and checks as [`PlanningScene::from_yaml`].
    ///
    /// # Errors
    /// As [`PlanningScene::from_yaml`].
    pub fn from_json(bytes: &[u8]) -> Result<Self> {
        Self::from_json_with_limit(bytes, MAX_SCENE_ITEMS)
    }

    /// [`PlanningScene::from_json`] with at most `max_objects` collision objects, as
    /// [`PlanningScene::from_yaml_with_limit`].
    ///
    /// # Errors
    /// As [`PlanningScene::from_yaml_with_limit`].
    pub fn from_json_with_limit(bytes: &[u8], max_objects: usize) -> Result<Self> {
        let raw: RawScene = with_object_limit(max_objects, || {
            serde_json::from_slice(bytes).map_err(|e| Error::invalid("scene", e.to_string()))
        })?;
        raw.validate()
    }

    /// Number of shapes of all objects.
    pub fn shape_count(&self) -> usize {
        self.objects.iter().map(|o| o.shapes.len()).sum()
    }
}

// ---- The message as written (lenient: unknown fields are ignored, as ROS tools do). ----

#[derive(Deserialize, Default)]
struct RawScene {
    #[serde(default)]
    name: String,
    #[serde(default)]
    world: RawWorld,
    #[serde(default)]
    robot_state: Option<RawRobotState>,
    #[serde(default)]
    allowed_collision_matrix: Option<RawAcm>,
}

#[derive(Deserialize, Default)]
struct RawWorld {
    #[serde(default, deserialize_with = "bounded_objects")]
    collision_objects: Vec<RawObject>,
}

#[derive(Deserialize, Default)]
struct RawHeader {
    #[serde(default)]
    frame_id: String,
}

#[derive(Deserialize)]
struct RawObject {
    #[serde(default)]
    id: String,
    #[serde(default)]
    header: Option<RawHeader>,
    #[serde(default)]
    pose: Option<RawPose>,
    #[serde(default)]
    primitives: Vec<RawPrimitive>,
    #[serde(default)]
    primitive_poses: Vec<RawPose>,
    #[serde(default)]
    meshes: Vec<RawMesh>,
    #[serde(default)]
    mesh_poses: Vec<RawPose>,
    #[serde(default)]
    planes: Vec<RawPlane>,
    #[serde(default)]
    plane_poses: Vec<RawPose>,
    #[serde(default)]
    operation: Option<NameOrCode>,
}

/// A vector or quaternion as written: a list `[x, y, z(, w)]` or a map `{x, y, z(, w)}` (missing
/// map components are 0, as in a ROS message).
enum Coords {
    List(Vec<Real>),
    Map { x: Real, y: Real, z: Real, w: Real },
}

impl<'de> Deserialize<'de> for Coords {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Coords;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a list of numbers or a map with keys x, y, z (and w)")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<Coords, A::Error> {
                let mut out = Vec::new();
                while let Some(v) = seq.next_element::<Real>()? {
                    if out.len() == 4 {
                        return Err(serde::de::Error::custom("more than 4 numbers"));
                    }
                    out.push(v);
                }
                Ok(Coords::List(out))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> std::result::Result<Coords, A::Error> {
                let [mut x, mut y, mut z, mut w] = [0.0; 4];
                while let Some(key) = map.next_key::<String>()? {
                    let slot = match key.as_str() {
                        "x" => &mut x,
                        "y" => &mut y,
                        "z" => &mut z,
                        "w" => &mut w,
                        other => {
                            let shown = sublevel_core::error::clip(other);
                            return Err(serde::de::Error::custom(format!("unknown component `{shown}`")));
                        }
                    };
                    *slot = map.next_value::<Real>()?;
                }
                Ok(Coords::Map { x, y, z, w })
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

#[derive(Deserialize)]
struct RawPose {
    #[serde(default)]
    position: Option<Coords>,
    #[serde(default)]
    orientation: Option<Coords>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum NameOrCode {
    Code(i64),
    Name(String),
}

#[derive(Deserialize)]
struct RawPrimitive {
    #[serde(rename = "type")]
    kind: NameOrCode,
    #[serde(default)]
    dimensions: Vec<Real>,
}

#[derive(Deserialize)]
struct RawTriangle {
    vertex_indices: Vec<i64>,
}

#[derive(Deserialize)]
struct RawMesh {
    #[serde(default)]
    triangles: Vec<RawTriangle>,
    #[serde(default)]
    vertices: Vec<Coords>,
}

#[derive(Deserialize)]
struct RawPlane {
    coef: Vec<Real>,
}

#[derive(Deserialize, Default)]
struct RawJointState {
    #[serde(default)]
    name: Vec<String>,
    #[serde(default)]
    position: Vec<Real>,
}

#[derive(Deserialize, Default)]
struct RawRobotState {
    #[serde(default)]
    joint_state: RawJointState,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum AcmRow {
    List(Vec<bool>),
    Entry { enabled: Vec<bool> },
}

#[derive(Deserialize, Default)]
struct RawAcm {
    #[serde(default)]
    entry_names: Vec<String>,
    #[serde(default)]
    entry_values: Vec<AcmRow>,
    #[serde(default)]
    default_entry_names: Vec<String>,
    #[serde(default)]
    default_entry_values: Vec<bool>,
}

// ---- Validation. ----

/// Checks that a length or radius is a primitive's dimension: finite, within
/// [[`sublevel_core::primitive::MIN_DIMENSION`], [`sublevel_core::primitive::MAX_DIMENSION`]]
/// meters — the rule every stored primitive passes.
fn positive(field: &str, v: Real) -> Result<Real> {
    sublevel_core::primitive::check_dimension(field, v)
}

fn vec3(field: &str, v: &Coords) -> Result<[Real; 3]> {
    let out = match v {
        Coords::List(l) if l.len() == 3 => [l[0], l[1], l[2]],
        Coords::List(l) => return Err(Error::invalid(field, format!("needs 3 numbers, got {}", l.len()))),
        Coords::Map { w, .. } if *w != 0.0 => return Err(Error::invalid(field, "a vector has no `w` component")),
        Coords::Map { x, y, z, .. } => [*x, *y, *z],
    };
    if let Some(bad) = out.iter().find(|v| !v.is_finite() || v.abs() > MAX_COORDINATE) {
        return Err(Error::invalid(
            field,
            format!("coordinates must be finite within ±{MAX_COORDINATE:e} m, got {bad}"),
        ));
    }
    Ok(out)
}

/// A pose message as an isometry (see the module docs for the quaternion rules).
fn pose(field: &str, p: &RawPose) -> Result<Isometry3> {
    let t = match &p.position {
        Some(v) => vec3(&format!("{field}.position"), v)?,
        None => [0.0; 3],
    };
    let of = format!("{field}.orientation");
    let (x, y, z, w) = match &p.orientation {
        None => (0.0, 0.0, 0.0, 0.0),
        Some(Coords::List(l)) if l.len() == 4 => (l[0], l[1], l[2], l[3]),
        Some(Coords::List(l)) => {
            return Err(Error::invalid(of, format!("needs 4 numbers [x, y, z, w], got {}", l.len())))
        }
        Some(Coords::Map { x, y, z, w }) => (*x, *y, *z, *w),
    };
    let q = [w, x, y, z];
    if q.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(of, "quaternion entries must be finite numbers"));
    }
    let norm = q.iter().map(|v| v * v).sum::<Real>().sqrt();
    let q = if norm == 0.0 {
        [1.0, 0.0, 0.0, 0.0]
    } else if (norm - 1.0).abs() <= QUATERNION_NORM_SLACK {
        q.map(|v| v / norm)
    } else {
        return Err(Error::invalid(
            of,
            format!("quaternion norm {norm:.6} is not 1 (within {QUATERNION_NORM_SLACK}) nor 0 (identity)"),
        ));
    };
    pose_from_parts(field, q, t)
}

fn primitive(field: &str, p: &RawPrimitive) -> Result<Shape> {
    let kind = match &p.kind {
        NameOrCode::Code(1) => "box",
        NameOrCode::Code(2) => "sphere",
        NameOrCode::Code(3) => "cylinder",
        NameOrCode::Code(4) => "cone",
        NameOrCode::Name(n) => match n.to_ascii_lowercase().as_str() {
            "box" => "box",
            "sphere" => "sphere",
            "cylinder" => "cylinder",
            "cone" => "cone",
            _ => {
                let shown = sublevel_core::error::clip(n);
                return Err(Error::invalid(
                    format!("{field}.type"),
                    format!("unknown primitive `{shown}`: box, sphere, cylinder or cone (1–4)"),
                ));
            }
        },
        NameOrCode::Code(c) => {
            return Err(Error::invalid(
                format!("{field}.type"),
                format!("unknown primitive code {c}: 1 box, 2 sphere, 3 cylinder, 4 cone"),
            ))
        }
    };
    let d = &p.dimensions;
    let df = format!("{field}.dimensions");
    let want = if kind == "box" {
        3
    } else if kind == "sphere" {
        1
    } else {
        2
    };
    if d.len() != want {
        return Err(Error::invalid(df, format!("a {kind} needs {want} dimensions, got {}", d.len())));
    }
    let at = |k: usize| positive(&format!("{df}[{k}]"), d[k]);
    Ok(match kind {
        "box" => Shape::Box { size: [at(0)?, at(1)?, at(2)?] },
        "sphere" => Shape::Sphere { radius: at(0)? },
        "cylinder" => Shape::Cylinder { height: at(0)?, radius: at(1)? },
        _ => Shape::Cone { height: at(0)?, radius: at(1)? },
    })
}

fn mesh(field: &str, m: &RawMesh) -> Result<Shape> {
    if m.vertices.len() > MAX_SCENE_ITEMS || m.triangles.len() > MAX_SCENE_ITEMS {
        return Err(Error::invalid(field, format!("more than {MAX_SCENE_ITEMS} vertices or triangles")));
    }
    let vertices: Vec<[Real; 3]> = m
        .vertices
        .iter()
        .enumerate()
        .map(|(k, v)| vec3(&format!("{field}.vertices[{k}]"), v))
        .collect::<Result<_>>()?;
    if m.triangles.is_empty() {
        return Err(Error::invalid(format!("{field}.triangles"), "a mesh needs at least one triangle"));
    }
    let n = vertices.len() as i64;
    let triangles = m
        .triangles
        .iter()
        .enumerate()
        .map(|(k, t)| {
            let f = format!("{field}.triangles[{k}].vertex_indices");
            if t.vertex_indices.len() != 3 {
                return Err(Error::invalid(f, format!("needs 3 indices, got {}", t.vertex_indices.len())));
            }
            let mut out = [0u32; 3];
            for (o, &i) in out.iter_mut().zip(&t.vertex_indices) {
                if !(0..n).contains(&i) {
                    return Err(Error::invalid(f, format!("index {i} outside the {n} vertices")));
                }
                *o = i as u32;
            }
            Ok(out)
        })
        .collect::<Result<_>>()?;
    Ok(Shape::Mesh { vertices, triangles })
}

fn plane(field: &str, p: &RawPlane) -> Result<Shape> {
    let f = format!("{field}.coef");
    if p.coef.len() != 4 || p.coef.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(f, "needs 4 finite numbers [a, b, c, d] of a·x + b·y + c·z + d = 0"));
    }
    let norm = (p.coef[0] * p.coef[0] + p.coef[1] * p.coef[1] + p.coef[2] * p.coef[2]).sqrt();
    if norm < 1e-12 {
        return Err(Error::invalid(f, "the normal (a, b, c) is zero"));
    }
    let offset = p.coef[3] / norm;
    if offset.abs() > MAX_COORDINATE {
        return Err(Error::invalid(f, format!("the plane is farther than {MAX_COORDINATE:e} m from the origin")));
    }
    Ok(Shape::Plane { normal: [p.coef[0] / norm, p.coef[1] / norm, p.coef[2] / norm], offset })
}

/// Places `shapes` (from `items`, with `poses` of the same count) under the object's pose.
fn placed<T>(
    field: &str,
    poses_field: &str,
    items: &[T],
    poses: &[RawPose],
    object: &Isometry3,
    shape: impl Fn(&str, &T) -> Result<Shape>,
) -> Result<Vec<PlacedShape>> {
    if poses.len() != items.len() {
        return Err(Error::invalid(
            poses_field,
            format!("{} poses for {} shapes in `{field}`: one pose per shape", poses.len(), items.len()),
        ));
    }
    items
        .iter()
        .zip(poses)
        .enumerate()
        .map(|(k, (item, p))| {
            let shape = shape(&format!("{field}[{k}]"), item)?;
            let pose_field = format!("{poses_field}[{k}]");
            let local = pose(&pose_field, p)?;
            // The shape is stored at the composed pose: checked in that form, by the rule the
            // store applies when it reopens.
            let composed = object * local;
            StoredPose::checked(&pose_field, &composed).map_err(|e| match e {
                Error::InvalidArgument { field, reason } => {
                    Error::InvalidArgument { field, reason: format!("composed with the object's `pose`: {reason}") }
                }
                other => other,
            })?;
            Ok(PlacedShape { shape, pose: composed })
        })
        .collect()
}

impl RawObject {
    fn validate(&self, field: &str) -> Result<CollisionObject> {
        if self.id.is_empty() {
            return Err(Error::invalid(format!("{field}.id"), "a collision object needs an id"));
        }
        if self.id.len() > MAX_NAME_BYTES {
            return Err(Error::invalid(
                format!("{field}.id"),
                format!("at most {MAX_NAME_BYTES} bytes, got {}", self.id.len()),
            ));
        }
        let object = match &self.pose {
            Some(p) => pose(&format!("{field}.pose"), p)?,
            None => Isometry3::identity(),
        };
        let f = |name: &str| format!("{field}.{name}");
        let mut shapes = placed(
            &f("primitives"),
            &f("primitive_poses"),
            &self.primitives,
            &self.primitive_poses,
            &object,
            primitive,
        )?;
        shapes.extend(placed(&f("meshes"), &f("mesh_poses"), &self.meshes, &self.mesh_poses, &object, mesh)?);
        shapes.extend(placed(&f("planes"), &f("plane_poses"), &self.planes, &self.plane_poses, &object, plane)?);
        if shapes.is_empty() {
            return Err(Error::invalid(field, format!("collision object `{}` has no shape", self.id)));
        }
        Ok(CollisionObject {
            id: self.id.clone(),
            frame_id: self.header.as_ref().map(|h| h.frame_id.clone()).unwrap_or_default(),
            shapes,
        })
    }
}

/// Checks that the instance names of `objects` ([`instance_name`]) are unique and at most
/// [`MAX_NAME_BYTES`] long: an object `a` of two shapes names `a#0` and `a#1`, so an object whose
/// id is `a#1` would share a name with it (the allowed-collision matrix and the robot checks know
/// instances by these names). `first[i]` is object i's index in the message.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `world.collision_objects[k].id` of the later object.
fn unique_instance_names(objects: &[CollisionObject], first: &[usize]) -> Result<()> {
    let mut seen: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for (object, &k) in objects.iter().zip(first) {
        let field = || format!("world.collision_objects[{k}].id");
        for s in 0..object.shapes.len() {
            let name = instance_name(&object.id, object.shapes.len(), s);
            if name.len() > MAX_NAME_BYTES {
                return Err(Error::invalid(
                    field(),
                    format!(
                        "its instance name `{}` is longer than {MAX_NAME_BYTES} bytes",
                        sublevel_core::error::clip(&name)
                    ),
                ));
            }
            if let Some(other) = seen.insert(name.clone(), k) {
                return Err(Error::invalid(
                    field(),
                    format!(
                        "its instance name `{}` is also the name of a shape of `world.collision_objects[{other}]` (an object of several shapes names them `ID#k`)",
                        sublevel_core::error::clip(&name)
                    ),
                ));
            }
        }
    }
    Ok(())
}

impl RawAcm {
    fn validate(&self) -> Result<AllowedCollisionMatrix> {
        let n = self.entry_names.len();
        if self.entry_values.len() != n {
            return Err(Error::invalid(
                "allowed_collision_matrix.entry_values",
                format!("{} rows for {n} entry_names", self.entry_values.len()),
            ));
        }
        let mut allowed = Vec::with_capacity(n);
        for (i, row) in self.entry_values.iter().enumerate() {
            let row = match row {
                AcmRow::List(r) | AcmRow::Entry { enabled: r } => r,
            };
            if row.len() != n {
                return Err(Error::invalid(
                    format!("allowed_collision_matrix.entry_values[{i}]"),
                    format!("{} entries for {n} entry_names", row.len()),
                ));
            }
            allowed.push(row.clone());
        }
        if self.default_entry_values.len() != self.default_entry_names.len() {
            return Err(Error::invalid(
                "allowed_collision_matrix.default_entry_values",
                format!(
                    "{} values for {} default_entry_names",
                    self.default_entry_values.len(),
                    self.default_entry_names.len()
                ),
            ));
        }
        let defaults =
            self.default_entry_names.iter().cloned().zip(self.default_entry_values.iter().copied()).collect();
        Ok(AllowedCollisionMatrix { names: self.entry_names.clone(), allowed, defaults })
    }
}

impl RawScene {
    fn validate(self) -> Result<PlanningScene> {
        if self.world.collision_objects.len() > MAX_SCENE_ITEMS {
            return Err(Error::invalid("world.collision_objects", format!("more than {MAX_SCENE_ITEMS} objects")));
        }
        let mut objects: Vec<CollisionObject> = Vec::new();
        // The message index of each object (its first entry; APPENDs merge into it).
        let mut first: Vec<usize> = Vec::new();
        for (k, raw) in self.world.collision_objects.iter().enumerate() {
            let field = format!("world.collision_objects[{k}]");
            let append =
                match &raw.operation {
                    None | Some(NameOrCode::Code(0)) => false,
                    Some(NameOrCode::Code(3)) => true,
                    Some(NameOrCode::Name(n)) if n.eq_ignore_ascii_case("add") => false,
                    Some(NameOrCode::Name(n)) if n.eq_ignore_ascii_case("append") => true,
                    Some(_) => return Err(Error::invalid(
                        format!("{field}.operation"),
                        "a planning scene adds objects: ADD (0) or APPEND (3); REMOVE and MOVE belong to scene diffs",
                    )),
                };
            let object = raw.validate(&field)?;
            match objects.iter_mut().find(|o| o.id == object.id) {
                Some(existing) if append => existing.shapes.extend(object.shapes),
                Some(_) => {
                    let shown = sublevel_core::error::clip(&object.id);
                    return Err(Error::invalid(format!("{field}.id"), format!("id `{shown}` is used twice")));
                }
                None => {
                    objects.push(object);
                    first.push(k);
                }
            }
        }
        unique_instance_names(&objects, &first)?;
        let allowed_collision = self.allowed_collision_matrix.as_ref().map(RawAcm::validate).transpose()?;
        let joints = self.robot_state.unwrap_or_default().joint_state;
        if !joints.position.is_empty() && joints.position.len() != joints.name.len() {
            return Err(Error::invalid(
                "robot_state.joint_state.position",
                format!("{} positions for {} names", joints.position.len(), joints.name.len()),
            ));
        }
        if let Some(k) = joints.position.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("robot_state.joint_state.position[{k}]"), "must be a finite number"));
        }
        let joint_positions = joints.name.into_iter().zip(joints.position).collect();
        Ok(PlanningScene { name: self.name, objects, allowed_collision, joint_positions })
    }
}

mod budget;
mod import;
mod limits;
mod request;
#[cfg(test)]
mod tests;
mod world;

pub use import::{ImportPlan, ImportedInstance, ImportedScene, MeshImport, PlannedInstance, PlannedMesh, SkippedShape};
pub use limits::{JointLimitEntry, JointLimitMaps, JointLimitsYaml};
pub use request::MotionPlanRequest;
pub use world::{acm_override, allowed_override, world_objects};
