//! The depth each input view gives the network, and how much it flickers over frames.
//!
//! The PoseGaussian paper's per-frame competitors (GPS-Gaussian and its kin) take depth from a
//! stereo module run on every frame's source images, so that their depth, and with it their
//! renders, change from frame to frame even where the person does not move: the flicker the
//! pose conditioning and the Temporal Pose Stabilizer remove. [`DepthInput::Stereo`] puts that
//! setting back with classical stereo: each input view is rectified with a partner input camera
//! and matched by Semi-Global Matching (`fewview-geom`, the code of the fusion method's stereo
//! start), searched only over the depths the visual hull allows, and the hull's depth fills what
//! stereo leaves unmatched. OpenCV's checks drop doubtful disparities by default;
//! [`StereoChecks::Dense`] keeps every pixel's winner, as GPS-Gaussian's stereo network outputs
//! one everywhere, and with a wider search ([`StereoSettings::hull_front`], `hull_behind`) it
//! flickers from frame to frame the way per-frame stereo on real video does. [`DepthInput::Hull`] (the visual hull alone, smooth over time) and
//! [`DepthInput::Dataset`] (the capture's exact depth, an oracle) are the ablations.
//!
//! GPS-Gaussian rectifies the two source views of each target together. Our inference computes
//! each input view's maps once per frame and shares them between targets (the stabilizer works
//! per input view too), so each input view has one stereo partner ([`StereoPartner`]): by
//! default its second nearest input camera, which on the paper's split (every third camera of a
//! ring held out) is exactly the other source view of the held-out camera it flanks, 60° away on
//! the synthetic capture; the nearest (30°) is the alternative.

use fewview_geom::stereo::pairs::{StereoView, overlap_fraction};
use fewview_geom::stereo::rectify::Side;
use fewview_geom::stereo::sgm::SgmParams;
use fewview_geom::stereo::source::{
    DisparityRange, Photometry, exact_disparity_range, match_pair, rectify_pair,
};
use fewview_scene::{Camera, Image};
use serde::{Deserialize, Serialize};

use crate::error::{HumanError, Result};
use crate::maps::{DepthMap, Mask};

/// Where the depth the network reads comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum DepthInput {
    /// Two-view stereo per frame with a partner input camera, searched over the visual hull's
    /// depth range, the hull where it does not match (the paper's setting: per-frame depth that
    /// flickers).
    #[default]
    Stereo,
    /// The visual hull of the input masks (smooth over time).
    Hull,
    /// The capture's own depth maps (an oracle; the synthetic capture has them).
    Dataset,
}

impl DepthInput {
    /// What runs stored before the choice existed read: the hull.
    pub fn before_choice() -> Self {
        Self::Hull
    }

    /// The error when the dataset's depth is asked for and the capture has none.
    pub(crate) fn dataset_depth_missing() -> HumanError {
        HumanError::argument(
            "depth input",
            "the capture has no depth maps, so the dataset's depth cannot be the input (choose stereo or hull)",
        )
    }

    /// The range the depth head refines within, around this depth. The hull bounds the
    /// surface from the front, so the surface lies behind it; stereo and the dataset's depth
    /// lie on it, give or take their error.
    pub fn bracket(self) -> DepthBracket {
        match self {
            Self::Hull => DepthBracket::default(),
            Self::Stereo | Self::Dataset => DepthBracket {
                front: 0.05,
                behind: 0.05,
            },
        }
    }
}

/// Where the depth head's `(−1, 1)` lands (a deviation: the paper normalises depth to the
/// scene's near/far range; ours brackets each pixel around the input depth, so that the head
/// refines it instead of finding the person in a range of metres; see
/// [`crate::depth::DepthInput::bracket`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthBracket {
    /// How far in front of the input depth the depth may go (metres).
    pub front: f32,
    /// How far behind it.
    pub behind: f32,
}

impl DepthBracket {
    /// An error naming the setting when the bracket is not a finite, non-empty range.
    pub fn check(&self) -> Result<()> {
        check_range("depth bracket", self.front as f64, self.behind as f64)
    }
}

