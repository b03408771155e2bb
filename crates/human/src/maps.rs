//! Per-view rasters of a capture besides the colour image: binary masks and metric depth maps,
//! with their PNG readers, and the colour reader that makes every image 3-channel sRGB.
//!
//! Rasters are row-major, `width × height`; index `y * width + x` is the pixel whose centre is at
//! `(x + 0.5, y + 0.5)` in the crate's (fewview-scene's) pixel convention.

use std::path::Path;

use fewview_scene::Image;

use crate::error::{HumanError, Result};

/// A binary foreground mask.
#[derive(Clone, Debug, PartialEq)]
pub struct Mask {
    pub width: usize,
    pub height: usize,
    pub data: Vec<bool>,
}

impl Mask {
    pub fn new(width: usize, height: usize, data: Vec<bool>) -> Self {
        debug_assert_eq!(data.len(), width * height);
        Self {
            width,
            height,
            data,
        }
    }

    /// Whether pixel `(x, y)` is foreground; false outside the raster.
    pub fn get(&self, x: i64, y: i64) -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < self.width
            && (y as usize) < self.height
            && self.data[y as usize * self.width + x as usize]
    }

    /// Number of foreground pixels.
    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&m| m).count()
    }

    /// Reads an 8- or 16-bit grey (or colour, first channel) PNG; a pixel is foreground when its
    /// value is at least `threshold` (on the 8-bit scale).
    pub fn load(path: &Path, threshold: u8) -> Result<Self> {
        let img = decode(path)?;
        let grey = img.to_luma8();
        let (w, h) = (grey.width() as usize, grey.height() as usize);
        let data = grey
            .into_raw()
            .into_iter()
            .map(|v| v >= threshold)
            .collect();
        Ok(Self::new(w, h, data))
    }
}

/// A z-depth map (camera z of the surface through each pixel centre), metres; 0 = no surface.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl DepthMap {
    /// Depth at pixel `(x, y)`; 0 outside the raster.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        if x < self.width && y < self.height {
            self.data[y * self.width + x]
        } else {
            0.0
        }
    }

    /// Reads a 16-bit grey PNG of millimetres (0 = none) as metres. An 8-bit file is refused: it
    /// cannot hold millimetre depth, so it is not this format.
    pub fn load_millimetres(path: &Path) -> Result<Self> {
        let img = decode(path)?;
        let image::DynamicImage::ImageLuma16(grey) = img else {
            return Err(HumanError::format(
                path,
                format!(
                    "depth must be a 16-bit grey PNG of millimetres, found {:?}",
                    img.color()
                ),
            ));
        };
        let (w, h) = (grey.width() as usize, grey.height() as usize);
        let data = grey
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 1000.0)
            .collect();
        Ok(Self {
            width: w,
            height: h,
            data,
        })
    }
}

/// Reads a colour image as 3-channel sRGB in `[0, 1]`: grey is repeated, alpha composited over
/// black (the datasets' background).
pub fn load_rgb(path: &Path) -> Result<Image> {
    let img = Image::load(path)?;
    Ok(match img.channels {
        3 => img,
        1 => {
            let data = img.data.iter().flat_map(|&v| [v, v, v]).collect();
            Image::from_vec(img.width, img.height, 3, data)
        }
        _ => img.composite_over([0.0, 0.0, 0.0]),
    })
}

/// An error unless a raster read from `path` is `width × height`.
pub fn check_size(path: &Path, got: (usize, usize), want: (usize, usize)) -> Result<()> {
    if got != want {
        return Err(HumanError::invalid(
            path,
            format!(
                "{}×{} pixels, but the camera is {}×{}",
                got.0, got.1, want.0, want.1
            ),
        ));
    }
    Ok(())
}

fn decode(path: &Path) -> Result<image::DynamicImage> {
    image::ImageReader::open(path)
        .map_err(|e| HumanError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| HumanError::io(path, e))?
        .decode()
        .map_err(|e| HumanError::format(path, format!("cannot decode image: {e}")))
}
