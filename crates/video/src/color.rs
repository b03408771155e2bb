//! RGB ↔ Y'CbCr 4:2:0 conversion (ITU-R BT.601 / BT.709 / BT.2020 matrices, limited or full
//! range), done here in `f32` rather than by the codec library so that the matrix we write is
//! the matrix we signal in the H.264 VUI, and the matrix we read is the one the stream declares.
//!
//! Chroma siting follows H.264's default `chroma_sample_loc_type = 0` (ITU-T H.264 Annex E,
//! Figure E-1; the MPEG-2 convention): a chroma sample sits horizontally on the even luma
//! column and vertically half-way between the two luma rows. Downsampling therefore averages
//! the two rows and filters columns with the `[1, 2, 1] / 4` kernel centred on the even column;
//! upsampling interpolates bilinearly from those same positions.

use rayon::prelude::*;

use fewview_scene::Image;

/// Which Y'CbCr matrix converts R'G'B' to luma/chroma (ITU-T H.264 Table E-5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Matrix {
    /// Kr = 0.299, Kb = 0.114 (`matrix_coefficients` 5 and 6).
    Bt601,
    /// Kr = 0.2126, Kb = 0.0722 (`matrix_coefficients` 1).
    Bt709,
    /// Kr = 0.2627, Kb = 0.0593 (`matrix_coefficients` 9, non-constant luminance).
    Bt2020,
}

impl Matrix {
    /// `(Kr, Kb)` of the matrix.
    fn weights(self) -> (f32, f32) {
        match self {
            Matrix::Bt601 => (0.299, 0.114),
            Matrix::Bt709 => (0.2126, 0.0722),
            Matrix::Bt2020 => (0.2627, 0.0593),
        }
    }
}

/// A Y'CbCr flavour: matrix plus quantisation range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct YuvFormat {
    pub matrix: Matrix,
    /// `true`: Y' and C in 0..=255; `false` ("TV"/limited range): Y' in 16..=235, C in 16..=240.
    pub full_range: bool,
}

impl YuvFormat {
    /// What we write: BT.709 limited range, the HD default every player assumes and honours.
    pub const WRITE: YuvFormat = YuvFormat {
        matrix: Matrix::Bt709,
        full_range: false,
    };

    /// `(y_offset, y_scale, c_scale)` of the 8-bit quantisation.
    fn quantisation(self) -> (f32, f32, f32) {
        if self.full_range {
            (0.0, 255.0, 255.0)
        } else {
            (16.0, 219.0, 224.0)
        }
    }

    /// Y', Cb, Cr (8-bit code values, unrounded) of one R'G'B' triple in `[0, 1]`.
    #[inline]
    fn encode(self, r: f32, g: f32, b: f32) -> [f32; 3] {
        let (kr, kb) = self.matrix.weights();
        let kg = 1.0 - kr - kb;
        let (off, ys, cs) = self.quantisation();
        let y = kr * r + kg * g + kb * b;
        let pb = (b - y) / (2.0 * (1.0 - kb));
        let pr = (r - y) / (2.0 * (1.0 - kr));
        [off + ys * y, 128.0 + cs * pb, 128.0 + cs * pr]
    }

    /// R'G'B' (unclamped) of 8-bit Y', Cb, Cr code values.
    #[inline]
    fn decode(self, y: f32, cb: f32, cr: f32) -> [f32; 3] {
        let (kr, kb) = self.matrix.weights();
        let kg = 1.0 - kr - kb;
        let (off, ys, cs) = self.quantisation();
        let y = (y - off) / ys;
        let pb = (cb - 128.0) / cs;
        let pr = (cr - 128.0) / cs;
        let r = y + 2.0 * (1.0 - kr) * pr;
        let b = y + 2.0 * (1.0 - kb) * pb;
        let g = (y - kr * r - kb * b) / kg;
        [r, g, b]
    }
}

/// 8-bit planar Y'CbCr 4:2:0 with even width and height, planes tightly packed (I420 order).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Yuv420 {
    pub width: usize,
    pub height: usize,
    pub y: Vec<u8>,
    pub u: Vec<u8>,
    pub v: Vec<u8>,
}

