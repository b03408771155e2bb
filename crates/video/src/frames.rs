//! A folder of numbered image frames, the format every tool can make and read.
//!
//! Written as `frame_00000.png`, `frame_00001.png`, ... (8-bit RGB PNG) plus `video.json`
//! holding the frame rate, since images carry none. Read back: every `.png`/`.jpg`/`.jpeg` in
//! the folder in natural order (`f2` before `f10`), the frame rate from `video.json` when it is
//! there and otherwise 25 fps, the default of FFmpeg's image-sequence reader. A `video.json`
//! whose frame count disagrees with the folder (frames added or deleted by hand) is an error
//! rather than a silently wrong timing.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use fewview_scene::Image;
use fewview_scene::error::{Result, SceneError};

/// Frame rate assumed for a folder without `video.json` (FFmpeg's `image2` demuxer default).
pub const DEFAULT_FOLDER_FPS: f32 = 25.0;
/// The sidecar that records the frame rate of a frame folder.
const SIDECAR: &str = "video.json";

#[derive(serde::Serialize, serde::Deserialize)]
struct Sidecar {
    fps: f32,
    frames: usize,
}

fn frame_name(index: usize) -> String {
    format!("frame_{index:05}.png")
}

/// Whether `name` is something this module writes into a frame folder.
fn is_our_output(name: &str) -> bool {
    name == SIDECAR
        || name
            .strip_prefix("frame_")
            .and_then(|r| r.strip_suffix(".png"))
            .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

/// Writes validated RGB `frames` into the folder `dir`.
///
/// The frames go to a temporary sibling folder first, which then replaces `dir` by rename, so
/// a reader never sees a half-written or mixed sequence. An existing `dir` is replaced only when
/// it holds nothing but an earlier output of this function (frames and `video.json`); anything
/// else in it is an error, so we never delete a user's files.
pub(crate) fn write_frames(dir: &Path, frames: &[Image], fps: f32) -> Result<()> {
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if dir.exists() {
        let entries = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
        for entry in entries {
            let entry = entry.map_err(|e| SceneError::io(dir, e))?;
            let name = entry.file_name();
            if !name.to_str().is_some_and(is_our_output) {
                return Err(SceneError::invalid(
                    dir,
                    format!(
                        "folder already holds {name:?}, which is not a frame of ours; refusing to replace it"
                    ),
                ));
            }
        }
    }
    std::fs::create_dir_all(&parent).map_err(|e| SceneError::io(&parent, e))?;
    let staging = tempfile::Builder::new()
        .prefix(".frames-")
        .tempdir_in(&parent)
        .map_err(|e| SceneError::io(dir, e))?;
    for (index, frame) in frames.iter().enumerate() {
        frame.save_png(&staging.path().join(frame_name(index)))?;
    }
    let sidecar = serde_json::to_vec_pretty(&Sidecar {
        fps,
        frames: frames.len(),
    })
    .expect("plain struct serialises");
    fewview_scene::atomic::write_bytes(&staging.path().join(SIDECAR), &sidecar)?;

    // `tempdir` creates 0700; a finished video folder should be as readable as `mkdir` makes it.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(staging.path(), std::fs::Permissions::from_mode(0o755))
            .map_err(|e| SceneError::io(dir, e))?;
    }
    let staged = staging.keep();
    swap_in(&staged, dir, &parent).map_err(|e| {
        let _ = std::fs::remove_dir_all(&staged);
        SceneError::io(dir, e)
    })
}

/// Moves the finished folder `staged` to `dir`, replacing an existing `dir` (already checked
/// to hold only our files) by two renames, so `dir` is never half-written.
fn swap_in(staged: &Path, dir: &Path, parent: &Path) -> std::io::Result<()> {
    if !dir.exists() {
        return std::fs::rename(staged, dir);
    }
    let old = tempfile::Builder::new()
        .prefix(".frames-old-")
        .tempdir_in(parent)?;
    // Rename onto the empty placeholder: POSIX lets a directory replace an empty one.
    std::fs::rename(dir, old.path())?;
    if let Err(e) = std::fs::rename(staged, dir) {
        let _ = std::fs::rename(old.path(), dir);
        return Err(e);
    }
    // Dropping `old` deletes the previous frames.
    old.close()
}

