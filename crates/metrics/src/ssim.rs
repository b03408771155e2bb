//! Structural similarity (Wang et al. 2004, "Image quality assessment: from error visibility to
//! structural similarity", Eq. 13 with the Gaussian-weighted local statistics of their §III-C),
//! its mean over an image, and the exact gradient of that mean with respect to one image.
//!
//! Per channel and pixel `p`, with `G` the normalised Gaussian window (σ = 1.5, radius
//! `⌊3.5σ + 0.5⌋ = 5`, i.e. 11×11, applied separably):
//!
//! ```text
//! μx = G∗x   μy = G∗y   σx² = G∗x² − μx²   σy² = G∗y² − μy²   σxy = G∗(xy) − μx μy
//! S = (2 μx μy + C1)(2 σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2)),  C1 = (K1 L)², C2 = (K2 L)²
//! ```
//!
//! with `K1 = 0.01`, `K2 = 0.03`, data range `L = 1`, and population (not sample) covariances.
//! Two border conventions are offered ([`SsimBorder`]):
//!
//! * [`SsimBorder::ReflectCrop`] (default) is scikit-image's
//!   `structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
//!   data_range=1, channel_axis=-1)`: the filter extends the image by half-sample symmetric
//!   reflection (SciPy `mode='reflect'`, `d c b a | a b c d | d c b a`) and the mean is taken
//!   after cropping `radius` pixels from every border. This is the evaluation metric.
//! * [`SsimBorder::ZeroSame`] is the 3DGS training loss (`ssim()` in the Inria `loss_utils.py`):
//!   a zero-padded "same" convolution and the mean over every pixel.
//!
//! Colour images: the mean runs over channels × pixels, which equals scikit-image's mean of
//! per-channel means.
//!
//! ## Gradient
//! With `N = A1 A2`, `D = B1 B2` (`A1 = 2μxμy + C1`, `A2 = 2σxy + C2`, `B1 = μx² + μy² + C1`,
//! `B2 = σx² + σy² + C2`), the partial derivatives of `S` with respect to the three filtered
//! quantities that depend on `x` are
//!
//! ```text
//! ∂S/∂μx     = (2 μy (A2 − A1) − 2 μx S (B2 − B1)) / D
//! ∂S/∂(G∗x²) = −S / B2
//! ∂S/∂(G∗xy) = 2 A1 / D
//! ```
//!
//! and, writing `a, b, c` for these maps times the per-pixel weight of the mean,
//! `∂mean/∂x = Gᵀa + 2x·Gᵀb + y·Gᵀc`, where `Gᵀ` is the adjoint of the border-handled filter
//! (zero-padded correlation, then folding the padded positions back onto the pixels they were
//! reflected from). Everything is computed by the same generic code in `f32` (training) or `f64`
//! (finite-difference checks).

use fewview_scene::Image;
use num_traits::Float;
use rayon::prelude::*;

use crate::error::{MetricsError, Result, check_mask, check_same_shape};

/// How the Gaussian filter treats the image border and which pixels the mean covers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SsimBorder {
    /// scikit-image: reflect padding, mean over the image cropped by the window radius.
    #[default]
    ReflectCrop,
    /// Inria 3DGS loss: zero padding ("same" convolution), mean over all pixels.
    ZeroSame,
}

/// SSIM constants. The defaults are Wang et al.'s and scikit-image's.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SsimOptions {
    pub border: SsimBorder,
    /// Standard deviation of the Gaussian window in pixels (1.5).
    pub sigma: f64,
    pub k1: f64,
    pub k2: f64,
    /// Value range of the images (1 for `[0, 1]` data).
    pub data_range: f64,
}

impl Default for SsimOptions {
    fn default() -> Self {
        Self {
            border: SsimBorder::ReflectCrop,
            sigma: 1.5,
            k1: 0.01,
            k2: 0.03,
            data_range: 1.0,
        }
    }
}

impl SsimOptions {
    /// The 3DGS training-loss variant (zero padding, mean over all pixels).
    pub fn training_loss() -> Self {
        Self {
            border: SsimBorder::ZeroSame,
            ..Self::default()
        }
    }

    /// Window radius as scikit-image/SciPy choose it: `⌊3.5σ + 0.5⌋` (5 for σ = 1.5).
    pub fn radius(&self) -> usize {
        (3.5 * self.sigma + 0.5).floor() as usize
    }

    fn validate(&self) -> Result<()> {
        let ok = self.sigma.is_finite()
            && self.sigma > 0.0
            && self.k1.is_finite()
            && self.k1 > 0.0
            && self.k2.is_finite()
            && self.k2 > 0.0
            && self.data_range.is_finite()
            && self.data_range > 0.0;
        if ok {
            Ok(())
        } else {
            Err(MetricsError::invalid(
                "SSIM options must be finite and positive",
            ))
        }
    }
}

/// Mean SSIM of two images of the same shape with the default (scikit-image) options.
pub fn ssim(a: &Image, b: &Image) -> Result<f64> {
    ssim_with(a, b, &SsimOptions::default())
}

/// Mean SSIM with the given options.
pub fn ssim_with(a: &Image, b: &Image, opts: &SsimOptions) -> Result<f64> {
    check_same_shape(a, b)?;
    let (x, y) = (planar::<f32>(a), planar::<f32>(b));
    let shape = Shape {
        width: a.width,
        height: a.height,
        channels: a.channels,
    };
    Ok(ssim_planar(&x, &y, shape, opts, None, false)?.0)
}

