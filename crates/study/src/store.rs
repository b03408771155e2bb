//! Durable study state in SQLite: each participant's randomised plan (written once, when they
//! join, so that a reload or a server restart resumes the same sequence) and every answer,
//! committed before the server replies (WAL journal, `synchronous = FULL`).

use std::path::Path;

use crate::analysis::Response;
use rusqlite::{Connection, OptionalExtension, params};

use crate::config::StudyConfig;
use crate::error::StudyError;

/// One comparison shown to a participant.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Trial {
    pub index: usize,
    pub scene: String,
    pub left: String,
    pub right: String,
}

/// Why an answer was refused; mapped to HTTP status codes by the server.
#[derive(Debug, thiserror::Error)]
pub enum SubmitError {
    #[error("unknown participant {0:?}")]
    UnknownParticipant(String),
    #[error("{0}")]
    Invalid(String),
    #[error("{0}")]
    Conflict(String),
    #[error(transparent)]
    Db(#[from] rusqlite::Error),
}

pub struct Store {
    conn: Connection,
}

/// SplitMix64 step: the plan's random stream.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// FNV-1a of the participant id, to mix into the study seed.
fn fnv1a(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// A participant's plan: every scene × unordered method pair once, in a random order, each with
/// a random left/right assignment (the fusion paper §5: scene, method pairing and left–right order are
/// randomised). Deterministic in (study seed, participant id).
pub fn plan(config: &StudyConfig, participant: &str) -> Vec<Trial> {
    let mut trials = Vec::new();
    for scene in &config.scenes {
        for a in 0..config.methods.len() {
            for b in a + 1..config.methods.len() {
                trials.push((
                    scene.clone(),
                    config.methods[a].clone(),
                    config.methods[b].clone(),
                ));
            }
        }
    }
    let mut state = config.seed ^ fnv1a(participant);
    for i in (1..trials.len()).rev() {
        let j = (splitmix(&mut state) % (i as u64 + 1)) as usize;
        trials.swap(i, j);
    }
    trials
        .into_iter()
        .enumerate()
        .map(|(index, (scene, a, b))| {
            let (left, right) = if splitmix(&mut state) & 1 == 0 {
                (a, b)
            } else {
                (b, a)
            };
            Trial {
                index,
                scene,
                left,
                right,
            }
        })
        .collect()
}

impl Store {
    pub fn open(path: &Path) -> crate::error::Result<Self> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| StudyError::io(dir, e))?;
        }
        let failed = |what: &'static str| {
            move |error| StudyError::Database {
                path: path.to_path_buf(),
                what,
                error,
            }
        };
        let conn = Connection::open(path).map_err(failed("cannot open database"))?;
        // SQLite opens any file lazily; a file that is not a database fails at the first
        // statement, here, and the error must name it.
        let not_a_database = failed("not a usable SQLite database");
        conn.busy_timeout(std::time::Duration::from_secs(10))
            .map_err(not_a_database)?;
        conn.pragma_update(None, "journal_mode", "WAL")
            .map_err(not_a_database)?;
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(not_a_database)?;
        conn.execute_batch(
            "CREATE TABLE IF NOT EXISTS participants (
                 id TEXT PRIMARY KEY, created_at TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP);
             CREATE TABLE IF NOT EXISTS trials (
                 participant TEXT NOT NULL REFERENCES participants(id), idx INTEGER NOT NULL,
                 scene TEXT NOT NULL, left_method TEXT NOT NULL, right_method TEXT NOT NULL,
                 PRIMARY KEY (participant, idx));
             CREATE TABLE IF NOT EXISTS responses (
                 participant TEXT NOT NULL, idx INTEGER NOT NULL, question TEXT NOT NULL,
                 scene TEXT NOT NULL, left_method TEXT NOT NULL, right_method TEXT NOT NULL,
                 winner TEXT NOT NULL, answered_at TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP,
                 PRIMARY KEY (participant, idx, question),
                 FOREIGN KEY (participant, idx) REFERENCES trials(participant, idx));",
        )
        .map_err(failed("cannot create the study tables"))?;
        Ok(Self { conn })
    }

    /// Registers a participant with their plan, or does nothing if they exist. Returns whether
    /// they are new.
    pub fn join(&mut self, config: &StudyConfig, participant: &str) -> rusqlite::Result<bool> {
        let tx = self.conn.transaction()?;
        let exists = tx
            .query_row(
                "SELECT 1 FROM participants WHERE id = ?1",
                [participant],
                |_| Ok(()),
            )
            .optional()?
            .is_some();
        if !exists {
            tx.execute("INSERT INTO participants (id) VALUES (?1)", [participant])?;
            for t in plan(config, participant) {
                tx.execute(
                    "INSERT INTO trials (participant, idx, scene, left_method, right_method) VALUES (?1, ?2, ?3, ?4, ?5)",
                    params![participant, t.index as i64, t.scene, t.left, t.right],
                )?;
            }
        }
        tx.commit()?;
        Ok(!exists)
    }

    pub fn exists(&self, participant: &str) -> rusqlite::Result<bool> {
        Ok(self
            .conn
            .query_row(
                "SELECT 1 FROM participants WHERE id = ?1",
                [participant],
                |_| Ok(()),
            )
            .optional()?
            .is_some())
    }

    /// (answered trials, total trials, next unanswered trial).
    pub fn progress(&self, participant: &str) -> rusqlite::Result<(usize, usize, Option<Trial>)> {
        let total: i64 = self.conn.query_row(
            "SELECT COUNT(*) FROM trials WHERE participant = ?1",
            [participant],
            |r| r.get(0),
        )?;
        let answered: i64 = self.conn.query_row(
            "SELECT COUNT(DISTINCT idx) FROM responses WHERE participant = ?1",
            [participant],
            |r| r.get(0),
        )?;
        let next = self
            .conn
            .query_row(
                "SELECT idx, scene, left_method, right_method FROM trials t WHERE participant = ?1
                 AND NOT EXISTS (SELECT 1 FROM responses r WHERE r.participant = t.participant AND r.idx = t.idx)
                 ORDER BY idx LIMIT 1",
                [participant],
                |r| Ok(Trial { index: r.get::<_, i64>(0)? as usize, scene: r.get(1)?, left: r.get(2)?, right: r.get(3)? }),
            )
            .optional()?;
        Ok((answered as usize, total as usize, next))
    }

    pub fn trial(&self, participant: &str, index: usize) -> rusqlite::Result<Option<Trial>> {
        self.conn
            .query_row(
                "SELECT idx, scene, left_method, right_method FROM trials WHERE participant = ?1 AND idx = ?2",
                params![participant, index as i64],
                |r| Ok(Trial { index: r.get::<_, i64>(0)? as usize, scene: r.get(1)?, left: r.get(2)?, right: r.get(3)? }),
            )
            .optional()
    }

    /// Stores the answers (`question id → "left" | "right"`) to trial `index`, all in one
    /// transaction. The trial must be the participant's next one; re-sending the answers of an
    /// already answered trial (a retried request) is accepted if they are the same.
    pub fn submit(
        &mut self,
        config: &StudyConfig,
        participant: &str,
        index: usize,
        answers: &std::collections::BTreeMap<String, String>,
    ) -> Result<(), SubmitError> {
        for (q, side) in answers {
            if !config.questions.iter().any(|c| &c.id == q) {
                return Err(SubmitError::Invalid(format!("unknown question {q:?}")));
            }
            if side != "left" && side != "right" {
                return Err(SubmitError::Invalid(format!(
                    "answer to {q} must be \"left\" or \"right\", got {side:?}"
                )));
            }
        }
        if let Some(q) = config
            .questions
            .iter()
            .find(|q| !answers.contains_key(&q.id))
        {
            return Err(SubmitError::Invalid(format!("missing answer to {}", q.id)));
        }
        let tx = self.conn.transaction()?;
        let trial = tx
            .query_row(
                "SELECT scene, left_method, right_method FROM trials WHERE participant = ?1 AND idx = ?2",
                params![participant, index as i64],
                |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?, r.get::<_, String>(2)?)),
            )
            .optional()?;
        let Some((scene, left, right)) = trial else {
            let known = tx
                .query_row(
                    "SELECT 1 FROM participants WHERE id = ?1",
                    [participant],
                    |_| Ok(()),
                )
                .optional()?
                .is_some();
            return Err(if known {
                SubmitError::Invalid(format!("trial {index} does not exist"))
            } else {
                SubmitError::UnknownParticipant(participant.to_string())
            });
        };
        let winner_of = |side: &str| {
            if side == "left" {
                left.clone()
            } else {
                right.clone()
            }
        };
        // Already answered: accept an identical retry, refuse a change.
        let mut stmt = tx.prepare(
            "SELECT question, winner FROM responses WHERE participant = ?1 AND idx = ?2",
        )?;
        let stored: Vec<(String, String)> = stmt
            .query_map(params![participant, index as i64], |r| {
                Ok((r.get(0)?, r.get(1)?))
            })?
            .collect::<rusqlite::Result<_>>()?;
        drop(stmt);
        if !stored.is_empty() {
            let same = stored.len() == answers.len()
                && stored
                    .iter()
                    .all(|(q, w)| answers.get(q).map(|s| winner_of(s)) == Some(w.clone()));
            return if same {
                Ok(())
            } else {
                Err(SubmitError::Conflict(format!(
                    "trial {index} was already answered differently"
                )))
            };
        }
        let next: Option<i64> = tx
            .query_row(
                "SELECT MIN(idx) FROM trials t WHERE participant = ?1
                 AND NOT EXISTS (SELECT 1 FROM responses r WHERE r.participant = t.participant AND r.idx = t.idx)",
                [participant],
                |r| r.get(0),
            )
            .optional()?
            .flatten();
        if next != Some(index as i64) {
            return Err(SubmitError::Conflict(format!(
                "trial {index} is not the next one (next: {next:?})"
            )));
        }
        for (q, side) in answers {
            tx.execute(
                "INSERT INTO responses (participant, idx, question, scene, left_method, right_method, winner)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                params![participant, index as i64, q, scene, left, right, winner_of(side)],
            )?;
        }
        tx.commit()?;
        Ok(())
    }

    /// Every stored answer, in participant and trial order.
    pub fn responses(&self) -> rusqlite::Result<Vec<Response>> {
        let mut stmt = self.conn.prepare(
            "SELECT participant, question, scene, left_method, right_method, winner FROM responses ORDER BY participant, idx, question",
        )?;
        stmt.query_map([], |r| {
            Ok(Response {
                participant: r.get(0)?,
                question: r.get(1)?,
                scene: r.get(2)?,
                left: r.get(3)?,
                right: r.get(4)?,
                winner: r.get(5)?,
            })
        })?
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::Store;

    /// A file that is not a database (a config passed by mistake) is refused with its name;
    /// before, the error was SQLite's bare "file is not a database".
    #[test]
    fn a_file_that_is_not_a_database_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("answers.sqlite");
        std::fs::write(&path, "title = \"not a database\"\n".repeat(200)).unwrap();
        let err = Store::open(&path).err().expect("refused");
        let shown = format!("{err:#}");
        assert!(
            shown.starts_with(&format!("{}: not a usable SQLite database", path.display())),
            "{shown}"
        );
        assert!(shown.contains("not a database"), "{shown}");
    }
}
