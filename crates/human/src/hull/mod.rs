//! The visual hull of the input views' masks, and its depth in each source view: the geometry
//! prior a pose-guided, feed-forward human renderer such as PoseGaussian ("PoseGaussian:
//! Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction") can start its per-pixel
//! depth from, before any learning.
//!
//! **Space carving as a field.** Each mask becomes a signed distance to its silhouette
//! ([`edt`]), in pixels; a 3D point's distance to a camera's silhouette cone is that distance at
//! its projection, times `z / f` (metres at the point's depth). The hull field is the largest of
//! these over the cameras that see the point (project in front of the camera and inside the
//! image): `φ ≤ 0` means the point projects inside the mask of every camera that sees it, the
//! classic carving rule. Points seen by fewer than [`HullConfig::min_views`] cameras (by
//! default: all of them) are outside.
//! Keeping `φ` rather than a bit per voxel puts the surface below the voxel size: marching cubes
//! interpolates its zero level.
//!
//! **Voxels** ([`Hull::occupied`]): [`Footprint::Centre`] keeps a voxel whose centre is inside
//! (`φ ≤ 0`); [`Footprint::Conservative`] keeps one whose bounding sphere reaches inside
//! (`φ ≤ √3/2 · voxel`), so no part of the true body is carved by the grid's sampling.
//!
//! **Bounds**: given, or found from the cameras: a cube around the point their optical axes meet,
//! of half-size 0.9 × the nearest camera's distance to it (inward-looking rigs, the only ones a
//! visual hull suits), carved coarsely first (voxels 4× larger) to find the hull's box, padded by
//! two coarse voxels so the surface closes inside the grid.
//!
//! **Depth** ([`Hull::source_depths`]): the zero level is meshed by fewview-geom's marching cubes
//! and drawn by its triangle rasteriser into each camera: z-depth of the hull through every
//! pixel centre, 0 where the ray misses it.

pub mod edt;

use fewview_geom::mcubes::{GridSpec, marching_cubes};
use fewview_geom::{Mesh, raster};
use fewview_scene::{Camera, axes_meeting_point};
use nalgebra::Vector3;
use rayon::prelude::*;

use crate::error::{HumanError, Result};
use crate::maps::{DepthMap, Mask};

/// Field value of points too few cameras see: far outside, still finite for marching cubes.
const FAR: f32 = 1e30;

/// Largest number of grid samples (4 bytes each) a hull may have.
pub const MAX_SAMPLES: usize = 1 << 26;

/// Nearest camera-space depth of a triangle the depth renderer draws (metres).
const NEAR: f32 = 1e-3;

/// Axis-aligned box, world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// How a hull is carved.
#[derive(Clone, Debug, PartialEq)]
pub struct HullConfig {
    /// Edge of a voxel, world units (metres for the captures here). Default 0.01.
    pub voxel: f64,
    /// The box to carve; `None` finds it from the cameras (module docs).
    pub bounds: Option<Bounds>,
    /// Cameras that must see a point (project in front of them, inside the image) for it to be
    /// kept; `None` (the default) means every camera. With fewer, a point that one camera sees
    /// inside its mask and the others do not see at all is kept: in an inward-looking rig that
    /// is space just in front of a camera, not the person.
    pub min_views: Option<usize>,
}

impl Default for HullConfig {
    fn default() -> Self {
        Self {
            voxel: 0.01,
            bounds: None,
            min_views: None,
        }
    }
}

/// Which voxels [`Hull::occupied`] keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Footprint {
    /// The voxel's centre projects inside every mask that sees it.
    Centre,
    /// Some point within the voxel's bounding sphere may: a superset that never loses surface.
    Conservative,
}

/// A carved visual hull: the field `φ` (module docs) on a grid, metres, `≤ 0` inside.
#[derive(Clone, Debug)]
pub struct Hull {
    pub spec: GridSpec,
    /// `field[(i·ny + j)·nz + k]` at `origin + voxel·(i, j, k)`, fewview-geom's grid layout.
    pub field: Vec<f32>,
}

/// One view's silhouette as a signed distance image.
struct Silhouette<'a> {
    camera: &'a Camera,
    sdf: Vec<f32>,
    width: usize,
    height: usize,
    /// Metres per pixel at unit depth.
    scale: f64,
}

impl Silhouette<'_> {
    /// Distance (world units) from `p` to this view's silhouette cone, negative inside; `None`
    /// when the camera does not see `p`.
    fn distance(&self, p: &Vector3<f64>) -> Option<f64> {
        let (u, v, z) = self.camera.project(p)?;
        // Pixel (i, j) has its centre at (i + 0.5, j + 0.5).
        let (x, y) = (u - 0.5, v - 0.5);
        let (wl, hl) = ((self.width - 1) as f64, (self.height - 1) as f64);
        if !(x >= 0.0 && y >= 0.0 && x <= wl && y <= hl) {
            return None;
        }
        let (x0, y0) = (
            (x.floor() as usize).min(self.width - 2),
            (y.floor() as usize).min(self.height - 2),
        );
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let at = |i: usize, j: usize| self.sdf[j * self.width + i] as f64;
        let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
        let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
        Some((top * (1.0 - fy) + bottom * fy) * z * self.scale)
    }
}

