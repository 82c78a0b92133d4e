//! Persistence (SQLite, WAL): every episode's create request, every applied action and every
//! finished result, each written before the response that reports it, so that a server killed
//! at any point restarts with its finished results intact and can replay the actions of the
//! episodes that were running (the engine is deterministic).
//!
//! Tables: `episodes(id, owner, split, uid, method, request, state, created_at)` (`created_at`:
//! RFC 3339 UTC with milliseconds, set by the database on insert; a database from before the
//! column existed gets it added, its episodes stamped with the time of that upgrade),
//! `actions(episode, seq,
//! step, action, planner_seconds)` (the raw action JSON as received), `results(seq, episode,
//! owner, method, line)` (`seq` = finish order; `line` = the `objview run` JSON line).

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use rusqlite::{params, Connection, OpenFlags, OptionalExtension};

use crate::error::ServerError;

/// A database operation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("database: {0}")]
pub struct DbError(pub String);

impl From<rusqlite::Error> for DbError {
    fn from(e: rusqlite::Error) -> DbError {
        DbError(e.to_string())
    }
}

/// An episode as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRow {
    /// The episode id.
    pub id: String,
    /// Who created it (a token's hash; empty without tokens).
    pub owner: String,
    /// The split id the object comes from.
    pub split: String,
    /// The object's uid.
    pub uid: String,
    /// The method (planner) name.
    pub method: String,
    /// The validated create request (JSON), enough to start the episode again.
    pub request: String,
    /// `running` or `finished`.
    pub state: String,
    /// When it was created (RFC 3339 UTC, `2025-01-31T12:00:00.123Z`); set by
    /// [`Db::insert_episode`], ignored when inserting.
    pub created_at: String,
    /// Its creation order (the row id); set by [`Db::insert_episode`], ignored when inserting.
    pub seq: i64,
}

