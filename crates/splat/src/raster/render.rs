//! The rasterizer's host entry points: [`forward`] renders an image and keeps what the backward
//! pass needs in a [`ForwardContext`]; [`backward`] turns per-pixel gradients into gradients of
//! every Gaussian parameter.

use rayon::prelude::*;

use super::blend::{TileGeometry, TileGrad, TileState};
use super::inputs::{GaussianRefs, RenderCamera, RenderSettings, TILE};
use super::kernels::{KernelBuild, backward_tile_with, forward_tile_with};
use super::project::{CameraF, ParamGrad, Splat, SplatGrad, project_one, project_one_backward};
use super::tiles::{TileBins, bin};
use crate::real::Real;

/// Channels of the rasterizer's output image, interleaved per pixel: R, G, B, depth, alpha.
pub const OUT_CHANNELS: usize = 5;

/// A rendered image: `data` is H×W×5 (R, G, B, expected depth `Σ wᵢ zᵢ`, alpha `1 − T`).
#[derive(Clone, Debug)]
pub struct ForwardOutput<F> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<F>,
    /// Per Gaussian, the screen radius (px, 3σ) or 0 when not visible in this view.
    pub radii: Vec<F>,
    /// Splat–pixel pairs evaluated by the blending stage.
    pub pairs: u64,
}

impl<F: Real> ForwardOutput<F> {
    /// The RGB channels as an H×W×3 buffer.
    pub fn rgb(&self) -> Vec<F> {
        self.data
            .chunks_exact(OUT_CHANNELS)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect()
    }

    /// One of the five channels as an H×W buffer.
    pub fn channel(&self, c: usize) -> Vec<F> {
        self.data.chunks_exact(OUT_CHANNELS).map(|p| p[c]).collect()
    }
}

/// What the backward pass needs from the forward pass.
#[derive(Clone, Debug)]
pub struct ForwardContext<F> {
    pub camera: RenderCamera,
    pub settings: RenderSettings,
    /// Gaussian index of each visible splat.
    pub ids: Vec<u32>,
    pub splats: Vec<Splat<F>>,
    pub bins: TileBins,
    /// Final per-pixel state of every tile (tile-major).
    pub tiles: Vec<TileState<F>>,
    pub num_gaussians: usize,
}

/// Gradients of the Gaussian parameters, in the same flat layout as [`GaussianRefs`], plus the
/// gradient with respect to each projected centre in NDC units (`∂L/∂u · W/2`, `∂L/∂v · H/2`,
/// as the reference code's `means2D`, whose norm drives densification).
#[derive(Clone, Debug, PartialEq)]
pub struct ParamGradients<F> {
    pub means: Vec<F>,
    pub log_scales: Vec<F>,
    pub quats: Vec<F>,
    pub opacity_logits: Vec<F>,
    pub sh: Vec<F>,
    pub means2d: Vec<F>,
    /// Splat–pixel pairs evaluated by the blending backward.
    pub pairs: u64,
}

pub(crate) fn tile_geometry(cam: &RenderCamera, t: usize, tiles_x: usize) -> TileGeometry {
    let (tx, ty) = (t % tiles_x, t / tiles_x);
    let (x0, y0) = (tx * TILE, ty * TILE);
    TileGeometry {
        x0,
        y0,
        width: TILE.min(cam.width - x0),
        height: TILE.min(cam.height - y0),
    }
}

/// Renders the Gaussians from `camera`.
pub fn forward<F: Real>(
    gaussians: &GaussianRefs<'_, F>,
    camera: &RenderCamera,
    settings: &RenderSettings,
) -> (ForwardOutput<F>, ForwardContext<F>) {
    let n = gaussians.len();
    let cam = CameraF::<F>::new(camera, settings.near_plane);
    let projected: Vec<_> = (0..n)
        .into_par_iter()
        .map(|i| project_one(gaussians, i, &cam, settings.sh_degree))
        .collect();
    let mut radii = vec![F::zero(); n];
    let mut ids = Vec::new();
    let mut splats = Vec::new();
    for (i, p) in projected.into_iter().enumerate() {
        if let Some(p) = p {
            radii[i] = p.radius;
            ids.push(i as u32);
            splats.push(p.splat);
        }
    }
    let (tiles_x, tiles_y) = (camera.tiles_x(), camera.tiles_y());
    let bins = bin(&splats, tiles_x, tiles_y);
    let build = KernelBuild::best();
    let tiles: Vec<(TileState<F>, u64)> = (0..bins.num_tiles())
        .into_par_iter()
        .map(|t| {
            let geo = tile_geometry(camera, t, tiles_x);
            let mut state = TileState::default();
            let pairs = forward_tile_with(build, &geo, bins.tile_entries(t), &splats, &mut state);
            (state, pairs)
        })
        .collect();

    let (w, h) = (camera.width, camera.height);
    let bg = settings.background.map(|v| F::c(v as f64));
    let mut data = vec![F::zero(); w * h * OUT_CHANNELS];
    let mut pairs = 0;
    for (t, (state, p)) in tiles.iter().enumerate() {
        pairs += p;
        let geo = tile_geometry(camera, t, tiles_x);
        for r in 0..geo.height {
            for c in 0..geo.width {
                let o = ((geo.y0 + r) * w + geo.x0 + c) * OUT_CHANNELS;
                let tr = state.transmittance[r][c];
                for ch in 0..3 {
                    data[o + ch] = state.color[ch][r][c] + tr * bg[ch];
                }
                data[o + 3] = state.depth[r][c];
                data[o + 4] = F::one() - tr;
            }
        }
    }
    let tiles = tiles.into_iter().map(|(s, _)| s).collect();
    (
        ForwardOutput {
            width: w,
            height: h,
            data,
            radii,
            pairs,
        },
        ForwardContext {
            camera: camera.clone(),
            settings: settings.clone(),
            ids,
            splats,
            bins,
            tiles,
            num_gaussians: n,
        },
    )
}

