//! The in-memory catalog of bodies and scenes, written through to a [`Store`].
//!
//! ```text
//! mod.rs        the catalog's state and locks; opening a store; jobs, bodies, scenes, instances
//! body.rs       stored bodies built on first use, and the background warm-up that builds the rest
//! query.rs      the query methods: single queries and batches, answered on a snapshot
//! grouping.rs   reading a scene's posed bodies and replacing instances by their container (§V)
//! robots.rs     stored robots, and a scene as the world of the robot checks
//! scene_robot.rs the robot placed in a scene: base, joint positions, attached objects
//! clouds.rs     point-cloud obstacles of a scene (in memory only) and the scene version
//! ```

mod body;
mod clouds;
#[cfg(all(test, feature = "store"))]
mod clouds_tests;
mod grouping;
#[cfg(all(test, feature = "store"))]
mod primitive_tests;
mod query;
mod robots;
mod scene_robot;
#[cfg(all(test, feature = "store"))]
mod scene_robot_tests;
#[cfg(all(test, feature = "store"))]
mod tests;

pub use body::{bounding_body, BodyEntry, BodyFacts, BuiltBody, WarmUp};
pub use clouds::{
    BuiltCloud, CloudBodiesModel, CloudFrame, CloudSet, CloudUpdate, SceneCloud, BODY_MEMORY_BYTES,
    DEFAULT_MAX_CLOUD_BYTES, DEFAULT_NOISE_RADIUS, DEFAULT_SELF_FILTER_PADDING, MAX_CLOUDS_PER_SCENE,
};
pub use grouping::PosedInstance;
pub use robots::{RobotEntry, RobotWorld};
pub use scene_robot::{PlacedRobot, SceneRobotCheck};

use super::cache::WarmStartCache;
use super::store::Store;
use super::{
    BodyRecord, InstanceRecord, JobRecord, JobRecordState, MeshRecord, PlanningContext, SceneMeta, StoredPose,
};
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::sync::atomic::AtomicUsize;
use std::sync::{Arc, Mutex, MutexGuard, RwLock, RwLockReadGuard, RwLockWriteGuard};
use sublevel_core::body::Body;
use sublevel_core::compound::CompoundBody;
use sublevel_core::math::Isometry3;
use sublevel_query::NewtonParams;

/// Longest accepted body or scene name, in bytes.
pub const MAX_NAME_BYTES: usize = 256;

/// An instance as seen from outside: its body and pose.
#[derive(Clone, Debug)]
pub struct InstanceView {
    /// The instance's id.
    pub id: String,
    /// The instantiated body's id.
    pub body_id: String,
    /// Its pose.
    pub pose: Isometry3,
}

/// A scene as seen from outside.
#[derive(Clone, Debug)]
pub struct SceneView {
    /// The scene's id.
    pub id: String,
    /// Its name.
    pub name: String,
    /// Its instances, ordered by id.
    pub instances: Vec<InstanceView>,
    /// What the planning scene it was imported from says beyond its shapes (empty otherwise).
    pub planning: Arc<PlanningContext>,
    /// The scene version this view was read at ([`Catalog::scene_version`]).
    pub version: u64,
    /// Its point-cloud obstacles by name (in memory only, see [`Catalog::set_point_cloud`]).
    pub clouds: Arc<CloudSet>,
}

#[derive(Debug)]
struct Instance {
    /// The instantiated body (built on first use, see [`BodyEntry::built`]).
    entry: Arc<BodyEntry>,
    pose: Isometry3,
}

impl Instance {
    fn of(entry: &Arc<BodyEntry>, pose: Isometry3) -> Self {
        Self { entry: entry.clone(), pose }
    }

    /// The instantiated body's id.
    fn body_id(&self) -> &str {
        &self.entry.id
    }
}

