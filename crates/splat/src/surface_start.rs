//! The surface start: Gaussians on the mesh of a surface reconstruction, for captures whose
//! photos lie too far apart (tens of degrees) for two-view stereo to find the geometry.
//!
//! The `surface` command (neural implicit surfaces from sparse views with noisy poses) turns a
//! few wide-apart photos into a watertight mesh and corrected poses. This module carries both
//! into splat training:
//!
//! * **Points** where the training views see the mesh: spread uniformly over its area at the
//!   density of every [`SURFACE_STRIDE`]-th pixel, kept where a training view shows them (in
//!   its image and mask, not hidden), coloured from the view that sees each most squarely. Scales
//!   come from the sampling density (the reference code's nearest-neighbour scales,
//!   [`crate::init::knn_scales`], at most the intended spacing); each Gaussian is flat along the
//!   mesh's normal (its normal axis [`FLATNESS`] times the others), as surface-aligned splats
//!   (2D Gaussian splatting, Gaussian surfels) start.
//! * **Poses**: the surface run's refined training cameras, mapped into the frame of the
//!   dataset's cameras by the Alg. 1 alignment (`poses_refined_aligned.json`), when the
//!   surface run started from poses other than the dataset's ([`SurfaceRun::started_from_noise`]).
//! * **Depth during training** ([`SurfaceDepthTerm`]): the L1 distance between the splats'
//!   rendered depth and the mesh's, relative to the mesh's (a log-depth L1 to first order),
//!   weighted [`SURFACE_DEPTH_WEIGHT`] (DN-Splatter's depth weight, "DN-Splatter: Depth and
//!   Normal Priors for Gaussian Splatting and Meshing").
//!
//! A surface run folder gives `metrics.json` (its dataset and training views, which must be
//! this run's), `mesh_input_frame.ply` (the mesh in the input's own world, mapped back here by
//! the inverse of [`Dataset::to_source_world`]) and `poses_refined_aligned.json`.

use std::path::{Path, PathBuf};

use burn::tensor::Tensor;
use fewview_geom::Mesh;
use fewview_geom::similarity::Similarity;
use fewview_scene::{Camera, Dataset, PointCloud, View};
use nalgebra::Vector3;

use crate::init::{INITIAL_OPACITY, knn_scales};
use crate::model::{Gaussian, GaussianModel, inverse_sigmoid};
use crate::sh::SH_C0;
use crate::train::{LossContext, LossTerm, TrainError};

/// The surface start's density: a sample every this many pixels of the training views, at
/// their median depth.
pub const SURFACE_STRIDE: usize = 2;

/// Scale along the normal relative to the tangent scales of a surface-start Gaussian.
pub const FLATNESS: f32 = 0.1;

/// Default weight of [`SurfaceDepthTerm`].
pub const SURFACE_DEPTH_WEIGHT: f32 = 0.2;

/// A finished surface run, in the frame of the dataset it was run on.
#[derive(Clone, Debug)]
pub struct SurfaceRun {
    pub dir: PathBuf,
    /// The mesh in the dataset's frame.
    pub mesh: Mesh,
    /// The refined training cameras in the dataset's frame, in training order.
    pub cameras: Vec<Camera>,
    /// Mean rotation error (degrees) of the poses the surface run started from.
    pub initial_rotation_deg: f64,
}

/// Why a surface start cannot be built, naming the file or the step.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SurfaceStartError(String);

fn init_error(path: &Path, message: impl std::fmt::Display) -> SurfaceStartError {
    SurfaceStartError(format!("{}: {message}", path.display()))
}