/// Mean of the SSIM map over the pixels where `mask > 0.5` (1-channel, same size) and over
/// channels — the masked SSIM of DTU evaluations. With [`SsimBorder::ReflectCrop`] only masked
/// pixels inside the cropped interior count; with [`SsimBorder::ZeroSame`] all masked pixels do.
pub fn ssim_masked(a: &Image, b: &Image, mask: &Image, opts: &SsimOptions) -> Result<f64> {
    check_same_shape(a, b)?;
    check_mask(mask, a.width, a.height)?;
    let (x, y) = (planar::<f32>(a), planar::<f32>(b));
    let m: Vec<f32> = mask
        .data
        .iter()
        .map(|&v| if v > 0.5 { 1.0 } else { 0.0 })
        .collect();
    let shape = Shape {
        width: a.width,
        height: a.height,
        channels: a.channels,
    };
    Ok(ssim_planar(&x, &y, shape, opts, Some(&m), false)?.0)
}

/// Mean SSIM and its gradient with respect to `rendered` (H×W×C interleaved like the image),
/// in `f32` working precision with the mean accumulated in `f64`. The 3DGS loss term
/// `λ (1 − SSIM)` has gradient `−λ ·` this.
/// For repeated calls at one size, [`SsimWorkspace::value_and_grad`] avoids the allocations.
pub fn ssim_with_grad(
    rendered: &Image,
    target: &Image,
    opts: &SsimOptions,
) -> Result<(f64, Vec<f32>)> {
    let mut ws = SsimWorkspace::new();
    let (value, grad) = ws.value_and_grad(rendered, target, None, opts)?;
    Ok((value, grad.to_vec()))
}

/// [`ssim_with_grad`] restricted to masked pixels (see [`ssim_masked`]).
pub fn ssim_masked_with_grad(
    rendered: &Image,
    target: &Image,
    mask: &Image,
    opts: &SsimOptions,
) -> Result<(f64, Vec<f32>)> {
    let mut ws = SsimWorkspace::new();
    let (value, grad) = ws.value_and_grad(rendered, target, Some(mask), opts)?;
    Ok((value, grad.to_vec()))
}

/// The same computation on interleaved (H×W×C) `f64` buffers, for reference checks: returns the
/// mean SSIM and, if `want_grad`, its gradient with respect to `rendered` (interleaved).
pub fn ssim_with_grad_f64(
    rendered: &[f64],
    target: &[f64],
    (width, height, channels): (usize, usize, usize),
    opts: &SsimOptions,
    mask: Option<&[f64]>,
    want_grad: bool,
) -> Result<(f64, Option<Vec<f64>>)> {
    let shape = Shape {
        width,
        height,
        channels,
    };
    let n = width * height * channels;
    if rendered.len() != n || target.len() != n {
        return Err(MetricsError::ShapeMismatch(format!(
            "buffers of {} and {} values for a {width}x{height}x{channels} image",
            rendered.len(),
            target.len()
        )));
    }
    if let Some(m) = mask
        && m.len() != width * height
    {
        return Err(MetricsError::ShapeMismatch(format!(
            "mask of {} values for a {width}x{height} image",
            m.len()
        )));
    }
    let to_planar = |v: &[f64]| {
        let mut out = vec![0.0; n];
        for p in 0..width * height {
            for c in 0..channels {
                out[c * width * height + p] = v[p * channels + c];
            }
        }
        out
    };
    let m: Option<Vec<f64>> =
        mask.map(|m| m.iter().map(|&v| if v > 0.5 { 1.0 } else { 0.0 }).collect());
    let (value, grad) = ssim_planar(
        &to_planar(rendered),
        &to_planar(target),
        shape,
        opts,
        m.as_deref(),
        want_grad,
    )?;
    Ok((value, grad.map(|g| interleave(&g, shape))))
}

#[derive(Clone, Copy, Debug)]
struct Shape {
    width: usize,
    height: usize,
    channels: usize,
}

fn planar<T: Float>(img: &Image) -> Vec<T> {
    let mut out = Vec::new();
    planar_into(img, &mut out);
    out
}

/// C×H×W planes of an H×W×C image, written into `out` (resized, not reallocated when the size
/// is unchanged).
fn planar_into<T: Float>(img: &Image, out: &mut Vec<T>) {
    let (hw, c) = (img.width * img.height, img.channels);
    out.resize(hw * c, T::zero());
    if c == 0 {
        return;
    }
    for (k, plane) in out.chunks_exact_mut(hw.max(1)).enumerate() {
        for (o, &v) in plane.iter_mut().zip(img.data.iter().skip(k).step_by(c)) {
            *o = T::from(v).unwrap_or_else(T::nan);
        }
    }
}

/// Buffers kept between repeated SSIM value + gradient calls at one image size (the training
/// loop), so that a call allocates nothing after the first.
#[derive(Debug, Default)]
pub struct SsimWorkspace {
    x: Vec<f32>,
    y: Vec<f32>,
    bufs: Buffers<f32>,
    grad: Vec<f32>,
}

impl SsimWorkspace {
    pub fn new() -> Self {
        Self::default()
    }

