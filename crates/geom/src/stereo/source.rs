//! Where the depth of a stereo pair comes from: [`DepthSource`] is the seam between the
//! hierarchical point cloud and whatever estimates depth. [`SgmSource`] rectifies the pair and
//! runs Semi-Global Matching in both directions (our stand-in for the fusion paper's UniMatch);
//! [`DepthMapSource`] serves a user's own depth maps (one per view, e.g. from a learned model).

use std::path::Path;

use fewview_scene::{Camera, Image};

use super::pairs::StereoView;
pub use super::range::{
    DisparityRange, MAX_DISPARITIES, disparity_range, exact_disparity_range, points_depth_range,
    points_disparity_range,
};
use super::rectify::{Rectification, RectifiedImage, Side};
use super::refine::{RefineOptions, grey, refine};
use super::search_window::{match_window, window_start};
use super::sgm::SgmParams;
use super::sweep::sweep_pair;
pub use super::view_depth::{PairDepths, ViewDepth};
use crate::error::{GeomError, Result};
use crate::io::read_depth;

/// A source of depth for stereo pairs of training views (indices into the caller's views).
pub trait DepthSource: Sync {
    /// What the depth comes from, for reports ("sgm", "depth maps").
    fn name(&self) -> &str;
    /// The depth maps of views `first` and `second` as seen together.
    fn pair_depths(&self, first: usize, second: usize) -> Result<PairDepths>;
}

/// How the two photos of a pair are brought to one brightness before they are matched.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Photometry {
    /// As they are (OpenCV's `StereoSGBM`: its cost compares x-derivatives of the images,
    /// clipped, which a moderate exposure difference barely moves).
    #[default]
    AsIs,
    /// The right rectified image scaled per channel so that its mean over the pixels the two
    /// share (at the middle of the disparity range) equals the left one's: a difference of exposure or white balance between the photos
    /// (a phone's automatic exposure) would otherwise read to the matcher's absolute-difference
    /// cost and to the refinement's intensity fit as a change of surface. The global form of
    /// the per-pair normalisation of multi-view stereo's normalised cross-correlation costs.
    /// It pays beyond about one EV (more consistent points); on photos that agree it costs a
    /// little accuracy, because view-dependent colour then reads as a gain.
    GainMatched,
}

/// Scales `right` per channel so that its mean equals `left`'s over the pixels the two share
/// at the disparity `shift` (left `(x, y)` against right `(x − shift, y)`, both inside their
/// originals: the middle of the search range lines up roughly the same surfaces); values are
/// clipped to `[0, 1]`. Returns the gains; a channel without signal keeps gain 1.
pub fn match_gains(left: &RectifiedImage, right: &mut RectifiedImage, shift: i32) -> Vec<f64> {
    let (w, c) = (left.image.width, left.image.channels);
    let (mut l_sum, mut r_sum) = (vec![0.0f64; c], vec![0.0f64; c]);
    for (p, _) in left.inside.iter().enumerate().filter(|(_, i)| **i) {
        // The right pixel `(x − shift, y)`; a negative shift (per-image canvases) looks right.
        let xr = (p % w) as i64 - shift as i64;
        if !(0..w as i64).contains(&xr) {
            continue;
        }
        let q = p - p % w + xr as usize;
        if !right.inside[q] {
            continue;
        }
        for k in 0..c {
            l_sum[k] += left.image.data[p * c + k] as f64;
            r_sum[k] += right.image.data[q * c + k] as f64;
        }
    }
    let gains: Vec<f64> = l_sum
        .iter()
        .zip(&r_sum)
        .map(|(l, r)| if *l > 0.0 && *r > 0.0 { l / r } else { 1.0 })
        .collect();
    for (i, v) in right.image.data.iter_mut().enumerate() {
        *v = (*v as f64 * gains[i % c]).clamp(0.0, 1.0) as f32;
    }
    gains
}

