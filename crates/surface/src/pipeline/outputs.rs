//! What a run writes besides its configuration and matches: the refined cameras (also in the
//! input's format), the mesh in both frames, the test views' renders and depth maps, and the
//! mesh's Chamfer scores against a reference.

use std::path::Path;

use fewview_geom::{Mesh, Similarity};
use fewview_scene::numpy::Array as NpyArray;
use fewview_scene::{Camera, Dataset, Image};

use super::report::{ChamferReport, TestViewMetrics};
use crate::config::RunConfig;
use crate::error::{Result, SurfaceError};
use crate::extract::{MeshOptions, final_mesh, render_view};
use crate::field::Field;
use crate::train::state::TrainView;

/// The cameras of `gt` mapped into the reconstruction's world by the inverse of the Alg. 1
/// alignment `x_gt = s R x_est + t`.
pub fn camera_in_estimate_frame(gt: &Camera, alignment: &Similarity) -> Camera {
    Camera::new(
        gt.intrinsics,
        alignment.inverse().apply_to_pose(&gt.world_to_camera),
    )
}

/// Chamfer of `mesh` against `reference` on the whole reference and, given per-face flags, on
/// its observed part, after registering it ([`register_to_reference`]); what cannot be scored
/// is `None`, with the reasons.
pub(super) fn reference_scores(
    mesh: &Mesh,
    reference: &Mesh,
    observed: Option<&[bool]>,
    alignment: &Similarity,
) -> (Option<ChamferReport>, Option<ChamferReport>, Option<String>) {
    if mesh.faces.is_empty() {
        return (None, None, Some("the extracted mesh is empty".into()));
    }
    let aligned = match register_to_reference(mesh, reference, alignment) {
        Ok(m) => m,
        Err(e) => return (None, None, Some(format!("registration: {e}"))),
    };
    let mut errors = Vec::new();
    let mut score = |flags: Option<&[bool]>, what: &str| {
        chamfer_of(&aligned, reference, flags)
            .map_err(|e| errors.push(format!("{what}: {e}")))
            .ok()
    };
    let whole = score(None, "whole surface");
    let seen = observed.and_then(|flags| score(Some(flags), "observed part"));
    let why = (!errors.is_empty()).then(|| errors.join("; "));
    (whole, seen, why)
}

/// The map from the reconstruction's frame to the input's own world, the frame of the refined
/// camera file: the Alg. 1 alignment onto the cameras the poses are scored against (`scored`,
/// the truth's when given), then that dataset's map back to its file's frame (DTU: `scale_mat`,
/// to the millimetres of DTU's reference point clouds; LLFF: NeRF's normalisation undone).
/// `mesh_input_frame.ply` and the raw depth maps are in this world, so they overlay the
/// refined cameras in the tools that read the input's format.
pub(super) fn input_world(scored: &Dataset, alignment: &Similarity) -> Result<Similarity> {
    match &scored.to_source_world {
        None => Ok(*alignment),
        Some(m) => Ok(Similarity::from_matrix4(m)?.compose(alignment)),
    }
}

/// The rendered depth as a `height × width` array of depths along the optical axis (the
/// convention of COLMAP's and MVSNet's depth maps, not the distance along the ray that NeuS
/// renders), times `units` (the scale of the map to the input's world); 0 where the rendered
/// opacity is under one half (background). The weights' expected distance is divided by their
/// sum first, so that partly covered pixels are not pulled towards the camera.
pub(super) fn z_depth(
    render: &crate::extract::ViewRender,
    camera: &Camera,
    units: f64,
) -> NpyArray {
    let (w, h) = (render.depth.width, render.depth.height);
    let axis = camera.world_to_camera.rotation.row(2).transpose();
    let data = (0..w * h)
        .map(|i| {
            let alpha = f64::from(render.alpha.data[i]);
            if alpha < 0.5 {
                return 0.0;
            }
            let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let (_, direction) = camera.ray(x, y);
            f64::from(render.depth.data[i]) / alpha * direction.dot(&axis) * units
        })
        .collect();
    NpyArray {
        shape: vec![h, w],
        data,
    }
}

/// The surface paper Alg. 3: the mesh pre-aligned with the pose-evaluation similarity, then
/// registered to the reference by FPFH + RANSAC and point-to-point ICP (ICP also from the
/// pre-alignment, see `fewview_geom::registration::IcpStarts`).
pub fn register_to_reference(
    mesh: &Mesh,
    reference: &Mesh,
    alignment: &Similarity,
) -> Result<Mesh> {
    use fewview_geom::registration::{RegistrationOptions, register};
    let voxel = fewview_geom::mesh::bbox_diagonal(&reference.vertices) / 100.0;
    let src = fewview_geom::Points::from_positions(mesh.vertices.clone());
    let dst = fewview_geom::Points::from_positions(reference.vertices.clone());
    let reg = register(
        &src,
        &dst,
        Some(alignment),
        &RegistrationOptions::for_voxel(voxel),
    )?;
    Ok(Mesh {
        vertices: reg.transformation.apply_points(&mesh.vertices),
        ..mesh.clone()
    })
}