    /// Same as [`ssim_with_grad`] (or [`ssim_masked_with_grad`] with a mask), returning the
    /// gradient (H×W×C interleaved) as a slice of the workspace.
    pub fn value_and_grad(
        &mut self,
        rendered: &Image,
        target: &Image,
        mask: Option<&Image>,
        opts: &SsimOptions,
    ) -> Result<(f64, &[f32])> {
        check_same_shape(rendered, target)?;
        let shape = Shape {
            width: rendered.width,
            height: rendered.height,
            channels: rendered.channels,
        };
        let m: Option<Vec<f32>> = match mask {
            Some(mask) => {
                check_mask(mask, rendered.width, rendered.height)?;
                Some(
                    mask.data
                        .iter()
                        .map(|&v| if v > 0.5 { 1.0 } else { 0.0 })
                        .collect(),
                )
            }
            None => None,
        };
        planar_into(rendered, &mut self.x);
        planar_into(target, &mut self.y);
        let value = ssim_planar_into(
            &self.x,
            &self.y,
            shape,
            opts,
            m.as_deref(),
            true,
            &mut self.bufs,
        )?;
        let (hw, c) = (shape.width * shape.height, shape.channels);
        self.grad.resize(hw * c, 0.0);
        for (k, plane) in self.bufs.grad.chunks_exact(hw).enumerate() {
            for (o, &v) in self.grad.iter_mut().skip(k).step_by(c).zip(plane) {
                *o = v;
            }
        }
        Ok((value, &self.grad))
    }
}

fn interleave<T: Float>(planes: &[T], shape: Shape) -> Vec<T> {
    let (hw, c) = (shape.width * shape.height, shape.channels);
    let mut out = vec![T::zero(); hw * c];
    for k in 0..c {
        for p in 0..hw {
            out[p * c + k] = planes[k * hw + p];
        }
    }
    out
}

/// The normalised 1-D Gaussian `exp(−k²/2σ²)`, `k = −r..=r` (SciPy's `gaussian_filter` and
/// the Inria `gaussian()` window agree on it).
fn gaussian_kernel<T: Float>(sigma: f64, radius: usize) -> Vec<T> {
    let w: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let k = i as f64 - radius as f64;
            (-k * k / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let s: f64 = w.iter().sum();
    w.iter().map(|&v| T::from(v / s).expect("finite")).collect()
}

/// Half-sample symmetric reflection of `p` into `[0, n)`, valid for `−n ≤ p < 2n`.
#[inline]
fn reflect(p: isize, n: usize) -> usize {
    let n = n as isize;
    if p < 0 {
        (-1 - p) as usize
    } else if p >= n {
        (2 * n - 1 - p) as usize
    } else {
        p as usize
    }
}

/// Rows processed per rayon task: enough work per task, enough tasks for load balance.
const ROWS_PER_TASK: usize = 4;

/// The engine: planar (C×H×W) inputs, optional per-pixel 0/1 mask; returns the weighted mean and
/// optionally the planar gradient with respect to `x`.
fn ssim_planar<T: Float + Send + Sync>(
    x: &[T],
    y: &[T],
    shape: Shape,
    opts: &SsimOptions,
    mask: Option<&[T]>,
    want_grad: bool,
) -> Result<(f64, Option<Vec<T>>)> {
    let mut bufs = Buffers::default();
    let value = ssim_planar_into(x, y, shape, opts, mask, want_grad, &mut bufs)?;
    Ok((value, want_grad.then_some(bufs.grad)))
}

/// Scratch buffers of the engine, kept between calls by [`SsimWorkspace`] so that repeated
/// calls at one size allocate (and page-fault) nothing.
#[derive(Debug)]
struct Buffers<T> {
    weight: Vec<T>,
    coef: Vec<T>,
    grad: Vec<T>,
}

impl<T> Default for Buffers<T> {
    fn default() -> Self {
        Self {
            weight: Vec::new(),
            coef: Vec::new(),
            grad: Vec::new(),
        }
    }
}

/// [`ssim_planar`] writing the gradient (if wanted) into `bufs.grad`.
#[allow(clippy::too_many_arguments)]
fn ssim_planar_into<T: Float + Send + Sync>(
    x: &[T],
    y: &[T],
    shape: Shape,
    opts: &SsimOptions,
    mask: Option<&[T]>,
    want_grad: bool,
    bufs: &mut Buffers<T>,
) -> Result<f64> {
    opts.validate()?;
    let Shape {
        width: w,
        height: h,
        channels: ch,
    } = shape;
    let r = opts.radius();
    if w == 0 || h == 0 || ch == 0 {
        return Err(MetricsError::invalid("SSIM of an empty image"));
    }
    if opts.border == SsimBorder::ReflectCrop && (w < 2 * r + 1 || h < 2 * r + 1) {
        return Err(MetricsError::invalid(format!(
            "SSIM needs images of at least {0}x{0} pixels (the window size), got {w}x{h}",
            2 * r + 1
        )));
    }
    // A fold without early exit vectorises; NaN/∞ inputs are rare.
    if !x.iter().chain(y).fold(true, |ok, v| ok & v.is_finite()) {
        return Err(MetricsError::invalid(
            "image contains NaN or infinite values",
        ));
    }

    // Per-pixel weight of the mean: 1 / (#counted pixels × channels) where counted.
    let in_region = |px: usize, py: usize| match opts.border {
        SsimBorder::ReflectCrop => px >= r && px + r < w && py >= r && py + r < h,
        SsimBorder::ZeroSame => true,
    };
    let weight = &mut bufs.weight;
    weight.clear();
    weight.resize(w * h, T::zero());
    let mut count = 0usize;
    for py in 0..h {
        for px in 0..w {
            let masked_in = mask.is_none_or(|m| m[py * w + px] > T::zero());
            if masked_in && in_region(px, py) {
                weight[py * w + px] = T::one();
                count += 1;
            }
        }
    }
    if count == 0 {
        return Err(MetricsError::invalid(
            "SSIM mask selects no pixel inside the evaluated region",
        ));
    }
    let norm = T::from(1.0 / (count * ch) as f64).expect("finite");
    weight.iter_mut().for_each(|v| *v = *v * norm);

    let g: Vec<T> = gaussian_kernel(opts.sigma, r);
    let c1 = T::from((opts.k1 * opts.data_range).powi(2)).expect("finite");
    let c2 = T::from((opts.k2 * opts.data_range).powi(2)).expect("finite");
    let filter = Filter {
        g: &g,
        r,
        w,
        h,
        border: opts.border,
    };

    // Forward: per row, the five filtered maps, S, and (for the gradient) the weighted partials
    // a, b, c stored as one row of 3W values.
    let rows = ch * h;
    let coef_len = if want_grad { 3 * w } else { 0 };
    // Every element is overwritten by the forward pass, so a reused buffer needs no clearing.
    let coef = &mut bufs.coef;
    coef.resize(rows * coef_len, T::zero());
    let weight = &bufs.weight[..];
    let value: f64 = if want_grad {
        coef.par_chunks_mut(ROWS_PER_TASK * coef_len)
            .enumerate()
            .map(|(task, out)| {
                let first = task * ROWS_PER_TASK;
                let n = out.len() / coef_len;
                dispatch!(forward_rows(
                    &filter,
                    x,
                    y,
                    weight,
                    c1,
                    c2,
                    first,
                    n,
                    Some(out)
                ))
            })
            .sum()
    } else {
        (0..rows.div_ceil(ROWS_PER_TASK))
            .into_par_iter()
            .map(|task| {
                let first = task * ROWS_PER_TASK;
                let n = ROWS_PER_TASK.min(rows - first);
                dispatch!(forward_rows(&filter, x, y, weight, c1, c2, first, n, None))
            })
            .sum()
    };
    if !want_grad {
        return Ok(value);
    }

    // Backward: the forward pass left the horizontal adjoints of the weighted partials in `coef`.
    let hadj = &bufs.coef[..];
    // Vertical adjoint and the chain rule through G∗x² and G∗xy (overwrites every element).
    let grad = &mut bufs.grad;
    grad.resize(rows * w, T::zero());
    grad.par_chunks_mut(ROWS_PER_TASK * w)
        .enumerate()
        .for_each(|(task, out)| {
            dispatch!(vertical_adjoint_rows(
                &filter,
                hadj,
                x,
                y,
                task * ROWS_PER_TASK,
                out
            ));
        });
    Ok(value)
}

/// The separable Gaussian filter with its border rule.
struct Filter<'a, T> {
    g: &'a [T],
    r: usize,
    w: usize,
    h: usize,
    border: SsimBorder,
}