/// A disparity map of a rectified image: `x_left − x_right` in pixels, row-major, NaN where the
/// matcher found none.
#[derive(Clone, Debug, PartialEq)]
pub struct DisparityMap {
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
}

impl DisparityMap {
    pub fn new(width: usize, height: usize, values: Vec<f32>) -> Self {
        debug_assert_eq!(values.len(), width * height);
        Self {
            width,
            height,
            values,
        }
    }

    /// The fraction of pixels with a disparity.
    pub fn valid_fraction(&self) -> f64 {
        let n = self.values.iter().filter(|v| v.is_finite()).count();
        n as f64 / self.values.len().max(1) as f64
    }
}

/// Everything two-view stereo computes for one pair.
#[derive(Clone, Debug)]
pub struct PairStereo {
    pub rectification: Rectification,
    /// True when the rectified left view is the pair's second view (the second camera sat to the
    /// left of the first; matching always runs with the right camera at `+x`).
    pub swapped: bool,
    pub left: RectifiedImage,
    pub right: RectifiedImage,
    /// The parameters used, with the pair's disparity range.
    pub params: SgmParams,
    /// The matcher's disparities of each rectified image, before sub-pixel refinement.
    pub left_disparity: DisparityMap,
    pub right_disparity: DisparityMap,
    /// Depth maps of the pair's first and second view in their original cameras.
    pub depths: PairDepths,
}

/// The rectification [`match_pair`] uses for cameras `first` and `second`, and whether it
/// swapped them (the rectified left camera is `second` when `second` sits to `first`'s left).
pub fn rectify_pair(first: &Camera, second: &Camera) -> Result<(Rectification, bool)> {
    let baseline = second.center() - first.center();
    let first_x = first.world_to_camera.rotation.row(0).transpose();
    let swapped = baseline.dot(&first_x) < 0.0;
    let (l, r) = if swapped {
        (second, first)
    } else {
        (first, second)
    };
    Ok((Rectification::new(l, r)?, swapped))
}

/// Rectifies `first` and `second`, brings them to one brightness (`photometry`), matches them
/// both ways and maps the disparities back to depth in the original cameras. `range` picks the
/// disparity search range (with [`DisparityRange::FromDepthBounds`], and with
/// [`DisparityRange::FromSparsePoints`] when the views share too few points, both views need
/// depth bounds; see [`super::pairs::with_depth_bounds`]).
pub fn match_pair(
    first: &StereoView,
    second: &StereoView,
    params: &SgmParams,
    range: DisparityRange,
    refine_options: Option<&RefineOptions>,
    photometry: Photometry,
) -> Result<PairStereo> {
    let pair_name = || format!("views {} and {}", first.name, second.name);
    let (rect, swapped) = rectify_pair(first.camera, second.camera)
        .map_err(|e| GeomError::invalid(pair_name(), e.to_string()))?;
    let (l, r) = if swapped {
        (second, first)
    } else {
        (first, second)
    };
    let mut params = params.clone();
    let from_points = match range {
        DisparityRange::FromSparsePoints => points_disparity_range(&rect, l, r, l.sparse_points),
        _ => None,
    };
    (params.min_disparity, params.num_disparities) = match (range, from_points) {
        (DisparityRange::Fixed { min, count }, _) => (min, count),
        (_, Some(found)) => found,
        _ => {
            let (near, far) = pair_bounds(l, r).ok_or_else(|| {
                GeomError::invalid(
                    pair_name(),
                    "no depth bounds to choose the disparity range from",
                )
            })?;
            disparity_range(&rect, near, far)
        }
    };
    let (left, mut right) = rayon::join(
        || rect.rectify_image(Side::Left, l.image),
        || rect.rectify_image(Side::Right, r.image),
    );
    if photometry == Photometry::GainMatched {
        let middle = params.min_disparity + params.num_disparities as i32 / 2;
        match_gains(&left, &mut right, middle);
    }
    let (lu8, ru8) = (eight_bit_rgb(&left.image), eight_bit_rgb(&right.image));
    let (w, h) = (left.image.width, left.image.height);
    let shift = window_start(&params);
    let (mut lf, mut rf) = match_window(&lu8, &ru8, (w, h, 3), &params, shift)
        .map_err(|e| GeomError::invalid(pair_name(), e.to_string()))?;
    drop_outside(&mut lf, w, &left.inside, &right.inside, -1.0);
    drop_outside(&mut rf, w, &right.inside, &left.inside, 1.0);
    let (ld, rd) = (
        DisparityMap::new(w, h, lf.clone()),
        DisparityMap::new(w, h, rf.clone()),
    );
    // Without refinement every SGM disparity counts as verified.
    let (mut l_ok, mut r_ok) = (lf.clone(), rf.clone());
    if let Some(o) = refine_options {
        let (lg, rg) = (grey(&left.image), grey(&right.image));
        let l_done = refine(&lg, &rg, w, h, &mut lf, -1.0, o);
        let r_done = refine(&rg, &lg, w, h, &mut rf, 1.0, o);
        l_ok = only_where(&lf, &l_done);
        r_ok = only_where(&rf, &r_done);
    }
    let left_depth = view_depth(&rect, Side::Left, &lf, &l_ok)?;
    let right_depth = view_depth(&rect, Side::Right, &rf, &r_ok)?;
    let depths = if swapped {
        PairDepths {
            first: right_depth,
            second: left_depth,
        }
    } else {
        PairDepths {
            first: left_depth,
            second: right_depth,
        }
    };
    Ok(PairStereo {
        rectification: rect,
        swapped,
        left,
        right,
        params,
        left_disparity: ld,
        right_disparity: rd,
        depths,
    })
}