impl SurfaceRun {
    /// Reads the surface run in `dir` and checks that it reconstructed `ds`'s training views.
    pub fn load(dir: &Path, ds: &Dataset) -> Result<Self, SurfaceStartError> {
        let metrics_path = dir.join("metrics.json");
        let text = std::fs::read_to_string(&metrics_path)
            .map_err(|e| init_error(&metrics_path, format!("{e} (not a finished surface run?)")))?;
        let metrics: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| init_error(&metrics_path, format!("not JSON: {e}")))?;
        let dataset = metrics["dataset"].as_str().unwrap_or_default();
        let views: Option<Vec<usize>> = metrics["train_views"].as_array().map(|a| {
            a.iter()
                .filter_map(|v| v.as_u64().map(|v| v as usize))
                .collect()
        });
        let (Some(views), false) = (views, dataset.is_empty()) else {
            return Err(init_error(
                &metrics_path,
                "no dataset or training views: not a surface run",
            ));
        };
        if dataset != ds.name {
            return Err(init_error(
                dir,
                format!("a surface run of `{dataset}`, not of `{}`", ds.name),
            ));
        }
        if views != ds.train {
            return Err(init_error(
                dir,
                format!(
                    "reconstructed views {views:?}, this run trains on {:?}",
                    ds.train
                ),
            ));
        }
        let initial_rotation_deg = metrics["initial_pose_error"]["rotation_deg"]
            .as_f64()
            .unwrap_or(0.0);
        let mesh_path = dir.join("mesh_input_frame.ply");
        let mesh =
            fewview_geom::io::read_mesh(&mesh_path).map_err(|e| init_error(&mesh_path, e))?;
        if mesh.faces.is_empty() {
            return Err(init_error(&mesh_path, "the mesh has no faces"));
        }
        let mesh = match &ds.to_source_world {
            Some(m) => Similarity::from_matrix4(m)
                .map_err(|e| init_error(&mesh_path, format!("the dataset's source map: {e}")))?
                .inverse()
                .apply_to_mesh(&mesh),
            None => mesh,
        };
        let cameras_path = dir.join("poses_refined_aligned.json");
        let cameras = fewview_geom::io::cameras::read_cameras(&cameras_path)
            .map_err(|e| init_error(&cameras_path, e))?;
        if cameras.len() != ds.train.len() {
            return Err(init_error(
                &cameras_path,
                format!(
                    "{} cameras for {} training views",
                    cameras.len(),
                    ds.train.len()
                ),
            ));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            mesh,
            cameras,
            initial_rotation_deg,
        })
    }

    /// Whether the surface run started from poses other than the dataset's (the `surface`
    /// command's `--pose-noise`, or the user's own initial poses).
    pub fn started_from_noise(&self) -> bool {
        self.initial_rotation_deg > 1e-6
    }

    /// Gives `ds`'s training views the refined poses (their intrinsics stay the dataset's:
    /// the surface run may have worked at another resolution).
    pub fn adopt_poses(&self, ds: &mut Dataset) {
        for (&i, refined) in ds.train.clone().iter().zip(&self.cameras) {
            let view = &mut ds.views[i];
            view.camera = Camera::new(view.camera.intrinsics, refined.world_to_camera);
        }
    }
}

/// Which poses a run started from a surface run trains with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum SurfacePoses {
    /// The refined ones when the surface run started from poses other than the dataset's.
    #[default]
    Auto,
    /// The surface run's refined poses.
    Refined,
    /// The dataset's poses.
    Dataset,
}

/// Gives `ds`'s training views the poses `choice` names from the surface run in `dir`, and says
/// which in a line for the user.
pub fn adopt_surface_poses(
    ds: &mut Dataset,
    dir: &Path,
    choice: SurfacePoses,
) -> Result<String, SurfaceStartError> {
    let run = SurfaceRun::load(dir, ds)?;
    let refined = match choice {
        SurfacePoses::Auto => run.started_from_noise(),
        SurfacePoses::Refined => true,
        SurfacePoses::Dataset => false,
    };
    if !refined {
        return Ok(format!(
            "surface start from {}: training with the dataset's poses",
            dir.display()
        ));
    }
    run.adopt_poses(ds);
    Ok(format!(
        "surface start from {}: training with its refined poses (it started {:.2}° off)",
        dir.display(),
        run.initial_rotation_deg
    ))
}