impl<T: Float> Filter<'_, T> {
    /// Row of the (vertically) filtered plane: `out[i] = Σ_k g_k plane[R(py + k − r)][i]`.
    /// Returns the source row index for tap `k`, or `None` for a zero-padded row.
    #[inline(always)]
    fn source_row(&self, py: usize, k: usize) -> Option<usize> {
        let p = py as isize + k as isize - self.r as isize;
        match self.border {
            SsimBorder::ReflectCrop => Some(reflect(p, self.h)),
            SsimBorder::ZeroSame => (p >= 0 && (p as usize) < self.h).then_some(p as usize),
        }
    }

    /// Fills the `r` padding values on both sides of `buf[r..r + w]`.
    #[inline(always)]
    fn pad_row(&self, buf: &mut [T]) {
        let (r, w) = (self.r, self.w);
        for j in 0..r {
            let (left, right) = match self.border {
                SsimBorder::ReflectCrop => {
                    let l = reflect(j as isize - r as isize, w);
                    let rr = reflect((w + j) as isize, w);
                    (buf[r + l], buf[r + rr])
                }
                SsimBorder::ZeroSame => (T::zero(), T::zero()),
            };
            buf[j] = left;
            buf[r + w + j] = right;
        }
    }

    /// `out[i] = Σ_k g_k padded[i + k]`, `i = 0..out.len()`, using the kernel's symmetry
    /// (`g_k = g_{2r−k}`) to halve the multiplications.
    #[inline(always)]
    fn correlate(&self, padded: &[T], out: &mut [T]) {
        // Blocks of LANES outputs with all taps applied in registers: LLVM vectorises the fixed
        // block loop, and each output is loaded and stored once.
        const LANES: usize = 16;
        let (r, n) = (self.r, out.len());
        let taps = 2 * r + 1;
        assert!(padded.len() >= n + 2 * r && self.g.len() == taps);
        let gc = self.g[r];
        let full = n / LANES * LANES;
        for start in (0..full).step_by(LANES) {
            let mut acc = [T::zero(); LANES];
            let centre = &padded[start + r..start + r + LANES];
            for l in 0..LANES {
                acc[l] = gc * centre[l];
            }
            for k in 0..r {
                let gk = self.g[k];
                let left = &padded[start + k..start + k + LANES];
                let right = &padded[start + 2 * r - k..start + 2 * r - k + LANES];
                for l in 0..LANES {
                    acc[l] = acc[l] + gk * (left[l] + right[l]);
                }
            }
            out[start..start + LANES].copy_from_slice(&acc);
        }
        for i in full..n {
            let mut acc = gc * padded[i + r];
            for k in 0..r {
                acc = acc + self.g[k] * (padded[i + k] + padded[i + 2 * r - k]);
            }
            out[i] = acc;
        }
    }

    /// Adjoint of "pad then correlate" along a row: zero-pad `grad_out` by `2r`, correlate to the
    /// `w + 2r` padded positions, then fold each padded position onto the pixel it was copied
    /// from (reflect) or drop it (zero padding).
    #[inline(always)]
    fn horizontal_adjoint(
        &self,
        grad_out: &[T],
        grad_in: &mut [T],
        scratch: &mut [T],
        ext: &mut [T],
    ) {
        let (r, w) = (self.r, self.w);
        scratch.iter_mut().for_each(|v| *v = T::zero());
        scratch[2 * r..2 * r + w].copy_from_slice(grad_out);
        self.correlate(scratch, ext);
        grad_in.copy_from_slice(&ext[r..r + w]);
        if self.border == SsimBorder::ReflectCrop {
            for j in 0..r {
                let left = reflect(j as isize - r as isize, w);
                let right = reflect((w + j) as isize, w);
                grad_in[left] = grad_in[left] + ext[j];
                grad_in[right] = grad_in[right] + ext[r + w + j];
            }
        }
    }

    /// Adjoint of the vertical pass for output row `py`, on a plane whose rows hold `stride`
    /// values (three coefficient rows side by side): sums `g_k · rows[p − k + r]` over every
    /// padded row position `p` that maps to `py`.
    #[inline(always)]
    fn vertical_adjoint(
        &self,
        plane: &[T],
        py: usize,
        stride: usize,
        acc: &mut [T],
        taps: &mut Vec<(usize, T)>,
    ) {
        let (r, h) = (self.r as isize, self.h as isize);
        taps.clear();
        let py = py as isize;
        let mut add_position = |p: isize| {
            for (k, &gk) in self.g.iter().enumerate() {
                let src = p - k as isize + r;
                if (0..h).contains(&src) {
                    taps.push((src as usize, gk));
                }
            }
        };
        add_position(py);
        if self.border == SsimBorder::ReflectCrop {
            // Padded rows −1−py (top) and 2h−1−py (bottom) were copies of row py.
            if py < r {
                add_position(-1 - py);
            }
            if py >= h - r {
                add_position(2 * h - 1 - py);
            }
        }
        weighted_row_sum(plane, stride, taps, &mut acc[..stride]);
    }
}

