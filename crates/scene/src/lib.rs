//! # sublevel-scene
//!
//! Scenes: instances of bodies under rigid poses, warm-start caches, and the persistent store.
//!
//! A *scene* is a set of *instances*; each instance is a stored [`Body`](sublevel_core::Body) (or an
//! exact [`Primitive`], answered by [`sublevel_query::shape`]) placed in the world by a pose
//! `x ↦ R x + t` (unit quaternion `(w, x, y, z)`, translation in meters; paper §IV-C). Queries
//! always run between two instances of one scene:
//!
//! ```text
//! distance(a, b)  = min ‖x − y‖   s.t. p_a'(x) ≤ 1, p_b'(y) ≤ 1      (eq. "distance")
//! growth(1, 2)    = min p_1'(x)   s.t. p_2'(x) ≤ 1                   (eq. "overlap")
//! ```
//!
//! A moving scene asks the same pairs again and again with slightly different poses, so every
//! answer leaves a warm start in a per-scene [`cache::WarmStartCache`], keyed by the ordered pair
//! and the query kind. Warm starts live in body frames, so they stay meaningful when poses change;
//! they are dropped when an instance is removed (or its scene deleted).
//!
//! The modules, each using only those listed before it:
//!
//! - [`store`]: the [`store::Store`] trait (bodies, scenes, instances with their poses; put / get /
//!   list / delete) and its redb implementation [`store::RedbStore`]. Bodies are stored as their
//!   JSON body file, scenes and instances as serde JSON. Every write is one transaction.
//! - [`cache`]: the warm-start cache.
//! - `answer`: one query between two posed instances ([`QueryKind`], [`QueryOptions`], the
//!   replies, [`planner::answer_pair`]), on the path [`sublevel_query::dispatch`] picks, with the
//!   pair's warm start from a cache.
//! - [`Catalog`]: the in-memory state the service works on — parsed bodies (`Arc<Body>`, so
//!   queries never touch the database), scenes with their instances and caches — written through
//!   to the store. Input is validated before anything is written, and memory changes only after
//!   the store committed, so bad input never loses or half-writes data.
//!   A scene also holds point-cloud obstacles from depth sensors, in memory only (never in the
//!   store), replaced atomically, and a scene version raised by every change.
//! - [`moveit`]: MoveIt planning scenes (`moveit_msgs/PlanningScene` in YAML or JSON) read into
//!   typed, validated collision objects, allowed-collision matrix and robot state, and imported
//!   into the catalog as scenes of exact primitives, their meshes planned for compound fits
//!   ([`moveit::ImportPlan`]).
//! - [`planner`]: what a motion planner asks of a scene — private views with pose overrides and
//!   warm starts of their own, candidate states, scene-wide checks with a broad phase.
//!
//! This crate knows nothing of gRPC, tokio or prost; `sublevel-server` translates.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub use sublevel_core::{Error, Result};

mod answer;
pub mod cache;
mod catalog;
pub mod moveit;
pub mod planner;
pub mod store;

pub use answer::{
    precision_limited, DistanceReply, GrowthReply, PairRef, QueryAnswer, QueryKind, QueryOptions, QueryPair, TreeInfo,
    PRECISION_LIMIT,
};
pub use catalog::{
    bounding_body, BodyEntry, BodyFacts, BuiltBody, BuiltCloud, Catalog, CloudBodiesModel, CloudFrame, CloudSet,
    CloudUpdate, InstanceView, PlacedRobot, PosedInstance, RobotEntry, RobotWorld, SceneCloud, SceneRobotCheck,
    SceneView, WarmUp, BODY_MEMORY_BYTES, DEFAULT_MAX_CLOUD_BYTES, DEFAULT_NOISE_RADIUS, DEFAULT_SELF_FILTER_PADDING,
    MAX_CLOUDS_PER_SCENE, MAX_JOB_RECORDS, MAX_NAME_BYTES,
};

