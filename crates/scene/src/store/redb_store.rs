//! [`RedbStore`]: the [`Store`] on a redb database file (see the parent module for its tables).

use super::{encode, QuarantinedRecord, Store};
use crate::{BodyRecord, InstanceRecord, JobRecord, RobotRecord, SceneMeta, SceneRecord};
use crate::{Error, Result};
use redb::{Durability, ReadableTable, TableDefinition};
use std::collections::BTreeMap;
use std::path::Path;

const BODIES: TableDefinition<&str, &str> = TableDefinition::new("bodies");
const SCENES: TableDefinition<&str, &str> = TableDefinition::new("scenes");
const INSTANCES: TableDefinition<&str, &str> = TableDefinition::new("instances");
const JOBS: TableDefinition<&str, &str> = TableDefinition::new("jobs");
const QUARANTINE: TableDefinition<&str, &str> = TableDefinition::new("quarantine");
const ROBOTS: TableDefinition<&str, &str> = TableDefinition::new("robots");

/// A table's name, definition and the parse check of its records.
type TableCheck =
    (&'static str, TableDefinition<'static, &'static str, &'static str>, fn(&str) -> std::result::Result<(), String>);

fn table_def(name: &str) -> Option<TableDefinition<'static, &'static str, &'static str>> {
    match name {
        "bodies" => Some(BODIES),
        "scenes" => Some(SCENES),
        "instances" => Some(INSTANCES),
        "jobs" => Some(JOBS),
        "robots" => Some(ROBOTS),
        _ => None,
    }
}

/// File name of the database inside the data directory.
pub const DATABASE_FILE: &str = "sublevel.redb";

/// [`Store`] on a redb database file.
///
/// Structural writes (bodies, scenes, instances added or removed) commit with immediate
/// durability (fsync); pose updates marked `frequent` commit with eventual durability, so a
/// moving scene does not pay an fsync per frame — a power loss may lose the last poses, a crash
/// of the process loses nothing, and no write is ever half-applied.
pub struct RedbStore {
    db: redb::Database,
}

impl std::fmt::Debug for RedbStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RedbStore").finish_non_exhaustive()
    }
}

fn storage(e: impl std::fmt::Display) -> Error {
    Error::Storage(e.to_string())
}

fn decode<T: serde::de::DeserializeOwned>(kind: &str, id: &str, text: &str) -> Result<T> {
    serde_json::from_str(text).map_err(|e| Error::Storage(format!("stored {kind} `{id}` is unreadable: {e}")))
}

/// Whether `text` parses as a `T`, and why not.
fn readable<T: serde::de::DeserializeOwned>(text: &str) -> std::result::Result<(), String> {
    serde_json::from_str::<T>(text).map(|_| ()).map_err(|e| e.to_string())
}

fn instance_key(scene_id: &str, instance_id: &str) -> String {
    format!("{scene_id}/{instance_id}")
}

/// The key range holding the instances of `scene_id`.
fn instance_range(scene_id: &str) -> (String, String) {
    (format!("{scene_id}/"), format!("{scene_id}0"))
}

impl RedbStore {
    /// Opens (or creates) the database `DATABASE_FILE` inside `dir`, creating `dir` if needed.
    ///
    /// # Errors
    /// [`Error::Io`] if the directory cannot be created, [`Error::Storage`] if the database cannot
    /// be opened (e.g. another server holds it).
    pub fn open_dir(dir: &Path) -> Result<Self> {
        std::fs::create_dir_all(dir)?;
        Self::open(&dir.join(DATABASE_FILE))
    }

    /// Opens (or creates) a database file.
    ///
    /// # Errors
    /// [`Error::Storage`] if the database cannot be opened or initialized.
    pub fn open(path: &Path) -> Result<Self> {
        let db = redb::Database::create(path).map_err(storage)?;
        let txn = db.begin_write().map_err(storage)?;
        for table in [BODIES, SCENES, INSTANCES, JOBS, QUARANTINE, ROBOTS] {
            txn.open_table(table).map_err(storage)?;
        }
        txn.commit().map_err(storage)?;
        let store = Self { db };
        let moved = store.quarantine_unreadable()?;
        if moved > 0 {
            tracing::warn!(
                records = moved,
                "moved unreadable records to the quarantine table; the rest of the store is served"
            );
        }
        Ok(store)
    }

