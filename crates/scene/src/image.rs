//! `f32` images (sRGB in `[0, 1]`, H×W×C row-major) and their PNG/JPEG I/O.

use std::path::Path;

use crate::error::{Result, SceneError};

/// A float image, H×W×C row-major, values in `[0, 1]` for colour data.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl Image {
    pub fn new(width: usize, height: usize, channels: usize) -> Self {
        Self {
            width,
            height,
            channels,
            data: vec![0.0; width * height * channels],
        }
    }

    pub fn from_vec(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Self {
        assert_eq!(data.len(), width * height * channels, "image buffer size");
        Self {
            width,
            height,
            channels,
            data,
        }
    }

    /// This image divided by its largest value, so that its brightest pixel is white: the
    /// preview PNG of a depth map, whose units (scene units, millimetres) a PNG cannot hold. An
    /// image without a positive value comes back unchanged.
    pub fn scaled_to_unit_max(&self) -> Self {
        let max = self.data.iter().copied().fold(0.0f32, f32::max);
        let scale = if max > 0.0 && max.is_finite() {
            1.0 / max
        } else {
            1.0
        };
        let data = self.data.iter().map(|v| v * scale).collect();
        Self::from_vec(self.width, self.height, self.channels, data)
    }

    pub fn filled(width: usize, height: usize, value: &[f32]) -> Self {
        let mut data = Vec::with_capacity(width * height * value.len());
        for _ in 0..width * height {
            data.extend_from_slice(value);
        }
        Self::from_vec(width, height, value.len(), data)
    }

    #[inline]
    pub fn index(&self, x: usize, y: usize, c: usize) -> usize {
        (y * self.width + x) * self.channels + c
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize, c: usize) -> f32 {
        self.data[self.index(x, y, c)]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, c: usize, v: f32) {
        let i = self.index(x, y, c);
        self.data[i] = v;
    }

    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let i = self.index(x, y, 0);
        &self.data[i..i + self.channels]
    }

    pub fn num_pixels(&self) -> usize {
        self.width * self.height
    }

    /// The decoder of a PNG or JPEG file.
    fn decoder(path: &Path) -> Result<impl image::ImageDecoder> {
        image::ImageReader::open(path)
            .map_err(|e| SceneError::io(path, e))?
            .with_guessed_format()
            .map_err(|e| SceneError::io(path, e))?
            .into_decoder()
            .map_err(|e| SceneError::format(path, format!("cannot decode image: {e}")))
    }

    /// The width and height of an image file as [`Image::load`] returns it (after its EXIF
    /// orientation), read from the header alone.
    pub fn dimensions(path: &Path) -> Result<(usize, usize)> {
        use image::ImageDecoder;
        let mut decoder = Self::decoder(path)?;
        let (w, h) = decoder.dimensions();
        let turned = decoder.orientation().is_ok_and(|o| {
            use image::metadata::Orientation::*;
            matches!(o, Rotate90 | Rotate270 | Rotate90FlipH | Rotate270FlipH)
        });
        Ok(if turned {
            (h as usize, w as usize)
        } else {
            (w as usize, h as usize)
        })
    }

    /// Reads a PNG or JPEG (8 or 16 bit, grey/RGB/RGBA) into `[0, 1]` floats, keeping the
    /// alpha channel when the file has one, turned upright by its EXIF orientation (as a
    /// photo viewer shows it; phones store the sensor's pixels and the turn apart).
    pub fn load(path: &Path) -> Result<Self> {
        use image::ImageDecoder;
        let mut decoder = Self::decoder(path)?;
        let orientation = decoder
            .orientation()
            .unwrap_or(image::metadata::Orientation::NoTransforms);
        let mut img = image::DynamicImage::from_decoder(decoder)
            .map_err(|e| SceneError::format(path, format!("cannot decode image: {e}")))?;
        img.apply_orientation(orientation);
        let (w, h) = (img.width() as usize, img.height() as usize);
        let out = if img.color().has_alpha() {
            Self::from_vec(w, h, 4, img.into_rgba32f().into_raw())
        } else if img.color().channel_count() == 1 {
            Self::from_vec(w, h, 1, img.to_luma32f().into_raw())
        } else {
            Self::from_vec(w, h, 3, img.into_rgb32f().into_raw())
        };
        Ok(out)
    }

    /// The RGB image of an RGBA one composited over `background` (`rgb·a + bg·(1 − a)`);
    /// an RGB image is returned as is.
    pub fn composite_over(&self, background: [f32; 3]) -> Self {
        if self.channels != 4 {
            return self.clone();
        }
        let mut out = Self::new(self.width, self.height, 3);
        for (dst, src) in out.data.chunks_exact_mut(3).zip(self.data.chunks_exact(4)) {
            let a = src[3];
            for c in 0..3 {
                dst[c] = src[c] * a + background[c] * (1.0 - a);
            }
        }
        out
    }

    /// One channel as its own image.
    pub fn channel(&self, c: usize) -> Self {
        let data = self
            .data
            .chunks_exact(self.channels)
            .map(|p| p[c])
            .collect();
        Self::from_vec(self.width, self.height, 1, data)
    }

    /// Box-filter downscale by an integer factor (each output pixel averages a `k×k` block, as
    /// `cv2.INTER_AREA` does at integer factors). Trailing rows/columns that do not fill a block
    /// are dropped.
    pub fn downscale(&self, k: usize) -> Self {
        if k <= 1 {
            return self.clone();
        }
        let (w, h, ch) = (self.width / k, self.height / k, self.channels);
        let mut out = Self::new(w, h, ch);
        let norm = 1.0 / (k * k) as f32;
        for y in 0..h {
            for x in 0..w {
                for c in 0..ch {
                    let mut s = 0.0;
                    for dy in 0..k {
                        for dx in 0..k {
                            s += self.get(x * k + dx, y * k + dy, c);
                        }
                    }
                    out.set(x, y, c, s * norm);
                }
            }
        }
        out
    }

    /// Resamples to `width × height` with a Lanczos-3 filter (for non-integer factors).
    pub fn resize(&self, width: usize, height: usize) -> Self {
        if width == self.width && height == self.height {
            return self.clone();
        }
        let buf: image::ImageBuffer<image::Rgba<f32>, Vec<f32>> = {
            let mut rgba = Vec::with_capacity(self.num_pixels() * 4);
            for p in self.data.chunks_exact(self.channels) {
                rgba.extend((0..4).map(|c| p.get(c).copied().unwrap_or(1.0)));
            }
            image::ImageBuffer::from_raw(self.width as u32, self.height as u32, rgba)
                .expect("buffer size matches")
        };
        let r = image::imageops::resize(
            &buf,
            width as u32,
            height as u32,
            image::imageops::FilterType::Lanczos3,
        );
        let mut out = Self::new(width, height, self.channels);
        for (dst, src) in out.data.chunks_exact_mut(self.channels).zip(r.pixels()) {
            dst.copy_from_slice(&src.0[..self.channels]);
        }
        out
    }

    /// The `width × height` window whose top-left pixel is `(x, y)`, clipped to the image.
    pub fn crop(&self, x: usize, y: usize, width: usize, height: usize) -> Self {
        let (x, y) = (x.min(self.width), y.min(self.height));
        let (w, h) = (width.min(self.width - x), height.min(self.height - y));
        let mut out = Self::new(w, h, self.channels);
        for row in 0..h {
            let src = self.index(x, y + row, 0);
            let dst = out.index(0, row, 0);
            out.data[dst..dst + w * self.channels]
                .copy_from_slice(&self.data[src..src + w * self.channels]);
        }
        out
    }

    /// Whether every value is finite.
    pub fn is_finite(&self) -> bool {
        self.data.iter().all(|v| v.is_finite())
    }

    /// 8-bit quantisation (clamped, rounded) of 1, 3 or 4 channels.
    pub fn to_u8(&self) -> Vec<u8> {
        self.data
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect()
    }

    /// Writes a JPEG of quality 90 atomically (1 or 3 channels), for pictures a person looks
    /// at rather than data read back.
    pub fn save_jpeg(&self, path: &Path) -> Result<()> {
        let color = match self.channels {
            1 => image::ExtendedColorType::L8,
            3 => image::ExtendedColorType::Rgb8,
            c => {
                return Err(SceneError::invalid(
                    path,
                    format!("cannot write a {c}-channel image as JPEG"),
                ));
            }
        };
        let bytes = self.to_u8();
        crate::atomic::write_with(path, |file| {
            image::codecs::jpeg::JpegEncoder::new_with_quality(file, 90)
                .encode(&bytes, self.width as u32, self.height as u32, color)
                .map_err(std::io::Error::other)
        })
    }

    /// Writes an 8-bit PNG atomically (temporary file in the same folder, then rename), so a
    /// crash never leaves a half-written image.
    pub fn save_png(&self, path: &Path) -> Result<()> {
        let color = match self.channels {
            1 => image::ExtendedColorType::L8,
            3 => image::ExtendedColorType::Rgb8,
            4 => image::ExtendedColorType::Rgba8,
            c => {
                return Err(SceneError::invalid(
                    path,
                    format!("cannot write a {c}-channel image as PNG"),
                ));
            }
        };
        let bytes = self.to_u8();
        crate::atomic::write_with(path, |file| {
            image::write_buffer_with_format(
                file,
                &bytes,
                self.width as u32,
                self.height as u32,
                color,
                image::ImageFormat::Png,
            )
            .map_err(std::io::Error::other)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaling_to_unit_max_makes_the_largest_value_one() {
        let depth = Image::from_vec(3, 1, 1, vec![0.0, 2.5, 10.0]);
        assert_eq!(depth.scaled_to_unit_max().data, vec![0.0, 0.25, 1.0]);
        let empty = Image::from_vec(2, 1, 1, vec![0.0, -1.0]);
        assert_eq!(empty.scaled_to_unit_max().data, vec![0.0, -1.0]);
    }

    #[test]
    fn crop_copies_the_window_and_clips_at_the_border() {
        let img = Image::from_vec(4, 3, 1, (0..12).map(|v| v as f32).collect());
        assert_eq!(img.crop(1, 1, 2, 2).data, vec![5.0, 6.0, 9.0, 10.0]);
        let clipped = img.crop(3, 2, 5, 5);
        assert_eq!(
            (clipped.width, clipped.height, clipped.data),
            (1, 1, vec![11.0])
        );
    }

    #[test]
    fn png_roundtrip_is_exact_at_8_bits() {
        let dir = tempfile::tempdir().unwrap();
        let mut img = Image::new(5, 3, 3);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i * 17 % 256) as f32 / 255.0;
        }
        let path = dir.path().join("a.png");
        img.save_png(&path).unwrap();
        let back = Image::load(&path).unwrap();
        assert_eq!(back.channels, 3);
        for (a, b) in img.data.iter().zip(&back.data) {
            assert!((a - b).abs() < 1e-6);
        }
    }

    #[test]
    fn composite_and_downscale() {
        let img = Image::filled(4, 4, &[1.0, 0.0, 0.0, 0.25]);
        let c = img.composite_over([1.0, 1.0, 1.0]);
        assert_eq!(c.pixel(0, 0), &[1.0, 0.75, 0.75]);
        let mut g = Image::new(4, 2, 1);
        g.data = vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        let d = g.downscale(2);
        assert_eq!(d.data, vec![2.5, 4.5]);
    }

    /// A JPEG whose EXIF says "rotate 90° clockwise to view" (orientation 6) loads upright:
    /// a 4×2 photo with a white left column becomes 2×4 with a white top row.
    #[test]
    fn exif_orientation_is_applied() {
        let dir = tempfile::tempdir().unwrap();
        let mut img = Image::new(4, 2, 3);
        for y in 0..2 {
            for c in 0..3 {
                img.set(0, y, c, 1.0);
            }
        }
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 100)
            .encode(&img.to_u8(), 4, 2, image::ExtendedColorType::Rgb8)
            .unwrap();
        // APP1 "Exif\0\0" + little-endian TIFF with one IFD entry: 0x0112 SHORT 1 = 6.
        let mut tiff = b"II*\0\x08\0\0\0\x01\0".to_vec();
        tiff.extend_from_slice(&[0x12, 0x01, 3, 0, 1, 0, 0, 0, 6, 0, 0, 0, 0, 0, 0, 0]);
        let mut app1 = b"Exif\0\0".to_vec();
        app1.extend_from_slice(&tiff);
        let len = (app1.len() + 2) as u16;
        let mut bytes = jpeg[..2].to_vec();
        bytes.extend_from_slice(&[0xFF, 0xE1]);
        bytes.extend_from_slice(&len.to_be_bytes());
        bytes.extend_from_slice(&app1);
        bytes.extend_from_slice(&jpeg[2..]);
        let path = dir.path().join("turned.jpg");
        std::fs::write(&path, &bytes).unwrap();
        let back = Image::load(&path).unwrap();
        assert_eq!((back.width, back.height), (2, 4));
        assert_eq!(Image::dimensions(&path).unwrap(), (2, 4));
        assert!(
            back.get(0, 0, 0) > 0.9 && back.get(1, 0, 0) > 0.9,
            "top row white"
        );
        assert!(back.get(0, 3, 0) < 0.1, "bottom row dark");
    }

    /// 16-bit PNGs keep their precision; RGBA keeps its alpha.
    #[test]
    fn sixteen_bit_and_rgba_pngs_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("deep.png");
        let px: Vec<u16> = vec![1, 40000, 65535, 30000, 2, 3, 4, 5];
        let buf: image::ImageBuffer<image::Rgba<u16>, Vec<u16>> =
            image::ImageBuffer::from_raw(2, 1, px.clone()).unwrap();
        buf.save(&path).unwrap();
        let back = Image::load(&path).unwrap();
        assert_eq!((back.width, back.height, back.channels), (2, 1, 4));
        for (a, &b) in back.data.iter().zip(&px) {
            assert!((a - b as f32 / 65535.0).abs() < 1e-6, "{a} {b}");
        }
    }

    #[test]
    fn unreadable_file_names_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.png");
        std::fs::write(&path, b"not a png").unwrap();
        let err = Image::load(&path).unwrap_err().to_string();
        assert!(err.contains("bad.png"), "{err}");
    }
}
