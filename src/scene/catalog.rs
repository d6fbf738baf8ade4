//! The in-memory catalog of bodies and scenes, written through to a [`Store`].

use super::cache::WarmStartCache;
use super::store::Store;
use super::{BodyRecord, InstanceRecord, JobRecord, JobRecordState, SceneMeta, StoredPose};
use crate::body::Body;
use crate::math::Isometry3;
use crate::query::{
    CertifiedDistance, CertifiedGrowth, CertifyMode, CertifyParams, DistanceResult, GrowthResult, NewtonParams,
    PoseGradient,
};
use crate::{Error, Result};
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, MutexGuard, RwLock, RwLockReadGuard, RwLockWriteGuard};

/// Longest accepted body or scene name, in bytes.
pub const MAX_NAME_BYTES: usize = 256;

/// A stored body, parsed once and shared with every query that uses it.
#[derive(Debug)]
pub struct BodyEntry {
    /// The body's id.
    pub id: String,
    /// Its name.
    pub name: String,
    /// The validated body.
    pub body: Arc<Body>,
}

/// Which query to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QueryKind {
    /// Euclidean distance between `first` and `second` (eq. "distance").
    Distance,
    /// Growth measure d(first ‖ second) (eq. "overlap").
    Growth,
    /// Collide-with-margin: is the distance below [`QueryPair::margin`]? (see
    /// [`super::planner::answer_pair`]).
    Collide,
}

/// Per-query options: certification mode and pose gradients.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct QueryOptions {
    /// [`CertifyMode::Newton`] (default: the SDP only as a fallback) or [`CertifyMode::Certify`]
    /// (always attach the level-0 certificate); see [`crate::query::certified`].
    pub mode: CertifyMode,
    /// Also return the gradients of the value with respect to both poses
    /// ([`crate::query::gradient`]).
    pub with_gradient: bool,
    /// Solve cold: ignore the pair's warm start and leave none behind.
    pub cold: bool,
    /// Distance queries: also the penetration depth when overlapping (signed distance,
    /// [`crate::query::penetration`]).
    pub signed: bool,
}

/// One query of a batch: a kind, an ordered pair of instance ids and its options.
#[derive(Clone, Debug)]
pub struct QueryPair {
    /// Which query.
    pub kind: QueryKind,
    /// First instance (A, or p₁).
    pub first: String,
    /// Second instance (B, or p₂).
    pub second: String,
    /// Certification and gradient options.
    pub options: QueryOptions,
    /// For [`QueryKind::Collide`]: the margin in meters (≥ 0); ignored otherwise.
    pub margin: crate::math::Real,
}

impl QueryPair {
    /// This query by reference ([`PairRef`]).
    pub fn view(&self) -> PairRef<'_> {
        PairRef {
            kind: self.kind,
            first: &self.first,
            second: &self.second,
            options: self.options,
            margin: self.margin,
        }
    }
}

/// One query with borrowed instance ids: what [`super::planner::answer_pair`] needs (the ids key
/// the warm starts). Built from a [`QueryPair`] ([`QueryPair::view`]) or from columns
/// ([`Catalog::batch_columns`]) without allocating.
#[derive(Clone, Copy, Debug)]
pub struct PairRef<'a> {
    /// Which query.
    pub kind: QueryKind,
    /// First instance (A, or p₁).
    pub first: &'a str,
    /// Second instance (B, or p₂).
    pub second: &'a str,
    /// Certification and gradient options.
    pub options: QueryOptions,
    /// For [`QueryKind::Collide`]: the margin in meters (≥ 0); ignored otherwise.
    pub margin: crate::math::Real,
}

/// A certified distance answer with optional pose gradients.
#[derive(Clone, Debug)]
pub struct DistanceReply {
    /// The answer with its source and certificate.
    pub answer: CertifiedDistance,
    /// (∂D/∂ξ_a, ∂D/∂ξ_b) when asked for and the answer is not a lower bound (twists, see
    /// [`crate::query::gradient`]).
    pub gradients: Option<(PoseGradient, PoseGradient)>,
    /// The inputs limit the accuracy (see [`precision_limited`]).
    pub precision_limited: bool,
    /// The signed distance was asked for ([`QueryOptions::signed`]).
    pub signed: bool,
    /// With [`QueryOptions::signed`] on an overlapping answer of convex bodies: the penetration.
    pub penetration: Option<crate::query::penetration::Penetration>,
}

