//! Reprojection of the training photos into a virtual view through meshes of rendered depth
//! (the fusion paper, "Splat-based Gradient-domain Fusion for Seamless View Transition", supplement §1):
//! each training view's depth, as the Gaussians render it, is meshed with the Eq. (1) depth-edge
//! test and coloured by its photo; the mesh is rasterised into the virtual camera with a
//! z-buffer, giving the reprojected image `f*` and its mask `Ω_f*`.
//!
//! A reprojected pixel is kept only where it shows the surface the virtual view itself renders:
//! its mesh depth must agree with the virtual view's rendered depth within 1 % (relative), so a
//! photo does not paint what it saw onto a surface that hides it from the virtual camera. The
//! mask is then eroded by 1 px, dropping the half-covered pixels at its border.
//!
//! That test trusts the virtual view's own depth, so a floater in it hides the references
//! behind it from the loss. [`Occlusion::Meshes`] tests the two references against each other
//! instead (a pixel is kept unless the other mesh lies in front of it): what the photos saw
//! stands, whatever the virtual view renders in front of it.

use fewview_geom::depth::{TAU_DEPTH, depth_to_mesh};
use fewview_geom::mesh::Mesh;
use fewview_geom::raster::{Rasterized, rasterize_mesh_colors};
use fewview_scene::{Camera, Image};

use crate::error::FusionError;

/// A photo reprojected into a virtual view: colours and where they are valid.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    pub width: usize,
    pub height: usize,
    /// `[H, W, 3]`, row-major; 0 outside `valid`.
    pub image: Vec<f32>,
    /// `[H, W]`: `Ω` of the reference.
    pub valid: Vec<bool>,
}

/// What decides that a reprojected pixel shows what the virtual camera sees.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Occlusion {
    /// The virtual view's own rendered depth (our reading of the supplement's occlusion test).
    #[default]
    OwnDepth,
    /// The two references' meshes: a pixel is hidden when the other mesh lies in front of it.
    Meshes,
}

/// How reprojections are validated.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReprojectOptions {
    #[serde(default)]
    pub occlusion: Occlusion,
    /// Largest relative difference between the mesh depth and the virtual view's own depth.
    pub depth_tolerance: f32,
    /// Pixels eroded from the mask's border (3×3 square per step).
    pub erode: usize,
    /// Render pixels with an alpha below this have no depth (they are not meshed, and in a
    /// virtual view they validate nothing).
    pub min_alpha: f32,
}

impl Default for ReprojectOptions {
    fn default() -> Self {
        Self {
            occlusion: Occlusion::OwnDepth,
            depth_tolerance: 0.01,
            erode: 1,
            min_alpha: 0.5,
        }
    }
}

/// The depth of the visible surface from a render's expected depth `Σ wᵢ zᵢ` and alpha:
/// `depth / alpha`, 0 where alpha is below `min_alpha`.
pub fn surface_depth(depth: &[f32], alpha: &[f32], min_alpha: f32) -> Vec<f32> {
    depth
        .iter()
        .zip(alpha)
        .map(|(&d, &a)| {
            if a >= min_alpha && a > 0.0 {
                d / a
            } else {
                0.0
            }
        })
        .collect()
}

/// The smallest Eq. (1) threshold of a reference mesh, in units of the measure of a plane facing
/// the camera, `1/(fₓ f_y)`.
///
/// The paper's τ = 10⁻⁴ is about 100 such units at its image sizes (f ≈ 1000 px), room for the
/// pixel-to-pixel noise of depth rendered from Gaussians. On a small image the same τ is only a
/// few units: on the 200-pixel demo views (f = 180 px) it cut 60 % of the rendered depth's pixels
/// away against 20 % of the exact depth's. So τ is raised to 16 units where that is larger; at
/// the sizes of LLFF, DTU and NeRF-synthetic runs (f ≥ 400 px) it stays as printed.
pub const MESH_FLAT_MARGIN: f64 = 16.0;

/// Eq. (1)'s τ for a reference mesh of `camera` (see [`MESH_FLAT_MARGIN`]).
pub fn mesh_tau(camera: &Camera) -> f32 {
    let k = &camera.intrinsics;
    TAU_DEPTH.max((MESH_FLAT_MARGIN / (k.fx * k.fy)) as f32)
}

/// The mesh of one training view: its surface depth meshed with the Eq. (1) test ([`mesh_tau`]),
/// the vertices coloured by its photo.
pub fn reference_mesh(depth: &[f32], camera: &Camera, photo: &Image) -> Result<Mesh, FusionError> {
    Ok(depth_to_mesh(depth, camera, Some(photo), mesh_tau(camera))?)
}

/// Reprojects a reference mesh into `camera`. With `own_depth` (the virtual view's surface
/// depth), pixels whose mesh depth disagrees with it are invalid; then the mask is eroded.
pub fn reproject(
    mesh: &Mesh,
    camera: &Camera,
    own_depth: Option<&[f32]>,
    options: &ReprojectOptions,
) -> Result<Reference, FusionError> {
    let (width, height) = (camera.width() as usize, camera.height() as usize);
    if let Some(d) = own_depth
        && d.len() != width * height
    {
        return Err(FusionError::Invalid(format!(
            "the virtual view's depth has {} values for a {width}×{height} camera",
            d.len()
        )));
    }
    let raster = rasterize_mesh_colors(mesh, camera, NEAR)?;
    let agrees = |p: usize| match own_depth {
        None => true,
        Some(d) => d[p] > 0.0 && (raster.depth[p] - d[p]).abs() <= options.depth_tolerance * d[p],
    };
    Ok(reference_where(&raster, width, height, options, agrees))
}

