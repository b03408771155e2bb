//! What the page shows of a run, read and checked once before serving.
//!
//! The kind of run comes from its files:
//! - **splat** (`fewview train`, `demo`, `fusion`): `point_cloud.ply`; with `config.json` (the
//!   background, near plane and split), `cameras.json` (the training cameras, then the held-out
//!   ones, in `config.json`'s order), `metrics.json`, `renders/test/*.png` (held-out renders),
//!   `ground_truth/*.png` (the demo's ground truth, shown beside the renders) and videos
//!   (`*.mp4`, `*.gif`, `*.webm` in the run folder);
//! - **surface** (`fewview surface`): `mesh.ply`, `poses_initial.json`, `poses_refined.json`,
//!   `metrics.json` and `renders/*.png`;
//! - **poses** (`fewview poses`): `poses_report.json`, the estimated `cameras.json`, the
//!   model's points (`sparse/0/points3D.txt`, drawn as dots) and `cameras.png`;
//! - a lone Gaussian PLY (`fewview view --ply FILE`).
//!
//! Only the files listed here are served (by index, never by a path from the request).

use std::path::{Path, PathBuf};

use fewview_scene::Camera;
use fewview_scene::load::LoadOptions;
use serde::Serialize;

use crate::error::{Result, ViewError};
use crate::ply::{GaussianPly, check_gaussian_ply};

/// Which kind of run a folder holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RunKind {
    Splat,
    Surface,
    Poses,
    Ply,
}

/// A camera as the page draws it: pinhole intrinsics in pixels, world-to-camera (OpenCV axes),
/// rotation row-major.
#[derive(Clone, Debug, Serialize)]
pub struct PageCamera {
    pub name: String,
    /// `train`, `test`, `initial`, `refined` or `estimated`.
    pub group: &'static str,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: u32,
    pub height: u32,
    pub rotation: [f64; 9],
    pub translation: [f64; 3],
}

impl PageCamera {
    fn new(name: String, group: &'static str, c: &Camera) -> Self {
        let k = &c.intrinsics;
        let r = &c.world_to_camera.rotation;
        let t = &c.world_to_camera.translation;
        Self {
            name,
            group,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
            rotation: [
                r[(0, 0)],
                r[(0, 1)],
                r[(0, 2)],
                r[(1, 0)],
                r[(1, 1)],
                r[(1, 2)],
                r[(2, 0)],
                r[(2, 1)],
                r[(2, 2)],
            ],
            translation: [t[0], t[1], t[2]],
        }
    }
}

/// A held-out render and, when the run has it, its ground truth (URLs).
#[derive(Clone, Debug, Serialize)]
pub struct PageImage {
    pub name: String,
    pub render: String,
    pub truth: Option<String>,
}

/// A video of the run (URL).
#[derive(Clone, Debug, Serialize)]
pub struct PageVideo {
    pub name: String,
    pub url: String,
}

/// The Gaussians: where to stream them from and their row layout.
#[derive(Clone, Debug, Serialize)]
pub struct PageModel {
    pub url: String,
    #[serde(flatten)]
    pub layout: GaussianPly,
}

/// Everything the page is told about the run (`GET /api/run`).
#[derive(Clone, Debug, Serialize)]
pub struct Manifest {
    pub kind: RunKind,
    pub title: String,
    pub model: Option<PageModel>,
    /// `GET /api/mesh` serves it (see [`MeshBuffers`]).
    pub has_mesh: bool,
    /// The colour behind the Gaussians (`C + T·bg`), as the run rendered.
    pub background: [f32; 3],
    /// Gaussians whose centre is nearer than this (camera z) are not drawn.
    pub near_plane: f64,
    pub cameras: Vec<PageCamera>,
    pub metrics: Option<serde_json::Value>,
    pub images: Vec<PageImage>,
    pub videos: Vec<PageVideo>,
    /// Things the page should tell the user (a missing camera file, ...).
    pub notes: Vec<String>,
}

/// A mesh as flat little-endian arrays: `u32 vertices, u32 faces, u32 has_colors`, then
/// `f32` positions (3 per vertex), `f32` colours (3 per vertex, when present) and `u32`
/// indices (3 per face).
pub struct MeshBuffers(pub Vec<u8>);