/// `out[i] = Σ_(row, g) g · plane[row · stride + i]`, in register blocks of 16 columns so each
/// output is stored once however many taps there are.
#[inline(always)]
fn weighted_row_sum<T: Float>(plane: &[T], stride: usize, taps: &[(usize, T)], out: &mut [T]) {
    const LANES: usize = 16;
    let n = out.len();
    let full = n / LANES * LANES;
    for start in (0..full).step_by(LANES) {
        let mut acc = [T::zero(); LANES];
        for &(row, g) in taps {
            let src = &plane[row * stride + start..row * stride + start + LANES];
            for l in 0..LANES {
                acc[l] = acc[l] + g * src[l];
            }
        }
        out[start..start + LANES].copy_from_slice(&acc);
    }
    for i in full..n {
        let mut acc = T::zero();
        for &(row, g) in taps {
            acc = acc + g * plane[row * stride + i];
        }
        out[i] = acc;
    }
}

/// Calls a row kernel through its AVX2-compiled twin when the CPU has AVX2 (8-lane vectors;
/// the portable build only assumes SSE2), else through the portable one. The kernels are
/// `#[inline(always)]` so each twin gets its own code generation.
macro_rules! dispatch {
    ($kernel:ident($($arg:expr),* $(,)?)) => {{
        #[cfg(target_arch = "x86_64")]
        {
            if fewview_scene::cpu::avx2() {
                // SAFETY: the CPU supports AVX2 (checked just above).
                unsafe { avx2::$kernel($($arg),*) }
            } else {
                $kernel($($arg),*)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            $kernel($($arg),*)
        }
    }};
}
use dispatch;

/// AVX2 twins of the row kernels (same code, compiled with `avx2` enabled).
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::*;

    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn forward_rows<T: Float>(
        f: &Filter<'_, T>,
        x: &[T],
        y: &[T],
        weight: &[T],
        c1: T,
        c2: T,
        first: usize,
        n: usize,
        coef: Option<&mut [T]>,
    ) -> f64 {
        super::forward_rows(f, x, y, weight, c1, c2, first, n, coef)
    }

    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn vertical_adjoint_rows<T: Float>(
        f: &Filter<'_, T>,
        hadj: &[T],
        x: &[T],
        y: &[T],
        first: usize,
        out: &mut [T],
    ) {
        super::vertical_adjoint_rows(f, hadj, x, y, first, out);
    }
}