/// A certified growth answer with optional pose gradients.
#[derive(Clone, Debug)]
pub struct GrowthReply {
    /// The answer with its source and certificate.
    pub answer: CertifiedGrowth,
    /// (∂d/∂ξ₁, ∂d/∂ξ₂) when asked for and the answer is not a lower bound.
    pub gradients: Option<(PoseGradient, PoseGradient)>,
    /// The inputs limit the accuracy (see [`precision_limited`]).
    pub precision_limited: bool,
}

/// Relative precision in a body's normalized coordinates below which an answer is flagged as
/// limited by its inputs: 1e-9, ten times the Newton KKT tolerance's square root region.
pub const PRECISION_LIMIT: crate::math::Real = 1e-9;

/// True when one unit in the last place of the largest coordinate involved (the two poses'
/// translations and the bodies' centers, meters) exceeds [`PRECISION_LIMIT`] of the smaller
/// body's scale: the query's inputs already carry that error in normalized coordinates, before
/// any solver runs (e.g. a 1 mm body 500 km from the origin).
pub fn precision_limited(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> bool {
    let mag = [
        pose_a.translation.vector.amax(),
        pose_b.translation.vector.amax(),
        a.center().amax() + a.scale(),
        b.center().amax() + b.scale(),
    ]
    .into_iter()
    .fold(0.0, crate::math::Real::max);
    mag * crate::math::Real::EPSILON > PRECISION_LIMIT * a.scale().min(b.scale())
}

/// The answer of one query of a batch.
///
/// The distance variant is larger (its warm start carries earlier answers for the motion
/// predictor); answers are built once per query and moved, so boxing it would only add an
/// allocation to every query.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)]
pub enum QueryAnswer {
    /// A distance answer.
    Distance(DistanceReply),
    /// A growth answer.
    Growth(GrowthReply),
    /// A collide-with-margin answer.
    Collide(super::planner::CollideReply),
}

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
}

#[derive(Debug)]
struct Instance {
    body_id: String,
    body: Arc<Body>,
    pose: Isometry3,
}

#[derive(Debug)]
struct SceneState {
    id: String,
    name: String,
    instances: BTreeMap<String, Instance>,
    cache: WarmStartCache,
    /// Set (under this scene's lock) when the scene is deleted, so a request that fetched the
    /// scene just before cannot write it back to the store.
    deleted: bool,
}