/// Points on a mesh where views see it.
#[derive(Clone, Debug, Default)]
pub struct SurfaceSample {
    /// Positions and the photos' colours there.
    pub cloud: PointCloud,
    /// Unit normals, facing the view that sampled the point.
    pub normals: Vec<[f32; 3]>,
    /// The intended distance between neighbouring samples.
    pub spacing: Vec<f32>,
}

/// Near plane for rasterising `mesh` into `camera`: far in front of the camera centre compared
/// with the scene, so that no triangle the view sees is skipped.
fn near_plane(mesh: &Mesh, camera: &Camera) -> f32 {
    let (lo, hi) = mesh.bounds().unwrap_or(([0.0; 3], [0.0; 3]));
    let centre = Vector3::from_fn(|k, _| 0.5 * (lo[k] as f64 + hi[k] as f64));
    (1e-4 * (camera.center() - centre).norm()).max(1e-9) as f32
}

/// The mesh's z-depth through every pixel centre of `camera`, 0 where it shows no surface.
pub fn mesh_depth(mesh: &Mesh, camera: &Camera) -> Result<Vec<f32>, SurfaceStartError> {
    fewview_geom::raster::mesh_depth(mesh, camera, near_plane(mesh, camera))
        .map_err(|e| SurfaceStartError(format!("rasterising the surface mesh: {e}")))
}

/// Whether `view` counts pixel `i`: inside its mask and its valid region, when it has them.
fn counts(view: &View, i: usize) -> bool {
    let inside = |im: &Option<fewview_scene::Image>| im.as_ref().is_none_or(|m| m.data[i] >= 0.5);
    inside(&view.mask) && inside(&view.valid)
}

/// The most points a surface start samples on its mesh.
pub const MAX_SURFACE_SAMPLES: usize = 2_000_000;

/// Relative depth margin within which a mesh point counts as the surface a view shows.
const VISIBLE_WITHIN: f64 = 0.01;

/// A view's mesh depth, for visibility tests.
struct Seen<'a> {
    view: &'a View,
    depth: Vec<f32>,
}

impl Seen<'_> {
    /// Where the view shows point `p`, and how squarely: its pixel and `|cos|` between the
    /// ray and `normal`; `None` when the point is outside the image or the mask, or hidden.
    fn sees(&self, p: &Vector3<f64>, normal: &Vector3<f64>) -> Option<(usize, f64)> {
        let camera = &self.view.camera;
        let (u, v, z) = camera.project(p)?;
        let (w, h) = (camera.width() as f64, camera.height() as f64);
        if !(0.0..w).contains(&u) || !(0.0..h).contains(&v) {
            return None;
        }
        let i = v as usize * w as usize + u as usize;
        let surface = self.depth[i] as f64;
        if !counts(self.view, i) || surface <= 0.0 || z > surface * (1.0 + VISIBLE_WITHIN) {
            return None;
        }
        let ray = (camera.center() - p).normalize();
        Some((i, normal.dot(&ray).abs()))
    }
}

