//! [`MemoryStore`]: a [`Store`] in memory, for programs that embed the catalog without a
//! database (the `store` feature off) and for tests.

use super::{encode, Store};
use crate::{BodyRecord, InstanceRecord, JobRecord, RobotRecord, SceneMeta, SceneRecord};
use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard};
use sublevel_core::Result;

/// [`Store`] in memory: nothing survives the process. Every write is checked like
/// [`super::RedbStore`]'s (the record must read back to the same JSON, [`encode`]) and is atomic
/// (one lock per call).
#[derive(Debug, Default)]
pub struct MemoryStore {
    tables: Mutex<Tables>,
}

#[derive(Debug, Default)]
struct Tables {
    bodies: BTreeMap<String, BodyRecord>,
    scenes: BTreeMap<String, SceneMeta>,
    /// (scene id, instance id) → instance.
    instances: BTreeMap<(String, String), InstanceRecord>,
    jobs: BTreeMap<String, JobRecord>,
    robots: BTreeMap<String, RobotRecord>,
}

impl MemoryStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }

    fn tables(&self) -> MutexGuard<'_, Tables> {
        // Every update is a single insert or remove: a poisoned lock holds consistent tables.
        self.tables.lock().unwrap_or_else(|e| e.into_inner())
    }
}

fn scene_record(t: &Tables, id: &str, meta: &SceneMeta) -> SceneRecord {
    let instances = t
        .instances
        .range((id.to_owned(), String::new())..)
        .take_while(|((s, _), _)| s == id)
        .map(|((_, i), r)| (i.clone(), r.clone()))
        .collect();
    SceneRecord { meta: meta.clone(), instances }
}

impl Store for MemoryStore {
    fn put_body(&self, id: &str, record: &BodyRecord) -> Result<()> {
        encode("body", record)?;
        self.tables().bodies.insert(id.to_owned(), record.clone());
        Ok(())
    }

    fn get_body(&self, id: &str) -> Result<Option<BodyRecord>> {
        Ok(self.tables().bodies.get(id).cloned())
    }

