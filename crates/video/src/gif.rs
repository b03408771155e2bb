//! Animated `.gif`: the dependency-free format every browser plays. Each frame gets its own
//! 256-colour palette from NeuQuant (Dekker 1994, via the `gif`/`color_quant` crates), frames
//! quantised in parallel, without dithering so the error stays small and unstructured and the
//! file stays small; the animation loops forever. Reading goes through the `image` crate's
//! decoder, which applies each frame's disposal method and offset to the full canvas.
//!
//! GIF timing is whole centiseconds: a frame rate is written as the delay
//! `round(100 / fps)` cs, so 25, 20, 10 fps round-trip exactly and 30 fps reads back as
//! 100 / 3 ≈ 33.3 fps. Browsers play delays under 2 cs as 10 cs, so frame rates above 50 fps
//! are refused rather than silently slowed down.

use std::io::BufReader;
use std::path::Path;

use image::AnimationDecoder;
use image::codecs::gif::GifDecoder;
use rayon::prelude::*;

use fewview_scene::Image;
use fewview_scene::error::{Result, SceneError};

/// Fastest GIF frame rate browsers honour (a 2 cs delay).
pub const MAX_GIF_FPS: f32 = 50.0;
/// Frame rate browsers use for a GIF whose delays are all zero (they play 0 cs as 10 cs).
const ZERO_DELAY_FPS: f32 = 10.0;

/// The frame delay in centiseconds that plays `fps` most closely.
fn delay_centiseconds(path: &Path, fps: f32) -> Result<u16> {
    if fps > MAX_GIF_FPS {
        return Err(SceneError::invalid(
            path,
            format!(
                "GIF cannot play {fps} fps: browsers cap GIF animation at {MAX_GIF_FPS} fps (2 cs per frame)"
            ),
        ));
    }
    Ok((100.0 / fps).round().clamp(2.0, u16::MAX as f32) as u16)
}

/// Writes validated RGB `frames` as a looping animated GIF, atomically.
/// `speed` is NeuQuant's sampling factor, 1 (best palette) to 30 (fastest).
pub(crate) fn write_gif(path: &Path, frames: &[Image], fps: f32, speed: i32) -> Result<()> {
    let delay = delay_centiseconds(path, fps)?;
    let (w, h) = (frames[0].width, frames[0].height);
    let (Ok(w16), Ok(h16)) = (u16::try_from(w), u16::try_from(h)) else {
        return Err(SceneError::invalid(
            path,
            format!("{w}x{h} is too large for GIF (65535 max)"),
        ));
    };
    let speed = speed.clamp(1, 30);
    let quantised: Vec<::gif::Frame<'static>> = frames
        .par_iter()
        .map(|frame| {
            let mut f = ::gif::Frame::from_rgb_speed(w16, h16, &frame.to_u8(), speed);
            f.delay = delay;
            f
        })
        .collect();
    fewview_scene::atomic::write_with(path, |file| {
        let to_io = |e: ::gif::EncodingError| std::io::Error::other(e);
        let mut encoder = ::gif::Encoder::new(file, w16, h16, &[]).map_err(to_io)?;
        encoder.set_repeat(::gif::Repeat::Infinite).map_err(to_io)?;
        for frame in &quantised {
            encoder.write_frame(frame).map_err(to_io)?;
        }
        encoder.into_inner().map_err(to_io)?;
        Ok(())
    })
}

/// Reads an animated (or still) GIF as full-canvas RGB frames, with each frame's disposal
/// applied and transparency composited over `background`, and its mean frame rate.
pub(crate) fn read_gif(path: &Path, background: [f32; 3]) -> Result<(Vec<Image>, f32)> {
    let file = std::fs::File::open(path).map_err(|e| SceneError::io(path, e))?;
    let corrupt = |e: image::ImageError| SceneError::format(path, format!("corrupt GIF: {e}"));
    let decoder = GifDecoder::new(BufReader::new(file)).map_err(corrupt)?;
    let raw = decoder.into_frames().collect_frames().map_err(corrupt)?;
    if raw.is_empty() {
        return Err(SceneError::format(path, "GIF has no frames"));
    }
    let mut total_ms = 0.0f64;
    let mut frames = Vec::with_capacity(raw.len());
    for frame in raw {
        let (numer, denom) = frame.delay().numer_denom_ms();
        total_ms += numer as f64 / denom.max(1) as f64;
        let buffer = frame.into_buffer();
        let (w, h) = (buffer.width() as usize, buffer.height() as usize);
        let data = buffer
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 255.0)
            .collect();
        frames.push(Image::from_vec(w, h, 4, data).composite_over(background));
    }
    let fps = if total_ms > 0.0 {
        (frames.len() as f64 * 1000.0 / total_ms) as f32
    } else {
        ZERO_DELAY_FPS
    };
    Ok((frames, fps))
}