impl Yuv420 {
    /// The planes concatenated as I420 (`Y`, then `U`, then `V`).
    pub fn to_i420(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.y.len() + self.u.len() + self.v.len());
        out.extend_from_slice(&self.y);
        out.extend_from_slice(&self.u);
        out.extend_from_slice(&self.v);
        out
    }

    /// Copies planes that may carry row padding (`strides` in bytes for Y, U, V).
    pub fn from_strided(
        (width, height): (usize, usize),
        (y, u, v): (&[u8], &[u8], &[u8]),
        (sy, su, sv): (usize, usize, usize),
    ) -> Self {
        let (cw, ch) = (width.div_ceil(2), height.div_ceil(2));
        let copy = |plane: &[u8], stride: usize, w: usize, h: usize| -> Vec<u8> {
            let mut out = Vec::with_capacity(w * h);
            for row in 0..h {
                out.extend_from_slice(&plane[row * stride..row * stride + w]);
            }
            out
        };
        Self {
            width,
            height,
            y: copy(y, sy, width, height),
            u: copy(u, su, cw, ch),
            v: copy(v, sv, cw, ch),
        }
    }
}

#[inline]
fn to_code(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// Converts an RGB image with even width and height to Y'CbCr 4:2:0.
///
/// Values outside `[0, 1]` are clamped first (renders overshoot slightly); the caller has
/// already rejected non-finite values.
pub(crate) fn rgb_to_yuv420(img: &Image, format: YuvFormat) -> Yuv420 {
    assert_eq!(img.channels, 3, "rgb_to_yuv420 takes RGB");
    let (w, h) = (img.width, img.height);
    assert!(w % 2 == 0 && h % 2 == 0, "4:2:0 needs even dimensions");
    let rgb = |x: usize, y: usize| -> [f32; 3] {
        let i = (y * w + x) * 3;
        [
            img.data[i].clamp(0.0, 1.0),
            img.data[i + 1].clamp(0.0, 1.0),
            img.data[i + 2].clamp(0.0, 1.0),
        ]
    };

    let mut luma = vec![0u8; w * h];
    luma.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let [r, g, b] = rgb(x, y);
            *out = to_code(format.encode(r, g, b)[0]);
        }
    });

    // Chroma at (2i, 2j + 0.5): [1, 2, 1] / 4 across columns 2i-1, 2i, 2i+1 (edge-clamped),
    // averaged over rows 2j and 2j+1. Filtering R'G'B' then converting equals converting then
    // filtering (the matrix is linear), and keeps one conversion per chroma sample.
    let (cw, ch) = (w / 2, h / 2);
    let mut chroma = vec![(0u8, 0u8); cw * ch];
    chroma.par_chunks_mut(cw).enumerate().for_each(|(j, row)| {
        for (i, out) in row.iter_mut().enumerate() {
            let x0 = 2 * i;
            let taps = [
                (x0.saturating_sub(1), 0.25),
                (x0, 0.5),
                ((x0 + 1).min(w - 1), 0.25),
            ];
            let mut acc = [0.0f32; 3];
            for y in [2 * j, 2 * j + 1] {
                for &(x, wt) in &taps {
                    let p = rgb(x, y);
                    for c in 0..3 {
                        acc[c] += 0.5 * wt * p[c];
                    }
                }
            }
            let [_, cb, cr] = format.encode(acc[0], acc[1], acc[2]);
            *out = (to_code(cb), to_code(cr));
        }
    });
    Yuv420 {
        width: w,
        height: h,
        y: luma,
        u: chroma.iter().map(|c| c.0).collect(),
        v: chroma.iter().map(|c| c.1).collect(),
    }
}