impl Hull {
    /// Carves the hull of `masks` seen by `cameras` (one mask per camera, the camera's size).
    pub fn carve(cameras: &[Camera], masks: &[Mask], config: &HullConfig) -> Result<Hull> {
        check_inputs(cameras, masks, config)?;
        let sils: Vec<Silhouette> = cameras
            .par_iter()
            .zip(masks)
            .map(|(camera, mask)| Silhouette {
                camera,
                sdf: edt::signed_distance(mask),
                width: mask.width,
                height: mask.height,
                scale: 1.0 / (camera.intrinsics.fx * camera.intrinsics.fy).sqrt(),
            })
            .collect();
        let bounds = match config.bounds {
            Some(b) => b,
            None => auto_bounds(&sils, config)?,
        };
        let spec = grid(&bounds, config.voxel)?;
        let field = sample(&sils, &spec, min_views(config, &sils));
        Ok(Hull { spec, field })
    }

    /// The voxel edge.
    pub fn voxel(&self) -> f64 {
        self.spec.voxel[0]
    }

    /// Which grid samples are kept (grid layout of [`Hull::field`]).
    pub fn occupied(&self, footprint: Footprint) -> Vec<bool> {
        let limit = match footprint {
            Footprint::Centre => 0.0,
            Footprint::Conservative => 0.5 * 3f64.sqrt() * self.voxel(),
        } as f32;
        self.field.iter().map(|&v| v <= limit).collect()
    }

    /// The world position of grid sample `(i, j, k)`.
    pub fn position(&self, i: usize, j: usize, k: usize) -> Vector3<f64> {
        let (o, s) = (self.spec.origin, self.spec.voxel);
        Vector3::new(
            o[0] + s[0] * i as f64,
            o[1] + s[1] * j as f64,
            o[2] + s[2] * k as f64,
        )
    }

    /// The field at `p`, trilinearly interpolated; [`f64::INFINITY`] outside the grid.
    pub fn value_at(&self, p: &Vector3<f64>) -> f64 {
        let [_, ny, nz] = self.spec.dims;
        let mut base = [0usize; 3];
        let mut frac = [0f64; 3];
        for a in 0..3 {
            let t = (p[a] - self.spec.origin[a]) / self.spec.voxel[a];
            let n = self.spec.dims[a];
            if !(t >= 0.0 && t <= (n - 1) as f64) {
                return f64::INFINITY;
            }
            base[a] = (t.floor() as usize).min(n - 2);
            frac[a] = t - base[a] as f64;
        }
        let mut sum = 0.0;
        for corner in 0..8 {
            let d = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
            let w: f64 = (0..3)
                .map(|a| if d[a] == 1 { frac[a] } else { 1.0 - frac[a] })
                .product();
            let idx = ((base[0] + d[0]) * ny + base[1] + d[1]) * nz + base[2] + d[2];
            sum += w * self.field[idx] as f64;
        }
        sum
    }

    /// Whether `p` is inside the hull, allowing `tolerance` world units outside it.
    pub fn contains(&self, p: &Vector3<f64>, tolerance: f64) -> bool {
        self.value_at(p) <= tolerance
    }

    /// The hull's surface (zero level of the field), by marching cubes.
    pub fn mesh(&self) -> Result<Mesh> {
        Ok(marching_cubes(&self.field, &self.spec, 0.0)?)
    }

    /// The hull's z-depth in each camera (0 where a pixel's ray misses it).
    pub fn source_depths(&self, cameras: &[Camera]) -> Result<Vec<DepthMap>> {
        let mesh = self.mesh()?;
        cameras.iter().map(|c| render_depth(&mesh, c)).collect()
    }
}

/// A mesh's z-depth through every pixel centre of `camera`, 0 where none.
pub fn render_depth(mesh: &Mesh, camera: &Camera) -> Result<DepthMap> {
    Ok(DepthMap {
        width: camera.width() as usize,
        height: camera.height() as usize,
        data: raster::mesh_depth(mesh, camera, NEAR)?,
    })
}