/// `values` where `keep`, NaN elsewhere.
fn only_where(values: &[f32], keep: &[bool]) -> Vec<f32> {
    values
        .iter()
        .zip(keep)
        .map(|(&v, &k)| if k { v } else { f32::NAN })
        .collect()
}

/// The original-camera depth of `side` from all its disparities and the verified ones.
fn view_depth(
    rect: &Rectification,
    side: Side,
    disparity: &[f32],
    verified: &[f32],
) -> Result<ViewDepth> {
    let depth = rect.depth_from_disparity(side, disparity)?;
    let checked = rect.depth_from_disparity(side, verified)?;
    Ok(ViewDepth {
        depth,
        verified: checked.iter().map(|&d| d > 0.0).collect(),
    })
}

/// The depth range both views see, when both know their bounds.
fn pair_bounds(a: &StereoView, b: &StereoView) -> Option<(f64, f64)> {
    let (na, fa) = a.depth_bounds?;
    let (nb, fb) = b.depth_bounds?;
    Some((na.min(nb), fa.max(fb)))
}

/// Drops disparities (pixels, NaN where none, rows `w` wide) whose pixel, or whose match in
/// the other image (at `x + sign·d`), lies where the rectified image has no source pixels.
fn drop_outside(disp: &mut [f32], w: usize, inside: &[bool], other_inside: &[bool], sign: f32) {
    for (i, v) in disp.iter_mut().enumerate() {
        if !v.is_finite() {
            continue;
        }
        let xm = ((i % w) as f32 + sign * *v).round();
        let matched = xm >= 0.0 && (xm as usize) < w && other_inside[i - i % w + xm as usize];
        if !inside[i] || !matched {
            *v = f32::NAN;
        }
    }
}

/// An image as interleaved 8-bit RGB (grey repeated; alpha dropped).
pub fn eight_bit_rgb(image: &Image) -> Vec<u8> {
    let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let mut out = Vec::with_capacity(image.width * image.height * 3);
    for p in image.data.chunks(image.channels.max(1)) {
        match image.channels {
            1 | 2 => out.extend([q(p[0]); 3]),
            _ => out.extend([q(p[0]), q(p[1]), q(p[2])]),
        }
    }
    out
}