/// A run, ready to serve.
pub struct Run {
    pub manifest: Manifest,
    /// Files the page may fetch, by index (`GET /files/{index}`).
    pub files: Vec<PathBuf>,
    pub mesh: Option<MeshBuffers>,
}

/// How to open a run.
#[derive(Clone, Debug, Default)]
pub struct OpenOptions {
    /// The dataset the run was trained on, to read its cameras from when the run has no
    /// `cameras.json` (runs from before it was written): the views `config.json` names, their
    /// intrinsics resized to the run's image size.
    pub data: Option<PathBuf>,
    /// How to load that dataset (format, downscale, lens handling).
    pub load: LoadOptions,
}

/// Defaults of `fewview_splat::raster::RenderSettings` for runs that lack a `config.json`.
const DEFAULT_NEAR_PLANE: f64 = 0.2;

impl Run {
    /// A lone Gaussian PLY, drawn over black.
    pub fn from_ply(path: &Path) -> Result<Self> {
        let layout = check_gaussian_ply(path)?;
        let mut run = Run::empty(RunKind::Ply, display_name(path));
        let url = run.add_file(path.to_path_buf());
        run.manifest.model = Some(PageModel { url, layout });
        Ok(run)
    }

    /// The run in `dir`, its kind detected from its files.
    pub fn open(dir: &Path) -> Result<Self> {
        Self::open_with(dir, &OpenOptions::default())
    }

    /// [`Run::open`], with the cameras of a run without `cameras.json` read from a dataset.
    pub fn open_with(dir: &Path, opts: &OpenOptions) -> Result<Self> {
        let meta = std::fs::metadata(dir).map_err(|e| ViewError::io(dir, e))?;
        if !meta.is_dir() {
            return Err(ViewError::format(
                dir,
                "is a file, not a run directory (use --ply FILE for a Gaussian PLY)",
            ));
        }
        if dir.join("point_cloud.ply").is_file() {
            Self::open_splat(dir, opts)
        } else if opts.data.is_some() {
            Err(ViewError::format(
                dir,
                "--data reads the cameras of a train, demo or fusion run (no point_cloud.ply here)",
            ))
        } else if dir.join("mesh.ply").is_file() {
            Self::open_surface(dir)
        } else if dir.join("poses_report.json").is_file() {
            Self::open_poses(dir)
        } else {
            Err(ViewError::format(
                dir,
                "not a run directory: no point_cloud.ply (train, demo, fusion), mesh.ply \
                 (surface) or poses_report.json (poses)",
            ))
        }
    }

    fn empty(kind: RunKind, title: String) -> Self {
        Run {
            manifest: Manifest {
                kind,
                title,
                model: None,
                has_mesh: false,
                background: [0.0; 3],
                near_plane: DEFAULT_NEAR_PLANE,
                cameras: Vec::new(),
                metrics: None,
                images: Vec::new(),
                videos: Vec::new(),
                notes: Vec::new(),
            },
            files: Vec::new(),
            mesh: None,
        }
    }

    fn add_file(&mut self, path: PathBuf) -> String {
        self.files.push(path);
        format!("/files/{}", self.files.len() - 1)
    }

