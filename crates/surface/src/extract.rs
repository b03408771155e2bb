//! From the trained field to outputs: the mesh (chunked marching cubes over the SDF, clipped to
//! the unit sphere, culled by the training masks, coloured by the colour network) and renders
//! of colour, depth and normals at arbitrary cameras.

use burn::tensor::{Device, Tensor, TensorData};
use fewview_geom::Mesh;
use fewview_geom::cleanup::{CullOptions, cull_by_masks};
use fewview_geom::mcubes::marching_cubes_chunked;
use fewview_optim::f32_values;
use fewview_scene::{Camera, Image};

use crate::error::{Result, SurfaceError};
use crate::field::{Field, sdf_and_gradient};
use crate::render::{SampleConfig, render_rays, sample_rays};

/// Options of [`extract_mesh`].
#[derive(Clone, Debug, PartialEq)]
pub struct MeshOptions {
    /// Samples per axis over `[−1, 1]³` (NeuS uses 512; 256 by default here).
    pub resolution: usize,
    /// Cells per chunk edge.
    pub chunk: usize,
}

impl Default for MeshOptions {
    fn default() -> Self {
        Self {
            resolution: 256,
            chunk: 32,
        }
    }
}

fn host_tensors(params: &[Vec<f32>], device: &Device) -> Vec<Tensor<1>> {
    params
        .iter()
        .map(|p| Tensor::from_data(TensorData::new(p.clone(), [p.len()]), device))
        .collect()
}

/// The zero level set of the field inside the unit sphere (`max(s, ‖P‖ − 1)`, so the surface
/// closes at the sphere), by chunked marching cubes.
pub fn extract_mesh(field: &Field, params: &[Vec<f32>], opts: &MeshOptions) -> Result<Mesh> {
    // Marching cubes takes an infallible SDF: the first error is kept here (the remaining
    // chunks are not evaluated) and returned instead of the mesh.
    let mut failure: Option<SurfaceError> = None;
    let mesh = marching_cubes_chunked(
        |pos: &[[f64; 3]]| {
            if failure.is_some() {
                return vec![f32::NAN; pos.len()];
            }
            let flat: Vec<f32> = pos.iter().flat_map(|p| p.map(|v| v as f32)).collect();
            let s = match field.sdf_host(params, &flat) {
                Ok(s) => s,
                Err(e) => {
                    failure = Some(e);
                    return vec![f32::NAN; pos.len()];
                }
            };
            pos.iter()
                .zip(s)
                .map(|(p, v)| {
                    let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() as f32;
                    v.max(r - 1.0)
                })
                .collect()
        },
        ([-1.0; 3], [1.0; 3]),
        [opts.resolution; 3],
        opts.chunk,
        0.0,
    );
    match failure {
        Some(e) => Err(e),
        None => Ok(mesh?),
    }
}

/// Colours of mesh vertices: the colour network seen head-on (view direction `−n`).
pub fn vertex_colors(
    field: &Field,
    params: &[Vec<f32>],
    vertices: &[[f32; 3]],
) -> Result<Vec<[f32; 3]>> {
    let device = Device::flex();
    let t = host_tensors(params, &device);
    let idx = field.index();
    let mut out = Vec::with_capacity(vertices.len());
    for chunk in vertices.chunks(16384) {
        let n = chunk.len();
        let pts = Tensor::<2>::from_data(TensorData::new(chunk.concat(), [n, 3]), &device);
        let (_, feat, grad) = sdf_and_gradient(
            field.sdf.as_ref(),
            &t[idx.sdf.clone()],
            pts.clone(),
            field.config.fd_scheme,
            field.sdf.fd_step(),
        );
        let len = (grad.clone().powi_scalar(2).sum_dim(1) + 1e-12).sqrt();
        let dirs = (grad.clone() / len).neg();
        let rgb = field
            .color
            .forward(t[idx.color].clone(), pts, grad, dirs, feat);
        let v = f32_values(rgb, "vertex colours")?;
        out.extend(v.chunks(3).map(|c| [c[0], c[1], c[2]]));
    }
    Ok(out)
}

/// Mesh, culled by the masks of `cameras` (a vertex seen on background in any view goes) and
/// coloured.
pub fn final_mesh(
    field: &Field,
    params: &[Vec<f32>],
    opts: &MeshOptions,
    cull: Option<(&[Camera], &[Image])>,
) -> Result<Mesh> {
    let mut mesh = extract_mesh(field, params, opts)?;
    if let Some((cams, masks)) = cull
        && !mesh.faces.is_empty()
    {
        mesh = cull_by_masks(&mesh, cams, masks, &CullOptions::default())?;
    }
    if !mesh.vertices.is_empty() {
        mesh.colors = Some(vertex_colors(field, params, &mesh.vertices)?);
    }
    Ok(mesh)
}

/// Renders of one camera.
pub struct ViewRender {
    pub rgb: Image,
    /// Distance along the ray, 1 channel.
    pub depth: Image,
    /// World normals mapped to `[0, 1]` (`(n + 1)/2`), 3 channels.
    pub normal: Image,
    /// Rendered opacity `Σ w`, 1 channel.
    pub alpha: Image,
}

/// Renders every pixel of `camera` (no gradients), `chunk` rays at a time.
pub fn render_view(
    field: &Field,
    params: &[Vec<f32>],
    camera: &Camera,
    sample: &SampleConfig,
    background: [f32; 3],
    chunk: usize,
) -> Result<ViewRender> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let device = Device::flex();
    let t = host_tensors(params, &device);
    let mut rgb = Vec::with_capacity(w * h * 3);
    let mut depth = Vec::with_capacity(w * h);
    let mut normal = Vec::with_capacity(w * h * 3);
    let mut alpha = Vec::with_capacity(w * h);
    let pixels: Vec<(usize, usize)> = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).collect();
    let sdf_fn = |p: &[f32]| field.sdf_host(params, p);
    for block in pixels.chunks(chunk.max(1)) {
        let mut o = Vec::with_capacity(block.len());
        let mut d = Vec::with_capacity(block.len());
        for &(x, y) in block {
            let (oo, dd) = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
            o.push([oo.x as f32, oo.y as f32, oo.z as f32]);
            d.push([dd.x as f32, dd.y as f32, dd.z as f32]);
        }
        let z = sample_rays(&sdf_fn, &o, &d, sample, None)?;
        let n = o.len();
        let ot = Tensor::<2>::from_data(TensorData::new(o.concat(), [n, 3]), &device);
        let dt = Tensor::<2>::from_data(TensorData::new(d.concat(), [n, 3]), &device);
        let out = render_rays(field, &t, ot, dt, &z, 1.0, background)?;
        rgb.extend(f32_values(out.color, "rendered colour")?);
        let ws = f32_values(out.weight_sum, "rendered opacity")?;
        depth.extend(f32_values(out.depth, "rendered depth")?);
        let nn = f32_values(out.normal, "rendered normals")?;
        for k in 0..n {
            let v = &nn[3 * k..3 * k + 3];
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-8);
            for a in 0..3 {
                normal.push(if ws[k] > 1e-3 {
                    0.5 * (v[a] / len + 1.0)
                } else {
                    0.0
                });
            }
        }
        alpha.extend(ws);
    }
    Ok(ViewRender {
        rgb: Image::from_vec(w, h, 3, rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect()),
        depth: Image::from_vec(w, h, 1, depth),
        normal: Image::from_vec(w, h, 3, normal),
        alpha: Image::from_vec(w, h, 1, alpha),
    })
}
