//! Video files for novel-view renders and for evaluating rendered sequences: write what common
//! players open, read what users hand us.
//!
//! | path | container | written as | read |
//! |---|---|---|---|
//! | `*.mp4` | MP4 | H.264, yuv420p, BT.709 limited range (signalled), OpenH264 encoder | H.264 8-bit 4:2:0 of any profile OpenH264 decodes |
//! | `*.gif` | GIF89a | looping animation, a NeuQuant palette per frame, no dithering | any GIF, disposal and transparency applied |
//! | no extension, trailing `/`, or an existing folder | frame folder | `frame_00000.png`, ... + `video.json` (frame rate) | every PNG/JPEG, in natural order |
//!
//! Frames are [`Image`]s: `f32` sR'G'B' in `[0, 1]`, H×W×C. Writing takes RGB or grey frames,
//! clamps values to `[0, 1]` and rejects NaN/∞; **RGBA frames are rejected** (a video has no
//! alpha, and which background to composite over is the caller's decision: use
//! [`Image::composite_over`]). Reading always returns RGB; alpha in GIF or PNG input is
//! composited over [`ReadOptions::background`] (white by default, the NeRF-synthetic
//! evaluation convention).
//!
//! H.264 4:2:0 needs even width and height: odd sizes are **padded by repeating the last
//! row/column** by default, so no rendered pixel is lost and the decoded video is one pixel
//! larger ([`OddSizePolicy::PadEdge`]); [`OddSizePolicy::Crop`] drops the last row/column
//! instead. GIF and frame folders keep any size.
//!
//! Every output is written atomically (temporary file or folder beside it, then rename).

mod color;
mod frames;
mod gif;
mod mp4_h264;
mod options;
#[cfg(test)]
mod tests;

use std::path::Path;

use fewview_scene::Image;
use fewview_scene::error::{Result, SceneError};

pub use frames::DEFAULT_FOLDER_FPS;
pub use gif::MAX_GIF_FPS;
pub use mp4_h264::MAX_MP4_FPS;
pub use options::{DEFAULT_QP, H264Quality, OddSizePolicy, ReadOptions, VideoOptions};

/// The video container a path names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Container {
    /// `.mp4`: H.264 in an ISO base-media file.
    Mp4,
    /// `.gif`: an animated GIF.
    Gif,
    /// A folder of numbered PNG (written) or PNG/JPEG (read) frames.
    FrameFolder,
}

impl Container {
    /// The container `path` names: a path ending in `/` or without an extension is a frame
    /// folder; otherwise the (case-insensitive) extension decides. Looks only at the name
    /// ([`read_video`] also takes any existing folder as a frame folder).
    pub fn for_path(path: &Path) -> Result<Self> {
        let text = path.as_os_str().to_string_lossy();
        if text.ends_with('/') || text.ends_with(std::path::MAIN_SEPARATOR) {
            return Ok(Container::FrameFolder);
        }
        match path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
        {
            None => Ok(Container::FrameFolder),
            Some(ext) if ext == "mp4" => Ok(Container::Mp4),
            Some(ext) if ext == "gif" => Ok(Container::Gif),
            Some(ext) => Err(SceneError::invalid(
                path,
                format!(
                    "unsupported video container '.{ext}' (use .mp4, .gif, or a folder of frames)"
                ),
            )),
        }
    }
}

/// Checks the frames and frame rate and returns the frames as RGB.
fn validated_rgb(path: &Path, frames: &[Image], fps: f32) -> Result<Vec<Image>> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(SceneError::invalid(
            path,
            format!("frame rate {fps} is not a positive number"),
        ));
    }
    let Some(first) = frames.first() else {
        return Err(SceneError::invalid(path, "no frames to write"));
    };
    if first.width == 0 || first.height == 0 {
        return Err(SceneError::invalid(path, "frames are empty (0 pixels)"));
    }
    let mut rgb = Vec::with_capacity(frames.len());
    for (index, frame) in frames.iter().enumerate() {
        if (frame.width, frame.height) != (first.width, first.height) {
            return Err(SceneError::invalid(
                path,
                format!(
                    "frame {index} is {}x{} but frame 0 is {}x{}",
                    frame.width, frame.height, first.width, first.height
                ),
            ));
        }
        if frame.data.len() != frame.width * frame.height * frame.channels {
            return Err(SceneError::invalid(
                path,
                format!("frame {index} has a malformed buffer"),
            ));
        }
        if !frame.is_finite() {
            return Err(SceneError::invalid(
                path,
                format!("frame {index} contains NaN or infinity"),
            ));
        }
        rgb.push(match frame.channels {
            3 => frame.clone(),
            1 => {
                let data = frame.data.iter().flat_map(|&v| [v, v, v]).collect();
                Image::from_vec(frame.width, frame.height, 3, data)
            }
            4 => {
                return Err(SceneError::invalid(
                    path,
                    format!(
                        "frame {index} is RGBA: videos carry no alpha, composite it first (Image::composite_over)"
                    ),
                ));
            }
            c => {
                return Err(SceneError::invalid(
                    path,
                    format!("frame {index} has {c} channels (expected RGB or grey)"),
                ));
            }
        });
    }
    Ok(rgb)
}

/// Writes `frames` at `fps` frames per second as the container [`Container::for_path`] picks
/// for `path` (`.mp4`, `.gif`, or a frame folder), atomically.
pub fn write_video(path: &Path, frames: &[Image], fps: f32, opts: &VideoOptions) -> Result<()> {
    let container = Container::for_path(path)?;
    let rgb = validated_rgb(path, frames, fps)?;
    match container {
        Container::Mp4 => mp4_h264::write_mp4(path, &rgb, fps, opts),
        Container::Gif => gif::write_gif(path, &rgb, fps, opts.gif_speed),
        Container::FrameFolder => frames::write_frames(path, &rgb, fps),
    }
}

/// Reads the video at `path` as RGB frames and its frame rate, with default [`ReadOptions`].
pub fn read_video(path: &Path) -> Result<(Vec<Image>, f32)> {
    read_video_with(path, &ReadOptions::default())
}

/// Reads the video at `path` (`.mp4`, `.gif`, or a folder of PNG/JPEG frames, which may be
/// any existing folder) as RGB frames and its frame rate in frames per second (for a
/// variable-frame-rate file, its mean rate).
pub fn read_video_with(path: &Path, opts: &ReadOptions) -> Result<(Vec<Image>, f32)> {
    let container = if path.is_dir() {
        Container::FrameFolder
    } else {
        Container::for_path(path)?
    };
    match container {
        Container::Mp4 => mp4_h264::read_mp4(path),
        Container::Gif => gif::read_gif(path, opts.background),
        Container::FrameFolder => frames::read_frames(path, opts.background),
    }
}