    fn open_splat(dir: &Path, opts: &OpenOptions) -> Result<Self> {
        let ply = dir.join("point_cloud.ply");
        let layout = check_gaussian_ply(&ply)?;
        let mut run = Run::empty(RunKind::Splat, display_name(dir));
        let url = run.add_file(ply);
        run.manifest.model = Some(PageModel { url, layout });
        let config = read_json(&dir.join("config.json"))?;
        let (mut train, mut test) = (Vec::new(), Vec::new());
        match &config {
            Some(c) => {
                if let Some(bg) = c["run"]["train"]["background"].as_array() {
                    for (k, v) in bg.iter().take(3).enumerate() {
                        run.manifest.background[k] = v.as_f64().unwrap_or(0.0) as f32;
                    }
                }
                if let Some(near) = c["run"]["train"]["near_plane"].as_f64() {
                    run.manifest.near_plane = near;
                }
                let names = |key: &str| -> Vec<String> {
                    c[key]
                        .as_array()
                        .map(|a| {
                            a.iter()
                                .filter_map(|v| v.as_str().map(str::to_string))
                                .collect()
                        })
                        .unwrap_or_default()
                };
                train = names("train_views");
                test = names("test_views");
            }
            None => run
                .manifest
                .notes
                .push("no config.json: drawn over black".into()),
        }
        let cams_path = dir.join("cameras.json");
        let cams = if cams_path.is_file() {
            if opts.data.is_some() {
                run.manifest
                    .notes
                    .push("cameras from the run's cameras.json (--data not needed)".into());
            }
            Some(fewview_geom::io::cameras::read_cameras(&cams_path)?)
        } else if let Some(data) = &opts.data {
            let config = config.as_ref().ok_or_else(|| {
                ViewError::format(
                    dir.join("config.json"),
                    "missing: --data needs it to know which views the run used",
                )
            })?;
            run.manifest
                .notes
                .push(format!("cameras from the dataset {}", data.display()));
            Some(dataset_cameras(config, &train, &test, data, &opts.load)?)
        } else {
            run.manifest.notes.push(
                "no cameras.json (a run from before it was written): no camera frusta; \
                 `fewview view RUN_DIR --data DATASET` reads them from the dataset"
                    .into(),
            );
            None
        };
        if let Some(cams) = cams {
            for (i, c) in cams.iter().enumerate() {
                let (name, group) = if i < train.len() {
                    (train[i].clone(), "train")
                } else if i - train.len() < test.len() {
                    (test[i - train.len()].clone(), "test")
                } else {
                    (format!("camera_{i}"), "train")
                };
                run.manifest.cameras.push(PageCamera::new(name, group, c));
            }
        }
        run.manifest.metrics = read_json(&dir.join("metrics.json"))?;
        let truth_dir = dir.join("ground_truth");
        for render in pngs(&dir.join("renders").join("test"))? {
            let name = stem(&render);
            let truth = truth_dir.join(format!("{name}.png"));
            let truth = truth.is_file().then(|| run.add_file(truth));
            let render = run.add_file(render);
            run.manifest.images.push(PageImage {
                name,
                render,
                truth,
            });
        }
        run.add_videos(dir)?;
        Ok(run)
    }

    fn open_surface(dir: &Path) -> Result<Self> {
        let mut run = Run::empty(RunKind::Surface, display_name(dir));
        let mesh = fewview_geom::io::read_mesh(&dir.join("mesh.ply"))?;
        run.mesh = Some(mesh_buffers(&mesh));
        run.manifest.has_mesh = true;
        for (file, group) in [
            ("poses_initial.json", "initial"),
            ("poses_refined.json", "refined"),
        ] {
            let path = dir.join(file);
            if path.is_file() {
                let cams = fewview_geom::io::cameras::read_cameras(&path)?;
                for (i, c) in cams.iter().enumerate() {
                    run.manifest
                        .cameras
                        .push(PageCamera::new(format!("{group} {i}"), group, c));
                }
            } else {
                run.manifest.notes.push(format!("no {file}"));
            }
        }
        run.manifest.metrics = read_json(&dir.join("metrics.json"))?;
        for render in pngs(&dir.join("renders"))? {
            let name = stem(&render);
            let render = run.add_file(render);
            run.manifest.images.push(PageImage {
                name,
                render,
                truth: None,
            });
        }
        run.add_videos(dir)?;
        Ok(run)
    }

