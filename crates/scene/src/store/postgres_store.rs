//! [`PostgresStore`]: the [`Store`] on PostgreSQL (feature `postgres`), shared by the replicas of
//! a scale-out deployment (`deploy/SCALING.md`); the embedded [`super::RedbStore`] stays the
//! single-node default.
//!
//! The same tables as the redb store, each a `(key text primary key, value text)` table of the
//! same JSON records (checked by [`encode`] before every write), in the schema's
//! `sublevel_`-prefixed tables:
//!
//! ```text
//! sublevel_bodies      body_id                → BodyRecord
//! sublevel_scenes      scene_id               → SceneMeta
//! sublevel_instances   (scene_id, inst_id)    → InstanceRecord
//! sublevel_jobs        job_id                 → JobRecord
//! sublevel_robots      robot_id               → RobotRecord
//! sublevel_quarantine  (tbl, key)             → reason, text
//! ```
//!
//! Every method is one transaction (or one statement). Frequent pose updates
//! (`put_instances(…, frequent = true)`) commit with `synchronous_commit = off` for that
//! transaction: atomic, and durable a few hundred milliseconds later (the redb store's
//! "eventual" durability).
//!
//! The client is rust-postgres's blocking [`postgres::Client`], which drives its own small tokio
//! runtime and must not be called on a thread that runs async tasks; every call therefore runs on
//! a short-lived scoped thread (tens of microseconds, small against a database round trip), so
//! the store can be used from any thread, like the redb store. One connection, behind a mutex:
//! the catalog writes through one transaction at a time per call.

use super::{encode, QuarantinedRecord, Store};
use crate::{BodyRecord, InstanceRecord, JobRecord, RobotRecord, SceneMeta, SceneRecord};
use crate::{Error, Result};
use postgres::{Client, NoTls};
use std::sync::Mutex;

/// The tables of the module docs (created if missing).
const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS sublevel_bodies (key text PRIMARY KEY, value text NOT NULL);
CREATE TABLE IF NOT EXISTS sublevel_scenes (key text PRIMARY KEY, value text NOT NULL);
CREATE TABLE IF NOT EXISTS sublevel_instances (
    scene_id text NOT NULL, instance_id text NOT NULL, value text NOT NULL,
    PRIMARY KEY (scene_id, instance_id));
CREATE TABLE IF NOT EXISTS sublevel_jobs (key text PRIMARY KEY, value text NOT NULL);
CREATE TABLE IF NOT EXISTS sublevel_robots (key text PRIMARY KEY, value text NOT NULL);
CREATE TABLE IF NOT EXISTS sublevel_quarantine (
    tbl text NOT NULL, key text NOT NULL, reason text NOT NULL, text text NOT NULL,
    PRIMARY KEY (tbl, key));
";

/// [`Store`] on a PostgreSQL database (see the module docs).
pub struct PostgresStore {
    /// The one connection; a std mutex because every call is blocking and short (one round trip
    /// or one transaction), never held across an await.
    client: Mutex<Client>,
}

impl std::fmt::Debug for PostgresStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PostgresStore").finish_non_exhaustive()
    }
}

fn storage(e: postgres::Error) -> Error {
    Error::Storage(format!("postgres: {e}"))
}

/// Parses a stored JSON value of `table`/`key`.
fn parse<T: serde::de::DeserializeOwned>(table: &str, key: &str, text: &str) -> Result<T> {
    serde_json::from_str(text).map_err(|e| Error::Storage(format!("unreadable record {table}/{key}: {e}")))
}

impl PostgresStore {
    /// Connects to `url` (a libpq connection string or `postgres://user@host:port/db` URL, no
    /// TLS: run it on loopback, a private network or through a TLS sidecar) and creates the
    /// tables if missing.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--store` for an unparsable URL; [`Error::Storage`] when
    /// the server cannot be reached or refuses the schema.
    pub fn connect(url: &str) -> Result<Self> {
        let config: postgres::Config =
            url.parse().map_err(|e| Error::invalid("--store", format!("not a PostgreSQL URL: {e}")))?;
        let client = off_runtime(move || {
            let mut client = config.connect(NoTls).map_err(storage)?;
            client.batch_execute(SCHEMA).map_err(storage)?;
            Ok(client)
        })?;
        Ok(Self { client: Mutex::new(client) })
    }