/// An error naming `what` unless `front` and `behind` are finite distances ≥ 0, not both 0.
fn check_range(what: &str, front: f64, behind: f64) -> Result<()> {
    let distance = |v: f64| v.is_finite() && v >= 0.0;
    if distance(front) && distance(behind) && front + behind > 0.0 {
        return Ok(());
    }
    let m = format!("{front},{behind}: expected two distances ≥ 0 in metres, not both 0");
    Err(HumanError::argument(what, m))
}

impl Default for DepthBracket {
    fn default() -> Self {
        Self {
            front: 0.03,
            behind: 0.12,
        }
    }
}

/// Which input camera each view is matched with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum StereoPartner {
    /// The input camera whose optical axis is nearest: the shortest baseline, the easiest match.
    Nearest,
    /// The second nearest. On a ring where every third camera is held out (the PoseGaussian
    /// paper's split), it is the other source view of the held-out camera this view flanks:
    /// GPS-Gaussian's stereo pair, twice the nearest's angle.
    #[default]
    SecondNearest,
}

impl StereoPartner {
    /// What runs stored before the choice existed used: the nearest.
    pub fn before_choice() -> Self {
        Self::Nearest
    }

    /// The rank among the other cameras by nearness of the optical axis (0 = nearest).
    fn rank(self) -> usize {
        match self {
            Self::Nearest => 0,
            Self::SecondNearest => 1,
        }
    }
}

/// Which of Semi-Global Matching's disparities stereo depth keeps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum StereoChecks {
    /// OpenCV's `StereoSGBM` checks: uniqueness, left–right consistency and the speckle
    /// filter drop doubtful pixels, which take the hull's depth.
    #[default]
    Opencv,
    /// Every masked pixel keeps the winning disparity, as a stereo network regresses one
    /// everywhere (GPS-Gaussian's per-frame setting): denser, and noisier from frame to frame.
    Dense,
}

impl StereoChecks {
    /// `sgm` with these checks: `Dense` turns off uniqueness, left–right agreement and speckles.
    fn applied(self, sgm: &SgmParams) -> SgmParams {
        match self {
            Self::Opencv => sgm.clone(),
            Self::Dense => SgmParams {
                uniqueness_ratio: 0,
                disp12_max_diff: i32::from(i16::MAX),
                speckle_window_size: 0,
                ..sgm.clone()
            },
        }
    }
}

/// How stereo depth is searched and kept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StereoSettings {
    /// Which input camera each view is matched with.
    #[serde(default = "StereoPartner::before_choice")]
    pub partner: StereoPartner,
    /// Semi-Global Matching's parameters; the disparity range is set per pair.
    pub sgm: SgmParams,
    /// Which disparities are kept.
    #[serde(default)]
    pub checks: StereoChecks,
    /// How far in front of the hull's depth stereo may put the surface (metres).
    pub hull_front: f64,
    /// How far behind it.
    pub hull_behind: f64,
    /// Smallest fraction of a view that must land in its partner's image.
    pub min_overlap: f64,
}

impl StereoSettings {
    /// An error naming the setting when the search bracket is not a finite, non-empty range.
    pub fn check(&self) -> Result<()> {
        check_range(
            "stereo search around the hull",
            self.hull_front,
            self.hull_behind,
        )
    }
}

impl Default for StereoSettings {
    fn default() -> Self {
        let bracket = DepthBracket::default();
        Self {
            partner: StereoPartner::default(),
            sgm: SgmParams::default(),
            checks: StereoChecks::default(),
            hull_front: bracket.front as f64,
            hull_behind: bracket.behind as f64,
            min_overlap: 0.2,
        }
    }
}

/// One view as stereo reads it: a cropped input view with its mask and its hull's depth.
#[derive(Clone, Copy, Debug)]
pub struct StereoInput<'a> {
    /// Named in errors (the capture's camera name).
    pub name: &'a str,
    pub camera: &'a Camera,
    pub image: &'a Image,
    pub mask: &'a Mask,
    pub hull: &'a DepthMap,
}

/// Stereo depth of the two views of a pair.
#[derive(Clone, Debug)]
pub struct PairDepth {
    /// Per view, the stereo depth where it matched inside the hull's range and the mask, the
    /// hull's depth elsewhere.
    pub depth: [DepthMap; 2],
    /// Per view, the fraction of its masked hull pixels stereo matched.
    pub matched: [f64; 2],
}