    /// The output of `fewview poses`: its cameras, its points as a mesh without faces, its
    /// report as the metrics and its picture of the cameras from above.
    fn open_poses(dir: &Path) -> Result<Self> {
        let mut run = Run::empty(RunKind::Poses, display_name(dir));
        let cams = fewview_geom::io::cameras::read_named_cameras(&dir.join("cameras.json"))?;
        for (i, (c, name)) in cams.iter().enumerate() {
            let name = name.clone().unwrap_or_else(|| format!("camera {i}"));
            run.manifest
                .cameras
                .push(PageCamera::new(name, "estimated", c));
        }
        let model = dir.join("sparse").join("0");
        match fewview_scene::colmap::read_points_in(&model)? {
            Some(points) => {
                let cloud = fewview_geom::Mesh {
                    vertices: points.iter().map(|p| p.xyz.map(|v| v as f32)).collect(),
                    faces: Vec::new(),
                    colors: Some(
                        points
                            .iter()
                            .map(|p| p.rgb.map(|c| f32::from(c) / 255.0))
                            .collect(),
                    ),
                    normals: None,
                };
                run.mesh = Some(mesh_buffers(&cloud));
                run.manifest.has_mesh = true;
            }
            None => run.manifest.notes.push("no sparse/0/points3D".into()),
        }
        run.manifest.metrics = read_json(&dir.join("poses_report.json"))?;
        let picture = dir.join("cameras.png");
        if picture.is_file() {
            let render = run.add_file(picture);
            run.manifest.images.push(PageImage {
                name: "cameras and points from above".into(),
                render,
                truth: None,
            });
        }
        Ok(run)
    }

    fn add_videos(&mut self, dir: &Path) -> Result<()> {
        for path in files_with(dir, &["mp4", "gif", "webm"])? {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let url = self.add_file(path);
            self.manifest.videos.push(PageVideo { name, url });
        }
        Ok(())
    }
}

/// The cameras of the views `train` then `test` (names from the run's `config.json`) in the
/// dataset at `data`, resized by the factor between the run's image size (`config.json`'s
/// `width`, `height`: its first training view's) and the dataset's first training view.
fn dataset_cameras(
    config: &serde_json::Value,
    train: &[String],
    test: &[String],
    data: &Path,
    load: &LoadOptions,
) -> Result<Vec<Camera>> {
    let names: Vec<&String> = train.iter().chain(test).collect();
    let Some(first) = names.first() else {
        return Err(ViewError::format(
            data,
            "the run's config.json names no views to look up in the dataset",
        ));
    };
    let ds = fewview_scene::load_dataset(data, load)?;
    let find = |name: &str| {
        ds.views
            .iter()
            .find(|v| v.name == name)
            .map(|v| &v.camera)
            .ok_or_else(|| {
                ViewError::format(
                    data,
                    format!(
                        "has no view `{name}`, which the run's config.json names (another dataset?)"
                    ),
                )
            })
    };
    let scale = match config["width"].as_f64() {
        Some(w) if w > 0.0 => w / f64::from(find(first)?.width()),
        _ => 1.0,
    };
    names
        .iter()
        .map(|name| {
            let c = find(name)?;
            let size = |n: u32| ((f64::from(n) * scale).round() as u32).max(1);
            Ok(if scale == 1.0 {
                c.clone()
            } else {
                c.resized(size(c.width()), size(c.height()))
            })
        })
        .collect()
}

fn display_name(path: &Path) -> String {
    std::fs::canonicalize(path)
        .unwrap_or_else(|_| path.to_path_buf())
        .display()
        .to_string()
}

use fewview_scene::file_stem as stem;

/// The JSON in `path`, or `None` when there is no such file.
fn read_json(path: &Path) -> Result<Option<serde_json::Value>> {
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|e| ViewError::io(path, e))?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| ViewError::format(path, format!("not JSON: {e}")))
}