/// An applied action as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct ActionRow {
    /// The step it was applied at.
    pub step: usize,
    /// The raw `action` JSON as received.
    pub action: String,
    /// Planning time the engine was given for it (seconds).
    pub planner_seconds: f64,
}

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS episodes (
    id TEXT PRIMARY KEY,
    owner TEXT NOT NULL,
    split TEXT NOT NULL,
    uid TEXT NOT NULL,
    method TEXT NOT NULL,
    request TEXT NOT NULL,
    state TEXT NOT NULL,
    created_at TEXT NOT NULL DEFAULT ''
);
CREATE TABLE IF NOT EXISTS actions (
    episode TEXT NOT NULL,
    seq INTEGER NOT NULL,
    step INTEGER NOT NULL,
    action TEXT NOT NULL,
    planner_seconds REAL NOT NULL,
    PRIMARY KEY (episode, seq)
);
CREATE TABLE IF NOT EXISTS results (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    episode TEXT NOT NULL UNIQUE,
    owner TEXT NOT NULL,
    method TEXT NOT NULL,
    line TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS results_owner_method ON results (owner, method);
";

/// The current time as SQLite writes it: RFC 3339 UTC with milliseconds.
const NOW: &str = "strftime('%Y-%m-%dT%H:%M:%fZ', 'now')";

/// Adds `episodes.created_at` to a database written before it existed (its episodes get the
/// time of this upgrade: their creation time was not recorded).
fn add_created_at(conn: &Connection) -> rusqlite::Result<()> {
    let has =
        conn.prepare("SELECT 1 FROM pragma_table_info('episodes') WHERE name = 'created_at'")?.exists([])?;
    if !has {
        conn.execute_batch(&format!(
            "ALTER TABLE episodes ADD COLUMN created_at TEXT NOT NULL DEFAULT '';
             UPDATE episodes SET created_at = {NOW} WHERE created_at = '';"
        ))?;
    }
    Ok(())
}

/// The server's database (one connection; writes are short transactions).
pub struct Db {
    path: PathBuf,
    conn: Mutex<Connection>,
}

fn open_err(path: &Path, e: impl std::fmt::Display) -> ServerError {
    ServerError::Db { path: path.display().to_string(), reason: e.to_string() }
}

impl Db {
    /// Opens (creating if needed) the database at `path` in WAL mode.
    pub fn open(path: &Path) -> Result<Db, ServerError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| open_err(path, e))?;
        }
        let conn = Connection::open(path).map_err(|e| open_err(path, e))?;
        conn.pragma_update(None, "journal_mode", "WAL").map_err(|e| open_err(path, e))?;
        // NORMAL in WAL mode: a committed transaction survives a killed process (not a power
        // loss), which is what the restart guarantee is about.
        conn.pragma_update(None, "synchronous", "NORMAL").map_err(|e| open_err(path, e))?;
        conn.busy_timeout(std::time::Duration::from_secs(10)).map_err(|e| open_err(path, e))?;
        conn.execute_batch(SCHEMA).map_err(|e| open_err(path, e))?;
        add_created_at(&conn).map_err(|e| open_err(path, e))?;
        Ok(Db { path: path.to_path_buf(), conn: Mutex::new(conn) })
    }

    /// Where it is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn conn(&self) -> std::sync::MutexGuard<'_, Connection> {
        self.conn.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Stores a new (running) episode, stamped with the current time; its creation order and
    /// time (`seq`, `created_at`).
    pub fn insert_episode(&self, e: &EpisodeRow) -> Result<(i64, String), DbError> {
        Ok(self.conn().query_row(
            &format!(
                "INSERT INTO episodes (id, owner, split, uid, method, request, state, created_at) \
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, {NOW}) RETURNING rowid, created_at"
            ),
            params![e.id, e.owner, e.split, e.uid, e.method, e.request, e.state],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )?)
    }

    /// Stores an action before it is applied (`seq` counts actions from 1); a result is stored
    /// by [`Db::record_end`].
    pub fn record_action(&self, id: &str, seq: usize, action: &ActionRow) -> Result<(), DbError> {
        self.conn().execute(
            "INSERT INTO actions (episode, seq, step, action, planner_seconds) VALUES (?1, ?2, ?3, ?4, ?5)",
            params![id, seq as i64, action.step as i64, action.action, action.planner_seconds],
        )?;
        Ok(())
    }

    /// Stores the result of an episode (after its last action, a time-out, an abort, or the
    /// replay after a restart).
    pub fn record_end(&self, id: &str, owner: &str, method: &str, line: &str) -> Result<(), DbError> {
        let mut conn = self.conn();
        let tx = conn.transaction()?;
        finish_in(&tx, id, owner, method, line)?;
        tx.commit()?;
        Ok(())
    }

    /// Every stored episode, in creation order.
    pub fn episodes(&self) -> Result<Vec<EpisodeRow>, DbError> {
        let conn = self.conn();
        let mut st = conn
            .prepare("SELECT id, owner, split, uid, method, request, state, created_at, rowid FROM episodes ORDER BY rowid")?;
        let rows = st.query_map([], |r| {
            Ok(EpisodeRow {
                id: r.get(0)?,
                owner: r.get(1)?,
                split: r.get(2)?,
                uid: r.get(3)?,
                method: r.get(4)?,
                request: r.get(5)?,
                state: r.get(6)?,
                created_at: r.get(7)?,
                seq: r.get(8)?,
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    /// The applied actions of episode `id`, in order.
    pub fn actions(&self, id: &str) -> Result<Vec<ActionRow>, DbError> {
        let conn = self.conn();
        let mut st = conn
            .prepare("SELECT step, action, planner_seconds FROM actions WHERE episode = ?1 ORDER BY seq")?;
        let rows = st.query_map([id], |r| {
            Ok(ActionRow {
                step: r.get::<_, i64>(0)? as usize,
                action: r.get(1)?,
                planner_seconds: r.get(2)?,
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    /// The result line of episode `id`, if it finished.
    pub fn result(&self, id: &str) -> Result<Option<String>, DbError> {
        Ok(self
            .conn()
            .query_row("SELECT line FROM results WHERE episode = ?1", [id], |r| r.get(0))
            .optional()?)
    }

    /// Methods with finished results of `owner`, and how many, by name.
    pub fn methods(&self, owner: &str) -> Result<Vec<(String, usize)>, DbError> {
        let conn = self.conn();
        let mut st = conn.prepare(
            "SELECT method, COUNT(*) FROM results WHERE owner = ?1 GROUP BY method ORDER BY method",
        )?;
        let rows = st.query_map([owner], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as usize)))?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    /// Result lines of `owner` (every owner when `None`), of one method or all, in finish order.
    pub fn results(&self, owner: Option<&str>, method: Option<&str>) -> Result<Vec<String>, DbError> {
        results_of(&self.conn(), owner, method)
    }
}

fn finish_in(
    tx: &rusqlite::Transaction<'_>,
    id: &str,
    owner: &str,
    method: &str,
    line: &str,
) -> Result<(), DbError> {
    tx.execute(
        "INSERT INTO results (episode, owner, method, line) VALUES (?1, ?2, ?3, ?4)",
        params![id, owner, method, line],
    )?;
    tx.execute("UPDATE episodes SET state = 'finished' WHERE id = ?1", [id])?;
    Ok(())
}

fn results_of(conn: &Connection, owner: Option<&str>, method: Option<&str>) -> Result<Vec<String>, DbError> {
    let mut st = conn.prepare(
        "SELECT line FROM results WHERE (?1 IS NULL OR owner = ?1) AND (?2 IS NULL OR method = ?2) ORDER BY seq",
    )?;
    let rows = st.query_map(params![owner, method], |r| r.get(0))?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// `objview export`: every finished result in the database at `path` (of one method, or all),
/// in finish order, as `objview run` lines. A running server may hold it (WAL readers do not
/// block the writer).
pub fn export(path: &Path, method: Option<&str>) -> Result<Vec<String>, ServerError> {
    if !path.is_file() {
        return Err(open_err(path, "no such file"));
    }
    let conn = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_WRITE | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(|e| open_err(path, e))?;
    conn.busy_timeout(std::time::Duration::from_secs(10)).map_err(|e| open_err(path, e))?;
    results_of(&conn, None, method).map_err(|e| open_err(path, e.0))
}
