//! The confidence-based hierarchical point cloud of the fusion paper §2 (its Fig. 1): stereo depth of
//! every pair of adjacent training views, back-projected and accepted in three tiers of falling
//! confidence, so that doubtful depth may only add geometry *behind* what is already trusted.
//!
//! 1. Every depth map of a pair is filtered with the depth-edge test of Eq. (1). Its measure is
//!    `1/(fₓ f_y)` on a plane facing the camera, so τ = 1e-4 would drop every pixel of an image
//!    whose focal length is below 100 px; τ is raised to [`FLAT_MARGIN`]`/(fₓ f_y)` where that is
//!    larger (an image of a few hundred pixels; at the paper's sizes τ stays as printed).
//! 2. Each pixel with depth is classified against the pair's other view: **R^c** (pairwise
//!    consistent) when its point lands in the partner's image, the partner's depth there
//!    (interpolated) back-projects to within `max_reprojection_px` of the pixel and agrees with
//!    the pixel's depth to `max_relative_depth` (the geometric-consistency filter of MVSNet, with
//!    the 1 px and 1 %); **R^o** (overlap with occlusion or mismatch) when it lands in the
//!    partner's image but fails that; **R^s** (seen by one view only) when it does not land in the
//!    partner's image. A view in several pairs keeps, per pixel, its most confident class.
//! 3. R^c points are accepted first. R^o points are then accepted only where they do not lie in
//!    front of accepted geometry as seen from any training view (their depth there is not below
//!    the nearest accepted depth at that pixel by more than `free_space_margin`): the paper notes
//!    that farther-than-true depths do little harm while closer ones degrade the result. R^s
//!    points follow with the same test against R^c and the accepted R^o.
//! 4. The cloud is contracted with Eq. (2) (`T`, `B_near`, `B_far` from the pairs' depth maps as
//!    [`crate::contract`] reads §2), and [`HierarchicalCloud::sample`] draws the paper's 10 % for
//!    the initial Gaussians.

use fewview_scene::{Camera, Image};
use nalgebra::Vector3;
use rayon::prelude::*;

use super::pairs::StereoView;
use super::source::DepthSource;
use super::view_depth::{PairDepths, ViewDepth};
use crate::contract::{Contraction, ContractionKind, contraction_reference, sample_indices};
use crate::depth::{DepthOptions, valid_pixels};
use crate::error::{GeomError, Result};
use crate::mesh::Points;

/// The smallest Eq. (1) threshold, in units of a camera-facing plane's measure `1/(fₓ f_y)`.
pub const FLAT_MARGIN: f64 = 4.0;

/// The three confidence tiers of Fig. 1, most confident first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Region {
    /// R^c: consistent between the two views of a pair.
    Consistent,
    /// R^o: inside the partner's view, but occluded there or mismatched.
    Overlap,
    /// R^s: seen by one view of the pair only.
    Single,
}

impl Region {
    pub const ALL: [Region; 3] = [Region::Consistent, Region::Overlap, Region::Single];