    /// Runs `f` with the connection on a scoped thread (see the module docs).
    fn with<T: Send>(&self, f: impl FnOnce(&mut Client) -> Result<T> + Send) -> Result<T> {
        let mut guard = self.client.lock().unwrap_or_else(|e| e.into_inner());
        let client: &mut Client = &mut guard;
        off_runtime(move || f(client))
    }
}

/// Runs `f` on a scoped thread that no async runtime drives.
fn off_runtime<T: Send>(f: impl FnOnce() -> Result<T> + Send) -> Result<T> {
    std::thread::scope(|s| {
        s.spawn(f).join().unwrap_or_else(|_| Err(Error::Storage("postgres: the client thread panicked".into())))
    })
}

impl PostgresStore {
    /// Every record of the key-value table `sublevel_{table}`, ordered by key.
    fn list<T: serde::de::DeserializeOwned>(&self, table: &str) -> Result<Vec<(String, T)>> {
        let sql = format!("SELECT key, value FROM sublevel_{table} ORDER BY key");
        let rows = self.with(|c| c.query(&sql, &[]).map_err(storage))?;
        rows.iter()
            .map(|r| {
                let key: String = r.get(0);
                let value = parse(table, &key, r.get(1))?;
                Ok((key, value))
            })
            .collect()
    }
}

/// `INSERT … ON CONFLICT DO UPDATE` of a key-value table.
fn upsert(table: &str) -> String {
    format!("INSERT INTO {table} (key, value) VALUES ($1, $2) ON CONFLICT (key) DO UPDATE SET value = EXCLUDED.value")
}

impl Store for PostgresStore {
    fn put_body(&self, id: &str, record: &BodyRecord) -> Result<()> {
        let json = encode("body", record)?;
        self.with(|c| c.execute(&upsert("sublevel_bodies"), &[&id, &json]).map(drop).map_err(storage))
    }

    fn get_body(&self, id: &str) -> Result<Option<BodyRecord>> {
        let row =
            self.with(|c| c.query_opt("SELECT value FROM sublevel_bodies WHERE key = $1", &[&id]).map_err(storage))?;
        row.map(|r| parse("bodies", id, r.get(0))).transpose()
    }

    fn list_bodies(&self) -> Result<Vec<(String, BodyRecord)>> {
        self.list("bodies")
    }

    fn delete_body(&self, id: &str) -> Result<bool> {
        self.with(|c| c.execute("DELETE FROM sublevel_bodies WHERE key = $1", &[&id]).map(|n| n > 0).map_err(storage))
    }

    fn put_robot(&self, id: &str, record: &RobotRecord) -> Result<()> {
        let json = encode("robot", record)?;
        self.with(|c| c.execute(&upsert("sublevel_robots"), &[&id, &json]).map(drop).map_err(storage))
    }

    fn list_robots(&self) -> Result<Vec<(String, RobotRecord)>> {
        self.list("robots")
    }

    fn delete_robot(&self, id: &str) -> Result<bool> {
        self.with(|c| c.execute("DELETE FROM sublevel_robots WHERE key = $1", &[&id]).map(|n| n > 0).map_err(storage))
    }

    fn put_scene(&self, id: &str, meta: &SceneMeta) -> Result<()> {
        let json = encode("scene", meta)?;
        self.with(|c| c.execute(&upsert("sublevel_scenes"), &[&id, &json]).map(drop).map_err(storage))
    }

    fn get_scene(&self, id: &str) -> Result<Option<SceneRecord>> {
        let (meta, rows) = self.with(|c| {
            let mut tx = c.transaction().map_err(storage)?;
            let meta = tx.query_opt("SELECT value FROM sublevel_scenes WHERE key = $1", &[&id]).map_err(storage)?;
            let rows = tx
                .query(
                    "SELECT instance_id, value FROM sublevel_instances WHERE scene_id = $1 ORDER BY instance_id",
                    &[&id],
                )
                .map_err(storage)?;
            tx.commit().map_err(storage)?;
            Ok((meta, rows))
        })?;
        let Some(meta) = meta else { return Ok(None) };
        let meta: SceneMeta = parse("scenes", id, meta.get(0))?;
        let mut instances = std::collections::BTreeMap::new();
        for r in &rows {
            let iid: String = r.get(0);
            let rec = parse("instances", &format!("{id}/{iid}"), r.get(1))?;
            instances.insert(iid, rec);
        }
        Ok(Some(SceneRecord { meta, instances }))
    }