/// The median of the finite positive values (0 when there are none).
fn median_positive(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite() && *x > 0.0).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Points spread uniformly over `mesh` at the density of every `stride`-th pixel of the views
/// (at their median depth), kept where at least one view shows them (in its image and mask,
/// not hidden): each with the colour of the view that sees it most squarely and the face
/// normal turned towards that view. Uniform area sampling leaves no holes where every view
/// sees the surface at a slant, as a sheet between two views 40° apart is.
pub fn sample_surface_in_views(
    mesh: &Mesh,
    views: &[&View],
    stride: usize,
    seed: u64,
) -> Result<SurfaceSample, SurfaceStartError> {
    let seen: Vec<Seen<'_>> = views
        .iter()
        .map(|&view| {
            Ok(Seen {
                view,
                depth: mesh_depth(mesh, &view.camera)?,
            })
        })
        .collect::<Result<_, SurfaceStartError>>()?;
    let depth = median_positive(seen.iter().flat_map(|s| s.depth.iter().map(|&d| d as f64)));
    let focal = median_positive(
        views
            .iter()
            .map(|v| v.camera.intrinsics.fx.min(v.camera.intrinsics.fy)),
    );
    let mut sample = SurfaceSample::default();
    if depth <= 0.0 || focal <= 0.0 {
        return Ok(sample);
    }
    let spacing = stride.max(1) as f64 * depth / focal;
    let wanted = (mesh.area() / (spacing * spacing)).ceil();
    let n = (wanted as usize).clamp(1, MAX_SURFACE_SAMPLES);
    let (points, faces) = fewview_geom::sampling::sample_surface_with_faces(mesh, n, seed)
        .map_err(|e| SurfaceStartError(format!("sampling the surface mesh: {e}")))?;
    for (q, &f) in points.iter().zip(&faces) {
        let p = Vector3::new(q[0] as f64, q[1] as f64, q[2] as f64);
        let normal = mesh.face_cross(f as usize).normalize();
        if !normal.iter().all(|v| v.is_finite()) {
            continue;
        }
        let best = seen
            .iter()
            .filter_map(|s| s.sees(&p, &normal).map(|(i, c)| (s, i, c)))
            .max_by(|a, b| a.2.total_cmp(&b.2));
        let Some((s, i, _)) = best else {
            continue;
        };
        let towards = s.view.camera.center() - p;
        let n = if normal.dot(&towards) < 0.0 {
            -normal
        } else {
            normal
        };
        let c = s.view.image.channels;
        let rgb = &s.view.image.data[i * c..i * c + 3];
        sample.cloud.positions.push(*q);
        sample.cloud.colors.push([rgb[0], rgb[1], rgb[2]]);
        sample.normals.push([n.x as f32, n.y as f32, n.z as f32]);
        sample.spacing.push(spacing as f32);
    }
    Ok(sample)
}

/// The rotation (w, x, y, z) taking the z axis to the unit vector `n`.
pub fn quat_z_to(n: [f32; 3]) -> [f32; 4] {
    let [x, y, z] = n;
    if z < -1.0 + 1e-6 {
        return [0.0, 1.0, 0.0, 0.0];
    }
    // q = (1 + z·n, z × n) normalised; z × n = (−n_y, n_x, 0).
    let q = [1.0 + z, -y, x, 0.0];
    let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    q.map(|v| v / norm)
}

/// Gaussians at the sample's points: the photo's colour, scales from the sampling density
/// (the nearest neighbours', at most the sample's own spacing), flat along the normal,
/// opacity [`INITIAL_OPACITY`].
pub fn from_surface_sample(sample: &SurfaceSample, sh_degree: usize) -> GaussianModel {
    let scales = knn_scales(&sample.cloud.positions)
        .into_iter()
        .zip(&sample.spacing)
        .map(|(s, &spacing)| s.min(spacing));
    let mut model = GaussianModel::new(sh_degree);
    let positions = &sample.cloud.positions;
    for (((p, c), n), s) in positions
        .iter()
        .zip(&sample.cloud.colors)
        .zip(&sample.normals)
        .zip(scales)
    {
        let mut sh = vec![0.0; model.sh_coeffs * 3];
        for k in 0..3 {
            sh[k] = ((c[k] as f64 - 0.5) / SH_C0) as f32;
        }
        let ls = s.max(1e-12).ln();
        model.push(&Gaussian {
            mean: *p,
            log_scale: [ls, ls, ls + FLATNESS.ln()],
            quat: quat_z_to(*n),
            opacity_logit: inverse_sigmoid(INITIAL_OPACITY),
            sh,
        });
    }
    model
}

/// The surface start of `ds` (its training views, whose cameras should already be the ones
/// training uses) from `run`'s mesh.
pub fn surface_model(
    ds: &Dataset,
    run: &SurfaceRun,
    sh_degree: usize,
    seed: u64,
) -> Result<GaussianModel, SurfaceStartError> {
    let views: Vec<&View> = ds.train_views().collect();
    let sample = sample_surface_in_views(&run.mesh, &views, SURFACE_STRIDE, seed)?;
    if sample.cloud.is_empty() {
        return Err(init_error(
            &run.dir,
            "no training view sees the surface mesh (a run of other cameras?)",
        ));
    }
    Ok(from_surface_sample(&sample, sh_degree))
}