    /// Fig. 1's colour coding: red R^c, green R^o, blue R^s.
    pub fn color(self) -> [f32; 3] {
        match self {
            Region::Consistent => [1.0, 0.0, 0.0],
            Region::Overlap => [0.0, 1.0, 0.0],
            Region::Single => [0.0, 0.0, 1.0],
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// Tolerances of the hierarchical cloud.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HierarchyOptions {
    /// Largest forward–backward reprojection error (pixels) of an R^c pixel.
    pub max_reprojection_px: f64,
    /// Largest relative depth difference of an R^c pixel.
    pub max_relative_depth: f64,
    /// How far (relative) a later-tier point may lie in front of accepted geometry.
    pub free_space_margin: f64,
    /// Fewest R^c pixels among an R^c pixel's 8 neighbours; with fewer it counts as R^o.
    pub min_consistent_neighbours: usize,
    /// The depth-edge filter of Eq. (1) applied to every depth map.
    #[serde(skip, default)]
    pub depth: DepthOptions,
    /// The contraction of Eq. (2); `None` keeps the points where they are.
    #[serde(skip, default = "default_contraction")]
    pub contraction: Option<ContractionKind>,
    /// Quantile of the pooled depths taken as `B_near` (see [`crate::contract`]).
    pub contraction_quantile: f64,
}

fn default_contraction() -> Option<ContractionKind> {
    Some(ContractionKind::Paper)
}

impl Default for HierarchyOptions {
    fn default() -> Self {
        Self {
            max_reprojection_px: 1.0,
            max_relative_depth: 0.01,
            free_space_margin: 0.01,
            min_consistent_neighbours: 4,
            depth: DepthOptions::default(),
            contraction: default_contraction(),
            contraction_quantile: 0.9,
        }
    }
}

/// Per region: pixels classified into it, and points accepted from it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RegionCounts {
    pub candidates: [usize; 3],
    pub accepted: [usize; 3],
}

/// The accepted points, their tiers and where they came from.
#[derive(Clone, Debug)]
pub struct HierarchicalCloud {
    /// World positions (contracted when the options ask for it) and the pixels' colours.
    pub points: Points,
    pub regions: Vec<Region>,
    /// The training view and pixel (row-major index) each point was seen at.
    pub sources: Vec<(u32, u32)>,
    pub counts: RegionCounts,
    pub contraction: Option<Contraction>,
    /// Per training view, the tier of the point accepted at each pixel.
    pub pixel_regions: Vec<Vec<Option<Region>>>,
    /// Per training view, the z-depth (before any contraction) of the point accepted at each
    /// pixel, 0 where none.
    pub pixel_depths: Vec<Vec<f32>>,
    /// The pairs whose depth could not be had (view indices), each with the reason.
    pub skipped: Vec<(usize, usize, String)>,
}

/// A pixel's best class over its view's pairs, with the depth that gave it.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    region: Region,
    depth: f32,
}

/// Builds the cloud for `views` from the depth `source` gives for each of `pairs`; a pair whose
/// depth cannot be had is skipped and listed with its reason ([`HierarchicalCloud::skipped`]),
/// and an error only says that no pair gave depth. `on_pair(done, total)` reports progress
/// after each pair.
pub fn hierarchical_cloud(
    views: &[StereoView],
    pairs: &[(usize, usize)],
    source: &dyn DepthSource,
    options: &HierarchyOptions,
    on_pair: &mut dyn FnMut(usize, usize),
) -> Result<HierarchicalCloud> {
    let mut best: Vec<Vec<Option<Candidate>>> = views
        .iter()
        .map(|v| vec![None; pixel_count(v.camera)])
        .collect();
    let mut filtered: Vec<(Vec<f32>, usize)> = Vec::new();
    let mut skipped = Vec::new();
    for (k, &(a, b)) in pairs.iter().enumerate() {
        let PairDepths { first, second } = match source.pair_depths(a, b) {
            Ok(depths) => depths,
            Err(e) => {
                skipped.push((a, b, e.to_string()));
                on_pair(k + 1, pairs.len());
                continue;
            }
        };
        let da = edge_filtered(first, &views[a], options)?;
        let db = edge_filtered(second, &views[b], options)?;
        let mut ca = classify(&views[a], &da, &views[b], &db, options);
        let mut cb = classify(&views[b], &db, &views[a], &da, options);
        demote_isolated(
            &mut ca,
            views[a].camera.width() as usize,
            options.min_consistent_neighbours,
        );
        demote_isolated(
            &mut cb,
            views[b].camera.width() as usize,
            options.min_consistent_neighbours,
        );
        keep_most_confident(&mut best[a], &ca, &da.depth);
        keep_most_confident(&mut best[b], &cb, &db.depth);
        filtered.push((da.depth, a));
        filtered.push((db.depth, b));
        on_pair(k + 1, pairs.len());
    }
    if filtered.is_empty() {
        let reasons: Vec<String> = skipped.iter().map(|(_, _, why)| why.clone()).collect();
        return Err(GeomError::invalid(
            "stereo pairs",
            format!("no pair gave depth: {}", reasons.join("; ")),
        ));
    }
    let cameras: Vec<&Camera> = views.iter().map(|v| v.camera).collect();
    let mut accepted = Accepted::new(&cameras);
    let mut counts = RegionCounts::default();
    for region in Region::ALL {
        let tier: Vec<(usize, usize, f32)> = best
            .iter()
            .enumerate()
            .flat_map(|(v, px)| {
                px.iter().enumerate().filter_map(move |(p, c)| {
                    c.filter(|c| c.region == region).map(|c| (v, p, c.depth))
                })
            })
            .collect();
        counts.candidates[region.index()] = tier.len();
        let points: Vec<(usize, usize, Vector3<f64>)> = tier
            .into_par_iter()
            .map(|(v, p, d)| (v, p, unproject_pixel(views[v].camera, p, d)))
            .filter(|(_, _, x)| {
                region == Region::Consistent
                    || !accepted.occludes(x, &cameras, options.free_space_margin)
            })
            .collect();
        counts.accepted[region.index()] = points.len();
        accepted.add(points, region, &cameras);
    }
    let contraction = match options.contraction {
        Some(kind) => Some(contraction_of(&filtered, views, options, kind)?),
        None => None,
    };
    let mut cloud = accepted.into_cloud(views, counts, contraction);
    cloud.skipped = skipped;
    Ok(cloud)
}