/// Bodies and scenes in memory, written through to a [`Store`].
///
/// Locks are std locks, not async ones: every critical section is short (a map lookup, a
/// microsecond query, or one store transaction) and never awaits. Lock order, to rule out
/// deadlocks: `bodies` → `scenes` → one scene's mutex.
pub struct Catalog {
    store: Box<dyn Store>,
    bodies: RwLock<BTreeMap<String, Arc<BodyEntry>>>,
    scenes: RwLock<BTreeMap<String, Arc<Mutex<SceneState>>>>,
    jobs: RwLock<BTreeMap<String, JobRecord>>,
    quarantined: usize,
    params: NewtonParams,
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

fn check_name(field: &str, name: &str) -> Result<()> {
    if name.len() > MAX_NAME_BYTES {
        return Err(Error::invalid(field, format!("at most {MAX_NAME_BYTES} bytes, got {}", name.len())));
    }
    Ok(())
}

impl Catalog {
    /// Loads every body, scene and job record of `store` into memory.
    ///
    /// The store always opens: a stored body that no longer validates, or an instance whose pose
    /// does not, is moved to the store's quarantine with the reason (see
    /// [`super::store`]) and counted in [`Catalog::quarantined`]; an instance whose body is
    /// missing is skipped with a warning (and kept). A job record still `running` was
    /// interrupted by the previous stop and is marked `interrupted`.
    ///
    /// # Errors
    /// [`Error::Storage`] when the store cannot be read.
    pub fn open(store: Box<dyn Store>, params: NewtonParams) -> Result<Self> {
        let mut bodies = BTreeMap::new();
        for (id, rec) in store.list_bodies()? {
            match Body::from_file(rec.body) {
                Ok(body) => {
                    let entry = BodyEntry { id: id.clone(), name: rec.name, body: Arc::new(body) };
                    bodies.insert(id, Arc::new(entry));
                }
                Err(e) => {
                    tracing::warn!(body_id = %id, error = %e, "quarantining stored body that does not validate");
                    store.quarantine("bodies", &id, &format!("does not validate: {e}"))?;
                }
            }
        }
        let mut scenes = BTreeMap::new();
        for (id, rec) in store.list_scenes()? {
            let mut instances = BTreeMap::new();
            for (iid, inst) in rec.instances {
                let Some(entry) = bodies.get(&inst.body_id) else {
                    tracing::warn!(scene_id = %id, instance_id = %iid, body_id = %inst.body_id, "skipping instance of missing body");
                    continue;
                };
                match inst.pose.to_isometry("pose") {
                    Ok(pose) => {
                        instances.insert(iid, Instance { body_id: inst.body_id, body: entry.body.clone(), pose });
                    }
                    Err(e) => {
                        tracing::warn!(scene_id = %id, instance_id = %iid, error = %e, "quarantining instance");
                        store.quarantine("instances", &format!("{id}/{iid}"), &format!("does not validate: {e}"))?;
                    }
                }
            }
            let state = SceneState {
                id: id.clone(),
                name: rec.meta.name,
                instances,
                cache: WarmStartCache::default(),
                deleted: false,
            };
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
        let quarantined = store.quarantined()?.len();
        if quarantined > 0 {
            tracing::warn!(records = quarantined, "the store's quarantine holds records that could not be loaded");
        }
        tracing::info!(bodies = bodies.len(), scenes = scenes.len(), jobs = jobs.len(), quarantined, "catalog loaded");
        Ok(Self {
            store,
            bodies: RwLock::new(bodies),
            scenes: RwLock::new(scenes),
            jobs: RwLock::new(jobs),
            quarantined,
            params,
        })
    }

    /// Number of records in the store's quarantine when the catalog was opened (unreadable or
    /// invalid records kept aside; see [`super::store`]). Health reports them.
    pub fn quarantined(&self) -> usize {
        self.quarantined
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
        self.store.put_body(&id, &BodyRecord { name: name.to_owned(), body: body.to_file() })?;
        let entry = BodyEntry { id: id.clone(), name: name.to_owned(), body: Arc::new(body) };
        write(&self.bodies).insert(id.clone(), Arc::new(entry));
        Ok(id)
    }

    /// The body with id `id`.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `body`).
    pub fn body(&self, id: &str) -> Result<Arc<BodyEntry>> {
        read(&self.bodies).get(id).cloned().ok_or_else(|| Error::not_found("body", id))
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
            if let Some((iid, _)) = s.instances.iter().find(|(_, inst)| inst.body_id == id) {
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
        self.store.put_scene(&id, &SceneMeta { name: name.to_owned() })?;
        let state = SceneState {
            id: id.clone(),
            name: name.to_owned(),
            instances: BTreeMap::new(),
            cache: WarmStartCache::default(),
            deleted: false,
        };
        write(&self.scenes).insert(id.clone(), Arc::new(Mutex::new(state)));
        Ok(id)
    }

    fn scene(&self, id: &str) -> Result<Arc<Mutex<SceneState>>> {
        read(&self.scenes).get(id).cloned().ok_or_else(|| Error::not_found("scene", id))
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
    /// unknown scene (the query itself then reports it).
    pub fn has_nonconvex(&self, scene_id: &str) -> bool {
        self.scene(scene_id).map(|sc| lock(&sc).instances.values().any(|i| i.body.report.nonconvex)).unwrap_or(false)
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
        drop(s);
        scenes.remove(id);
        Ok(())
    }

    /// Adds an instance of body `body_id` to scene `scene_id` under `pose`; returns its id.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or the body; [`Error::Storage`].
    pub fn add_instance(&self, scene_id: &str, body_id: &str, pose: Isometry3) -> Result<String> {
        // Hold the bodies lock so the body cannot be deleted between the check and the insert.
        let bodies = read(&self.bodies);
        let body = bodies.get(body_id).ok_or_else(|| Error::not_found("body", body_id))?.body.clone();
        self.with_scene(scene_id, |s| {
            let id = new_id("i");
            let rec = InstanceRecord { body_id: body_id.to_owned(), pose: StoredPose::from_isometry(&pose) };
            self.store.put_instances(scene_id, &[(&id, &rec)], false)?;
            s.instances.insert(id.clone(), Instance { body_id: body_id.to_owned(), body, pose });
            Ok(id)
        })
    }

    /// Sets the poses of many instances of one scene: all or nothing.
    ///
    /// Poses must already be validated (see [`crate::math::pose_from_parts`]); `poses[k].0` is
    /// the instance id. Returns the number of instances updated.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene; [`Error::InvalidArgument`] naming `poses[k].instance_id`
    /// for an unknown or repeated instance (nothing changes then); [`Error::Storage`].
    pub fn set_poses(&self, scene_id: &str, poses: &[(String, Isometry3)]) -> Result<usize> {
        self.with_scene(scene_id, |s| {
            let mut seen = std::collections::HashSet::new();
            let mut records = Vec::with_capacity(poses.len());
            for (k, (iid, pose)) in poses.iter().enumerate() {
                let field = format!("poses[{k}].instance_id");
                let inst = s
                    .instances
                    .get(iid)
                    .ok_or_else(|| Error::invalid(&field, format!("no instance `{iid}` in scene `{scene_id}`")))?;
                if !seen.insert(iid.as_str()) {
                    return Err(Error::invalid(field, format!("instance `{iid}` appears twice")));
                }
                records.push(InstanceRecord { body_id: inst.body_id.clone(), pose: StoredPose::from_isometry(pose) });
            }
            let rows: Vec<(&str, &InstanceRecord)> =
                poses.iter().zip(records.iter()).map(|((iid, _), rec)| (iid.as_str(), rec)).collect();
            self.store.put_instances(scene_id, &rows, true)?;
            for (iid, pose) in poses {
                if let Some(inst) = s.instances.get_mut(iid) {
                    inst.pose = *pose;
                }
            }
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

    // ----------------------------------------------------------------------------------------
    // Queries
    // ----------------------------------------------------------------------------------------

    /// Distance between instances `a` and `b` of a scene (eq. "distance"), warm-started from the
    /// previous answer of the same ordered pair; the new answer's warm start replaces it. The
    /// default path of [`Catalog::distance_with`] (SDP only as a fallback; a lower bound for
    /// nonconvex bodies — use `distance_with` to see which).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn distance(&self, scene_id: &str, a: &str, b: &str) -> Result<DistanceResult> {
        Ok(self.distance_with(scene_id, a, b, &QueryOptions::default())?.answer.result)
    }

    /// Growth measure d(p₁‖p₂) between instances `p1` and `p2` (eq. "overlap"), warm-started
    /// like [`Catalog::distance`].
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn growth(&self, scene_id: &str, p1: &str, p2: &str) -> Result<GrowthResult> {
        Ok(self.growth_with(scene_id, p1, p2, &QueryOptions::default())?.answer.result)
    }

    /// [`Catalog::distance`] with options: the certified answer ([`certified_distance`]) and, on
    /// request, its pose gradients. Solves outside the scene's lock ([`Catalog::batch`]), so a
    /// certificate (milliseconds to seconds with [`CertifyMode::Certify`]) holds up no other
    /// request of the scene.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn distance_with(&self, scene_id: &str, a: &str, b: &str, options: &QueryOptions) -> Result<DistanceReply> {
        let pair = PairRef { kind: QueryKind::Distance, first: a, second: b, options: *options, margin: 0.0 };
        match self.answer_snapshot(scene_id, &[pair])?.pop() {
            Some(QueryAnswer::Distance(d)) => Ok(d),
            _ => Err(Error::Numerical("a distance query answered with another kind".into())),
        }
    }

    /// [`Catalog::growth`] with options, like [`Catalog::distance_with`].
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn growth_with(&self, scene_id: &str, p1: &str, p2: &str, options: &QueryOptions) -> Result<GrowthReply> {
        let pair = PairRef { kind: QueryKind::Growth, first: p1, second: p2, options: *options, margin: 0.0 };
        match self.answer_snapshot(scene_id, &[pair])?.pop() {
            Some(QueryAnswer::Growth(g)) => Ok(g),
            _ => Err(Error::Numerical("a growth query answered with another kind".into())),
        }
    }

    /// The certification parameters of every query (the catalog's Newton parameters).
    pub(crate) fn certify_params(&self) -> CertifyParams {
        CertifyParams { newton: self.params, ..CertifyParams::default() }
    }

    /// Many queries of one scene, all at the poses of one moment; answers in order. Each instance
    /// is looked up once; the solves run outside the scene's lock (see
    /// [`Catalog::answer_snapshot`]), so batches of one scene run in parallel.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or any instance (checked before any query runs).
    pub fn batch(&self, scene_id: &str, pairs: &[QueryPair]) -> Result<Vec<QueryAnswer>> {
        let views: Vec<PairRef<'_>> = pairs.iter().map(QueryPair::view).collect();
        self.answer_snapshot(scene_id, &views)
    }

    /// Queries of one kind given in columns: pair k asks about `ids[first[k]]` and
    /// `ids[second[k]]` (the form of `BatchQueryRequest.columns`), like [`Catalog::batch`].
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `first` and `second` of different lengths or an index
    /// outside `ids`; [`Error::NotFound`] for the scene or an instance (checked before any query
    /// runs).
    pub fn batch_columns(
        &self,
        scene_id: &str,
        ids: &[String],
        (first, second): (&[u32], &[u32]),
        kind: QueryKind,
        options: QueryOptions,
        margin: crate::math::Real,
    ) -> Result<Vec<QueryAnswer>> {
        if first.len() != second.len() {
            return Err(Error::invalid(
                "columns.second",
                format!("has {} entries, `first` has {}", second.len(), first.len()),
            ));
        }
        for (field, column) in [("columns.first", first), ("columns.second", second)] {
            if let Some((k, i)) = column.iter().enumerate().find(|(_, &i)| i as usize >= ids.len()) {
                return Err(Error::invalid(
                    format!("{field}[{k}]"),
                    format!("index {i} is outside instance_ids (length {})", ids.len()),
                ));
            }
        }
        let views: Vec<PairRef<'_>> = first
            .iter()
            .zip(second)
            .map(|(&i, &j)| PairRef { kind, first: &ids[i as usize], second: &ids[j as usize], options, margin })
            .collect();
        self.answer_snapshot(scene_id, &views)
    }

    /// Answers `pairs` on a snapshot of the scene, solving outside its lock:
    ///
    /// ```text
    /// lock:    posed instances (body Arc + pose) of every id, warm starts of every pair → scratch
    /// unlock:  solve every pair in order with the scratch warm starts (repeated pairs warm-start
    ///          each other as before)
    /// lock:    write the new warm starts back (those of instances still in the scene)
    /// ```
    ///
    /// Two requests of one scene solve in parallel; a concurrent pose change is seen by the next
    /// request, never halfway through this one. Warm starts are copied as `Arc`s (no 1 KB copies).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    fn answer_snapshot(&self, scene_id: &str, pairs: &[PairRef<'_>]) -> Result<Vec<QueryAnswer>> {
        let scene = self.scene(scene_id)?;
        let (posed_by_id, mut scratch) = {
            let s = lock(&scene);
            if s.deleted {
                return Err(Error::not_found("scene", scene_id));
            }
            let mut posed_by_id: HashMap<&str, super::planner::Posed, foldhash::fast::RandomState> = HashMap::default();
            let mut scratch = WarmStartCache::default();
            for p in pairs {
                for id in [p.first, p.second] {
                    if !posed_by_id.contains_key(id) {
                        posed_by_id.insert(id, posed(&s, id)?);
                    }
                }
                if !p.options.cold {
                    s.cache.copy_pair(&mut scratch, warm_kind(p.kind), p.first, p.second);
                }
            }
            (posed_by_id, scratch)
        };
        let params = self.certify_params();
        let answers = pairs
            .iter()
            .map(|p| {
                let (a, b) = (&posed_by_id[p.first], &posed_by_id[p.second]);
                super::planner::answer_pair(*p, a, b, &mut scratch, &params)
            })
            .collect();
        if !scratch.is_empty() {
            let mut s = lock(&scene);
            if !s.deleted {
                let SceneState { instances, cache, .. } = &mut *s;
                cache.merge(scratch, |id| instances.contains_key(id));
            }
        }
        Ok(answers)
    }
}

/// The warm-start table a query kind uses (collide queries solve distances).
fn warm_kind(kind: QueryKind) -> super::cache::WarmKind {
    match kind {
        QueryKind::Distance | QueryKind::Collide => super::cache::WarmKind::Distance,
        QueryKind::Growth => super::cache::WarmKind::Growth,
    }
}

fn view(s: &SceneState) -> SceneView {
    SceneView {
        id: s.id.clone(),
        name: s.name.clone(),
        instances: s
            .instances
            .iter()
            .map(|(id, i)| InstanceView { id: id.clone(), body_id: i.body_id.clone(), pose: i.pose })
            .collect(),
    }
}

fn instance<'a>(s: &'a SceneState, id: &str) -> Result<&'a Instance> {
    s.instances.get(id).ok_or_else(|| Error::not_found("instance", id))
}

fn posed(s: &SceneState, id: &str) -> Result<super::planner::Posed> {
    let inst = instance(s, id)?;
    Ok(super::planner::Posed { body: inst.body.clone(), pose: inst.pose })
}

// --------------------------------------------------------------------------------------------
// Grouping (paper §V): reading a scene's posed bodies and replacing instances by their container
// --------------------------------------------------------------------------------------------

/// A posed body of a scene, as handed to a grouping job.
#[derive(Clone, Debug)]
pub struct PosedInstance {
    /// The instance's id.
    pub id: String,
    /// The instantiated body's id.
    pub body_id: String,
    /// The body (shared, parsed once).
    pub body: Arc<Body>,
    /// Its pose (body frame → world).
    pub pose: Isometry3,
}

impl Catalog {
    /// The posed bodies (body and stored pose) of instances of a scene, in the order of `ids`,
    /// read under the scene's lock so all poses are of one moment; nothing is copied but the
    /// poses (the bodies are shared).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn posed_by_ids(&self, scene_id: &str, ids: &[&str]) -> Result<Vec<super::planner::Posed>> {
        self.with_scene(scene_id, |s| ids.iter().map(|id| posed(s, id)).collect())
    }