    /// Inserts or replaces a record of a key-value table (immediate durability); `kind` names it
    /// in errors.
    fn put<T: serde::Serialize + serde::de::DeserializeOwned>(
        &self,
        def: TableDefinition<'static, &'static str, &'static str>,
        kind: &str,
        id: &str,
        record: &T,
    ) -> Result<()> {
        let json = encode(kind, record)?;
        self.write(Durability::Immediate, |txn| {
            txn.open_table(def).map_err(storage)?.insert(id, json.as_str()).map_err(storage)?;
            Ok(true)
        })
        .map(|_| ())
    }

    /// Deletes a record of a key-value table; false if it did not exist.
    fn delete(&self, def: TableDefinition<'static, &'static str, &'static str>, id: &str) -> Result<bool> {
        self.write(Durability::Immediate, |txn| {
            let mut t = txn.open_table(def).map_err(storage)?;
            let removed = t.remove(id).map_err(storage)?.is_some();
            Ok(removed)
        })
    }

    /// Every record of a key-value table, ordered by key; `kind` names them in errors.
    fn list<T: serde::de::DeserializeOwned>(
        &self,
        def: TableDefinition<'static, &'static str, &'static str>,
        kind: &str,
    ) -> Result<Vec<(String, T)>> {
        let txn = self.db.begin_read().map_err(storage)?;
        let table = txn.open_table(def).map_err(storage)?;
        let mut out = Vec::new();
        for row in table.iter().map_err(storage)? {
            let (k, v) = row.map_err(storage)?;
            out.push((k.value().to_owned(), decode(kind, k.value(), v.value())?));
        }
        Ok(out)
    }

    /// Moves every record that does not parse as its table's type to the quarantine, in one
    /// transaction; returns how many moved.
    fn quarantine_unreadable(&self) -> Result<usize> {
        let mut bad: Vec<(&'static str, String, String, String)> = Vec::new();
        {
            let txn = self.db.begin_read().map_err(storage)?;
            let checks: [TableCheck; 5] = [
                ("bodies", BODIES, readable::<BodyRecord>),
                ("scenes", SCENES, readable::<SceneMeta>),
                ("instances", INSTANCES, readable::<InstanceRecord>),
                ("jobs", JOBS, readable::<JobRecord>),
                ("robots", ROBOTS, readable::<RobotRecord>),
            ];
            for (name, def, check) in checks {
                let table = txn.open_table(def).map_err(storage)?;
                for row in table.iter().map_err(storage)? {
                    let (k, v) = row.map_err(storage)?;
                    if let Err(reason) = check(v.value()) {
                        tracing::warn!(table = name, key = k.value(), %reason, "quarantining unreadable record");
                        bad.push((name, k.value().to_owned(), v.value().to_owned(), format!("unreadable: {reason}")));
                    }
                }
            }
        }
        if bad.is_empty() {
            return Ok(0);
        }
        self.write(Durability::Immediate, |txn| {
            for (table, key, text, reason) in &bad {
                Self::move_to_quarantine(txn, table, key, text, reason)?;
            }
            Ok(true)
        })?;
        Ok(bad.len())
    }

    fn move_to_quarantine(
        txn: &redb::WriteTransaction,
        table: &str,
        key: &str,
        text: &str,
        reason: &str,
    ) -> Result<()> {
        let def = table_def(table).ok_or_else(|| Error::invalid("table", format!("no table `{table}`")))?;
        let record = QuarantinedRecord {
            table: table.to_owned(),
            key: key.to_owned(),
            reason: reason.to_owned(),
            text: text.to_owned(),
        };
        let json = serde_json::to_string(&record)?;
        txn.open_table(QUARANTINE)
            .map_err(storage)?
            .insert(format!("{table}/{key}").as_str(), json.as_str())
            .map_err(storage)?;
        txn.open_table(def).map_err(storage)?.remove(key).map_err(storage)?;
        Ok(())
    }

    fn write(&self, durability: Durability, f: impl FnOnce(&redb::WriteTransaction) -> Result<bool>) -> Result<bool> {
        let mut txn = self.db.begin_write().map_err(storage)?;
        txn.set_durability(durability);
        match f(&txn) {
            Ok(out) => {
                txn.commit().map_err(storage)?;
                Ok(out)
            }
            Err(e) => {
                txn.abort().map_err(storage)?;
                Err(e)
            }
        }
    }

    fn read_instances(
        table: &impl ReadableTable<&'static str, &'static str>,
        scene_id: &str,
    ) -> Result<BTreeMap<String, InstanceRecord>> {
        let (lo, hi) = instance_range(scene_id);
        let mut out = BTreeMap::new();
        for row in table.range(lo.as_str()..hi.as_str()).map_err(storage)? {
            let (k, v) = row.map_err(storage)?;
            let key = k.value();
            let inst_id = key.get(lo.len()..).unwrap_or_default().to_owned();
            out.insert(inst_id, decode("instance", key, v.value())?);
        }
        Ok(out)
    }
}

impl Store for RedbStore {
    fn put_body(&self, id: &str, record: &BodyRecord) -> Result<()> {
        self.put(BODIES, "body", id, record)
    }