use serde::{Deserialize, Serialize};
use sublevel_core::body::BodyFile;
use sublevel_core::math::{pose_from_parts, pose_to_parts, Isometry3, Real};
use sublevel_core::primitive::{Primitive, PrimitiveFile};

/// A pose as stored: unit quaternion `[w, x, y, z]` and translation `[tx, ty, tz]` in meters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoredPose {
    /// Unit quaternion `[w, x, y, z]`.
    pub rotation: [Real; 4],
    /// Translation in meters.
    pub translation: [Real; 3],
}

impl StoredPose {
    /// The stored form of a pose.
    pub fn from_isometry(pose: &Isometry3) -> Self {
        let (rotation, translation) = pose_to_parts(pose);
        Self { rotation, translation }
    }

    /// The stored form of `pose`, refused unless it reads back: the one rule every stored pose
    /// passes, applied when it is written (instances added, poses set, planning scenes imported
    /// at their composed poses) and again when the store reopens ([`StoredPose::to_isometry`]),
    /// so that no acknowledged pose is quarantined at the next start.
    ///
    /// # Errors
    /// [`sublevel_core::Error::InvalidArgument`] naming `field` for a translation beyond
    /// ±[`sublevel_core::math::MAX_COORDINATE`] m, a non-finite entry or a non-unit quaternion.
    pub fn checked(field: &str, pose: &Isometry3) -> Result<Self> {
        let stored = Self::from_isometry(pose);
        stored.to_isometry(field)?;
        Ok(stored)
    }

    /// The pose, validated as by [`pose_from_parts`].
    ///
    /// # Errors
    /// [`sublevel_core::Error::InvalidArgument`] naming `field` for a non-finite entry or non-unit quaternion.
    pub fn to_isometry(&self, field: &str) -> Result<Isometry3> {
        pose_from_parts(field, self.rotation, self.translation)
    }
}

/// A body as stored: its name and its JSON body file, plus the whole containment tree for a
/// compound body, or the exact primitive it stands for.
///
/// Record forms (JSON):
///
/// - `{name, body}` is a single body;
/// - `{name, body, compound}` is a compound body, `body` then holding its root node's body (so a
///   reader that ignores `compound` still sees a body containing the whole model) and `compound`
///   the compound file ([`sublevel_core::compound::CompoundFile`], format `sublevel.compound.v1`)
///   with every node;
/// - `{name, body, primitive}` is an exact primitive ([`PrimitiveFile`]: box, sphere, cylinder,
///   capsule, halfspace). `body` holds the primitive's bounding ellipsoid, a degree-2 body that
///   contains it, for readers that ignore `primitive` (their distances are then lower bounds of
///   the primitive's, their collisions a superset); for a halfspace, which no body contains, it is
///   a body of scale 0 that such a reader refuses to build (it quarantines the record rather than
///   answer for a wrong body). This reader builds the primitive and ignores `body`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BodyRecord {
    /// Human-readable name (not necessarily unique).
    pub name: String,
    /// The body file (degree, exponents, coefficients, center, scale, fit report); for a compound
    /// body, its root node's; for a primitive, its bounding ellipsoid (see above).
    pub body: BodyFile,
    /// The compound file of a compound body (with more than one node); absent for a single body.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compound: Option<sublevel_core::compound::CompoundFile>,
    /// The exact primitive the record stands for; absent for a fitted body.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub primitive: Option<PrimitiveFile>,
    /// The triangle mesh the body was fitted to, in the body's frame, when it was kept with it
    /// (a mesh of an imported planning scene); absent otherwise, and in records written before
    /// meshes were kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshRecord>,
}