/// Vertical adjoint for global rows `first..` (one output row of W gradient values each) and the
/// chain rule `Gᵀa + 2x·Gᵀb + y·Gᵀc`.
#[inline(always)]
fn vertical_adjoint_rows<T: Float>(
    f: &Filter<'_, T>,
    hadj: &[T],
    x: &[T],
    y: &[T],
    first: usize,
    out: &mut [T],
) {
    let (w, h) = (f.w, f.h);
    let mut acc = vec![T::zero(); 3 * w];
    let mut taps = Vec::with_capacity(3 * f.g.len());
    let two = T::one() + T::one();
    for (local, orow) in out.chunks_exact_mut(w).enumerate() {
        let row = first + local;
        let (c, py) = (row / h, row % h);
        f.vertical_adjoint(
            &hadj[c * h * 3 * w..(c + 1) * h * 3 * w],
            py,
            3 * w,
            &mut acc,
            &mut taps,
        );
        let base = c * h * w + py * w;
        let (xr, yr) = (&x[base..base + w], &y[base..base + w]);
        let (ga, rest) = acc.split_at(w);
        let (gb, gc) = rest.split_at(w);
        let (gb, gc, orow) = (&gb[..w], &gc[..w], &mut orow[..w]);
        for i in 0..w {
            orow[i] = ga[i] + two * xr[i] * gb[i] + yr[i] * gc[i];
        }
    }
}

/// Forward pass for `n` consecutive global rows (`channel · h + row`) starting at `first`:
/// returns the weighted sum of S. With `coef`, also writes for each row the horizontal adjoint
/// of the weighted partials `a | b | c` (3W values), the first half of the backward pass, which
/// is row-local and so fused here.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn forward_rows<T: Float>(
    f: &Filter<'_, T>,
    x: &[T],
    y: &[T],
    weight: &[T],
    c1: T,
    c2: T,
    first: usize,
    n: usize,
    mut coef: Option<&mut [T]>,
) -> f64 {
    let (w, h, r) = (f.w, f.h, f.r);
    let padded = w + 2 * r;
    // Vertical sums of x, y, x², y², xy, each with room for horizontal padding.
    let mut v = vec![T::zero(); 5 * padded];
    let mut m = vec![T::zero(); 5 * w];
    let mut srow = vec![T::zero(); w];
    let mut partials = vec![T::zero(); if coef.is_some() { 3 * w } else { 0 }];
    let mut scratch = vec![T::zero(); w + 4 * r];
    let mut ext = vec![T::zero(); w + 2 * r];
    let mut taps = Vec::with_capacity(f.g.len());
    let two = T::one() + T::one();
    let mut total = 0.0f64;
    for local in 0..n {
        let row = first + local;
        let (c, py) = (row / h, row % h);
        let plane = c * h * w;
        taps.clear();
        taps.extend((0..f.g.len()).filter_map(|k| f.source_row(py, k).map(|src| (src, f.g[k]))));
        vertical_moments(
            &x[plane..plane + h * w],
            &y[plane..plane + h * w],
            w,
            &taps,
            r,
            &mut v,
        );
        for q in 0..5 {
            let buf = &mut v[q * padded..(q + 1) * padded];
            f.pad_row(buf);
            f.correlate(buf, &mut m[q * w..(q + 1) * w]);
        }
        let wrow = &weight[py * w..(py + 1) * w];
        let (mx, rest) = m.split_at(w);
        let (my, rest) = rest.split_at(w);
        let (exx, rest) = rest.split_at(w);
        let (eyy, exy) = rest.split_at(w);
        let (mx, my, exx, eyy, exy, wrow) = (
            &mx[..w],
            &my[..w],
            &exx[..w],
            &eyy[..w],
            &exy[..w],
            &wrow[..w],
        );
        let srow = &mut srow[..w];
        for i in 0..w {
            let (mx, my) = (mx[i], my[i]);
            let a1 = two * mx * my + c1;
            let a2 = two * (exy[i] - mx * my) + c2;
            let b1 = mx * mx + my * my + c1;
            let b2 = (exx[i] - mx * mx) + (eyy[i] - my * my) + c2;
            srow[i] = wrow[i] * (a1 * a2 / (b1 * b2));
        }
        total += sum_f64(srow);
        if let Some(cf) = coef.as_deref_mut() {
            let (pa, rest) = partials.split_at_mut(w);
            let (pb, pc) = rest.split_at_mut(w);
            let (pb, pc) = (&mut pb[..w], &mut pc[..w]);
            for i in 0..w {
                let (mx, my) = (mx[i], my[i]);
                let a1 = two * mx * my + c1;
                let a2 = two * (exy[i] - mx * my) + c2;
                let b1 = mx * mx + my * my + c1;
                let b2 = (exx[i] - mx * mx) + (eyy[i] - my * my) + c2;
                let d = b1 * b2;
                let s = a1 * a2 / d;
                let wd = wrow[i] / d;
                pa[i] = wd * (two * my * (a2 - a1) - two * mx * s * (b2 - b1));
                pb[i] = -wd * s * b1;
                pc[i] = wd * two * a1;
            }
            let out = &mut cf[local * 3 * w..(local + 1) * 3 * w];
            for q in 0..3 {
                f.horizontal_adjoint(
                    &partials[q * w..(q + 1) * w],
                    &mut out[q * w..(q + 1) * w],
                    &mut scratch,
                    &mut ext,
                );
            }
        }
    }
    total
}