    /// The bodies and poses of instances of a scene, in the order asked (`ids` empty: every
    /// instance, ordered by id), read under the scene's lock so all poses are of one moment.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance.
    pub fn posed_instances(&self, scene_id: &str, ids: &[String]) -> Result<Vec<PosedInstance>> {
        self.with_scene(scene_id, |s| {
            let pick = |id: &str, inst: &Instance| PosedInstance {
                id: id.to_owned(),
                body_id: inst.body_id.clone(),
                body: inst.body.clone(),
                pose: inst.pose,
            };
            if ids.is_empty() {
                return Ok(s.instances.iter().map(|(id, inst)| pick(id, inst)).collect());
            }
            ids.iter().map(|id| instance(s, id).map(|inst| pick(id, inst))).collect()
        })
    }

    /// Replaces instances `remove` of a scene by one new instance of body `body_id` under `pose`,
    /// in one store transaction; returns the new instance's id. Warm starts involving a removed
    /// instance are dropped.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene, the body or an instance to remove (nothing changes
    /// then); [`Error::Storage`].
    pub fn replace_instances(
        &self,
        scene_id: &str,
        remove: &[String],
        body_id: &str,
        pose: Isometry3,
    ) -> Result<String> {
        let bodies = read(&self.bodies);
        let body = bodies.get(body_id).ok_or_else(|| Error::not_found("body", body_id))?.body.clone();
        self.with_scene(scene_id, |s| {
            for id in remove {
                instance(s, id)?;
            }
            let id = new_id("i");
            let rec = InstanceRecord { body_id: body_id.to_owned(), pose: StoredPose::from_isometry(&pose) };
            let removed: Vec<&str> = remove.iter().map(String::as_str).collect();
            self.store.replace_instances(scene_id, &removed, &[(id.as_str(), &rec)])?;
            for old in remove {
                s.instances.remove(old);
                s.cache.invalidate_instance(old);
            }
            s.instances.insert(id.clone(), Instance { body_id: body_id.to_owned(), body, pose });
            Ok(id)
        })
    }
}

#[cfg(all(test, feature = "store"))]
mod tests {
    use super::*;
    use crate::body::ellipsoid;
    use crate::math::pose_from_parts;
    use crate::scene::store::RedbStore;