/// Semi-Global Matching on rectified pairs of the given views.
pub struct SgmSource<'a> {
    pub views: &'a [StereoView<'a>],
    pub params: SgmParams,
    pub range: DisparityRange,
    /// Sub-pixel refinement of the disparities (`None`: SGM's own).
    pub refine: Option<RefineOptions>,
    pub photometry: Photometry,
}

impl DepthSource for SgmSource<'_> {
    fn name(&self) -> &str {
        "sgm"
    }

    fn pair_depths(&self, first: usize, second: usize) -> Result<PairDepths> {
        let (a, b) = (&self.views[first], &self.views[second]);
        match pair_method(a.camera, b.camera) {
            PairMethod::Rectified => {
                let pair = match_pair(
                    a,
                    b,
                    &self.params,
                    self.range,
                    self.refine.as_ref(),
                    self.photometry,
                )?;
                Ok(pair.depths)
            }
            PairMethod::PlaneSweep(_) => {
                let range = points_depth_range(a, b, a.sparse_points)
                    .or_else(|| pair_bounds(a, b).map(|(n, f)| (0.9 * n, 1.1 * f)))
                    .ok_or_else(|| {
                        GeomError::invalid(
                            format!("views {} and {}", a.name, b.name),
                            "no depth bounds to place the sweep's planes",
                        )
                    })?;
                sweep_pair(a, b, range, &self.params, self.refine.as_ref())
            }
        }
    }
}

/// How the depth of a pair of views is matched.
#[derive(Clone, Debug, PartialEq)]
pub enum PairMethod {
    /// Rectified Semi-Global Matching ([`match_pair`]).
    Rectified,
    /// Plane sweep in each view ([`sweep_pair`]), with the reason rectification cannot serve.
    PlaneSweep(String),
}

/// The largest tilt (degrees) rectification may give the optical axis of either camera of a
/// pair: beyond it the rectified images stretch so much along the rows (and, as the baseline
/// nears the optical axis, towards the epipoles inside the images) that block matching on rows
/// fails, and the pair is swept in its own cameras instead. (LLFF's fern has a pair tilted by
/// 42° that rectified matching serves well.)
pub const MAX_RECTIFYING_TILT_DEG: f64 = 45.0;

/// The largest cost volume (bytes) rectified matching may build; a rectified canvas stretched
/// beyond it (up to twice each image's side) is swept in the original cameras instead, whose
/// volume the image size bounds.
pub const MAX_RECTIFIED_VOLUME_BYTES: usize = 1 << 30;

/// Whether rectified matching serves cameras `first` and `second`, or plane sweep, and why.
pub fn pair_method(first: &Camera, second: &Camera) -> PairMethod {
    let rect = match rectify_pair(first, second) {
        Ok((rect, _)) => rect,
        Err(e) => return PairMethod::PlaneSweep(format!("rectification fails: {e}")),
    };
    // The tilt of each optical axis (a roll about it only turns the rows, which costs nothing).
    let turn = [Side::Left, Side::Right]
        .map(|side| {
            let (original, rectified) = (rect.original(side), rect.rectified(side));
            let cos = original
                .forward()
                .dot(&rectified.forward())
                .clamp(-1.0, 1.0);
            cos.acos().to_degrees()
        })
        .into_iter()
        .fold(0.0, f64::max);
    let canvas = rect.intrinsics.width as usize * rect.intrinsics.height as usize;
    let volume = canvas * MAX_DISPARITIES * std::mem::size_of::<i16>();
    if volume > MAX_RECTIFIED_VOLUME_BYTES {
        return PairMethod::PlaneSweep(format!(
            "its rectified canvas ({}×{}) would need a {:.1} GB cost volume",
            rect.intrinsics.width,
            rect.intrinsics.height,
            volume as f64 / (1u64 << 30) as f64
        ));
    }
    if rect.offset.abs() > 0.5 {
        return PairMethod::PlaneSweep(
            "the two views are turned so far apart that each needs a rectified canvas of its \
             own, which clips them"
                .into(),
        );
    }
    if turn > MAX_RECTIFYING_TILT_DEG {
        let axis = (first.forward() + second.forward()).normalize();
        let along = (second.center() - first.center())
            .normalize()
            .dot(&axis)
            .abs();
        PairMethod::PlaneSweep(format!(
            "rectification would tilt a camera's axis by {turn:.0}° (the baseline is {:.0}° \
             from the optical axis; at most {MAX_RECTIFYING_TILT_DEG:.0}° is matched on \
             rectified rows)",
            along.acos().to_degrees()
        ))
    } else {
        PairMethod::Rectified
    }
}