/// Chamfer-L1 of a registered mesh to the reference from uniform surface samples, on the whole
/// reference or, given per-face flags, on its observed part.
pub fn chamfer_of(
    aligned: &Mesh,
    reference: &Mesh,
    observed: Option<&[bool]>,
) -> Result<ChamferReport> {
    use fewview_geom::chamfer::{surface_metrics, surface_metrics_observed};
    let diag = fewview_geom::mesh::bbox_diagonal(&reference.vertices);
    let (n, taus) = (200_000, [0.01 * diag]);
    let m = match observed {
        Some(flags) => surface_metrics_observed(aligned, reference, flags, n, &taus, 0)?,
        None => surface_metrics(aligned, reference, n, &taus, 0)?,
    };
    Ok(ChamferReport {
        chamfer_l1: m.chamfer_l1,
        accuracy: m.accuracy,
        completeness: m.completeness,
        bbox_diagonal: diag,
        relative: m.chamfer_l1 / diag,
        fscore_1pct: m.fscore.first().map(|f| f.fscore).unwrap_or(f64::NAN),
    })
}

/// The field a run trained, with the configuration that says how to mesh and render it.
pub(super) struct TrainedField<'a> {
    pub field: &'a Field,
    pub params: &'a [Vec<f32>],
    pub config: &'a RunConfig,
}

/// Marching cubes of the field, culled by the training views' masks when the run uses them
/// (`cameras` are the refined training cameras), written as `mesh.ply` in the reconstruction's
/// frame and as `mesh_input_frame.ply` mapped by `to_input` into the input's world.
pub(super) fn write_meshes(
    trained: &TrainedField,
    views: &[TrainView],
    cameras: &[Camera],
    to_input: &Similarity,
    out: &Path,
) -> Result<Mesh> {
    let config = trained.config;
    let masks: Option<Vec<Image>> = views.iter().map(|v| v.mask.clone()).collect();
    let mesh = final_mesh(
        trained.field,
        trained.params,
        &MeshOptions {
            resolution: config.mesh_resolution,
            chunk: 32,
        },
        masks
            .as_ref()
            .filter(|_| config.train.use_masks)
            .map(|m| (cameras, m.as_slice())),
    )?;
    fewview_geom::io::write_mesh(&out.join("mesh.ply"), &mesh)?;
    fewview_geom::io::write_mesh(
        &out.join("mesh_input_frame.ply"),
        &to_input.apply_to_mesh(&mesh),
    )?;
    Ok(mesh)
}

/// Renders the first [`RunConfig::eval_views`] test views of `dataset` with the true cameras of
/// `scored` mapped into the reconstruction's frame by `alignment`, writes their colour, depth
/// and normal PNGs and depth maps (in the units of `to_input`) under `renders/`, and scores
/// them against the true images.
pub(super) fn render_test_views(
    trained: &TrainedField,
    dataset: &Dataset,
    scored: &Dataset,
    alignment: &Similarity,
    to_input: &Similarity,
    out: &Path,
) -> Result<Vec<TestViewMetrics>> {
    let renders = out.join("renders");
    std::fs::create_dir_all(&renders).map_err(|e| SurfaceError::io(&renders, e))?;
    let config = trained.config;
    let mut test_metrics = Vec::new();
    for &vi in dataset.test.iter().take(config.eval_views) {
        let gt_view = &scored.views[vi];
        let mut cam = camera_in_estimate_frame(&gt_view.camera, alignment);
        let (mut image, mut mask) = (gt_view.image.clone(), gt_view.mask.clone());
        if config.eval_scale > 1 {
            let k = config.eval_scale as usize;
            image = image.downscale(k);
            mask = mask.map(|m| m.downscale(k));
            cam = cam.resized(image.width as u32, image.height as u32);
        }
        let r = render_view(
            trained.field,
            trained.params,
            &cam,
            &config.train.sample,
            config.train.background,
            4096,
        )?;
        let name = |s: &str| renders.join(format!("{vi:03}_{s}.png"));
        r.rgb.save_png(&name("rgb"))?;
        r.depth.scaled_to_unit_max().save_png(&name("depth"))?;
        let depth_npy = renders.join(format!("{vi:03}_depth.npy"));
        fewview_scene::numpy::save_npy(&depth_npy, &z_depth(&r, &cam, to_input.scale))?;
        r.normal.save_png(&name("normal"))?;
        test_metrics.push(score_view(vi, &r.rgb, &image, mask.as_ref()));
    }
    Ok(test_metrics)
}

/// PSNR and SSIM of a rendered test view, inside its mask when it has one.
fn score_view(
    view: usize,
    rendered: &Image,
    image: &Image,
    mask: Option<&Image>,
) -> TestViewMetrics {
    let full = fewview_metrics::psnr::psnr(rendered, image).unwrap_or(f64::NAN);
    let (pm, sm) = match mask {
        Some(m) => (
            fewview_metrics::psnr::psnr_masked(rendered, image, m).unwrap_or(f64::NAN),
            fewview_metrics::ssim::ssim_masked(rendered, image, m, &Default::default())
                .unwrap_or(f64::NAN),
        ),
        None => (
            full,
            fewview_metrics::ssim::ssim(rendered, image).unwrap_or(f64::NAN),
        ),
    };
    TestViewMetrics {
        view,
        psnr_masked: pm,
        ssim_masked: sm,
        psnr: full,
    }
}