#[derive(Debug)]
struct SceneState {
    id: String,
    name: String,
    instances: BTreeMap<String, Instance>,
    cache: WarmStartCache,
    /// Instance names, allowed-collision matrix and robot state of an imported planning scene.
    planning: Arc<PlanningContext>,
    /// The scene's robot as last built, with the stored robot it was built from
    /// ([`Catalog::placed_robot`]).
    placed: Option<PlacedCache>,
    /// Set (under this scene's lock) when the scene is deleted, so a request that fetched the
    /// scene just before cannot write it back to the store.
    deleted: bool,
    /// The scene version: 1 when the scene is created or loaded, raised by every change of its
    /// instances, poses, planning context (robot, joint positions) or point clouds.
    version: u64,
    /// Point-cloud obstacles by name, replaced whole (copy on write) by every cloud change, so a
    /// reader's `Arc` is one moment's set ([`clouds`]).
    clouds: Arc<CloudSet>,
}

impl SceneState {
    /// A live scene at version 1 without point clouds.
    fn new(id: String, name: String, instances: BTreeMap<String, Instance>, planning: Arc<PlanningContext>) -> Self {
        Self {
            id,
            name,
            instances,
            cache: WarmStartCache::default(),
            planning,
            placed: None,
            deleted: false,
            version: 1,
            clouds: Arc::default(),
        }
    }

    /// Records a change of the scene: raises its version and returns the new one.
    fn changed(&mut self) -> u64 {
        self.version += 1;
        self.version
    }
}

/// A scene's built robot and the stored robot it was built from: valid while the scene's record
/// of its robot is the one it was built from and that stored robot is still the catalog's.
#[derive(Clone, Debug)]
struct PlacedCache {
    placed: Arc<PlacedRobot>,
    robot_source: Arc<sublevel_robot::FittedRobot>,
}

/// Bodies and scenes in memory, written through to a [`Store`].
///
/// Locks are std locks, not async ones: every critical section is short (a map lookup, a
/// microsecond query, or one store transaction) and never awaits. Lock order, to rule out
/// deadlocks: `bodies` → `scenes` → one scene's mutex.
pub struct Catalog {
    store: Arc<dyn Store>,
    bodies: RwLock<BTreeMap<String, Arc<BodyEntry>>>,
    scenes: RwLock<BTreeMap<String, Arc<Mutex<SceneState>>>>,
    jobs: RwLock<BTreeMap<String, JobRecord>>,
    robots: RwLock<BTreeMap<String, Arc<RobotEntry>>>,
    /// The quarantine count and the bodies waiting for their build (see [`body`]).
    builds: Arc<body::Builds>,
    params: NewtonParams,
    /// Bytes held by the point clouds of every scene ([`clouds`]).
    cloud_bytes: AtomicUsize,
}

/// Most job records kept; beyond it the oldest finished ones are deleted.
pub const MAX_JOB_RECORDS: usize = 1024;

impl std::fmt::Debug for Catalog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Catalog").field("params", &self.params).finish_non_exhaustive()
    }
}

// A panic while holding a lock cannot leave these maps half-updated (every update is a single
// insert/remove after the store committed), so a poisoned lock is safe to keep using.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
fn read<T>(m: &RwLock<T>) -> RwLockReadGuard<'_, T> {
    m.read().unwrap_or_else(|e| e.into_inner())
}
fn write<T>(m: &RwLock<T>) -> RwLockWriteGuard<'_, T> {
    m.write().unwrap_or_else(|e| e.into_inner())
}

/// A fresh random id with a kind prefix, e.g. `b-3f29c0d1a4e5b6c7`. Ids never contain `/`.
pub(crate) fn new_id(prefix: &str) -> String {
    format!("{prefix}-{:016x}", rand::random::<u64>())
}

/// Rejects a name (of a body, scene, robot, instance, cloud or attached object) longer than
/// [`MAX_NAME_BYTES`] or holding a control character (NUL, newline, …): names are printed in
/// logs and answers, and keyed in the allowed-collision matrix, where such bytes would forge or
/// split them.
pub(crate) fn check_name(field: &str, name: &str) -> Result<()> {
    if name.len() > MAX_NAME_BYTES {
        return Err(Error::invalid(field, format!("at most {MAX_NAME_BYTES} bytes, got {}", name.len())));
    }
    if let Some((at, c)) = name.char_indices().find(|(_, c)| c.is_control()) {
        return Err(Error::invalid(
            field,
            format!("holds the control character U+{:04X} at byte {at}: names are printable text", c as u32),
        ));
    }
    Ok(())
}