/// Depth maps given per view (z-depth, 0 = none), the same map for every pair a view is in.
pub struct DepthMapSource {
    pub maps: Vec<Vec<f32>>,
}

impl DepthMapSource {
    /// Reads `<dir>/<view name>.npy` (float H×W) or `.png` (16-bit, `png_scale` units per step)
    /// for every view; a missing file or a size that differs from the view's image is an error
    /// naming the file.
    pub fn load(dir: &Path, views: &[StereoView], png_scale: f32) -> Result<Self> {
        let mut maps = Vec::with_capacity(views.len());
        for v in views {
            let npy = dir.join(format!("{}.npy", v.name));
            let png = dir.join(format!("{}.png", v.name));
            let path = if npy.exists() { npy } else { png };
            if !path.exists() {
                return Err(GeomError::format(
                    dir.join(format!("{}.npy", v.name)),
                    format!("no depth map for training view {} (.npy or .png)", v.name),
                ));
            }
            let map = read_depth(&path, png_scale)?;
            if (map.width, map.height) != (v.image.width, v.image.height) {
                return Err(GeomError::format(
                    &path,
                    format!(
                        "depth map is {}×{} but image {} is {}×{}",
                        map.width, map.height, v.name, v.image.width, v.image.height
                    ),
                ));
            }
            maps.push(map.depth);
        }
        Ok(Self { maps })
    }
}

impl DepthSource for DepthMapSource {
    fn name(&self) -> &str {
        "depth maps"
    }

    fn pair_depths(&self, first: usize, second: usize) -> Result<PairDepths> {
        Ok(PairDepths {
            first: ViewDepth::trusted(self.maps[first].clone()),
            second: ViewDepth::trusted(self.maps[second].clone()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rectified image of `f(x, y)` per channel, all inside.
    fn rectified(w: usize, h: usize, f: impl Fn(usize, usize, usize) -> f32) -> RectifiedImage {
        let data = (0..w * h * 3)
            .map(|i| f(i / 3 % w, i / 3 / w, i % 3))
            .collect();
        RectifiedImage {
            image: Image::from_vec(w, h, 3, data),
            inside: vec![true; w * h],
        }
    }

    /// The right view sees the left one's content `shift` pixels to the left (positive) or to
    /// the right (negative, per-image canvases) at half brightness in channel 0: the gains
    /// compare the same surfaces and come out as 2, 1, 1.
    #[test]
    fn gains_compare_the_columns_the_shift_lines_up_either_way() {
        let (w, h) = (40, 6);
        // A ramp, so that sums over misaligned columns differ.
        let texture =
            |x: i64, c: usize| 0.05 + 0.015 * x as f32 + 0.01 * ((x * 7 + c as i64) % 5) as f32;
        for shift in [5i32, -5] {
            let left = rectified(w, h, |x, _, c| texture(x as i64, c));
            let mut right = rectified(w, h, |x, _, c| {
                let v = texture(x as i64 + shift as i64, c);
                if c == 0 { 0.5 * v } else { v }
            });
            let gains = match_gains(&left, &mut right, shift);
            for (c, want) in [2.0, 1.0, 1.0].iter().enumerate() {
                assert!((gains[c] - want).abs() < 1e-5, "shift {shift}: {gains:?}");
            }
        }
    }
}