fn pixel_count(camera: &Camera) -> usize {
    camera.width() as usize * camera.height() as usize
}

/// `depth` with the pixels that fail Eq. (1), or lie outside the view's mask, set to 0; the error
/// names the view.
fn edge_filtered(
    mut depth: ViewDepth,
    view: &StereoView,
    o: &HierarchyOptions,
) -> Result<ViewDepth> {
    let name = || format!("depth of view {}", view.name);
    if depth.verified.len() != depth.depth.len() {
        return Err(GeomError::invalid(
            name(),
            "verified mask and depth differ in size",
        ));
    }
    let k = &view.camera.intrinsics;
    let options = DepthOptions {
        // τ ≤ 0 turns the filter off, and stays off.
        tau: if o.depth.tau > 0.0 {
            o.depth.tau.max((FLAT_MARGIN / (k.fx * k.fy)) as f32)
        } else {
            o.depth.tau
        },
        ..o.depth
    };
    let keep = valid_pixels(&depth.depth, view.camera, &options)
        .map_err(|e| GeomError::invalid(name(), e.to_string()))?;
    let mask = view.mask.map(|m| &m.data);
    if mask.is_some_and(|m| m.len() != depth.depth.len()) {
        return Err(GeomError::invalid(
            name(),
            "the mask's size differs from the depth map's",
        ));
    }
    for (p, ((d, v), k)) in depth
        .depth
        .iter_mut()
        .zip(&mut depth.verified)
        .zip(keep)
        .enumerate()
    {
        if !k || mask.is_some_and(|m| m[p] < 0.5) {
            *d = 0.0;
            *v = false;
        }
    }
    Ok(depth)
}

fn unproject_pixel(camera: &Camera, p: usize, depth: f32) -> Vector3<f64> {
    let w = camera.width() as usize;
    camera.unproject((p % w) as f64 + 0.5, (p / w) as f64 + 0.5, depth as f64)
}