    fn list_scenes(&self) -> Result<Vec<(String, SceneRecord)>> {
        let (scenes, rows) = self.with(|c| {
            let mut tx = c.transaction().map_err(storage)?;
            let scenes = tx.query("SELECT key, value FROM sublevel_scenes ORDER BY key", &[]).map_err(storage)?;
            let rows = tx
                .query(
                    "SELECT scene_id, instance_id, value FROM sublevel_instances ORDER BY scene_id, instance_id",
                    &[],
                )
                .map_err(storage)?;
            tx.commit().map_err(storage)?;
            Ok((scenes, rows))
        })?;
        let mut out = std::collections::BTreeMap::new();
        for r in &scenes {
            let key: String = r.get(0);
            let meta: SceneMeta = parse("scenes", &key, r.get(1))?;
            out.insert(key, SceneRecord { meta, instances: std::collections::BTreeMap::new() });
        }
        for r in &rows {
            let (sid, iid): (String, String) = (r.get(0), r.get(1));
            if let Some(scene) = out.get_mut(&sid) {
                let rec = parse("instances", &format!("{sid}/{iid}"), r.get(2))?;
                scene.instances.insert(iid, rec);
            }
        }
        Ok(out.into_iter().collect())
    }

    fn delete_scene(&self, id: &str) -> Result<bool> {
        self.with(|c| {
            let mut tx = c.transaction().map_err(storage)?;
            tx.execute("DELETE FROM sublevel_instances WHERE scene_id = $1", &[&id]).map_err(storage)?;
            let n = tx.execute("DELETE FROM sublevel_scenes WHERE key = $1", &[&id]).map_err(storage)?;
            tx.commit().map_err(storage)?;
            Ok(n > 0)
        })
    }

    fn put_instances(&self, scene_id: &str, instances: &[(&str, &InstanceRecord)], frequent: bool) -> Result<()> {
        let rows = instances
            .iter()
            .map(|(id, r)| Ok(((*id).to_owned(), encode("instance", *r)?)))
            .collect::<Result<Vec<(String, String)>>>()?;
        self.with(|c| {
            let mut tx = c.transaction().map_err(storage)?;
            if frequent {
                tx.batch_execute("SET LOCAL synchronous_commit = off").map_err(storage)?;
            }
            let stmt = tx
                .prepare(
                    "INSERT INTO sublevel_instances (scene_id, instance_id, value) VALUES ($1, $2, $3) \
                     ON CONFLICT (scene_id, instance_id) DO UPDATE SET value = EXCLUDED.value",
                )
                .map_err(storage)?;
            for (id, json) in &rows {
                tx.execute(&stmt, &[&scene_id, id, json]).map_err(storage)?;
            }
            tx.commit().map_err(storage)
        })
    }

    fn delete_instance(&self, scene_id: &str, instance_id: &str) -> Result<bool> {
        self.with(|c| {
            c.execute(
                "DELETE FROM sublevel_instances WHERE scene_id = $1 AND instance_id = $2",
                &[&scene_id, &instance_id],
            )
            .map(|n| n > 0)
            .map_err(storage)
        })
    }

    fn put_job(&self, id: &str, record: &JobRecord) -> Result<()> {
        let json = encode("job", record)?;
        self.with(|c| c.execute(&upsert("sublevel_jobs"), &[&id, &json]).map(drop).map_err(storage))
    }

    fn list_jobs(&self) -> Result<Vec<(String, JobRecord)>> {
        self.list("jobs")
    }

    fn delete_jobs(&self, ids: &[&str]) -> Result<()> {
        let ids: Vec<String> = ids.iter().map(|s| (*s).to_owned()).collect();
        self.with(|c| c.execute("DELETE FROM sublevel_jobs WHERE key = ANY($1)", &[&ids]).map(drop).map_err(storage))
    }