/// A triangle mesh as stored with the body fitted to it ([`BodyRecord::mesh`]): the exact
/// geometry the fitted (containing) body stands for.
///
/// Vertices are in meters in the body's frame (the frame of the body's polynomial and of an
/// instance's pose); triangles index `vertices` (each index `< vertices.len()`, checked when the
/// record is stored by [`Catalog::add_fitted_body`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshRecord {
    /// Vertex positions `[x, y, z]`, meters, body frame.
    pub vertices: Vec<[Real; 3]>,
    /// Triangles as three indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

impl MeshRecord {
    /// Checks that every vertex is finite and every index is in range.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `field.vertices[k]` or `field.triangles[k]`.
    pub fn validate(&self, field: &str) -> Result<()> {
        if let Some(k) = self.vertices.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
            return Err(Error::invalid(format!("{field}.vertices[{k}]"), "coordinates must be finite"));
        }
        let n = self.vertices.len();
        if let Some(k) = self.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
            return Err(Error::invalid(
                format!("{field}.triangles[{k}]"),
                format!("an index is outside the {n} vertices"),
            ));
        }
        Ok(())
    }
}

impl BodyRecord {
    /// The record of a single body.
    pub fn single(name: &str, body: BodyFile) -> Self {
        Self { name: name.to_owned(), body, compound: None, primitive: None, mesh: None }
    }

    /// The record of an exact primitive, with its bounding ellipsoid as `body` (see
    /// [`BodyRecord`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `primitive` when the bounding ellipsoid does not build (a
    /// primitive smaller than the smallest body scale, 1 µm).
    pub fn primitive(name: &str, primitive: &Primitive) -> Result<Self> {
        Ok(Self::primitive_bounded(name, primitive, catalog::bounding_body(primitive)?.as_ref()))
    }

    /// [`BodyRecord::primitive`] with the primitive's bounding body already built
    /// ([`catalog::bounding_body`]'s answer), so that adding a primitive builds it once.
    pub(crate) fn primitive_bounded(
        name: &str,
        primitive: &Primitive,
        bound: Option<&sublevel_core::body::Body>,
    ) -> Self {
        let body = match bound {
            Some(b) => b.to_file(),
            None => BodyFile {
                degree: 2,
                exponents: Vec::new(),
                coefficients: Vec::new(),
                center: [0.0; 3],
                scale: 0.0,
                report: sublevel_core::body::FitReport {
                    method: "primitive".into(),
                    notes: vec!["a halfspace: no bounded body contains it; see `primitive`".into()],
                    ..Default::default()
                },
            },
        };
        Self { name: name.to_owned(), body, compound: None, primitive: Some(primitive.to_file()), mesh: None }
    }
}

/// A scene's own fields as stored (its instances are stored separately, one record each, so a
/// pose update writes only the instances that moved).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneMeta {
    /// Human-readable name (not necessarily unique).
    pub name: String,
    /// What an imported planning scene says beyond its shapes (empty for other scenes).
    #[serde(default, skip_serializing_if = "PlanningContext::is_empty")]
    pub planning: PlanningContext,
}

impl SceneMeta {
    /// The fields of a scene named `name`, with no planning context.
    pub fn named(name: &str) -> Self {
        Self { name: name.to_owned(), planning: PlanningContext::default() }
    }
}

/// What a MoveIt planning scene says beyond its shapes, kept with a scene imported from it for
/// the robot checks ([`sublevel_robot::RobotChecker`]): the objects' names, its
/// allowed-collision matrix, and its robot state.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanningContext {
    /// Instance id → the name the planning scene gives it (the collision object's id, with `#k`
    /// for its k-th shape): the names the allowed-collision matrix uses.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub names: std::collections::BTreeMap<String, String>,
    /// The planning scene's allowed-collision matrix, when it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub allowed_collision: Option<moveit::AllowedCollisionMatrix>,
    /// The robot state's joint positions by name (radians, meters): joints a configuration does
    /// not give take these.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub joint_positions: Vec<(String, sublevel_core::math::Real)>,
    /// The robot placed in the scene, when there is one ([`Catalog::set_scene_robot`]): its
    /// joint positions are `joint_positions`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<SceneRobot>,
}