/// Converts Y'CbCr 4:2:0 to an RGB image in `[0, 1]` (clamped), upsampling chroma bilinearly
/// from the `chroma_sample_loc_type = 0` positions. Width and height may be odd (the chroma
/// planes then have `ceil(w / 2) × ceil(h / 2)` samples).
pub(crate) fn yuv420_to_rgb(yuv: &Yuv420, format: YuvFormat) -> Image {
    let (w, h) = (yuv.width, yuv.height);
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let chroma = |plane: &[u8], cx: f32, cy: f32| -> f32 {
        // Bilinear with edge clamping; (cx, cy) are in chroma-sample units.
        let cx = cx.clamp(0.0, (cw - 1) as f32);
        let cy = cy.clamp(0.0, (ch - 1) as f32);
        let (x0, y0) = (cx.floor() as usize, cy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(cw - 1), (y0 + 1).min(ch - 1));
        let (fx, fy) = (cx - x0 as f32, cy - y0 as f32);
        let at = |x: usize, y: usize| plane[y * cw + x] as f32;
        let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
        let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    };
    let mut out = Image::new(w, h, 3);
    out.data
        .par_chunks_mut(w * 3)
        .enumerate()
        .for_each(|(y, row)| {
            let cy = (y as f32 - 0.5) * 0.5;
            for x in 0..w {
                let cx = x as f32 * 0.5;
                let rgb = format.decode(
                    yuv.y[y * w + x] as f32,
                    chroma(&yuv.u, cx, cy),
                    chroma(&yuv.v, cx, cy),
                );
                for c in 0..3 {
                    row[x * 3 + c] = rgb[c].clamp(0.0, 1.0);
                }
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(rgb: [f32; 3]) -> Image {
        Image::filled(4, 2, &rgb)
    }

    /// Textbook 8-bit code values (ITU-R BT.709 / BT.601 limited range, 100 % colour bars).
    #[test]
    fn code_values_match_the_standards() {
        let cases = [
            (YuvFormat::WRITE, [1.0, 1.0, 1.0], [235, 128, 128]),
            (YuvFormat::WRITE, [0.0, 0.0, 0.0], [16, 128, 128]),
            (YuvFormat::WRITE, [1.0, 0.0, 0.0], [63, 102, 240]),
            (YuvFormat::WRITE, [0.0, 1.0, 0.0], [173, 42, 26]),
            (YuvFormat::WRITE, [0.0, 0.0, 1.0], [32, 240, 118]),
            (
                YuvFormat {
                    matrix: Matrix::Bt601,
                    full_range: false,
                },
                [1.0, 0.0, 0.0],
                [81, 90, 240],
            ),
            (
                YuvFormat {
                    matrix: Matrix::Bt601,
                    full_range: true,
                },
                [1.0, 1.0, 1.0],
                [255, 128, 128],
            ),
        ];
        for (format, rgb, expected) in cases {
            let yuv = rgb_to_yuv420(&flat(rgb), format);
            assert_eq!(
                [yuv.y[0], yuv.u[0], yuv.v[0]],
                expected,
                "{rgb:?} {format:?}"
            );
        }
    }

    #[test]
    fn flat_colours_round_trip_within_quantisation() {
        for matrix in [Matrix::Bt601, Matrix::Bt709, Matrix::Bt2020] {
            for full_range in [false, true] {
                let format = YuvFormat { matrix, full_range };
                for rgb in [[0.2, 0.5, 0.9], [1.0, 0.3, 0.0], [0.5, 0.5, 0.5]] {
                    let back = yuv420_to_rgb(&rgb_to_yuv420(&flat(rgb), format), format);
                    for p in back.data.chunks_exact(3) {
                        for c in 0..3 {
                            // One 8-bit step of Y' and of each C moves R'G'B' by at most ~1.6/219.
                            assert!(
                                (p[c] - rgb[c]).abs() < 2.0 / 219.0,
                                "{format:?} {rgb:?} {p:?}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// A horizontal ramp is reproduced exactly in chroma by the [1,2,1] filter plus bilinear
    /// upsampling (both are exact on linear functions away from the edges).
    #[test]
    fn chroma_siting_is_consistent_on_ramps() {
        let (w, h) = (32, 8);
        let mut img = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let t = x as f32 / (w - 1) as f32;
                img.set(x, y, 0, t);
                img.set(x, y, 1, 0.5);
                img.set(x, y, 2, 1.0 - t);
            }
        }
        let format = YuvFormat::WRITE;
        let back = yuv420_to_rgb(&rgb_to_yuv420(&img, format), format);
        for y in 0..h {
            for x in 2..w - 2 {
                for c in 0..3 {
                    let d = (back.get(x, y, c) - img.get(x, y, c)).abs();
                    assert!(d < 2.5 / 219.0, "({x},{y},{c}): {d}");
                }
            }
        }
    }
}