/// The two reference meshes reprojected into `camera` under `options.occlusion`: against the
/// virtual view's `own_depth` ([`reproject`]), or against each other.
pub fn reproject_pair(
    meshes: [&Mesh; 2],
    camera: &Camera,
    own_depth: &[f32],
    options: &ReprojectOptions,
) -> Result<[Reference; 2], FusionError> {
    // The two references are independent: each is built on its own core.
    if options.occlusion == Occlusion::OwnDepth {
        let (f, g) = rayon::join(
            || reproject(meshes[0], camera, Some(own_depth), options),
            || reproject(meshes[1], camera, Some(own_depth), options),
        );
        return Ok([f?, g?]);
    }
    let (width, height) = (camera.width() as usize, camera.height() as usize);
    let (f, g) = rayon::join(
        || rasterize_mesh_colors(meshes[0], camera, NEAR),
        || rasterize_mesh_colors(meshes[1], camera, NEAR),
    );
    let rasters = [f?, g?];
    let in_front = |a: &Rasterized, b: &Rasterized, p: usize| {
        !b.covered(p) || a.depth[p] <= b.depth[p] * (1.0 + options.depth_tolerance)
    };
    let (f, g) = rayon::join(
        || {
            reference_where(&rasters[0], width, height, options, |p| {
                in_front(&rasters[0], &rasters[1], p)
            })
        },
        || {
            reference_where(&rasters[1], width, height, options, |p| {
                in_front(&rasters[1], &rasters[0], p)
            })
        },
    );
    Ok([f, g])
}

/// Nearer than this (camera z) nothing is rasterised.
const NEAR: f32 = 1e-6;

/// The reference of `raster` valid where it is covered and `keep` holds, eroded.
fn reference_where(
    raster: &Rasterized,
    width: usize,
    height: usize,
    options: &ReprojectOptions,
    keep: impl Fn(usize) -> bool,
) -> Reference {
    let visible: Vec<bool> = (0..width * height)
        .map(|p| raster.covered(p) && keep(p))
        .collect();
    let valid = erode(&visible, width, height, options.erode);
    let image = (0..width * height * 3)
        .map(|i| {
            if valid[i / 3] {
                raster.attributes[i]
            } else {
                0.0
            }
        })
        .collect();
    Reference {
        width,
        height,
        image,
        valid,
    }
}

/// `steps` erosions of a mask by a 3×3 square; pixels at the image border count as outside.
pub fn erode(mask: &[bool], width: usize, height: usize, steps: usize) -> Vec<bool> {
    let mut current = mask.to_vec();
    for _ in 0..steps {
        let inside = |x: isize, y: isize| {
            x >= 0
                && y >= 0
                && (x as usize) < width
                && (y as usize) < height
                && current[y as usize * width + x as usize]
        };
        current = (0..width * height)
            .map(|p| {
                let (x, y) = ((p % width) as isize, (p / width) as isize);
                (-1..=1).all(|dy| (-1..=1).all(|dx| inside(x + dx, y + dy)))
            })
            .collect();
    }
    current
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erosion_removes_one_pixel_of_border_per_step() {
        let (w, h) = (8, 6);
        let mask: Vec<bool> = (0..w * h)
            .map(|p| (1..7).contains(&(p % w)) && (1..5).contains(&(p / w)))
            .collect();
        let once = erode(&mask, w, h, 1);
        let want: Vec<bool> = (0..w * h)
            .map(|p| (2..6).contains(&(p % w)) && (2..4).contains(&(p / w)))
            .collect();
        assert_eq!(once, want);
        assert_eq!(erode(&mask, w, h, 0), mask);
        assert!(erode(&mask, w, h, 3).iter().all(|&v| !v));
    }

    #[test]
    fn references_tested_against_each_other_keep_the_nearer_surface() {
        use fewview_scene::{Intrinsics, Se3};
        let (w, h) = (30, 20);
        let camera = Camera::new(
            Intrinsics::centered(25.0, w as u32, h as u32),
            Se3::identity(),
        );
        // f sees a plane at depth 2 on the left two thirds, g one at depth 3 on the right two.
        let plane = |z: f32, cols: std::ops::Range<usize>| -> Vec<f32> {
            (0..w * h)
                .map(|p| if cols.contains(&(p % w)) { z } else { 0.0 })
                .collect()
        };
        let photo = Image::filled(w, h, &[0.5, 0.5, 0.5]);
        let f = reference_mesh(&plane(2.0, 0..20), &camera, &photo).unwrap();
        let g = reference_mesh(&plane(3.0, 10..30), &camera, &photo).unwrap();
        let options = ReprojectOptions {
            occlusion: Occlusion::Meshes,
            ..ReprojectOptions::default()
        };
        // The virtual view renders a floater at depth 1 everywhere: with its own depth as the
        // test nothing would be valid.
        let floater = vec![1.0f32; w * h];
        let [rf, rg] = reproject_pair([&f, &g], &camera, &floater, &options).unwrap();
        let row = h / 2;
        let at = |r: &Reference, x: usize| r.valid[row * w + x];
        assert!(at(&rf, 5) && at(&rf, 15), "f is in front wherever it is");
        assert!(!at(&rg, 15), "g is hidden behind f where both are");
        assert!(at(&rg, 25), "g alone stands");
        let own = ReprojectOptions::default();
        let [of, og] = reproject_pair([&f, &g], &camera, &floater, &own).unwrap();
        assert!(!of.valid.iter().any(|&v| v) && !og.valid.iter().any(|&v| v));
    }

    #[test]
    fn surface_depth_divides_by_alpha_and_drops_thin_pixels() {
        let d = surface_depth(&[2.0, 1.0, 3.0], &[1.0, 0.4, 0.6], 0.5);
        assert_eq!(d, vec![2.0, 0.0, 5.0]);
    }
}
