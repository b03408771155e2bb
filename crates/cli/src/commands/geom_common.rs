//! Small helpers shared by the geometry subcommands (image/mask loading, JSON reports, number
//! lists).

use std::path::Path;

use anyhow::{Context, Result, bail};
use fewview_scene::Image;

/// Loads an image as RGB (alpha dropped, grey kept as one channel).
pub fn load_image(path: &Path) -> Result<Image> {
    let img = Image::load(path).with_context(|| format!("reading image {}", path.display()))?;
    Ok(if img.channels == 4 {
        let mut rgb = Image::new(img.width, img.height, 3);
        for (d, s) in rgb.data.chunks_exact_mut(3).zip(img.data.chunks_exact(4)) {
            d.copy_from_slice(&s[..3]);
        }
        rgb
    } else {
        img
    })
}

/// Loads a mask image: channel 0 above one half is valid.
pub fn load_mask(path: &Path) -> Result<(Vec<bool>, usize, usize)> {
    let img = Image::load(path).with_context(|| format!("reading mask {}", path.display()))?;
    Ok((
        fewview_geom::blend::mask_from_image(&img, 0.5),
        img.width,
        img.height,
    ))
}

/// Writes a JSON value atomically (pretty-printed).
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    fewview_scene::atomic::write_bytes(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Parses `n` comma-separated numbers.
pub fn numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .with_context(|| format!("{what}: '{s}' is not a comma-separated list of numbers"))?;
    if v.len() != N {
        bail!("{what}: expected {N} numbers, got {}", v.len());
    }
    let mut out = [0.0; N];
    out.copy_from_slice(&v);
    Ok(out)
}