/// The index in `cameras` of each camera's stereo partner: the other camera whose optical axis
/// is nearest its own, or second nearest (`partner`; lower index on ties). An error with too
/// few cameras.
pub fn stereo_partners(cameras: &[&Camera], partner: StereoPartner) -> Result<Vec<usize>> {
    if cameras.len() < 2 + partner.rank() {
        let m = format!(
            "needs at least {} input cameras with this partner choice",
            2 + partner.rank()
        );
        return Err(HumanError::argument("stereo depth", m));
    }
    let axis = |c: &Camera| c.world_to_camera.rotation.row(2).transpose();
    Ok((0..cameras.len())
        .map(|i| {
            let a = axis(cameras[i]);
            let mut others: Vec<(f64, usize)> = (0..cameras.len())
                .filter(|&j| j != i)
                .map(|j| (-a.dot(&axis(cameras[j])), j))
                .collect();
            others.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            others[partner.rank()].1
        })
        .collect())
}

/// Depth of `first` and `second` from Semi-Global Matching between them, searched over the
/// disparities of the hull's bracket `[hull − hull_front, hull + hull_behind]` in both views,
/// and kept per pixel only inside that bracket and the mask. An error when the two views
/// share too little of the person to be matched.
pub fn pair_depth(
    first: &StereoInput,
    second: &StereoInput,
    settings: &StereoSettings,
) -> Result<PairDepth> {
    let pair = || format!("stereo depth of {} and {}", first.name, second.name);
    let typical = median_depth(first.hull, first.mask).ok_or_else(|| {
        HumanError::argument(pair(), format!("{} sees no visual hull", first.name))
    })?;
    let overlap = overlap_fraction(first.camera, second.camera, typical);
    if overlap < settings.min_overlap {
        let m = format!(
            "the two views share {:.0} % of the image (at least {:.0} % needed): stereo needs two views of the person",
            100.0 * overlap,
            100.0 * settings.min_overlap
        );
        return Err(HumanError::argument(pair(), m));
    }
    let (rect, _) = rectify_pair(first.camera, second.camera)?;
    let (near, far) = [first, second]
        .iter()
        .filter_map(|v| rectified_depth_range(v, rect.rectified(Side::Left), settings))
        .fold((f64::INFINITY, 0.0f64), |(n, f), (a, b)| {
            (n.min(a), f.max(b))
        });
    if !(near < far) {
        return Err(HumanError::argument(
            pair(),
            "the hull is behind the cameras",
        ));
    }
    let (min, count) = exact_disparity_range(&rect, near, far);
    let stereo = match_pair(
        &stereo_view(first),
        &stereo_view(second),
        &settings.checks.applied(&settings.sgm),
        DisparityRange::Fixed { min, count },
        None,
        Photometry::AsIs,
    )?;
    let (a, ma) = keep_in_bracket(first, &stereo.depths.first.depth, settings);
    let (b, mb) = keep_in_bracket(second, &stereo.depths.second.depth, settings);
    Ok(PairDepth {
        depth: [a, b],
        matched: [ma, mb],
    })
}

fn stereo_view<'a>(v: &StereoInput<'a>) -> StereoView<'a> {
    StereoView {
        name: v.name,
        camera: v.camera,
        image: v.image,
        depth_bounds: None,
        mask: None,
        sparse_points: &[],
    }
}