    fn quarantine(&self, table: &str, key: &str, reason: &str) -> Result<()> {
        self.with(|c| {
            let mut tx = c.transaction().map_err(storage)?;
            let text: Option<String> = match table {
                "bodies" | "scenes" | "jobs" | "robots" => {
                    let sql = format!("DELETE FROM sublevel_{table} WHERE key = $1 RETURNING value");
                    tx.query_opt(&sql, &[&key]).map_err(storage)?.map(|r| r.get(0))
                }
                "instances" => {
                    let (sid, iid) = key.split_once('/').unwrap_or((key, ""));
                    tx.query_opt(
                        "DELETE FROM sublevel_instances WHERE scene_id = $1 AND instance_id = $2 RETURNING value",
                        &[&sid, &iid],
                    )
                    .map_err(storage)?
                    .map(|r| r.get(0))
                }
                _ => None,
            };
            if let Some(text) = text {
                tx.execute(
                    "INSERT INTO sublevel_quarantine (tbl, key, reason, text) VALUES ($1, $2, $3, $4) \
                     ON CONFLICT (tbl, key) DO UPDATE SET reason = EXCLUDED.reason, text = EXCLUDED.text",
                    &[&table, &key, &reason, &text],
                )
                .map_err(storage)?;
            }
            tx.commit().map_err(storage)
        })
    }

    fn quarantined(&self) -> Result<Vec<QuarantinedRecord>> {
        let rows = self.with(|c| {
            c.query("SELECT tbl, key, reason, text FROM sublevel_quarantine ORDER BY tbl, key", &[]).map_err(storage)
        })?;
        Ok(rows
            .iter()
            .map(|r| QuarantinedRecord { table: r.get(0), key: r.get(1), reason: r.get(2), text: r.get(3) })
            .collect())
    }

    fn replace_instances(&self, scene_id: &str, remove: &[&str], add: &[(&str, &InstanceRecord)]) -> Result<()> {
        let rows = add
            .iter()
            .map(|(id, r)| Ok(((*id).to_owned(), encode("instance", *r)?)))
            .collect::<Result<Vec<(String, String)>>>()?;
        let remove: Vec<String> = remove.iter().map(|s| (*s).to_owned()).collect();
        self.with(|c| {
            let mut tx = c.transaction().map_err(storage)?;
            tx.execute(
                "DELETE FROM sublevel_instances WHERE scene_id = $1 AND instance_id = ANY($2)",
                &[&scene_id, &remove],
            )
            .map_err(storage)?;
            for (id, json) in &rows {
                tx.execute(
                    "INSERT INTO sublevel_instances (scene_id, instance_id, value) VALUES ($1, $2, $3) \
                     ON CONFLICT (scene_id, instance_id) DO UPDATE SET value = EXCLUDED.value",
                    &[&scene_id, id, json],
                )
                .map_err(storage)?;
            }
            tx.commit().map_err(storage)
        })
    }

    fn shared(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::conformance::{check_store, TempPostgres};

    /// The store checks of every store (`conformance::check_store`) on a throwaway PostgreSQL
    /// cluster; a second connection plays the restart. Skipped, with the reason printed, only
    /// when PostgreSQL is not installed (CI installs it: `scripts/setup-system`).
    #[test]
    fn postgres_store_passes_the_store_checks_and_keeps_data_across_reconnects() {
        let pg = match TempPostgres::start().expect("PostgreSQL is installed but did not start") {
            Ok(pg) => pg,
            Err(reason) => {
                eprintln!("SKIPPED postgres store test: {reason}");
                return;
            }
        };
        check_store(&|| Box::new(PostgresStore::connect(&pg.url).expect("connect")));
        let e = PostgresStore::connect("postgres://nobody@127.0.0.1:1/x").unwrap_err();
        assert!(matches!(e, Error::Storage(_)), "{e}");
        let e = PostgresStore::connect("postgres://[bad").unwrap_err();
        assert!(e.to_string().contains("--store"), "{e}");
    }
}