/// The vertical pass of the five moment maps x, y, x², y², xy for one output row: writes
/// `Σ_(row, g) g · q(row)` into the interior `[r, r + w)` of each of the five padded rows of `v`
/// (row length `w + 2r`), in register blocks of 8 columns.
#[inline(always)]
fn vertical_moments<T: Float>(
    x: &[T],
    y: &[T],
    w: usize,
    taps: &[(usize, T)],
    r: usize,
    v: &mut [T],
) {
    let full = w / 8 * 8;
    for start in (0..full).step_by(8) {
        moments_block::<T, 8>(x, y, w, taps, r, v, start);
    }
    for start in full..w {
        moments_block::<T, 1>(x, y, w, taps, r, v, start);
    }
}

/// [`vertical_moments`] for the `N` columns from `start`.
#[inline(always)]
fn moments_block<T: Float, const N: usize>(
    x: &[T],
    y: &[T],
    w: usize,
    taps: &[(usize, T)],
    r: usize,
    v: &mut [T],
    start: usize,
) {
    let mut acc = [[T::zero(); N]; 5];
    for &(row, g) in taps {
        let xr: &[T; N] = x[row * w + start..row * w + start + N]
            .try_into()
            .expect("N values");
        let yr: &[T; N] = y[row * w + start..row * w + start + N]
            .try_into()
            .expect("N values");
        for l in 0..N {
            let (a, b) = (xr[l], yr[l]);
            let (ga, gb) = (g * a, g * b);
            acc[0][l] = acc[0][l] + ga;
            acc[1][l] = acc[1][l] + gb;
            acc[2][l] = acc[2][l] + ga * a;
            acc[3][l] = acc[3][l] + gb * b;
            acc[4][l] = acc[4][l] + ga * b;
        }
    }
    let padded = w + 2 * r;
    for (q, a) in acc.iter().enumerate() {
        let o = q * padded + r + start;
        v[o..o + N].copy_from_slice(a);
    }
}