/// The L1 distance between the splats' rendered depth and a mesh's depth in the training
/// views, relative to the mesh's depth, over the pixels the mesh covers (see the module docs).
/// The rendered depth is the blend `Σ wᵢ zᵢ`, so a pixel the splats leave partly transparent
/// reads nearer than the mesh and is pulled to opacity too.
#[derive(Clone)]
pub struct SurfaceDepthTerm {
    /// Per training view: the mesh's z-depth, 0 where it shows nothing.
    depths: Vec<Vec<f32>>,
    weight: f32,
}

impl SurfaceDepthTerm {
    /// The term for `ds`'s training views (their current cameras) and `mesh`.
    pub fn new(ds: &Dataset, mesh: &Mesh, weight: f32) -> Result<Self, SurfaceStartError> {
        let depths = ds
            .train_views()
            .map(|v| {
                let depth = mesh_depth(mesh, &v.camera)?;
                Ok(depth
                    .iter()
                    .enumerate()
                    .map(|(i, &d)| if counts(v, i) { d } else { 0.0 })
                    .collect())
            })
            .collect::<Result<_, SurfaceStartError>>()?;
        Ok(Self { depths, weight })
    }
}

/// `mean |rendered − d| / d` over the pixels where the target depth `d > 0` (`rendered` is
/// `[H, W, 1]`, `depth` row-major `H·W`); `None` when no pixel has a target.
pub fn relative_depth_l1(rendered: Tensor<3>, depth: &[f32]) -> Option<Tensor<1>> {
    let weights = vec![1.0; depth.len()];
    crate::stereo_depth::weighted_relative_depth_l1(rendered, depth, &weights)
}

impl LossTerm for SurfaceDepthTerm {
    fn name(&self) -> &str {
        "surface-depth"
    }

    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError> {
        let Some(depth) = self.depths.get(ctx.view_index) else {
            return Ok(None);
        };
        let weights = vec![1.0; depth.len()];
        crate::stereo_depth::depth_loss_of_render(ctx, "surface", depth, &weights, self.weight)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, TensorData};
    use fewview_scene::{Image, Intrinsics};
    use nalgebra::{Quaternion, UnitQuaternion};

    use super::*;