/// The upstream gradient of the tile at `geo` in an image `width` pixels wide, or `None` when it
/// is zero at every pixel (a loss that covers part of the image, such as a masked or
/// virtual-view loss): then every splat's gradient from the tile is zero and the backward
/// skips it.
fn tile_grad<F: Real>(grad_out: &[F], geo: &TileGeometry, width: usize) -> Option<TileGrad<F>> {
    let mut grad = TileGrad::<F>::default();
    let mut any = false;
    for r in 0..geo.height {
        for c in 0..geo.width {
            let o = ((geo.y0 + r) * width + geo.x0 + c) * OUT_CHANNELS;
            for ch in 0..3 {
                grad.color[ch][r][c] = grad_out[o + ch];
            }
            grad.depth[r][c] = grad_out[o + 3];
            grad.alpha[r][c] = grad_out[o + 4];
            any |= grad_out[o..o + OUT_CHANNELS]
                .iter()
                .any(|&v| v != F::zero());
        }
    }
    any.then_some(grad)
}

/// Gradients of all Gaussian parameters given `grad_out`, the loss gradient with respect to the
/// forward output (H×W×5, same layout as [`ForwardOutput::data`]).
pub fn backward<F: Real>(
    gaussians: &GaussianRefs<'_, F>,
    ctx: &ForwardContext<F>,
    grad_out: &[F],
) -> ParamGradients<F> {
    const L: usize = SplatGrad::<f32>::LEN;
    let camera = &ctx.camera;
    let bins = &ctx.bins;
    let tiles_x = bins.tiles_x;
    let w = camera.width;
    let bg = ctx.settings.background.map(|v| F::c(v as f64));

    // 1. Per tile: gradient of each (tile, splat) pair, into that pair's slot.
    let build = KernelBuild::best();
    let mut slot_grads = vec![F::zero(); bins.entries.len() * L];
    let mut pieces = Vec::with_capacity(bins.num_tiles());
    let mut rest = slot_grads.as_mut_slice();
    for t in 0..bins.num_tiles() {
        let len = (bins.offsets[t + 1] - bins.offsets[t]) * L;
        let (piece, tail) = rest.split_at_mut(len);
        pieces.push(piece);
        rest = tail;
    }
    let pairs: u64 = pieces
        .into_par_iter()
        .enumerate()
        .map(|(t, piece)| {
            if piece.is_empty() {
                return 0;
            }
            let geo = tile_geometry(camera, t, tiles_x);
            let Some(grad) = tile_grad(grad_out, &geo, w) else {
                // No gradient reaches this tile: its pairs' gradients are the zeros already
                // in `piece`.
                return 0;
            };
            backward_tile_with(
                build,
                &geo,
                bins.tile_entries(t),
                &ctx.splats,
                &ctx.tiles[t],
                bg,
                &grad,
                piece,
            )
        })
        .sum();

    // 2. Per splat: sum its pairs in a fixed order (deterministic results).
    let mut splat_grads = vec![SplatGrad::<F>::default(); ctx.splats.len()];
    let order = &bins.depth_order;
    let sums: Vec<(usize, SplatGrad<F>)> = (0..order.len())
        .into_par_iter()
        .map(|rank| {
            let mut sum = [F::zero(); L];
            for &slot in &bins.pair_slots[bins.pair_offsets[rank]..bins.pair_offsets[rank + 1]] {
                let g = &slot_grads[slot as usize * L..(slot as usize + 1) * L];
                for k in 0..L {
                    sum[k] = sum[k] + g[k];
                }
            }
            (order[rank] as usize, SplatGrad::from_slice(&sum))
        })
        .collect();
    for (s, g) in sums {
        splat_grads[s] = g;
    }

    // 3. Per visible Gaussian: through the projection to the parameters.
    let n = ctx.num_gaussians;
    let k3 = gaussians.sh_coeffs * 3;
    let cam = CameraF::<F>::new(camera, ctx.settings.near_plane);
    let per: Vec<(ParamGrad<F>, Vec<F>)> = ctx
        .ids
        .par_iter()
        .zip(splat_grads.par_iter())
        .map(|(&id, dl)| {
            let mut sh = vec![F::zero(); k3];
            let p = project_one_backward(
                gaussians,
                id as usize,
                &cam,
                ctx.settings.sh_degree,
                dl,
                &mut sh,
            );
            (p, sh)
        })
        .collect();

    let mut out = ParamGradients {
        means: vec![F::zero(); n * 3],
        log_scales: vec![F::zero(); n * 3],
        quats: vec![F::zero(); n * 4],
        opacity_logits: vec![F::zero(); n],
        sh: vec![F::zero(); n * k3],
        means2d: vec![F::zero(); n * 2],
        pairs,
    };
    let (half_w, half_h) = (
        F::c(camera.width as f64 * 0.5),
        F::c(camera.height as f64 * 0.5),
    );
    for ((&id, (p, sh)), dl) in ctx.ids.iter().zip(per).zip(&splat_grads) {
        let i = id as usize;
        out.means[3 * i..3 * i + 3].copy_from_slice(&p.mean);
        out.log_scales[3 * i..3 * i + 3].copy_from_slice(&p.log_scale);
        out.quats[4 * i..4 * i + 4].copy_from_slice(&p.quat);
        out.opacity_logits[i] = p.opacity_logit;
        out.sh[k3 * i..k3 * (i + 1)].copy_from_slice(&sh);
        out.means2d[2 * i] = dl.mean[0] * half_w;
        out.means2d[2 * i + 1] = dl.mean[1] * half_h;
    }
    out
}