/// The nearest and farthest z-depth in `rectified` of the hull's bracket over `view`'s masked
/// pixels (`None` when none has a hull depth).
fn rectified_depth_range(
    view: &StereoInput,
    rectified: &Camera,
    s: &StereoSettings,
) -> Option<(f64, f64)> {
    let w = view.hull.width;
    let mut range: Option<(f64, f64)> = None;
    for (p, &d) in view.hull.data.iter().enumerate() {
        if d <= 0.0 || !view.mask.data[p] {
            continue;
        }
        let (u, v) = ((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
        for z in [d as f64 - s.hull_front, d as f64 + s.hull_behind] {
            let x = view.camera.unproject(u, v, z.max(1e-3));
            let zr = rectified.world_to_camera.transform_point(&x).z;
            range = Some(match range {
                None => (zr, zr),
                Some((n, f)) => (n.min(zr), f.max(zr)),
            });
        }
    }
    range
}

/// `stereo` where it lies in the hull's bracket inside the mask, the hull elsewhere; and the
/// fraction of the masked hull pixels kept.
fn keep_in_bracket(view: &StereoInput, stereo: &[f32], s: &StereoSettings) -> (DepthMap, f64) {
    let (mut kept, mut candidates) = (0usize, 0usize);
    let data = view
        .hull
        .data
        .iter()
        .zip(stereo)
        .zip(&view.mask.data)
        .map(|((&h, &d), &m)| {
            if h <= 0.0 || !m {
                return h;
            }
            candidates += 1;
            let (lo, hi) = (h as f64 - s.hull_front, h as f64 + s.hull_behind);
            if d > 0.0 && (lo..=hi).contains(&(d as f64)) {
                kept += 1;
                d
            } else {
                h
            }
        })
        .collect();
    let map = DepthMap {
        width: view.hull.width,
        height: view.hull.height,
        data,
    };
    (map, kept as f64 / candidates.max(1) as f64)
}

/// The median of `depth` over the masked pixels that have one.
fn median_depth(depth: &DepthMap, mask: &Mask) -> Option<f64> {
    let mut values: Vec<f32> = depth
        .data
        .iter()
        .zip(&mask.data)
        .filter(|(d, m)| **d > 0.0 && **m)
        .map(|(d, _)| *d)
        .collect();
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    values.select_nth_unstable_by(mid, f32::total_cmp);
    Some(values[mid] as f64)
}

/// Mean `|d_t − d_{t−1}|` (metres) over consecutive frames of one camera, over the pixels that
/// both frames' masks cover and both depths know; `None` with fewer than two frames or no such
/// pixel. `frames` are in time order.
pub fn flicker(frames: &[(&DepthMap, &Mask)]) -> Option<f64> {
    mean_change(frames, |v| v > 0.0)
}

/// Mean `|v_t − v_{t−1}|` over consecutive frames, over the pixels both masks cover where both
/// values are `known`.
pub(crate) fn mean_change(frames: &[(&DepthMap, &Mask)], known: fn(f32) -> bool) -> Option<f64> {
    let (mut sum, mut count) = (0.0f64, 0usize);
    for pair in frames.windows(2) {
        let ((d0, m0), (d1, m1)) = (pair[0], pair[1]);
        for p in 0..d0.data.len().min(d1.data.len()) {
            let (a, b) = (d0.data[p], d1.data[p]);
            if m0.data[p] && m1.data[p] && known(a) && known(b) {
                sum += (a - b).abs() as f64;
                count += 1;
            }
        }
    }
    (count > 0).then(|| sum / count as f64)
}

#[cfg(test)]
mod tests {
    use fewview_scene::Intrinsics;
    use nalgebra::Vector3;

    use super::*;

    const SIZE: u32 = 160;

    /// A camera on a circle of radius 3 around the origin at `degrees`, looking at the origin.
    fn ring_camera(degrees: f64) -> Camera {
        let a = degrees.to_radians();
        Camera::look_at(
            Intrinsics::centered(200.0, SIZE, SIZE),
            Vector3::new(3.0 * a.sin(), 0.0, -3.0 * a.cos()),
            Vector3::zeros(),
            -Vector3::y(),
        )
    }

    /// A textured plane `z = 0.4` (world) seen by `camera`: the image (a pattern with energy
    /// at every scale, fixed on the plane, flat grey where `x > blank_from`) and the exact
    /// z-depth.
    fn plane_view(camera: &Camera, blank_from: f64) -> (Image, DepthMap) {
        let n = SIZE as usize;
        let (mut image, mut depth) = (Image::new(n, n, 3), vec![0.0f32; n * n]);
        for p in 0..n * n {
            let (o, d) = camera.ray((p % n) as f64 + 0.5, (p / n) as f64 + 0.5);
            let t = (0.4 - o.z) / d.z;
            let x = o + d * t;
            let texture = |s: f64| ((x.x * s).sin() * (x.y * 1.3 * s).cos() + 1.0) / 2.0;
            let mut v = (0.5 * texture(17.0) + 0.3 * texture(41.0) + 0.2 * texture(97.0)) as f32;
            if x.x > blank_from {
                v = 0.5;
            }
            image.data[3 * p..3 * p + 3].copy_from_slice(&[v, 0.8 * v + 0.1, 1.0 - v]);
            depth[p] = camera.world_to_camera.transform_point(&x).z as f32;
        }
        let depth = DepthMap {
            width: n,
            height: n,
            data: depth,
        };
        (image, depth)
    }

    fn shifted(d: &DepthMap, by: f32) -> DepthMap {
        DepthMap {
            data: d.data.iter().map(|v| v + by).collect(),
            ..d.clone()
        }
    }

    /// Stereo of the plane between ring cameras at `first` and `second` degrees, with hulls
    /// `hull_offset` metres off the exact depth; and the exact depths.
    fn plane_stereo(
        first: f64,
        second: f64,
        hull_offset: f32,
    ) -> (Result<PairDepth>, [DepthMap; 2]) {
        let s = StereoSettings::default();
        plane_stereo_with(first, second, hull_offset, f64::INFINITY, &s)
    }

    /// [`plane_stereo`] with the plane blank where `x > blank_from`, and settings `s`.
    fn plane_stereo_with(
        first: f64,
        second: f64,
        hull_offset: f32,
        blank_from: f64,
        s: &StereoSettings,
    ) -> (Result<PairDepth>, [DepthMap; 2]) {
        let (a, b) = (ring_camera(first), ring_camera(second));
        let ((ia, ga), (ib, gb)) = (plane_view(&a, blank_from), plane_view(&b, blank_from));
        let (ha, hb) = (shifted(&ga, hull_offset), shifted(&gb, hull_offset));
        let n = SIZE as usize;
        let mask = Mask::new(n, n, vec![true; n * n]);
        let input = |camera, image, hull| StereoInput {
            name: "cam",
            camera,
            image,
            mask: &mask,
            hull,
        };
        let got = pair_depth(&input(&a, &ia, &ha), &input(&b, &ib, &hb), s);
        (got, [ga, gb])
    }

    #[test]
    fn each_camera_pairs_with_the_nearest_optical_axis() {
        let cameras: Vec<Camera> = [0.0, 30.0, 90.0, 120.0, 180.0, 200.0]
            .iter()
            .map(|&d| ring_camera(d))
            .collect();
        let refs: Vec<&Camera> = cameras.iter().collect();
        assert_eq!(
            stereo_partners(&refs, StereoPartner::Nearest).unwrap(),
            vec![1, 0, 3, 2, 5, 4]
        );
        let err = stereo_partners(&refs[..1], StereoPartner::Nearest)
            .unwrap_err()
            .to_string();
        assert!(err.contains("at least 2"), "{err}");
    }

    #[test]
    fn the_second_nearest_partner_on_the_papers_ring_is_the_other_source() {
        // Input cameras of a 12-camera ring with every third one held out (2, 5, 8, 11): each
        // pairs with the other camera flanking its held-out neighbour.
        let cameras: Vec<Camera> = [0.0, 30.0, 90.0, 120.0, 180.0, 210.0, 270.0, 300.0]
            .iter()
            .map(|&d| ring_camera(d))
            .collect();
        let refs: Vec<&Camera> = cameras.iter().collect();
        assert_eq!(
            stereo_partners(&refs, StereoPartner::SecondNearest).unwrap(),
            vec![7, 2, 1, 4, 3, 6, 5, 0]
        );
        let err = stereo_partners(&refs[..2], StereoPartner::SecondNearest)
            .unwrap_err()
            .to_string();
        assert!(err.contains("at least 3"), "{err}");
    }

    #[test]
    fn stereo_finds_a_textured_plane_and_keeps_only_the_hulls_bracket() {
        // The hull lies 2 cm in front of the surface, as a visual hull does.
        let (got, [ga, gb]) = plane_stereo(-12.0, 12.0, -0.02);
        let got = got.unwrap();
        for (k, truth) in [&ga, &gb].iter().enumerate() {
            assert!(got.matched[k] > 0.6, "matched {:?}", got.matched);
            let mut errors: Vec<f32> = (got.depth[k].data.iter().zip(&truth.data))
                .map(|(d, g)| (d - g).abs())
                .collect();
            errors.sort_by(f32::total_cmp);
            // One pixel of disparity is about 46 mm of depth here: the median within a fifth
            // of a pixel; nothing outside the bracket [hull − 3 cm, hull + 12 cm].
            assert!(
                errors[errors.len() / 2] < 0.01,
                "median {}",
                errors[errors.len() / 2]
            );
            assert!(
                *errors.last().unwrap() < 0.121,
                "worst {}",
                errors.last().unwrap()
            );
        }
    }

    #[test]
    fn dense_stereo_keeps_what_the_checks_drop_on_a_blank_wall() {
        // Half the plane is flat grey, where SGM's winner is a guess: OpenCV's checks drop
        // more of it than the dense setting, which keeps every winner inside the bracket. On
        // the textured plane the two agree.
        let run = |checks, blank_from| {
            let s = StereoSettings {
                checks,
                ..StereoSettings::default()
            };
            let (got, [truth, _]) = plane_stereo_with(-12.0, 12.0, -0.02, blank_from, &s);
            (got.unwrap(), truth)
        };
        let (checked, truth) = run(StereoChecks::Opencv, 0.0);
        let (dense, _) = run(StereoChecks::Dense, 0.0);
        let gained: Vec<f64> = (0..2)
            .map(|k| dense.matched[k] - checked.matched[k])
            .collect();
        assert!(
            gained.iter().all(|&g| g >= 0.0) && gained.iter().sum::<f64>() > 0.04,
            "matched: checked {:?}, dense {:?}",
            checked.matched,
            dense.matched
        );
        let worst = (dense.depth[0].data.iter().zip(&truth.data))
            .map(|(d, g)| (d - g).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 0.121, "worst {worst}");
        let (checked, _) = run(StereoChecks::Opencv, f64::INFINITY);
        let (dense, _) = run(StereoChecks::Dense, f64::INFINITY);
        for k in 0..2 {
            assert!((dense.matched[k] - checked.matched[k]).abs() < 0.01);
        }
    }

    #[test]
    fn a_search_or_bracket_that_is_not_a_range_is_an_error() {
        for (front, behind) in [(-0.1, 0.2), (0.0, 0.0), (f64::NAN, 0.1)] {
            let s = StereoSettings {
                hull_front: front,
                hull_behind: behind,
                ..StereoSettings::default()
            };
            let err = s.check().unwrap_err().to_string();
            assert!(
                err.contains("stereo search") && err.contains("metres"),
                "{err}"
            );
            let b = DepthBracket {
                front: front as f32,
                behind: behind as f32,
            };
            assert!(b.check().unwrap_err().to_string().contains("depth bracket"));
        }
        assert!(StereoSettings::default().check().is_ok());
        assert!(DepthBracket::default().check().is_ok());
    }

    #[test]
    fn stereo_of_views_that_share_nothing_is_an_error() {
        let err = plane_stereo(0.0, 180.0, 0.0).0.unwrap_err().to_string();
        assert!(err.contains("share") && err.contains("cam"), "{err}");
    }

    #[test]
    fn flicker_is_the_mean_change_over_pixels_both_masks_cover() {
        let map = |v: [f32; 3]| DepthMap {
            width: 3,
            height: 1,
            data: v.to_vec(),
        };
        let mask = |m: [bool; 3]| Mask::new(3, 1, m.to_vec());
        let (d0, d1, d2) = (
            map([1.0, 2.0, 3.0]),
            map([1.5, 2.0, 0.0]),
            map([1.5, 1.0, 5.0]),
        );
        let (m0, m1) = (mask([true, true, true]), mask([true, true, false]));
        // Frame 0→1: |0.5|, |0| (pixel 2 has no depth in frame 1); 1→2: 0 and 1 (pixel 2
        // outside frame 1's mask). Mean of 0.5, 0, 0, 1.
        let got = flicker(&[(&d0, &m0), (&d1, &m1), (&d2, &m0)]).unwrap();
        assert!((got - 0.375).abs() < 1e-9, "{got}");
        assert_eq!(flicker(&[(&d0, &m0)]), None);
    }
}