    #[test]
    fn the_flat_axis_turns_to_the_normal() {
        for n in [
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.48, -0.6, 0.64],
            [-0.36, 0.48, -0.8],
        ] {
            let [w, x, y, z] = quat_z_to(n).map(f64::from);
            let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
            let turned = q * Vector3::z();
            for k in 0..3 {
                assert!((turned[k] - n[k] as f64).abs() < 1e-6, "{n:?}: {turned:?}");
            }
        }
    }

    /// A camera at the origin looking down +z at a square of side 4 at z = 4 (its image 32×24,
    /// focal 20 px): it fills the view.
    fn wall_and_view() -> (Mesh, View) {
        let k = Intrinsics::centered(20.0, 32, 24);
        let camera = Camera::look_at(k, Vector3::zeros(), Vector3::z() * 4.0, -Vector3::y());
        let mesh = Mesh::new(
            vec![
                [-4.0, -4.0, 4.0],
                [4.0, -4.0, 4.0],
                [4.0, 4.0, 4.0],
                [-4.0, 4.0, 4.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let mut image = Image::new(32, 24, 3);
        for (i, v) in image.data.iter_mut().enumerate() {
            *v = (i % 97) as f32 / 97.0;
        }
        let mut mask = Image::new(32, 24, 1);
        for y in 0..24 {
            for x in 16..32 {
                mask.data[y * 32 + x] = 1.0;
            }
        }
        let view = View {
            name: "wall".into(),
            camera,
            image,
            mask: Some(mask),
            mask_is_alpha: false,
            valid: None,
            depth_bounds: None,
            source_index: 0,
        };
        (mesh, view)
    }

    #[test]
    fn samples_lie_on_the_mesh_inside_the_mask_with_the_photos_colours() {
        let (mesh, view) = wall_and_view();
        let sample = sample_surface_in_views(&mesh, &[&view], 2, 5).unwrap();
        // Spacing 2 px at depth 4 and focal 20: 0.4; the wall's 64 square units get 400 samples,
        // of which the masked right half of the view (3.2 × 4.8 of the wall) shows about 96.
        let n = sample.cloud.len();
        assert!((60..=130).contains(&n), "{n} samples");
        for ((p, c), n) in sample
            .cloud
            .positions
            .iter()
            .zip(&sample.cloud.colors)
            .zip(&sample.normals)
        {
            assert!((p[2] - 4.0).abs() < 1e-4, "{p:?}");
            // Back into the view: a pixel of the mask's half, whose colour it carries.
            let (u, v, _) = view
                .camera
                .project(&Vector3::new(p[0], p[1], p[2]).cast())
                .unwrap();
            let (x, y) = (u as usize, v as usize);
            assert!(x >= 16, "({x}, {y})");
            assert_eq!(c.as_slice(), &view.image.pixel(x, y)[..3]);
            assert_eq!(*n, [0.0, 0.0, -1.0], "faces the camera");
        }
        assert!(sample.spacing.iter().all(|&s| (s - 0.4).abs() < 1e-5));
        // Flat Gaussians: the smallest axis along the normal, FLATNESS times the others.
        let model = from_surface_sample(&sample, 0);
        let g = model.get(0);
        assert!((g.log_scale[2] - g.log_scale[0] - FLATNESS.ln()).abs() < 1e-6);
        assert!(g.log_scale[0] <= 0.4f32.ln() + 1e-6);
        assert_eq!(g.quat, quat_z_to([0.0, 0.0, -1.0]));
        // The depth the term is trained towards: 4 on every pixel of the wall.
        let depth = mesh_depth(&mesh, &view.camera).unwrap();
        assert!(depth.iter().all(|d| (d - 4.0).abs() < 1e-4));
        // A second wall behind the first is hidden: no sample lands on it.
        let mut two = mesh.clone();
        two.vertices.extend([
            [-4.0, -4.0, 6.0],
            [4.0, -4.0, 6.0],
            [4.0, 4.0, 6.0],
            [-4.0, 4.0, 6.0],
        ]);
        two.faces.extend([[4, 5, 6], [4, 6, 7]]);
        let behind = sample_surface_in_views(&two, &[&view], 2, 5).unwrap();
        assert!(
            behind
                .cloud
                .positions
                .iter()
                .all(|p| (p[2] - 4.0).abs() < 1e-4)
        );
    }

    #[test]
    fn the_depth_term_is_the_mean_relative_distance_and_its_gradient() {
        let device = Device::flex().autodiff();
        let rendered = Tensor::<3>::from_data(
            TensorData::new(vec![1.0f32, 3.0, 2.5, 9.0], [2, 2, 1]),
            &device,
        )
        .require_grad();
        // Targets 2, 2, none, 10: |1 − 2|/2 + |3 − 2|/2 + |9 − 10|/10 over 3 pixels.
        let loss = relative_depth_l1(rendered.clone(), &[2.0, 2.0, 0.0, 10.0]).unwrap();
        let value = fewview_optim::f32_values(loss.clone(), "loss").unwrap()[0];
        assert!((value - (0.5 + 0.5 + 0.1) / 3.0).abs() < 1e-6, "{value}");
        let grads = loss.backward();
        let g: Vec<f32> = rendered
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec()
            .unwrap();
        let want = [-0.5 / 3.0, 0.5 / 3.0, 0.0, -0.1 / 3.0];
        for (a, b) in g.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{g:?}");
        }
        assert!(relative_depth_l1(rendered, &[0.0; 4]).is_none());
    }
}