/// The files in `dir` (not recursive) with one of `exts`, sorted; none when `dir` is absent.
fn files_with(dir: &Path, exts: &[&str]) -> Result<Vec<PathBuf>> {
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| ViewError::io(dir, e))? {
        let path = entry.map_err(|e| ViewError::io(dir, e))?.path();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        if path.is_file() && exts.contains(&ext.as_str()) {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

fn pngs(dir: &Path) -> Result<Vec<PathBuf>> {
    files_with(dir, &["png"])
}

fn mesh_buffers(mesh: &fewview_geom::Mesh) -> MeshBuffers {
    let mut b = Vec::new();
    let colors = mesh
        .colors
        .as_ref()
        .filter(|c| c.len() == mesh.vertices.len());
    for v in [
        mesh.vertices.len() as u32,
        mesh.faces.len() as u32,
        colors.is_some() as u32,
    ] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for p in &mesh.vertices {
        for x in p {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    if let Some(colors) = colors {
        for c in colors {
            for x in c {
                b.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    for f in &mesh.faces {
        for i in f {
            b.extend_from_slice(&i.to_le_bytes());
        }
    }
    MeshBuffers(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_or_foreign_folder_is_a_one_line_error() {
        let dir = tempfile::tempdir().unwrap();
        let e = Run::open(&dir.path().join("nope"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("nope") && !e.contains('\n'), "{e}");
        let e = Run::open(dir.path()).err().unwrap().to_string();
        assert!(e.contains("not a run directory"), "{e}");
    }

    #[test]
    fn a_surface_run_serves_its_mesh_and_both_pose_sets() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = fewview_geom::Mesh {
            vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            faces: vec![[0, 1, 2]],
            colors: None,
            normals: None,
        };
        fewview_geom::io::write_mesh(&dir.path().join("mesh.ply"), &mesh).unwrap();
        let cam = Camera::look_at(
            fewview_scene::Intrinsics::centered(50.0, 64, 48),
            nalgebra::Vector3::new(0.0, -3.0, 1.0),
            nalgebra::Vector3::zeros(),
            nalgebra::Vector3::z(),
        );
        for f in ["poses_initial.json", "poses_refined.json"] {
            fewview_geom::io::cameras::write_cameras(
                &dir.path().join(f),
                std::slice::from_ref(&cam),
            )
            .unwrap();
        }
        let run = Run::open(dir.path()).unwrap();
        assert_eq!(run.manifest.kind, RunKind::Surface);
        let groups: Vec<_> = run.manifest.cameras.iter().map(|c| c.group).collect();
        assert_eq!(groups, ["initial", "refined"]);
        let b = &run.mesh.unwrap().0;
        assert_eq!(b.len(), 12 + 9 * 4 + 3 * 4);
    }

    #[test]
    fn a_poses_folder_serves_its_named_cameras_and_points() {
        let dir = tempfile::tempdir().unwrap();
        let cam = Camera::look_at(
            fewview_scene::Intrinsics::centered(50.0, 64, 48),
            nalgebra::Vector3::new(0.0, -3.0, 1.0),
            nalgebra::Vector3::zeros(),
            nalgebra::Vector3::z(),
        );
        let path = dir.path().join("cameras.json");
        fewview_geom::io::cameras::write_cameras(&path, &[cam.clone(), cam]).unwrap();
        let mut named: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        named[0]["name"] = "a.jpg".into();
        std::fs::write(&path, named.to_string()).unwrap();
        let model = dir.path().join("sparse").join("0");
        std::fs::create_dir_all(&model).unwrap();
        std::fs::write(
            model.join("points3D.txt"),
            "# one point\n1 0.5 -0.25 2 255 0 51 0.3 1 3 2 7\n",
        )
        .unwrap();
        std::fs::write(dir.path().join("poses_report.json"), r#"{"registered": 2}"#).unwrap();
        let run = Run::open(dir.path()).unwrap();
        assert_eq!(run.manifest.kind, RunKind::Poses);
        let cameras: Vec<_> = run
            .manifest
            .cameras
            .iter()
            .map(|c| (c.name.as_str(), c.group))
            .collect();
        assert_eq!(cameras, [("a.jpg", "estimated"), ("camera 1", "estimated")]);
        assert_eq!(run.manifest.metrics.unwrap()["registered"], 2);
        // One vertex, no faces, colours: the header, its position and its colour.
        let b = &run.mesh.unwrap().0;
        let words: Vec<u32> = b[..12]
            .chunks(4)
            .map(|w| u32::from_le_bytes(w.try_into().unwrap()))
            .collect();
        assert_eq!(words, [1, 0, 1]);
        let floats: Vec<f32> = b[12..]
            .chunks(4)
            .map(|w| f32::from_le_bytes(w.try_into().unwrap()))
            .collect();
        assert_eq!(floats, [0.5, -0.25, 2.0, 1.0, 0.0, 0.2]);
    }
}