/// Sum in `f64` with four independent accumulators (vectorisable, and no long dependency chain).
#[inline(always)]
fn sum_f64<T: Float>(v: &[T]) -> f64 {
    let mut acc = [0.0f64; 4];
    let chunks = v.chunks_exact(4);
    let tail: f64 = chunks
        .remainder()
        .iter()
        .map(|x| x.to_f64().unwrap_or(f64::NAN))
        .sum();
    for ch in chunks {
        for l in 0..4 {
            acc[l] += ch[l].to_f64().unwrap_or(f64::NAN);
        }
    }
    acc.iter().sum::<f64>() + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg_image(w: usize, h: usize, c: usize, seed: u64) -> Vec<f64> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..w * h * c)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64) / ((1u64 << 53) as f64)
            })
            .collect()
    }

    /// A direct 2-D reference: explicit padding and 11×11 weighted sums, no separability.
    fn naive_ssim(x: &[f64], y: &[f64], w: usize, h: usize, c: usize, opts: &SsimOptions) -> f64 {
        let r = opts.radius() as isize;
        let g: Vec<f64> = gaussian_kernel(opts.sigma, r as usize);
        let (c1, c2) = (
            (opts.k1 * opts.data_range).powi(2),
            (opts.k2 * opts.data_range).powi(2),
        );
        let at = |img: &[f64], px: isize, py: isize, k: usize| -> f64 {
            match opts.border {
                SsimBorder::ReflectCrop => img[(reflect(py, h) * w + reflect(px, w)) * c + k],
                SsimBorder::ZeroSame => {
                    if px < 0 || py < 0 || px >= w as isize || py >= h as isize {
                        0.0
                    } else {
                        img[(py as usize * w + px as usize) * c + k]
                    }
                }
            }
        };
        let (mut sum, mut n) = (0.0, 0usize);
        for k in 0..c {
            for py in 0..h as isize {
                for px in 0..w as isize {
                    if opts.border == SsimBorder::ReflectCrop
                        && (px < r || py < r || px >= w as isize - r || py >= h as isize - r)
                    {
                        continue;
                    }
                    let (mut mx, mut my, mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let wt = g[(dy + r) as usize] * g[(dx + r) as usize];
                            let a = at(x, px + dx, py + dy, k);
                            let b = at(y, px + dx, py + dy, k);
                            mx += wt * a;
                            my += wt * b;
                            xx += wt * a * a;
                            yy += wt * b * b;
                            xy += wt * a * b;
                        }
                    }
                    let (vx, vy, vxy) = (xx - mx * mx, yy - my * my, xy - mx * my);
                    sum += (2.0 * mx * my + c1) * (2.0 * vxy + c2)
                        / ((mx * mx + my * my + c1) * (vx + vy + c2));
                    n += 1;
                }
            }
        }
        sum / n as f64
    }

    #[test]
    fn identical_images_give_one() {
        for border in [SsimBorder::ReflectCrop, SsimBorder::ZeroSame] {
            let opts = SsimOptions {
                border,
                ..Default::default()
            };
            let data: Vec<f32> = lcg_image(23, 17, 3, 1).iter().map(|&v| v as f32).collect();
            let img = Image::from_vec(23, 17, 3, data);
            let v = ssim_with(&img, &img, &opts).unwrap();
            assert!((v - 1.0).abs() < 1e-6, "{border:?}: {v}");
            let (v, g) = ssim_with_grad(&img, &img, &opts).unwrap();
            assert!((v - 1.0).abs() < 1e-6);
            // SSIM is maximal at x = y, so the gradient vanishes there.
            let gmax = g.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!(gmax < 1e-6, "{border:?}: max |grad| {gmax}");
        }
    }

    #[test]
    fn separable_engine_matches_direct_2d_reference() {
        for border in [SsimBorder::ReflectCrop, SsimBorder::ZeroSame] {
            let opts = SsimOptions {
                border,
                ..Default::default()
            };
            for &(w, h, c) in &[(11, 11, 1), (19, 14, 3), (13, 25, 2)] {
                let x = lcg_image(w, h, c, 3);
                let y: Vec<f64> = x
                    .iter()
                    .zip(lcg_image(w, h, c, 4))
                    .map(|(a, b)| 0.7 * a + 0.3 * b)
                    .collect();
                let (v, _) = ssim_with_grad_f64(&x, &y, (w, h, c), &opts, None, false).unwrap();
                let reference = naive_ssim(&x, &y, w, h, c, &opts);
                assert!(
                    (v - reference).abs() < 1e-12,
                    "{border:?} {w}x{h}x{c}: {v} vs {reference}"
                );
            }
        }
    }

    /// Gradient against central finite differences of the f64 path, every pixel of a small
    /// image (borders included, where the reflection fold matters).
    #[test]
    fn gradient_matches_finite_differences() {
        let (w, h, c) = (14, 12, 2);
        let x = lcg_image(w, h, c, 7);
        let y: Vec<f64> = x
            .iter()
            .zip(lcg_image(w, h, c, 8))
            .map(|(a, b)| 0.6 * a + 0.4 * b)
            .collect();
        let mut mask = vec![0.0; w * h];
        for (i, m) in mask.iter_mut().enumerate() {
            *m = if (i * 7) % 5 < 3 { 1.0 } else { 0.0 };
        }
        for border in [SsimBorder::ReflectCrop, SsimBorder::ZeroSame] {
            for use_mask in [false, true] {
                let opts = SsimOptions {
                    border,
                    ..Default::default()
                };
                let m = use_mask.then_some(mask.as_slice());
                let (_, grad) = ssim_with_grad_f64(&x, &y, (w, h, c), &opts, m, true).unwrap();
                let grad = grad.unwrap();
                let eps = 1e-5;
                let gnorm = grad.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                let mut worst = 0.0f64;
                for i in 0..x.len() {
                    let mut xp = x.clone();
                    xp[i] += eps;
                    let mut xm = x.clone();
                    xm[i] -= eps;
                    let fp = ssim_with_grad_f64(&xp, &y, (w, h, c), &opts, m, false)
                        .unwrap()
                        .0;
                    let fm = ssim_with_grad_f64(&xm, &y, (w, h, c), &opts, m, false)
                        .unwrap()
                        .0;
                    let fd = (fp - fm) / (2.0 * eps);
                    // Relative to the entry, with the largest entry as the floor for tiny ones.
                    let rel = (fd - grad[i]).abs() / fd.abs().max(1e-2 * gnorm);
                    worst = worst.max(rel);
                }
                assert!(
                    worst < 1e-3,
                    "{border:?} mask={use_mask}: worst relative error {worst}"
                );
            }
        }
    }

    #[test]
    fn f32_gradient_agrees_with_f64() {
        let (w, h, c) = (37, 29, 3);
        let x = lcg_image(w, h, c, 11);
        let y: Vec<f64> = x
            .iter()
            .zip(lcg_image(w, h, c, 12))
            .map(|(a, b)| 0.5 * a + 0.5 * b)
            .collect();
        let xi = Image::from_vec(w, h, c, x.iter().map(|&v| v as f32).collect());
        let yi = Image::from_vec(w, h, c, y.iter().map(|&v| v as f32).collect());
        for border in [SsimBorder::ReflectCrop, SsimBorder::ZeroSame] {
            let opts = SsimOptions {
                border,
                ..Default::default()
            };
            let xs: Vec<f64> = xi.data.iter().map(|&v| v as f64).collect();
            let ys: Vec<f64> = yi.data.iter().map(|&v| v as f64).collect();
            let (v64, g64) = ssim_with_grad_f64(&xs, &ys, (w, h, c), &opts, None, true).unwrap();
            let (v32, g32) = ssim_with_grad(&xi, &yi, &opts).unwrap();
            assert!((v64 - v32).abs() < 1e-5, "{v64} vs {v32}");
            let gmax = g64
                .as_ref()
                .unwrap()
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            for (a, b) in g64.unwrap().iter().zip(&g32) {
                assert!((a - *b as f64).abs() < 1e-3 * gmax, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn rejects_bad_input() {
        let a = Image::filled(8, 8, &[0.5]);
        let err = ssim(&a, &a).unwrap_err().to_string();
        assert!(err.contains("at least 11x11"), "{err}");
        // The training variant works on any size.
        assert!((ssim_with(&a, &a, &SsimOptions::training_loss()).unwrap() - 1.0).abs() < 1e-6);
        let b = Image::filled(12, 12, &[0.5, 0.5, 0.5]);
        let c = Image::filled(12, 12, &[0.5]);
        assert!(
            ssim(&b, &c)
                .unwrap_err()
                .to_string()
                .contains("size mismatch")
        );
        let mut d = b.clone();
        d.data[5] = f32::NAN;
        assert!(ssim(&b, &d).unwrap_err().to_string().contains("NaN"));
        let mask = Image::filled(12, 12, &[0.0]);
        assert!(ssim_masked(&b, &b, &mask, &SsimOptions::default()).is_err());
    }
}