    fn get_body(&self, id: &str) -> Result<Option<BodyRecord>> {
        let txn = self.db.begin_read().map_err(storage)?;
        let table = txn.open_table(BODIES).map_err(storage)?;
        let Some(v) = table.get(id).map_err(storage)? else { return Ok(None) };
        decode("body", id, v.value()).map(Some)
    }

    fn list_bodies(&self) -> Result<Vec<(String, BodyRecord)>> {
        self.list(BODIES, "body")
    }

    fn delete_body(&self, id: &str) -> Result<bool> {
        self.delete(BODIES, id)
    }

    fn put_robot(&self, id: &str, record: &RobotRecord) -> Result<()> {
        self.put(ROBOTS, "robot", id, record)
    }

    fn list_robots(&self) -> Result<Vec<(String, RobotRecord)>> {
        self.list(ROBOTS, "robot")
    }

    fn delete_robot(&self, id: &str) -> Result<bool> {
        self.delete(ROBOTS, id)
    }

    fn put_scene(&self, id: &str, meta: &SceneMeta) -> Result<()> {
        self.put(SCENES, "scene", id, meta)
    }

    fn get_scene(&self, id: &str) -> Result<Option<SceneRecord>> {
        let txn = self.db.begin_read().map_err(storage)?;
        let scenes = txn.open_table(SCENES).map_err(storage)?;
        let Some(v) = scenes.get(id).map_err(storage)? else { return Ok(None) };
        let meta = decode("scene", id, v.value())?;
        let instances = Self::read_instances(&txn.open_table(INSTANCES).map_err(storage)?, id)?;
        Ok(Some(SceneRecord { meta, instances }))
    }

    fn list_scenes(&self) -> Result<Vec<(String, SceneRecord)>> {
        let txn = self.db.begin_read().map_err(storage)?;
        let scenes = txn.open_table(SCENES).map_err(storage)?;
        let instances = txn.open_table(INSTANCES).map_err(storage)?;
        let mut out = Vec::new();
        for row in scenes.iter().map_err(storage)? {
            let (k, v) = row.map_err(storage)?;
            let id = k.value().to_owned();
            let meta = decode("scene", &id, v.value())?;
            let inst = Self::read_instances(&instances, &id)?;
            out.push((id, SceneRecord { meta, instances: inst }));
        }
        Ok(out)
    }