impl Catalog {
    /// Loads every body, scene and job record of `store` into memory. Bodies are parsed, not
    /// built: each builds on first use, and [`Catalog::warm_up`] builds the rest (see [`body`]),
    /// so opening takes the time of reading the records (well under a second for 10 000 bodies).
    ///
    /// The store always opens: an instance whose pose no longer validates is moved to the store's
    /// quarantine with the reason (see [`super::store`]) and counted in [`Catalog::quarantined`];
    /// a stored body that no longer validates is moved there when it is built (its first use or
    /// the warm-up) and then answers [`Error::FailedPrecondition`] naming it; an instance whose
    /// body is missing is skipped with a warning (and kept). A job record still `running` was
    /// interrupted by the previous stop and is marked `interrupted`.
    ///
    /// # Errors
    /// [`Error::Storage`] when the store cannot be read.
    pub fn open(store: Box<dyn Store>, params: NewtonParams) -> Result<Self> {
        let store: Arc<dyn Store> = Arc::from(store);
        let builds = Arc::new(body::Builds::new(store.clone()));
        let mut bodies = BTreeMap::new();
        for (id, rec) in store.list_bodies()? {
            let entry = Arc::new(BodyEntry::of_record(&id, rec, &builds));
            bodies.insert(id, entry);
        }
        let mut scenes = BTreeMap::new();
        for (id, rec) in store.list_scenes()? {
            let mut instances = BTreeMap::new();
            for (iid, inst) in rec.instances {
                let Some(entry) = bodies.get(&inst.body_id) else {
                    tracing::warn!(scene_id = %id, instance_id = %iid, body_id = %inst.body_id, "skipping instance of missing body");
                    continue;
                };
                // The rule every write applied ([`StoredPose::checked`]).
                match inst.pose.to_isometry("pose") {
                    Ok(pose) => {
                        instances.insert(iid, Instance::of(entry, pose));
                    }
                    Err(e) => {
                        tracing::warn!(scene_id = %id, instance_id = %iid, error = %e, "quarantining instance");
                        store.quarantine("instances", &format!("{id}/{iid}"), &format!("does not validate: {e}"))?;
                    }
                }
            }
            let state = SceneState::new(id.clone(), rec.meta.name, instances, Arc::new(rec.meta.planning));
            scenes.insert(id, Arc::new(Mutex::new(state)));
        }
        let mut jobs = BTreeMap::new();
        for (id, mut rec) in store.list_jobs()? {
            if rec.state == JobRecordState::Running {
                rec.state = JobRecordState::Interrupted;
                rec.error =
                    "interrupted: the server stopped while the job was queued or running; no body was stored".into();
                store.put_job(&id, &rec)?;
            }
            jobs.insert(id, rec);
        }
        let robots = robots::load(store.as_ref())?;
        let quarantined = store.quarantined()?.len();
        builds.add_quarantined(quarantined);
        if quarantined > 0 {
            tracing::warn!(records = quarantined, "the store's quarantine holds records that could not be loaded");
        }
        tracing::info!(
            bodies = bodies.len(),
            scenes = scenes.len(),
            jobs = jobs.len(),
            robots = robots.len(),
            quarantined,
            "catalog loaded"
        );
        Ok(Self {
            store,
            bodies: RwLock::new(bodies),
            scenes: RwLock::new(scenes),
            jobs: RwLock::new(jobs),
            robots: RwLock::new(robots),
            builds,
            params,
            cloud_bytes: AtomicUsize::new(0),
        })
    }

    /// Number of records in the store's quarantine (unreadable or invalid records kept aside;
    /// see [`super::store`]): those there when the catalog was opened plus the bodies found
    /// invalid since, when they were built. Health reports them.
    pub fn quarantined(&self) -> usize {
        self.builds.quarantined()
    }