    fn at(x: f64) -> Isometry3 {
        pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, 0.0]).unwrap()
    }

    fn open(dir: &std::path::Path) -> Catalog {
        Catalog::open(Box::new(RedbStore::open_dir(dir).unwrap()), NewtonParams::default()).unwrap()
    }

    #[test]
    fn catalog_persists_and_warm_starts_follow_the_pair() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, i1, i2);
        {
            let c = open(dir.path());
            let b1 = c.add_body("r1", ellipsoid([0.0; 3], [0.5; 3]).unwrap()).unwrap();
            let b2 = c.add_body("r2", ellipsoid([0.0; 3], [0.25; 3]).unwrap()).unwrap();
            scene = c.create_scene("s").unwrap();
            i1 = c.add_instance(&scene, &b1, at(0.0)).unwrap();
            i2 = c.add_instance(&scene, &b2, at(2.0)).unwrap();
            // Spheres: distance = ‖c₁ − c₂‖ − r₁ − r₂.
            let d = c.distance(&scene, &i1, &i2).unwrap();
            assert!((d.distance - 1.25).abs() < 1e-9, "{}", d.distance);
            assert!(!d.warm_started);
            c.set_poses(&scene, &[(i2.clone(), at(1.5))]).unwrap();
            let d = c.distance(&scene, &i1, &i2).unwrap();
            assert!((d.distance - 0.75).abs() < 1e-9, "{}", d.distance);
            assert!(d.warm_started);
            // Growth of spheres: (‖c₁ − c₂‖ − r₂)² / r₁².
            let g = c.growth(&scene, &i1, &i2).unwrap();
            assert!((g.value - (1.25f64 / 0.5).powi(2)).abs() < 1e-9, "{}", g.value);
            assert_eq!(c.cached_warm_starts(&scene).unwrap(), 2);
            // A bad batch entry changes nothing; an unknown instance is NotFound.
            let err = c.set_poses(&scene, &[(i2.clone(), at(9.0)), ("i-nope".into(), at(0.0))]).unwrap_err();
            assert!(err.to_string().contains("poses[1].instance_id"), "{err}");
            assert!(matches!(c.distance(&scene, &i1, "i-nope"), Err(Error::NotFound { .. })));
            // The body is in use.
            assert!(
                matches!(c.delete_body(&b1), Err(Error::FailedPrecondition(m)) if m.contains("remove the instance first"))
            );
        }
        let c = open(dir.path());
        let v = c.get_scene(&scene).unwrap();
        assert_eq!(v.instances.len(), 2);
        let p2 = v.instances.iter().find(|i| i.id == i2).unwrap().pose;
        assert!((p2.translation.vector.x - 1.5).abs() < 1e-15, "the failed batch must not have moved i2");
        assert_eq!(c.cached_warm_starts(&scene).unwrap(), 0, "warm starts are memory only");
        let d = c.distance(&scene, &i1, &i2).unwrap();
        assert!((d.distance - 0.75).abs() < 1e-9);
        c.remove_instance(&scene, &i1).unwrap();
        assert_eq!(c.cached_warm_starts(&scene).unwrap(), 0);
        c.delete_scene(&scene).unwrap();
        assert!(matches!(c.get_scene(&scene), Err(Error::NotFound { .. })));
        drop(c);
        let c = open(dir.path());
        assert!(c.get_scene(&scene).is_err());
        assert_eq!(c.bodies().len(), 2);
    }
}