    fn delete_scene(&self, id: &str) -> Result<bool> {
        self.write(Durability::Immediate, |txn| {
            let removed = txn.open_table(SCENES).map_err(storage)?.remove(id).map_err(storage)?.is_some();
            let (lo, hi) = instance_range(id);
            let mut t = txn.open_table(INSTANCES).map_err(storage)?;
            t.retain_in(lo.as_str()..hi.as_str(), |_, _| false).map_err(storage)?;
            Ok(removed)
        })
    }

    fn put_instances(&self, scene_id: &str, instances: &[(&str, &InstanceRecord)], frequent: bool) -> Result<()> {
        let rows = instances
            .iter()
            .map(|(id, rec)| Ok((instance_key(scene_id, id), encode("instance", *rec)?)))
            .collect::<Result<Vec<_>>>()?;
        let durability = if frequent { Durability::Eventual } else { Durability::Immediate };
        self.write(durability, |txn| {
            let mut t = txn.open_table(INSTANCES).map_err(storage)?;
            for (k, v) in &rows {
                t.insert(k.as_str(), v.as_str()).map_err(storage)?;
            }
            Ok(true)
        })
        .map(|_| ())
    }

    fn delete_instance(&self, scene_id: &str, instance_id: &str) -> Result<bool> {
        let key = instance_key(scene_id, instance_id);
        self.write(Durability::Immediate, |txn| {
            let removed = txn.open_table(INSTANCES).map_err(storage)?.remove(key.as_str()).map_err(storage)?.is_some();
            Ok(removed)
        })
    }

    fn put_job(&self, id: &str, record: &JobRecord) -> Result<()> {
        self.put(JOBS, "job", id, record)
    }

    fn list_jobs(&self) -> Result<Vec<(String, JobRecord)>> {
        self.list(JOBS, "job")
    }

    fn delete_jobs(&self, ids: &[&str]) -> Result<()> {
        self.write(Durability::Immediate, |txn| {
            let mut t = txn.open_table(JOBS).map_err(storage)?;
            for id in ids {
                t.remove(*id).map_err(storage)?;
            }
            Ok(true)
        })
        .map(|_| ())
    }

    fn quarantine(&self, table: &str, key: &str, reason: &str) -> Result<()> {
        let def = table_def(table).ok_or_else(|| Error::invalid("table", format!("no table `{table}`")))?;
        self.write(Durability::Immediate, |txn| {
            let text = txn.open_table(def).map_err(storage)?.get(key).map_err(storage)?.map(|v| v.value().to_owned());
            match text {
                Some(text) => Self::move_to_quarantine(txn, table, key, &text, reason).map(|()| true),
                None => Ok(false),
            }
        })
        .map(|_| ())
    }

    fn quarantined(&self) -> Result<Vec<QuarantinedRecord>> {
        let txn = self.db.begin_read().map_err(storage)?;
        let table = txn.open_table(QUARANTINE).map_err(storage)?;
        let mut out = Vec::new();
        for row in table.iter().map_err(storage)? {
            let (k, v) = row.map_err(storage)?;
            out.push(decode("quarantined record", k.value(), v.value())?);
        }
        Ok(out)
    }