/// The region of every pixel of `own` with depth, judged against `partner`. Only verified depths
/// on both sides can be consistent.
fn classify(
    own: &StereoView,
    own_depth: &ViewDepth,
    partner: &StereoView,
    partner_depth: &ViewDepth,
    o: &HierarchyOptions,
) -> Vec<Option<Region>> {
    let (w, pw, ph) = (
        own.camera.width() as usize,
        partner.camera.width() as usize,
        partner.camera.height() as usize,
    );
    let checked: Vec<f32> = partner_depth
        .depth
        .iter()
        .zip(&partner_depth.verified)
        .map(|(&d, &v)| if v { d } else { 0.0 })
        .collect();
    own_depth
        .depth
        .par_iter()
        .enumerate()
        .map(|(p, &d)| {
            if d <= 0.0 {
                return None;
            }
            let x = unproject_pixel(own.camera, p, d);
            let Some((u, v, _)) = partner.camera.project(&x) else {
                return Some(Region::Single);
            };
            if !(u >= 0.0 && v >= 0.0 && u < pw as f64 && v < ph as f64) {
                return Some(Region::Single);
            }
            let consistent = own_depth.verified[p]
                && sample_depth(&checked, pw, ph, u, v).is_some_and(|dq| {
                    let back = partner.camera.unproject(u, v, dq);
                    own.camera.project(&back).is_some_and(|(bu, bv, bz)| {
                        let (pu, pv) = ((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
                        (bu - pu).hypot(bv - pv) < o.max_reprojection_px
                            && (bz - d as f64).abs() < o.max_relative_depth * d as f64
                    })
                });
            Some(if consistent {
                Region::Consistent
            } else {
                Region::Overlap
            })
        })
        .collect()
}

/// Demotes to R^o every R^c pixel with fewer than `min` R^c pixels among its 8 neighbours: a
/// consistent pixel alone among inconsistent ones agrees by chance more often than not (at
/// occlusion borders, where both views' windows straddle the same edge).
fn demote_isolated(classes: &mut [Option<Region>], width: usize, min: usize) {
    if min == 0 || width == 0 {
        return;
    }
    let height = classes.len() / width;
    let consistent: Vec<bool> = classes
        .iter()
        .map(|c| *c == Some(Region::Consistent))
        .collect();
    for y in 0..height {
        for x in 0..width {
            if !consistent[y * width + x] {
                continue;
            }
            let mut n = 0;
            for yy in y.saturating_sub(1)..(y + 2).min(height) {
                for xx in x.saturating_sub(1)..(x + 2).min(width) {
                    n += ((xx, yy) != (x, y) && consistent[yy * width + xx]) as usize;
                }
            }
            if n < min {
                classes[y * width + x] = Some(Region::Overlap);
            }
        }
    }
}

/// The depth of `map` at continuous pixel coordinates `(u, v)`: bilinear when the four
/// surrounding pixels have depth within 1 % of each other, else the nearest pixel's depth.
fn sample_depth(map: &[f32], w: usize, h: usize, u: f64, v: f64) -> Option<f64> {
    let (x, y) = (u - 0.5, v - 0.5);
    let (x0, y0) = (x.floor().max(0.0) as usize, y.floor().max(0.0) as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let q = [
        map[y0 * w + x0],
        map[y0 * w + x1],
        map[y1 * w + x0],
        map[y1 * w + x1],
    ];
    let (lo, hi) = q
        .iter()
        .fold((f32::MAX, 0f32), |(l, h), &d| (l.min(d), h.max(d)));
    if lo > 0.0 && hi <= 1.01 * lo {
        let (fx, fy) = (
            (x - x0 as f64).clamp(0.0, 1.0),
            (y - y0 as f64).clamp(0.0, 1.0),
        );
        let top = q[0] as f64 * (1.0 - fx) + q[1] as f64 * fx;
        let bottom = q[2] as f64 * (1.0 - fx) + q[3] as f64 * fx;
        return Some(top * (1.0 - fy) + bottom * fy);
    }
    let (nx, ny) = (
        (u.floor() as usize).min(w - 1),
        (v.floor() as usize).min(h - 1),
    );
    let d = map[ny * w + nx];
    (d > 0.0).then_some(d as f64)
}

/// Keeps, per pixel, the more confident of the stored candidate and this pair's class (with the
/// depth that gave it).
fn keep_most_confident(best: &mut [Option<Candidate>], classes: &[Option<Region>], depth: &[f32]) {
    for ((b, c), &d) in best.iter_mut().zip(classes).zip(depth) {
        if let Some(region) = *c
            && b.is_none_or(|old| region < old.region)
        {
            *b = Some(Candidate { region, depth: d });
        }
    }
}

/// Accepted points so far and, per training view, the nearest accepted depth at each pixel.
struct Accepted {
    positions: Vec<Vector3<f64>>,
    regions: Vec<Region>,
    sources: Vec<(u32, u32)>,
    nearest: Vec<Vec<f32>>,
}

impl Accepted {
    fn new(cameras: &[&Camera]) -> Self {
        Self {
            positions: Vec::new(),
            regions: Vec::new(),
            sources: Vec::new(),
            nearest: cameras
                .iter()
                .map(|c| vec![f32::INFINITY; pixel_count(c)])
                .collect(),
        }
    }

    /// Whether `x` lies in front of accepted geometry as seen from any of `cameras`.
    fn occludes(&self, x: &Vector3<f64>, cameras: &[&Camera], margin: f64) -> bool {
        cameras.iter().zip(&self.nearest).any(|(cam, nearest)| {
            // An empty pixel (infinite nearest depth) hides nothing.
            cam.pixel_of(x).is_some_and(|(p, z)| {
                nearest[p].is_finite() && z < nearest[p] as f64 * (1.0 - margin)
            })
        })
    }

    fn add(&mut self, points: Vec<(usize, usize, Vector3<f64>)>, region: Region, cams: &[&Camera]) {
        for (cam, nearest) in cams.iter().zip(self.nearest.iter_mut()) {
            for (_, _, x) in &points {
                if let Some((p, z)) = cam.pixel_of(x) {
                    nearest[p] = nearest[p].min(z as f32);
                }
            }
        }
        for (v, p, x) in points {
            self.positions.push(x);
            self.regions.push(region);
            self.sources.push((v as u32, p as u32));
        }
    }

    fn into_cloud(
        self,
        views: &[StereoView],
        counts: RegionCounts,
        contraction: Option<Contraction>,
    ) -> HierarchicalCloud {
        let mut pixel_regions: Vec<Vec<Option<Region>>> = views
            .iter()
            .map(|v| vec![None; pixel_count(v.camera)])
            .collect();
        let mut pixel_depths: Vec<Vec<f32>> = views
            .iter()
            .map(|v| vec![0.0; pixel_count(v.camera)])
            .collect();
        let mut colors = Vec::with_capacity(self.positions.len());
        for ((&(v, p), &r), x) in self.sources.iter().zip(&self.regions).zip(&self.positions) {
            let camera = views[v as usize].camera;
            pixel_regions[v as usize][p as usize] = Some(r);
            pixel_depths[v as usize][p as usize] =
                camera.world_to_camera.transform_point(x).z as f32;
            colors.push(pixel_color(views[v as usize].image, p as usize));
        }
        let positions = self
            .positions
            .iter()
            .map(|x| {
                let y = contraction.as_ref().map_or(*x, |c| c.apply(x));
                [y.x as f32, y.y as f32, y.z as f32]
            })
            .collect();
        HierarchicalCloud {
            points: Points {
                positions,
                colors: Some(colors),
                normals: None,
            },
            regions: self.regions,
            sources: self.sources,
            counts,
            contraction,
            pixel_regions,
            pixel_depths,
            skipped: Vec::new(),
        }
    }
}

fn pixel_color(image: &Image, p: usize) -> [f32; 3] {
    let px = &image.data[p * image.channels..(p + 1) * image.channels];
    if image.channels < 3 {
        [px[0]; 3]
    } else {
        [px[0], px[1], px[2]]
    }
}

/// Eq. (2)'s reference camera and bounds from the pairs' (edge-filtered) depth maps.
fn contraction_of(
    maps: &[(Vec<f32>, usize)],
    views: &[StereoView],
    o: &HierarchyOptions,
    kind: ContractionKind,
) -> Result<Contraction> {
    let list: Vec<(&[f32], &Camera)> = maps
        .iter()
        .map(|(d, v)| (d.as_slice(), views[*v].camera))
        .collect();
    let no_filter = DepthOptions {
        tau: 0.0,
        ..o.depth
    };
    let mut c = contraction_reference(&list, &no_filter, o.contraction_quantile, kind)?;
    c.view = c.view.map(|k| maps[k].1);
    Ok(c)
}

impl HierarchicalCloud {
    /// A random `fraction` of the points (the fusion paper: 0.1; alternative (a): 0.01), in order, with
    /// their regions.
    pub fn sample(&self, fraction: f64, seed: u64) -> Result<(Points, Vec<Region>)> {
        let idx = sample_indices(self.points.len(), fraction, seed)?;
        let regions = idx.iter().map(|&i| self.regions[i]).collect();
        Ok((self.points.select(&idx), regions))
    }

    /// The points coloured by region (Fig. 1).
    pub fn region_colored(&self) -> Points {
        Points {
            positions: self.points.positions.clone(),
            colors: Some(self.regions.iter().map(|r| r.color()).collect()),
            normals: None,
        }
    }

    /// The cloud seen from `camera` (Fig. 1): each point a `dot`×`dot` square in its region's
    /// colour, nearest first, on black. Contraction moves points along rays from `T`, so the
    /// contraction view ([`Contraction::view`]) shows them where the stereo saw them.
    pub fn render_regions(&self, camera: &Camera, dot: usize) -> Image {
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let mut img = Image::new(w, h, 3);
        let mut zbuf = vec![f64::INFINITY; w * h];
        let dot = dot.max(1) as i64;
        for (p, r) in self.points.positions.iter().zip(&self.regions) {
            let x = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let Some((u, v, z)) = camera.project(&x) else {
                continue;
            };
            let (u0, v0) = (u.floor() as i64 - dot / 2, v.floor() as i64 - dot / 2);
            for j in v0.max(0)..(v0 + dot).min(h as i64) {
                for i in u0.max(0)..(u0 + dot).min(w as i64) {
                    let k = j as usize * w + i as usize;
                    if z < zbuf[k] {
                        zbuf[k] = z;
                        img.data[3 * k..3 * k + 3].copy_from_slice(&r.color());
                    }
                }
            }
        }
        img
    }

    /// The region map of training view `view`: Fig. 1's colours where a point was accepted,
    /// black elsewhere.
    pub fn region_map(&self, view: usize, width: usize, height: usize) -> Image {
        let mut img = Image::new(width, height, 3);
        for (p, r) in self.pixel_regions[view].iter().enumerate() {
            if let Some(r) = r {
                img.data[p * 3..p * 3 + 3].copy_from_slice(&r.color());
            }
        }
        img
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stereo::source::DepthMapSource;
    use fewview_scene::{Intrinsics, Se3};
    use nalgebra::Matrix3;

    /// A camera at `(x, 0, 0)` looking along world +z (f = 300 px, so that a flat pixel's
    /// Eq. (1) measure, 1/f², stays below τ = 1e-4).
    fn camera(x: f64) -> Camera {
        Camera::new(
            Intrinsics::centered(300.0, 80, 60),
            Se3::new(Matrix3::identity(), Vector3::new(-x, 0.0, 0.0)),
        )
    }

    fn view<'a>(name: &'a str, camera: &'a Camera, image: &'a Image) -> StereoView<'a> {
        StereoView {
            name,
            camera,
            image,
            depth_bounds: Some((2.0, 10.0)),
            mask: None,
            sparse_points: &[],
        }
    }

    #[test]
    fn closer_outliers_are_refused_and_farther_ones_kept() {
        // A wall at z = 5 seen by two cameras 0.4 apart; view b's depth is exact except two
        // patches: one 20 % too close, one 25 % too far.
        let (ca, cb) = (camera(0.0), camera(0.4));
        let image = Image::new(80, 60, 3);
        let views = [view("a", &ca, &image), view("b", &cb, &image)];
        let exact = vec![5.0f32; 80 * 60];
        let mut wrong = exact.clone();
        let close = |x: usize, y: usize| (10..16).contains(&x) && (20..26).contains(&y);
        let far = |x: usize, y: usize| (30..36).contains(&x) && (20..26).contains(&y);
        for y in 0..60 {
            for x in 0..80 {
                if close(x, y) {
                    wrong[y * 80 + x] = 4.0;
                } else if far(x, y) {
                    wrong[y * 80 + x] = 6.25;
                }
            }
        }
        let source = DepthMapSource {
            maps: vec![exact, wrong],
        };
        let options = HierarchyOptions {
            contraction: None,
            ..Default::default()
        };
        let cloud =
            hierarchical_cloud(&views, &[(0, 1)], &source, &options, &mut |_, _| {}).unwrap();
        let region_of = |v: usize, x: usize, y: usize| cloud.pixel_regions[v][y * 80 + x];
        // The far patch is inconsistent but lies behind the wall: kept as R^o.
        assert_eq!(region_of(1, 32, 22), Some(Region::Overlap));
        // The close patch lies in front of the wall as view a sees it: refused.
        assert_eq!(region_of(1, 12, 22), None);
        // The wall itself is consistent in both views; b's last columns and a's first see what
        // the other cannot (a spans x ∈ [-0.67, 0.67] at z = 5, b [-0.27, 1.07]): R^s.
        assert_eq!(region_of(0, 50, 40), Some(Region::Consistent));
        assert_eq!(region_of(1, 50, 40), Some(Region::Consistent));
        assert_eq!(region_of(1, 75, 40), Some(Region::Single));
        assert_eq!(region_of(0, 5, 40), Some(Region::Single));
        // Eq. (1) drops the patches' border pixels: 5×5 of the close patch remain, all refused.
        let c = cloud.counts;
        assert_eq!(c.candidates[1] - c.accepted[1], 25, "{c:?}");
        assert_eq!(c.candidates[0], c.accepted[0]);
        assert_eq!(c.candidates[2], c.accepted[2]);
        // Every accepted point has its pixel's colour and the depth it was given.
        for (k, &(v, p)) in cloud.sources.iter().enumerate() {
            let cam = views[v as usize].camera;
            let z = cam
                .world_to_camera
                .transform_point(&crate::mesh::v3(&cloud.points.positions[k]))
                .z;
            let want = source.maps[v as usize][p as usize] as f64;
            assert!((z - want).abs() < 1e-4, "point {k}: {z} vs {want}");
        }
    }

    /// Depth maps for every pair but one, which fails as a pair without overlap would.
    struct OnePairFails(DepthMapSource);

    impl DepthSource for OnePairFails {
        fn name(&self) -> &str {
            "test"
        }
        fn pair_depths(&self, first: usize, second: usize) -> Result<PairDepths> {
            if (first, second) == (1, 2) {
                return Err(GeomError::invalid("views b and c", "they share nothing"));
            }
            self.0.pair_depths(first, second)
        }
    }

    /// A pair that gives no depth is skipped and listed with its reason; the other pair's points
    /// stay. When no pair gives depth, the error lists every reason.
    #[test]
    fn a_pair_without_depth_is_skipped_with_its_reason() {
        let cameras = [camera(0.0), camera(0.4), camera(30.0)];
        let image = Image::new(80, 60, 3);
        let views = [
            view("a", &cameras[0], &image),
            view("b", &cameras[1], &image),
            view("c", &cameras[2], &image),
        ];
        let source = OnePairFails(DepthMapSource {
            maps: vec![vec![5.0f32; 80 * 60]; 3],
        });
        let options = HierarchyOptions {
            contraction: None,
            ..Default::default()
        };
        let mut reported = Vec::new();
        let cloud =
            hierarchical_cloud(&views, &[(0, 1), (1, 2)], &source, &options, &mut |d, n| {
                reported.push((d, n));
            })
            .unwrap();
        assert_eq!(cloud.skipped.len(), 1);
        let (a, b, why) = &cloud.skipped[0];
        assert_eq!((*a, *b), (1, 2));
        assert!(
            why.contains("views b and c") && why.contains("share nothing"),
            "{why}"
        );
        assert!(cloud.counts.accepted[0] > 1000, "{:?}", cloud.counts);
        assert_eq!(reported, [(1, 2), (2, 2)]);
        let e = hierarchical_cloud(&views, &[(1, 2)], &source, &options, &mut |_, _| {})
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no pair gave depth") && e.contains("share nothing"),
            "{e}"
        );
    }

    #[test]
    fn a_pixel_keeps_its_most_confident_class_over_pairs() {
        let mut best = vec![None; 3];
        keep_most_confident(
            &mut best,
            &[Some(Region::Single), Some(Region::Overlap), None],
            &[1.0, 2.0, 3.0],
        );
        keep_most_confident(
            &mut best,
            &[
                Some(Region::Consistent),
                Some(Region::Single),
                Some(Region::Overlap),
            ],
            &[4.0, 5.0, 6.0],
        );
        let got: Vec<_> = best
            .iter()
            .map(|c| c.map(|c| (c.region, c.depth)))
            .collect();
        assert_eq!(
            got,
            vec![
                Some((Region::Consistent, 4.0)),
                Some((Region::Overlap, 2.0)),
                Some((Region::Overlap, 6.0))
            ]
        );
    }
}