    /// Writes a job's record (and prunes the oldest finished records beyond
    /// [`MAX_JOB_RECORDS`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the record does not survive its JSON round trip;
    /// [`Error::Storage`].
    pub fn record_job(&self, id: &str, record: &JobRecord) -> Result<()> {
        self.store.put_job(id, record)?;
        let mut jobs = write(&self.jobs);
        jobs.insert(id.to_owned(), record.clone());
        if jobs.len() > MAX_JOB_RECORDS {
            let mut done: Vec<(u64, String)> = jobs
                .iter()
                .filter(|(_, r)| r.state != JobRecordState::Running)
                .map(|(k, r)| (r.created_unix_ms, k.clone()))
                .collect();
            done.sort();
            let excess = jobs.len() - MAX_JOB_RECORDS;
            let old: Vec<String> = done.into_iter().take(excess).map(|(_, k)| k).collect();
            let refs: Vec<&str> = old.iter().map(String::as_str).collect();
            self.store.delete_jobs(&refs)?;
            for k in &old {
                jobs.remove(k);
            }
        }
        Ok(())
    }

    /// A job's stored record, if any.
    pub fn job(&self, id: &str) -> Option<JobRecord> {
        read(&self.jobs).get(id).cloned()
    }

    /// Every stored job record with its id, ordered by id (at most [`MAX_JOB_RECORDS`]).
    pub fn jobs(&self) -> Vec<(String, JobRecord)> {
        read(&self.jobs).iter().map(|(id, r)| (id.clone(), r.clone())).collect()
    }

    /// The Newton parameters every query uses.
    pub fn params(&self) -> &NewtonParams {
        &self.params
    }

    // ----------------------------------------------------------------------------------------
    // Bodies
    // ----------------------------------------------------------------------------------------

    /// Stores a validated body under a fresh id and returns the id.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `name` for an over-long name; [`Error::Storage`].
    pub fn add_body(&self, name: &str, body: Body) -> Result<String> {
        check_name("name", name)?;
        let id = new_id("b");
        self.store.put_body(&id, &BodyRecord::single(name, body.to_file()))?;
        let entry = BodyEntry::of_built(&id, name, BuiltBody { body: Arc::new(body), tree: None, primitive: None });
        write(&self.bodies).insert(id.clone(), Arc::new(entry));
        Ok(id)
    }

    /// Stores a validated compound body under a fresh id and returns the id. A
    /// one-node tree is stored as the single body it is (one-node tree semantics: its queries
    /// stay on the single-body path); a larger tree is stored as a compound record
    /// ([`BodyRecord`]: the root's body plus the compound file).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `name` for an over-long name; [`Error::Storage`].
    pub fn add_compound_body(&self, name: &str, tree: CompoundBody) -> Result<String> {
        self.add_fitted_body(name, tree, None)
    }

    /// [`Catalog::add_compound_body`], keeping `mesh` (the triangle mesh the body was fitted to,
    /// in the body's frame, meters) with the body ([`BodyRecord::mesh`]); the entry answers it
    /// from [`BodyEntry::mesh`].
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `name` for an over-long name, or `mesh.vertices[k]` /
    /// `mesh.triangles[k]` for a non-finite vertex or an index out of range
    /// ([`MeshRecord::validate`]); [`Error::Storage`].
    pub fn add_fitted_body(&self, name: &str, tree: CompoundBody, mesh: Option<MeshRecord>) -> Result<String> {
        check_name("name", name)?;
        if let Some(m) = &mesh {
            m.validate("mesh")?;
        }
        let id = new_id("b");
        let root = tree.body(tree.root()).clone();
        let (rec, built) = if tree.node_count() == 1 {
            let rec = BodyRecord { mesh, ..BodyRecord::single(name, root.to_file()) };
            (rec, BuiltBody { body: Arc::new(root), tree: None, primitive: None })
        } else {
            let rec = BodyRecord {
                name: name.to_owned(),
                body: root.to_file(),
                compound: Some(tree.to_file()),
                primitive: None,
                mesh,
            };
            (rec, BuiltBody { body: Arc::new(root), tree: Some(Arc::new(tree)), primitive: None })
        };
        self.store.put_body(&id, &rec)?;
        let entry = BodyEntry::of_built(&id, name, built).with_mesh(rec.mesh.map(Arc::new));
        write(&self.bodies).insert(id.clone(), Arc::new(entry));
        Ok(id)
    }