    fn replace_instances(&self, scene_id: &str, remove: &[&str], add: &[(&str, &InstanceRecord)]) -> Result<()> {
        let rows = add
            .iter()
            .map(|(id, rec)| Ok((instance_key(scene_id, id), encode("instance", *rec)?)))
            .collect::<Result<Vec<_>>>()?;
        self.write(Durability::Immediate, |txn| {
            let mut t = txn.open_table(INSTANCES).map_err(storage)?;
            for id in remove {
                t.remove(instance_key(scene_id, id).as_str()).map_err(storage)?;
            }
            for (k, v) in &rows {
                t.insert(k.as_str(), v.as_str()).map_err(storage)?;
            }
            Ok(true)
        })
        .map(|_| ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::StoredPose;
    use sublevel_core::body::ellipsoid;

    fn inst(body: &str, tx: f64) -> InstanceRecord {
        InstanceRecord {
            body_id: body.into(),
            pose: StoredPose { rotation: [1.0, 0.0, 0.0, 0.0], translation: [tx, 0.0, 0.0] },
        }
    }

    /// The store checks every store passes (`conformance::check_store`), reopening the file.
    #[test]
    fn redb_store_passes_the_store_checks() {
        let dir = tempfile::tempdir().unwrap();
        crate::store::conformance::check_store(&|| Box::new(RedbStore::open_dir(dir.path()).unwrap()));
    }

    #[test]
    fn redb_round_trip_survives_reopen_and_scopes_instances_by_scene() {
        let dir = tempfile::tempdir().unwrap();
        let body = ellipsoid([0.0; 3], [1.0, 2.0, 3.0]).unwrap();
        {
            let s = RedbStore::open_dir(dir.path()).unwrap();
            s.put_body("b-1", &BodyRecord::single("egg", body.to_file())).unwrap();
            s.put_scene("s-1", &SceneMeta::named("one")).unwrap();
            // "s-10" shares the prefix "s-1": its instances must not leak into s-1.
            s.put_scene("s-10", &SceneMeta::named("ten")).unwrap();
            s.put_instances("s-1", &[("i-a", &inst("b-1", 1.0)), ("i-b", &inst("b-1", 2.0))], false).unwrap();
            s.put_instances("s-10", &[("i-c", &inst("b-1", 3.0))], false).unwrap();
            s.put_instances("s-1", &[("i-b", &inst("b-1", 5.0))], true).unwrap();
        }
        let s = RedbStore::open_dir(dir.path()).unwrap();
        let b = s.get_body("b-1").unwrap().unwrap();
        assert_eq!(b.name, "egg");
        assert_eq!(b.body.coefficients, body.to_file().coefficients);
        assert_eq!(s.list_bodies().unwrap().len(), 1);
        let one = s.get_scene("s-1").unwrap().unwrap();
        assert_eq!(one.meta.name, "one");
        assert_eq!(one.instances.keys().collect::<Vec<_>>(), ["i-a", "i-b"]);
        assert_eq!(one.instances["i-b"].pose.translation[0], 5.0);
        assert_eq!(s.list_scenes().unwrap().len(), 2);

        assert!(s.delete_instance("s-1", "i-a").unwrap());
        assert!(!s.delete_instance("s-1", "i-a").unwrap());
        assert!(s.delete_scene("s-1").unwrap());
        assert!(s.get_scene("s-1").unwrap().is_none());
        let ten = s.get_scene("s-10").unwrap().unwrap();
        assert_eq!(ten.instances.len(), 1, "deleting s-1 must keep the instances of s-10");
        assert!(s.delete_body("b-1").unwrap());
        assert!(s.get_body("b-1").unwrap().is_none());
        assert!(!s.delete_body("b-1").unwrap());
    }

    /// A record whose JSON would not read back (a NaN becomes `null`) is refused and nothing is
    /// written: the store reopens with the records written before.
    #[test]
    fn a_record_that_would_not_read_back_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut file = ellipsoid([0.0; 3], [1.0; 3]).unwrap().to_file();
        {
            let s = RedbStore::open_dir(dir.path()).unwrap();
            s.put_body("b-ok", &BodyRecord::single("ok", file.clone())).unwrap();
            file.report.volume = f64::NAN;
            let e = s.put_body("b-nan", &BodyRecord::single("nan", file.clone())).unwrap_err();
            assert!(matches!(&e, Error::InvalidArgument { field, .. } if field == "body"), "{e}");
            let bad_pose = InstanceRecord {
                body_id: "b-ok".into(),
                pose: StoredPose { rotation: [1.0, 0.0, 0.0, 0.0], translation: [f64::INFINITY, 0.0, 0.0] },
            };
            assert!(s.put_instances("s", &[("i", &bad_pose)], true).is_err());
        }
        let s = RedbStore::open_dir(dir.path()).unwrap();
        assert_eq!(s.list_bodies().unwrap().len(), 1);
        assert!(s.quarantined().unwrap().is_empty());
        assert!(s.get_scene("s").unwrap().is_none());
    }
}
