//! Grouping (paper §V): reading a scene's posed bodies and replacing instances by their
//! container, for the grouping jobs.

use super::{instance, new_id, posed, read, BodyEntry, Catalog, Instance};
use crate::answer::Posed;
use crate::{Error, Result};
use crate::{InstanceRecord, StoredPose};
use std::sync::Arc;
use sublevel_core::body::Body;
use sublevel_core::math::Isometry3;

/// A posed body of a scene, as handed to a grouping job.
#[derive(Clone, Debug)]
pub struct PosedInstance {
    /// The instance's id.
    pub id: String,
    /// The instantiated body's id.
    pub body_id: String,
    /// The body (shared, parsed once); a compound body's root body.
    pub body: Arc<Body>,
    /// A compound body's containment tree (`None` for a single body).
    pub tree: Option<Arc<sublevel_core::compound::CompoundBody>>,
    /// The exact primitive the body stands for (`body` is then its bounding ellipsoid, a stand-in
    /// for a halfspace); `None` for a fitted body.
    pub primitive: Option<sublevel_core::primitive::Primitive>,
    /// Its pose (body frame → world).
    pub pose: Isometry3,
}

impl PosedInstance {
    /// Instance `id` of the body `entry` at `pose`, the body built if it was not yet.
    ///
    /// # Errors
    /// As [`BodyEntry::built`].
    pub(crate) fn of(id: String, entry: &BodyEntry, pose: Isometry3) -> Result<Self> {
        let built = entry.built()?;
        Ok(Self {
            id,
            body_id: entry.id.clone(),
            body: built.body.clone(),
            tree: built.tree.clone(),
            primitive: built.primitive,
            pose,
        })
    }
}

impl Catalog {
    /// The posed bodies (body and stored pose) of instances of a scene, in the order of `ids`,
    /// read under the scene's lock so all poses are of one moment; nothing is copied but the
    /// poses (the bodies are shared). Bodies not built yet are built after the lock is released.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance; [`Error::FailedPrecondition`] naming a
    /// body that does not validate.
    pub fn posed_by_ids(&self, scene_id: &str, ids: &[&str]) -> Result<Vec<Posed>> {
        let read: Vec<(Arc<BodyEntry>, Isometry3)> = self.with_scene(scene_id, |s| {
            ids.iter().map(|id| instance(s, id).map(|inst| (inst.entry.clone(), inst.pose))).collect()
        })?;
        read.into_iter().map(|(entry, pose)| Ok(posed(entry.built()?, pose))).collect()
    }

    /// The bodies and poses of instances of a scene, in the order asked (`ids` empty: every
    /// instance, ordered by id), read under the scene's lock so all poses are of one moment.
    /// Bodies not built yet are built after the lock is released.
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance; [`Error::FailedPrecondition`] naming a
    /// body that does not validate.
    pub fn posed_instances(&self, scene_id: &str, ids: &[String]) -> Result<Vec<PosedInstance>> {
        let read: Vec<(String, Arc<BodyEntry>, Isometry3)> = self.with_scene(scene_id, |s| {
            if ids.is_empty() {
                return Ok(s.instances.iter().map(|(id, inst)| (id.clone(), inst.entry.clone(), inst.pose)).collect());
            }
            ids.iter().map(|id| instance(s, id).map(|inst| (id.clone(), inst.entry.clone(), inst.pose))).collect()
        })?;
        read.into_iter().map(|(id, entry, pose)| PosedInstance::of(id, &entry, pose)).collect()
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
        let entry = bodies.get(body_id).ok_or_else(|| Error::not_found("body", body_id))?.clone();
        self.with_scene(scene_id, |s| {
            for id in remove {
                instance(s, id)?;
            }
            let id = new_id("i");
            let rec = InstanceRecord { body_id: body_id.to_owned(), pose: StoredPose::checked("pose", &pose)? };
            let removed: Vec<&str> = remove.iter().map(String::as_str).collect();
            self.store.replace_instances(scene_id, &removed, &[(id.as_str(), &rec)])?;
            for old in remove {
                s.instances.remove(old);
                s.cache.invalidate_instance(old);
            }
            s.instances.insert(id.clone(), Instance::of(&entry, pose));
            s.changed();
            Ok(id)
        })
    }
}