    /// Stores an exact primitive (box, sphere, cylinder, capsule, halfspace) under a fresh id and
    /// returns the id. It is used as a body is (instances, queries, scene checks); its record
    /// holds the primitive beside its bounding ellipsoid ([`BodyRecord`]). No fit, no SDP.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `name` for an over-long name, or `primitive` for one
    /// smaller than 1 µm ([`bounding_body`]); [`Error::Storage`].
    pub fn add_primitive(&self, name: &str, primitive: sublevel_core::primitive::Primitive) -> Result<String> {
        check_name("name", name)?;
        // The bounding ellipsoid built once, for the record and the built body.
        let bound = bounding_body(&primitive)?;
        let record = BodyRecord::primitive_bounded(name, &primitive, bound.as_ref());
        let built = BuiltBody::of_bound(primitive, bound)?;
        let id = new_id("b");
        self.store.put_body(&id, &record)?;
        let entry = BodyEntry::of_built(&id, name, built);
        write(&self.bodies).insert(id.clone(), Arc::new(entry));
        Ok(id)
    }

    /// The body with id `id` (not necessarily built: see [`BodyEntry::built`]).
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `body`).
    pub fn body(&self, id: &str) -> Result<Arc<BodyEntry>> {
        if let Some(entry) = read(&self.bodies).get(id).cloned() {
            return Ok(entry);
        }
        self.load_body(id)?.ok_or_else(|| Error::not_found("body", id))
    }

    /// A body another replica stored in a shared store ([`Store::shared`]) since this catalog
    /// was opened, now held here too (built on first use); `None` when the store has none (or is
    /// not shared).
    fn load_body(&self, id: &str) -> Result<Option<Arc<BodyEntry>>> {
        if !self.store.shared() {
            return Ok(None);
        }
        let Some(rec) = self.store.get_body(id)? else { return Ok(None) };
        let entry = Arc::new(BodyEntry::of_record(id, rec, &self.builds));
        Ok(Some(write(&self.bodies).entry(id.to_owned()).or_insert(entry).clone()))
    }

    /// A scene written by another replica to a shared store ([`Store::shared`]), loaded with its
    /// instances (scale-out: the replica that owns a scene loads it on first use, see
    /// `deploy/SCALING.md`); `None` when the store has none (or is not shared).
    fn load_scene(&self, id: &str) -> Result<Option<Arc<Mutex<SceneState>>>> {
        if !self.store.shared() {
            return Ok(None);
        }
        let Some(rec) = self.store.get_scene(id)? else { return Ok(None) };
        let mut instances = BTreeMap::new();
        for (iid, inst) in rec.instances {
            let (Ok(entry), Ok(pose)) = (self.body(&inst.body_id), inst.pose.to_isometry("pose")) else {
                tracing::warn!(scene_id = %id, instance_id = %iid, "skipping an instance that does not load");
                continue;
            };
            instances.insert(iid, Instance::of(&entry, pose));
        }
        let state = SceneState::new(id.to_owned(), rec.meta.name, instances, Arc::new(rec.meta.planning));
        tracing::info!(scene_id = %id, "scene loaded from the shared store");
        Ok(Some(write(&self.scenes).entry(id.to_owned()).or_insert_with(|| Arc::new(Mutex::new(state))).clone()))
    }

    /// All bodies, ordered by id.
    pub fn bodies(&self) -> Vec<Arc<BodyEntry>> {
        read(&self.bodies).values().cloned().collect()
    }

    /// Deletes a body that no instance uses.
    ///
    /// # Errors
    /// [`Error::NotFound`]; [`Error::FailedPrecondition`] while an instance uses it;
    /// [`Error::Storage`].
    pub fn delete_body(&self, id: &str) -> Result<()> {
        let mut bodies = write(&self.bodies);
        if !bodies.contains_key(id) {
            return Err(Error::not_found("body", id));
        }
        for scene in read(&self.scenes).values() {
            let s = lock(scene);
            if let Some((iid, _)) = s.instances.iter().find(|(_, inst)| inst.body_id() == id) {
                return Err(Error::FailedPrecondition(format!(
                    "body `{id}` is used by instance `{iid}` of scene `{}`; remove the instance first",
                    s.id
                )));
            }
        }
        self.store.delete_body(id)?;
        bodies.remove(id);
        Ok(())
    }

    // ----------------------------------------------------------------------------------------
    // Scenes
    // ----------------------------------------------------------------------------------------

    /// Creates an empty scene and returns its id.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `name` for an over-long name; [`Error::Storage`].
    pub fn create_scene(&self, name: &str) -> Result<String> {
        check_name("name", name)?;
        let id = new_id("s");
        self.store.put_scene(&id, &SceneMeta::named(name))?;
        let state = SceneState::new(id.clone(), name.to_owned(), BTreeMap::new(), Arc::default());
        write(&self.scenes).insert(id.clone(), Arc::new(Mutex::new(state)));
        Ok(id)
    }

    /// The scene `id` (its lock not taken; see [`Catalog::with_scene`]).
    fn scene(&self, id: &str) -> Result<Arc<Mutex<SceneState>>> {
        if let Some(scene) = read(&self.scenes).get(id).cloned() {
            return Ok(scene);
        }
        self.load_scene(id)?.ok_or_else(|| Error::not_found("scene", id))
    }

    /// Locks a live scene (one that was not deleted meanwhile).
    fn with_scene<T>(&self, id: &str, f: impl FnOnce(&mut SceneState) -> Result<T>) -> Result<T> {
        let scene = self.scene(id)?;
        let mut s = lock(&scene);
        if s.deleted {
            return Err(Error::not_found("scene", id));
        }
        f(&mut s)
    }

    /// A scene with its instances.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`).
    pub fn get_scene(&self, id: &str) -> Result<SceneView> {
        self.with_scene(id, |s| Ok(view(s)))
    }

    /// All scenes, ordered by id.
    pub fn scenes(&self) -> Vec<SceneView> {
        read(&self.scenes).values().map(|s| view(&lock(s))).collect()
    }

    /// Whether any instance of the scene is a nonconvex body, whose queries solve an SDP lower
    /// bound (milliseconds): the service runs such queries off its async workers. False for an
    /// unknown scene (the query itself then reports it). Builds no body ([`BodyEntry::facts`]).
    pub fn has_nonconvex(&self, scene_id: &str) -> bool {
        let nonconvex = |i: &Instance| i.entry.facts().nonconvex;
        self.scene(scene_id).map(|sc| lock(&sc).instances.values().any(nonconvex)).unwrap_or(false)
    }

    /// Whether any instance of the scene is a compound body (its queries run the tree queries,
    /// tens of µs each). False for an unknown scene. Builds no body.
    pub fn has_compound(&self, scene_id: &str) -> bool {
        let compound = |i: &Instance| i.entry.facts().compound;
        self.scene(scene_id).map(|sc| lock(&sc).instances.values().any(compound)).unwrap_or(false)
    }

    /// Deletes a scene with its instances and warm starts.
    ///
    /// # Errors
    /// [`Error::NotFound`]; [`Error::Storage`].
    pub fn delete_scene(&self, id: &str) -> Result<()> {
        let mut scenes = write(&self.scenes);
        let scene = scenes.get(id).cloned().ok_or_else(|| Error::not_found("scene", id))?;
        let mut s = lock(&scene);
        self.store.delete_scene(id)?;
        s.deleted = true;
        self.release_clouds(&mut s);
        drop(s);
        scenes.remove(id);
        Ok(())
    }

    /// Adds an instance of body `body_id` to scene `scene_id` under `pose`; returns its id.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or the body; [`Error::InvalidArgument`] naming `pose`
    /// when it would not read back from the store ([`StoredPose::checked`]); [`Error::Storage`].
    pub fn add_instance(&self, scene_id: &str, body_id: &str, pose: Isometry3) -> Result<String> {
        // Load it first if another replica stored it (shared store); then hold the bodies lock
        // so the body cannot be deleted between the check and the insert.
        self.body(body_id)?;
        self.scene(scene_id)?;
        let bodies = read(&self.bodies);
        let entry = bodies.get(body_id).ok_or_else(|| Error::not_found("body", body_id))?.clone();
        let stored = StoredPose::checked("pose", &pose)?;
        self.with_scene(scene_id, |s| {
            let id = new_id("i");
            let rec = InstanceRecord { body_id: body_id.to_owned(), pose: stored };
            self.store.put_instances(scene_id, &[(&id, &rec)], false)?;
            s.instances.insert(id.clone(), Instance::of(&entry, pose));
            s.changed();
            Ok(id)
        })
    }

    /// Adds an instance of body `body_id` to scene `scene_id` under `pose` and registers `name`
    /// as its planning name ([`PlanningContext::names`], the name the allowed-collision matrix
    /// and the robot checks use), under the scene's lock, so concurrent additions keep every
    /// name. Refused when the scene already holds `max_instances` instances. Returns the new
    /// instance's id.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or the body; [`Error::InvalidArgument`] naming `name`
    /// (longer than [`MAX_NAME_BYTES`]) or `pose` ([`StoredPose::checked`]);
    /// [`Error::ResourceExhausted`] when the scene is full; [`Error::Storage`] (nothing changes
    /// then).
    pub fn add_named_instance(
        &self,
        scene_id: &str,
        body_id: &str,
        pose: Isometry3,
        name: &str,
        max_instances: usize,
    ) -> Result<String> {
        check_name("name", name)?;
        let stored = StoredPose::checked("pose", &pose)?;
        self.body(body_id)?;
        self.scene(scene_id)?;
        let bodies = read(&self.bodies);
        let entry = bodies.get(body_id).ok_or_else(|| Error::not_found("body", body_id))?.clone();
        self.with_scene(scene_id, |s| {
            if s.instances.len() >= max_instances {
                return Err(Error::ResourceExhausted(format!(
                    "scene `{scene_id}` holds {} instances, the most a scene may hold",
                    s.instances.len()
                )));
            }
            if s.clouds.contains_key(name) {
                return Err(Error::invalid(
                    "name",
                    format!("`{}` is the name of a point cloud of the scene", sublevel_core::error::clip(name)),
                ));
            }
            let id = new_id("i");
            let mut planning = (*s.planning).clone();
            planning.names.insert(id.clone(), name.to_owned());
            let meta = SceneMeta { name: s.name.clone(), planning };
            let rec = InstanceRecord { body_id: body_id.to_owned(), pose: stored };
            self.store.put_instances(scene_id, &[(&id, &rec)], false)?;
            if let Err(e) = self.store.put_scene(scene_id, &meta) {
                let _ = self.store.delete_instance(scene_id, &id);
                return Err(e);
            }
            s.instances.insert(id.clone(), Instance::of(&entry, pose));
            s.planning = Arc::new(meta.planning);
            s.changed();
            Ok(id)
        })
    }

    /// Adds many instances to scene `scene_id` in one store transaction, instance k of body
    /// `instances[k].0` under pose `instances[k].1`; returns their ids in order. All or nothing.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or a body (naming `instances[k].body_id`; nothing is
    /// added then); [`Error::InvalidArgument`] naming `instances[k].pose` for a pose that would
    /// not read back from the store ([`StoredPose::checked`]); [`Error::Storage`].
    pub fn add_instances(&self, scene_id: &str, instances: &[(&str, Isometry3)]) -> Result<Vec<String>> {
        let records: Vec<InstanceRecord> = instances
            .iter()
            .enumerate()
            .map(|(k, (body_id, pose))| {
                let pose = StoredPose::checked(&format!("instances[{k}].pose"), pose)?;
                Ok(InstanceRecord { body_id: (*body_id).to_owned(), pose })
            })
            .collect::<Result<_>>()?;
        for (body_id, _) in instances {
            self.body(body_id)?;
        }
        self.scene(scene_id)?;
        let bodies = read(&self.bodies);
        let entries = instances
            .iter()
            .enumerate()
            .map(|(k, (body_id, _))| {
                let field = format!("instances[{k}].body_id");
                bodies.get(*body_id).cloned().ok_or_else(|| Error::not_found_at(field, "body", *body_id))
            })
            .collect::<Result<Vec<_>>>()?;
        self.with_scene(scene_id, |s| {
            let ids: Vec<String> = instances.iter().map(|_| new_id("i")).collect();
            let rows: Vec<(&str, &InstanceRecord)> = ids.iter().map(String::as_str).zip(records.iter()).collect();
            self.store.put_instances(scene_id, &rows, false)?;
            for ((id, entry), (_, pose)) in ids.iter().zip(&entries).zip(instances) {
                s.instances.insert(id.clone(), Instance::of(entry, *pose));
            }
            s.changed();
            Ok(ids)
        })
    }

    /// Sets the poses of many instances of one scene: all or nothing.
    ///
    /// Poses must already be validated (see [`sublevel_core::math::pose_from_parts`]); `poses[k].0` is
    /// the instance id. Returns the number of instances updated.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene, or for an unknown instance (naming `poses[k].instance_id`);
    /// [`Error::InvalidArgument`] naming `poses[k].instance_id` for a repeated one, or
    /// `poses[k].pose` for a pose that would not read back from the store
    /// ([`StoredPose::checked`]; nothing changes then); [`Error::Storage`].
    pub fn set_poses(&self, scene_id: &str, poses: &[(String, Isometry3)]) -> Result<usize> {
        self.with_scene(scene_id, |s| {
            let mut seen = std::collections::HashSet::new();
            let mut records = Vec::with_capacity(poses.len());
            for (k, (iid, pose)) in poses.iter().enumerate() {
                let field = format!("poses[{k}].instance_id");
                let inst = s.instances.get(iid).ok_or_else(|| Error::not_found_at(&field, "instance", iid.as_str()))?;
                if !seen.insert(iid.as_str()) {
                    return Err(Error::invalid(field, format!("instance `{iid}` appears twice")));
                }
                let pose = StoredPose::checked(&format!("poses[{k}].pose"), pose)?;
                records.push(InstanceRecord { body_id: inst.body_id().to_owned(), pose });
            }
            let rows: Vec<(&str, &InstanceRecord)> =
                poses.iter().zip(records.iter()).map(|((iid, _), rec)| (iid.as_str(), rec)).collect();
            self.store.put_instances(scene_id, &rows, true)?;
            for (iid, pose) in poses {
                if let Some(inst) = s.instances.get_mut(iid) {
                    inst.pose = *pose;
                }
            }
            s.changed();
            Ok(poses.len())
        })
    }

    /// Removes an instance and every warm start involving it.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or the instance; [`Error::Storage`].
    pub fn remove_instance(&self, scene_id: &str, instance_id: &str) -> Result<()> {
        self.with_scene(scene_id, |s| {
            if !s.instances.contains_key(instance_id) {
                return Err(Error::not_found("instance", instance_id));
            }
            self.store.delete_instance(scene_id, instance_id)?;
            s.instances.remove(instance_id);
            s.cache.invalidate_instance(instance_id);
            s.changed();
            Ok(())
        })
    }

    /// Number of warm starts cached for a scene (for monitoring and tests).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene.
    pub fn cached_warm_starts(&self, scene_id: &str) -> Result<usize> {
        self.with_scene(scene_id, |s| Ok(s.cache.len()))
    }
}

/// A scene as seen from outside (ids, names, poses).
fn view(s: &SceneState) -> SceneView {
    SceneView {
        id: s.id.clone(),
        name: s.name.clone(),
        instances: s
            .instances
            .iter()
            .map(|(id, i)| InstanceView { id: id.clone(), body_id: i.body_id().to_owned(), pose: i.pose })
            .collect(),
        planning: s.planning.clone(),
        version: s.version,
        clouds: s.clouds.clone(),
    }
}

/// The instance `id` of a locked scene.
fn instance<'a>(s: &'a SceneState, id: &str) -> Result<&'a Instance> {
    s.instances.get(id).ok_or_else(|| Error::not_found("instance", id))
}

/// A built body at a pose (the body shared, the pose copied).
fn posed(built: &BuiltBody, pose: Isometry3) -> crate::answer::Posed {
    crate::answer::Posed { body: built.body.clone(), tree: built.tree.clone(), primitive: built.primitive, pose }
}
