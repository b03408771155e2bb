//! `study.toml`: what a 2AFC study shows and asks.
//!
//! ```toml
//! title = "Novel-view videos"
//! seed = 7                        # randomises each participant's trial order and sides
//! database = "responses.sqlite"   # relative to this file
//! methods = ["FreeNeRF", "CoherentGS", "MVPGS", "Ours"]
//! scenes = ["truck", "train"]
//!
//! [[questions]]                   # optional; the default is the fusion paper's Q1 and Q2
//! id = "Q1"
//! text = "Which video shows more natural color transitions as the viewpoint changes?"
//!
//! [videos.truck]                  # one file per (scene, method), relative to this file
//! FreeNeRF = "videos/truck/freenerf.mp4"
//! ```
//!
//! Files ending in `.gif`, `.png`, `.jpg`, `.jpeg` or `.webp` are shown as images, everything
//! else (`.mp4`, `.webm`, ...) as looping muted videos.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Result, StudyError};

#[derive(Clone, Debug, serde::Deserialize, serde::Serialize)]
pub struct Question {
    pub id: String,
    pub text: String,
}

#[derive(Clone, Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default = "default_title")]
    title: String,
    #[serde(default)]
    seed: u64,
    #[serde(default = "default_database")]
    database: PathBuf,
    methods: Vec<String>,
    scenes: Vec<String>,
    #[serde(default)]
    questions: Option<Vec<Question>>,
    videos: BTreeMap<String, BTreeMap<String, PathBuf>>,
}

fn default_title() -> String {
    "Which video looks better?".into()
}
fn default_database() -> PathBuf {
    "responses.sqlite".into()
}

/// The fusion paper's two questions (supplementary §5).
pub fn paper_questions() -> Vec<Question> {
    vec![
        Question {
            id: "Q1".into(),
            text: "Which video shows more natural color transitions as the viewpoint changes?"
                .into(),
        },
        Question {
            id: "Q2".into(),
            text: "Which video has higher overall quality as the viewpoint changes?".into(),
        },
    ]
}

/// A validated study configuration with absolute paths.
#[derive(Clone, Debug)]
pub struct StudyConfig {
    pub title: String,
    pub seed: u64,
    pub database: PathBuf,
    pub methods: Vec<String>,
    pub scenes: Vec<String>,
    pub questions: Vec<Question>,
    /// `videos[scene][method]`.
    pub videos: BTreeMap<String, BTreeMap<String, PathBuf>>,
}

fn valid_name(s: &str) -> bool {
    !s.is_empty() && s.len() <= 100 && !s.chars().any(char::is_control)
}

impl StudyConfig {
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| StudyError::io(path, e))?;
        let raw: RawConfig =
            toml::from_str(&text).map_err(|e| StudyError::format(path, e.to_string().trim()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::from_raw(raw, base).map_err(|message| StudyError::format(path, message))
    }

    /// The validated configuration, or what is wrong with it.
    fn from_raw(raw: RawConfig, base: &Path) -> Result<Self, String> {
        if raw.methods.len() < 2 {
            return Err("a pairwise study needs at least two methods".into());
        }
        if raw.scenes.is_empty() {
            return Err("no scenes".into());
        }
        for list in [&raw.methods, &raw.scenes] {
            let mut seen = std::collections::BTreeSet::new();
            for n in list {
                if !valid_name(n) || !seen.insert(n) {
                    return Err(format!(
                        "method and scene names must be unique, non-empty and printable: {n:?}"
                    ));
                }
            }
        }
        let questions = raw.questions.unwrap_or_else(paper_questions);
        if questions.is_empty() {
            return Err("no questions".into());
        }
        let mut ids = std::collections::BTreeSet::new();
        for q in &questions {
            if !valid_name(&q.id) || !ids.insert(&q.id) || q.text.trim().is_empty() {
                return Err(format!("questions need unique ids and a text: {:?}", q.id));
            }
        }
        let mut videos = BTreeMap::new();
        for scene in &raw.scenes {
            let per = raw
                .videos
                .get(scene)
                .ok_or_else(|| format!("no [videos.{scene}] table"))?;
            let mut out = BTreeMap::new();
            for method in &raw.methods {
                let rel = per
                    .get(method)
                    .ok_or_else(|| format!("no video for scene {scene:?}, method {method:?}"))?;
                let path = base.join(rel);
                if !path.is_file() {
                    return Err(format!(
                        "video for scene {scene:?}, method {method:?} not found: {}",
                        path.display()
                    ));
                }
                out.insert(method.clone(), path);
            }
            videos.insert(scene.clone(), out);
        }
        for scene in raw.videos.keys() {
            if !raw.scenes.contains(scene) {
                return Err(format!(
                    "[videos.{scene}] names a scene that is not in `scenes`"
                ));
            }
        }
        Ok(Self {
            title: raw.title,
            seed: raw.seed,
            database: base.join(raw.database),
            methods: raw.methods,
            scenes: raw.scenes,
            questions,
            videos,
        })
    }

    /// Comparisons each participant makes: every scene × every unordered method pair.
    pub fn trials_per_participant(&self) -> usize {
        let k = self.methods.len();
        self.scenes.len() * k * (k - 1) / 2
    }
}