    fn list_bodies(&self) -> Result<Vec<(String, BodyRecord)>> {
        Ok(self.tables().bodies.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
    }

    fn delete_body(&self, id: &str) -> Result<bool> {
        Ok(self.tables().bodies.remove(id).is_some())
    }

    fn put_robot(&self, id: &str, record: &RobotRecord) -> Result<()> {
        encode("robot", record)?;
        self.tables().robots.insert(id.to_owned(), record.clone());
        Ok(())
    }

    fn list_robots(&self) -> Result<Vec<(String, RobotRecord)>> {
        Ok(self.tables().robots.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
    }

    fn delete_robot(&self, id: &str) -> Result<bool> {
        Ok(self.tables().robots.remove(id).is_some())
    }

    fn put_scene(&self, id: &str, meta: &SceneMeta) -> Result<()> {
        encode("scene", meta)?;
        self.tables().scenes.insert(id.to_owned(), meta.clone());
        Ok(())
    }

    fn get_scene(&self, id: &str) -> Result<Option<SceneRecord>> {
        let t = self.tables();
        Ok(t.scenes.get(id).map(|meta| scene_record(&t, id, meta)))
    }

    fn list_scenes(&self) -> Result<Vec<(String, SceneRecord)>> {
        let t = self.tables();
        Ok(t.scenes.iter().map(|(id, meta)| (id.clone(), scene_record(&t, id, meta))).collect())
    }

    fn delete_scene(&self, id: &str) -> Result<bool> {
        let mut t = self.tables();
        t.instances.retain(|(s, _), _| s != id);
        Ok(t.scenes.remove(id).is_some())
    }

    fn put_instances(&self, scene_id: &str, instances: &[(&str, &InstanceRecord)], _frequent: bool) -> Result<()> {
        for (_, r) in instances {
            encode("instance", *r)?;
        }
        let mut t = self.tables();
        for (id, r) in instances {
            t.instances.insert((scene_id.to_owned(), (*id).to_owned()), (*r).clone());
        }
        Ok(())
    }

    fn delete_instance(&self, scene_id: &str, instance_id: &str) -> Result<bool> {
        Ok(self.tables().instances.remove(&(scene_id.to_owned(), instance_id.to_owned())).is_some())
    }

    fn put_job(&self, id: &str, record: &JobRecord) -> Result<()> {
        encode("job", record)?;
        self.tables().jobs.insert(id.to_owned(), record.clone());
        Ok(())
    }

    fn list_jobs(&self) -> Result<Vec<(String, JobRecord)>> {
        Ok(self.tables().jobs.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
    }

    fn delete_jobs(&self, ids: &[&str]) -> Result<()> {
        let mut t = self.tables();
        for id in ids {
            t.jobs.remove(*id);
        }
        Ok(())
    }

    fn replace_instances(&self, scene_id: &str, remove: &[&str], add: &[(&str, &InstanceRecord)]) -> Result<()> {
        for (_, r) in add {
            encode("instance", *r)?;
        }
        let mut t = self.tables();
        for id in remove {
            t.instances.remove(&(scene_id.to_owned(), (*id).to_owned()));
        }
        for (id, r) in add {
            t.instances.insert((scene_id.to_owned(), (*id).to_owned()), (*r).clone());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Catalog, StoredPose};
    use sublevel_core::body::ellipsoid;
    use sublevel_core::math::{pose_from_parts, Isometry3};

    fn at(x: f64) -> Isometry3 {
        pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, 0.0]).unwrap()
    }

    /// The catalog runs on the memory store like on redb: a scene with two spheres answers the
    /// closed-form distance ‖c₁ − c₂‖ − r₁ − r₂, and deleting the scene drops its instances.
    /// The catalog runs on the memory store like on redb: spheres answer the closed form
    /// ‖c₁ − c₂‖ − r₁ − r₂, a record that would not read back is refused, deleting a scene drops
    /// its instances.
    #[test]
    fn a_catalog_on_the_memory_store_answers_and_deletes() {
        let store = MemoryStore::new();
        let meta = SceneMeta::named("x");
        store.put_scene("s-1", &meta).unwrap();
        let record = InstanceRecord { body_id: "b".into(), pose: StoredPose::from_isometry(&at(1.0)) };
        store.put_instances("s-1", &[("i-1", &record), ("i-2", &record)], true).unwrap();
        store.put_instances("s-10", &[("i-3", &record)], false).unwrap();
        assert_eq!(store.get_scene("s-1").unwrap().unwrap().instances.len(), 2, "s-10's instance is not s-1's");
        assert!(store.delete_scene("s-1").unwrap());
        assert!(store.get_scene("s-1").unwrap().is_none());
        // A body's mesh is kept with its record.
        let mesh = crate::MeshRecord {
            vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            triangles: vec![[0, 1, 2]],
        };
        let ball = ellipsoid([0.0; 3], [0.5; 3]).unwrap().to_file();
        store.put_body("b-m", &BodyRecord { mesh: Some(mesh.clone()), ..BodyRecord::single("m", ball) }).unwrap();
        assert_eq!(store.get_body("b-m").unwrap().unwrap().mesh, Some(mesh));

        let catalog = Catalog::open(Box::new(MemoryStore::new()), Default::default()).unwrap();
        let b = catalog.add_body("ball", ellipsoid([0.0; 3], [0.5; 3]).unwrap()).unwrap();
        let s = catalog.create_scene("two").unwrap();
        let i1 = catalog.add_instance(&s, &b, at(0.0)).unwrap();
        let i2 = catalog.add_instance(&s, &b, at(3.0)).unwrap();
        let d = catalog.distance(&s, &i1, &i2).unwrap();
        assert!((d.distance - 2.0).abs() < 1e-9, "{}", d.distance);
        catalog.delete_scene(&s).unwrap();
        assert!(catalog.get_scene(&s).is_err());
    }
}