fn check_inputs(cameras: &[Camera], masks: &[Mask], config: &HullConfig) -> Result<()> {
    if cameras.is_empty() || cameras.len() != masks.len() {
        let msg = format!(
            "{} cameras and {} masks (need one mask per camera)",
            cameras.len(),
            masks.len()
        );
        return Err(HumanError::argument("hull views", msg));
    }
    if !(config.voxel.is_finite() && config.voxel > 0.0) {
        return Err(HumanError::argument(
            "hull voxel",
            format!("{} (must be positive)", config.voxel),
        ));
    }
    if let Some(m) = config.min_views.filter(|&m| m == 0 || m > cameras.len()) {
        let msg = format!("{m} (need 1 to {})", cameras.len());
        return Err(HumanError::argument("hull min_views", msg));
    }
    if let Some(b) = &config.bounds
        && !(0..3).all(|a| b.min[a].is_finite() && b.max[a].is_finite() && b.max[a] > b.min[a])
    {
        return Err(HumanError::argument(
            "hull bounds",
            format!("{b:?} (need finite min < max)"),
        ));
    }
    for (v, (c, m)) in cameras.iter().zip(masks).enumerate() {
        if !c.is_finite() {
            return Err(HumanError::argument(
                format!("hull view {v}"),
                "camera is not finite",
            ));
        }
        let size_ok = (m.width, m.height) == (c.width() as usize, c.height() as usize);
        if !size_ok || m.data.len() != m.width * m.height || m.width < 2 || m.height < 2 {
            let msg = format!(
                "mask {}×{} for a {}×{} camera",
                m.width,
                m.height,
                c.width(),
                c.height()
            );
            return Err(HumanError::argument(format!("hull view {v}"), msg));
        }
        if m.count() == 0 {
            return Err(HumanError::argument(
                format!("hull view {v}"),
                "empty mask carves everything",
            ));
        }
    }
    Ok(())
}

fn min_views(config: &HullConfig, sils: &[Silhouette]) -> usize {
    config.min_views.unwrap_or(sils.len())
}

/// The grid of samples `voxel` apart covering `bounds`.
fn grid(bounds: &Bounds, voxel: f64) -> Result<GridSpec> {
    let mut dims = [0usize; 3];
    for a in 0..3 {
        dims[a] = ((bounds.max[a] - bounds.min[a]) / voxel).ceil() as usize + 1;
    }
    let total = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d));
    if total.is_none_or(|t| t > MAX_SAMPLES) {
        let msg =
            format!("{dims:?} samples exceed {MAX_SAMPLES}: use larger voxels or smaller bounds");
        return Err(HumanError::argument("hull voxel", msg));
    }
    let spec = GridSpec {
        dims,
        origin: bounds.min,
        voxel: [voxel; 3],
    };
    spec.check()?;
    Ok(spec)
}

/// The field on every sample of `spec`, in parallel over the first axis.
fn sample(sils: &[Silhouette], spec: &GridSpec, min_views: usize) -> Vec<f32> {
    let [nx, ny, nz] = spec.dims;
    let mut field = vec![0f32; nx * ny * nz];
    field
        .par_chunks_mut(ny * nz)
        .enumerate()
        .for_each(|(i, slab)| {
            for j in 0..ny {
                for k in 0..nz {
                    let p = Vector3::new(
                        spec.origin[0] + spec.voxel[0] * i as f64,
                        spec.origin[1] + spec.voxel[1] * j as f64,
                        spec.origin[2] + spec.voxel[2] * k as f64,
                    );
                    slab[j * nz + k] = value(sils, &p, min_views);
                }
            }
        });
    field
}

/// The hull field at one point.
fn value(sils: &[Silhouette], p: &Vector3<f64>, min_views: usize) -> f32 {
    let mut seen = 0;
    let mut worst = f64::NEG_INFINITY;
    for s in sils {
        if let Some(d) = s.distance(p) {
            seen += 1;
            worst = worst.max(d);
        }
    }
    if seen < min_views { FAR } else { worst as f32 }
}

/// The hull's box from a coarse carving of the cube the cameras look into (module docs).
fn auto_bounds(sils: &[Silhouette], config: &HullConfig) -> Result<Bounds> {
    let poses: Vec<_> = sils.iter().map(|s| s.camera.world_to_camera).collect();
    let centre = axes_meeting_point(&poses);
    let nearest = sils
        .iter()
        .map(|s| (s.camera.center() - centre).norm())
        .fold(f64::INFINITY, f64::min);
    let half = 0.9 * nearest;
    if !(half.is_finite() && half > 0.0) {
        return Err(HumanError::argument(
            "hull bounds",
            "the cameras do not surround a region; give bounds",
        ));
    }
    let coarse = (4.0 * config.voxel).max(2.0 * half / 128.0);
    let cube = Bounds {
        min: [centre.x - half, centre.y - half, centre.z - half],
        max: [centre.x + half, centre.y + half, centre.z + half],
    };
    let spec = grid(&cube, coarse)?;
    let field = sample(sils, &spec, min_views(config, sils));
    let hull = Hull { spec, field };
    let kept = hull.occupied(Footprint::Conservative);
    let [_, ny, nz] = hull.spec.dims;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (idx, _) in kept.iter().enumerate().filter(|(_, k)| **k) {
        let p = hull.position(idx / (ny * nz), (idx / nz) % ny, idx % nz);
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    if !lo[0].is_finite() {
        return Err(HumanError::argument(
            "hull views",
            "the masks' cones do not intersect: the hull is empty",
        ));
    }
    let pad = 2.0 * coarse;
    Ok(Bounds {
        min: [lo[0] - pad, lo[1] - pad, lo[2] - pad],
        max: [hi[0] + pad, hi[1] + pad, hi[2] + pad],
    })
}