/// Compares file names the way people number frames: digit runs by value, the rest by byte.
pub(crate) fn natural_cmp(a: &str, b: &str) -> Ordering {
    fn runs(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let bytes = s.as_bytes();
        for i in 1..=bytes.len() {
            if i == bytes.len() || bytes[i].is_ascii_digit() != bytes[start].is_ascii_digit() {
                out.push((bytes[start].is_ascii_digit(), &s[start..i]));
                start = i;
            }
        }
        out
    }
    let (ra, rb) = (runs(a), runs(b));
    for ((da, sa), (db, sb)) in ra.iter().zip(&rb) {
        let ord = if *da && *db {
            // By value without overflow: strip leading zeros, then shorter is smaller.
            let (ta, tb) = (sa.trim_start_matches('0'), sb.trim_start_matches('0'));
            ta.len().cmp(&tb.len()).then_with(|| ta.cmp(tb))
        } else {
            sa.cmp(sb)
        };
        if ord != Ordering::Equal {
            return ord;
        }
    }
    ra.len().cmp(&rb.len()).then_with(|| a.cmp(b))
}

fn is_frame_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
}

/// Reads every PNG/JPEG frame of the folder `dir` in natural order as RGB (grey replicated,
/// alpha composited over `background`) and the folder's frame rate.
pub(crate) fn read_frames(dir: &Path, background: [f32; 3]) -> Result<(Vec<Image>, f32)> {
    let entries = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| SceneError::io(dir, e))?.path();
        if path.is_file() && is_frame_file(&path) {
            let name = path
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            files.push((name, path));
        }
    }
    if files.is_empty() {
        return Err(SceneError::format(
            dir,
            "folder holds no PNG or JPEG frames",
        ));
    }
    files.sort_by(|a, b| natural_cmp(&a.0, &b.0));

    let mut frames: Vec<Image> = Vec::with_capacity(files.len());
    for (_, path) in &files {
        let img = Image::load(path)?;
        let rgb = match img.channels {
            1 => {
                let data = img.data.iter().flat_map(|&v| [v, v, v]).collect();
                Image::from_vec(img.width, img.height, 3, data)
            }
            // `Image::load` gives grey+alpha as RGBA, so 4 covers every alpha case.
            4 => img.composite_over(background),
            _ => img,
        };
        if let Some(first) = frames.first()
            && (first.width, first.height) != (rgb.width, rgb.height)
        {
            return Err(SceneError::invalid(
                path,
                format!(
                    "frame is {}x{} but the first frame is {}x{}",
                    rgb.width, rgb.height, first.width, first.height
                ),
            ));
        }
        frames.push(rgb);
    }

    let sidecar_path = dir.join(SIDECAR);
    let fps = match std::fs::read(&sidecar_path) {
        Ok(bytes) => {
            let sidecar: Sidecar = serde_json::from_slice(&bytes).map_err(|e| {
                SceneError::format(&sidecar_path, format!("corrupt frame-rate sidecar: {e}"))
            })?;
            if sidecar.frames != frames.len() {
                return Err(SceneError::invalid(
                    &sidecar_path,
                    format!(
                        "records {} frames but the folder holds {} PNG/JPEG frames",
                        sidecar.frames,
                        frames.len()
                    ),
                ));
            }
            if !(sidecar.fps.is_finite() && sidecar.fps > 0.0) {
                return Err(SceneError::invalid(
                    &sidecar_path,
                    format!("frame rate {} is not a positive number", sidecar.fps),
                ));
            }
            sidecar.fps
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => DEFAULT_FOLDER_FPS,
        Err(e) => return Err(SceneError::io(&sidecar_path, e)),
    };
    Ok((frames, fps))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_compares_numbers_by_value() {
        let mut names = vec![
            "f10.png", "f2.png", "f1.png", "f02.png", "a.png", "f100.png", "f9x.png",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            vec![
                "a.png", "f1.png", "f02.png", "f2.png", "f9x.png", "f10.png", "f100.png"
            ]
        );
        assert_eq!(
            natural_cmp(
                "frame_99999999999999999999999",
                "frame_100000000000000000000000"
            ),
            Ordering::Less
        );
    }

    #[test]
    fn only_our_files_count_as_our_output() {
        assert!(is_our_output("frame_00012.png"));
        assert!(is_our_output("video.json"));
        assert!(!is_our_output("frame_.png"));
        assert!(!is_our_output("notes.txt"));
        assert!(!is_our_output("frame_0001.jpg"));
    }
}