/// The robot of a scene: a stored robot at a base pose, with its grasped objects and link
/// padding, at the scene's joint positions ([`PlanningContext::joint_positions`]). A scene holds
/// at most one robot, as a MoveIt planning scene does; the robot checks of the scene use it when
/// they name no robot of their own.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneRobot {
    /// The stored robot's id (`r-…`).
    pub robot_id: String,
    /// The pose of the robot's root link in the scene.
    pub base: StoredPose,
    /// Objects attached to its links (grasped objects), in attachment order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub attached: Vec<AttachedRecord>,
    /// Padding per link (link name, meters ≥ 0), as MoveIt's link padding
    /// ([`sublevel_robot::RobotChecker::set_link_padding`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub link_padding: Vec<(String, sublevel_core::math::Real)>,
}

/// An object attached to a robot link, as stored: an exact bounded primitive at `origin` in the
/// link's frame, moving with the link ([`sublevel_robot::FittedRobot::attach`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AttachedRecord {
    /// The link it is attached to.
    pub link: String,
    /// Its name (unique among the robot's attached objects).
    pub name: String,
    /// Its shape.
    pub primitive: PrimitiveFile,
    /// Its pose in the link's frame.
    pub origin: StoredPose,
}

impl PlanningContext {
    /// Whether it holds nothing.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
            && self.allowed_collision.is_none()
            && self.joint_positions.is_empty()
            && self.robot.is_none()
    }

    /// The allowed-collision override of [`sublevel_robot::RobotChecker::new`]: the matrix's
    /// entry when the matrix names both (or has a default entry of either), else `None` (the
    /// robot's own defaults).
    pub fn allowed_override(&self) -> impl Fn(&str, &str) -> Option<bool> + '_ {
        move |a, b| moveit::acm_override(self.allowed_collision.as_ref()?, a, b)
    }
}

/// A fitted robot as stored: its name and its robot file ([`sublevel_robot::RobotFile`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RobotRecord {
    /// Human-readable name (not necessarily unique).
    pub name: String,
    /// The robot file (URDF, allowed pairs, link meshes and bodies).
    pub file: sublevel_robot::RobotFile,
}

/// An instance as stored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InstanceRecord {
    /// Id of the instantiated body.
    pub body_id: String,
    /// Its pose.
    pub pose: StoredPose,
}

/// A scene with all its instances, as read back from the store.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneRecord {
    /// The scene's own fields.
    pub meta: SceneMeta,
    /// Instances by id.
    pub instances: std::collections::BTreeMap<String, InstanceRecord>,
}

/// The lifecycle state of a stored job record.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobRecordState {
    /// Queued or running (a record still in this state when the server starts was interrupted).
    Running,
    /// Finished; `body_id` names the stored body.
    Succeeded,
    /// Finished without a body; `error` says why.
    Failed,
    /// The server stopped (or crashed) while the job was queued or running; no body was stored.
    Interrupted,
    /// Cancelled (by a client, or by a server shutting down) before it stored a body.
    Cancelled,
}

/// A fit or grouping job as stored, so that its outcome outlives the process that ran it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobRecord {
    /// `fit` or `group`.
    pub kind: String,
    /// Name of the body the job stores.
    pub name: String,
    /// Lifecycle state.
    pub state: JobRecordState,
    /// Id of the stored body once `Succeeded`; empty before.
    #[serde(default)]
    pub body_id: String,
    /// Why the job failed or was interrupted; empty otherwise.
    #[serde(default)]
    pub error: String,
    /// Last progress or final message.
    #[serde(default)]
    pub message: String,
    /// When the job was created, in milliseconds since the Unix epoch.
    #[serde(default)]
    pub created_unix_ms: u64,
    /// When the job finished, in milliseconds since the Unix epoch; 0 while it runs.
    #[serde(default)]
    pub finished_unix_ms: u64,
}
