//! Which compiled build of the tile kernels ([`forward_tile`], [`backward_tile`]) runs.
//!
//! The kernels are written once, generic and `#[inline(always)]`; each build below inlines the
//! same body into a function compiled for more of the CPU. AVX2 + FMA gives 8-wide vectors and
//! fused multiply-adds; AVX-512 (F and VL) keeps the same 8-wide loops but has 32 vector
//! registers instead of 16 and mask registers for the per-lane tests, so the backward pass's
//! ten gradient accumulators and the blend state no longer spill to the stack. The AVX2 and
//! AVX-512 builds run the same fused arithmetic in the same order, so their results are
//! bit-identical; the portable build rounds separately where the others fuse.

use super::blend::{TileGeometry, TileGrad, TileState, backward_tile, forward_tile};
use super::project::Splat;
use crate::real::{Fused, Real, Unfused};

/// A compiled build of the tile kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelBuild {
    /// Baseline x86-64 (SSE2) or any other architecture; multiply and add rounded separately.
    Portable,
    /// AVX2 + FMA.
    Avx2,
    /// AVX-512 F and VL, besides AVX2 + FMA.
    Avx512,
}

impl KernelBuild {
    /// The fastest build this CPU runs.
    pub fn best() -> Self {
        [Self::Avx512, Self::Avx2]
            .into_iter()
            .find(|b| b.available())
            .unwrap_or(Self::Portable)
    }

    /// Whether this CPU can run the build.
    pub fn available(self) -> bool {
        match self {
            Self::Portable => true,
            Self::Avx2 => fewview_scene::cpu::avx2_fma(),
            Self::Avx512 => fewview_scene::cpu::avx512(),
        }
    }
}

/// Defines `$name`: `$kernel` with fused multiply-adds, compiled with `$features` enabled (the
/// kernel is `#[inline(always)]`, so this build gets its own code generation). Calling it is
/// unsafe: the CPU must have the features.
#[cfg(target_arch = "x86_64")]
macro_rules! compiled_for {
    ($features:literal, $name:ident, $kernel:ident($($arg:ident: $ty:ty),* $(,)?)) => {
        #[target_feature(enable = $features)]
        #[allow(clippy::too_many_arguments)]
        fn $name<F: Real>($($arg: $ty),*) -> u64 {
            $kernel::<F, Fused>($($arg),*)
        }
    };
}

/// [`forward_tile`] in `build`, which must be [`KernelBuild::available`] (checked; an
/// unavailable build runs the portable one).
pub fn forward_tile_with<F: Real>(
    build: KernelBuild,
    geo: &TileGeometry,
    list: &[u32],
    splats: &[Splat<F>],
    state: &mut TileState<F>,
) -> u64 {
    #[cfg(target_arch = "x86_64")]
    {
        compiled_for!("avx2,fma", avx2, forward_tile(
            geo: &TileGeometry, list: &[u32], splats: &[Splat<F>], state: &mut TileState<F>,
        ));
        compiled_for!("avx512f,avx512vl,avx2,fma", avx512, forward_tile(
            geo: &TileGeometry, list: &[u32], splats: &[Splat<F>], state: &mut TileState<F>,
        ));
        if build.available() {
            match build {
                // SAFETY: the CPU runs this build (checked just above).
                KernelBuild::Avx512 => return unsafe { avx512(geo, list, splats, state) },
                // SAFETY: as above.
                KernelBuild::Avx2 => return unsafe { avx2(geo, list, splats, state) },
                KernelBuild::Portable => {}
            }
        }
    }
    forward_tile::<F, Unfused>(geo, list, splats, state)
}

/// [`backward_tile`] in `build` (as [`forward_tile_with`]).
#[allow(clippy::too_many_arguments)]
pub fn backward_tile_with<F: Real>(
    build: KernelBuild,
    geo: &TileGeometry,
    list: &[u32],
    splats: &[Splat<F>],
    state: &TileState<F>,
    background: [F; 3],
    grad: &TileGrad<F>,
    out: &mut [F],
) -> u64 {
    #[cfg(target_arch = "x86_64")]
    {
        compiled_for!("avx2,fma", avx2, backward_tile(
            geo: &TileGeometry, list: &[u32], splats: &[Splat<F>], state: &TileState<F>,
            background: [F; 3], grad: &TileGrad<F>, out: &mut [F],
        ));
        compiled_for!("avx512f,avx512vl,avx2,fma", avx512, backward_tile(
            geo: &TileGeometry, list: &[u32], splats: &[Splat<F>], state: &TileState<F>,
            background: [F; 3], grad: &TileGrad<F>, out: &mut [F],
        ));
        if build.available() {
            match build {
                // SAFETY: the CPU runs this build (checked just above).
                KernelBuild::Avx512 => {
                    return unsafe { avx512(geo, list, splats, state, background, grad, out) };
                }
                // SAFETY: as above.
                KernelBuild::Avx2 => {
                    return unsafe { avx2(geo, list, splats, state, background, grad, out) };
                }
                KernelBuild::Portable => {}
            }
        }
    }
    backward_tile::<F, Unfused>(geo, list, splats, state, background, grad, out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::blend::TILE_PIXELS;
    use crate::raster::project::SplatGrad;
    use crate::raster::render::{forward, tile_geometry};
    use crate::raster::tests::{Scene, camera, f32_refs, settings};

    /// Every build this CPU runs gives the best build's tiles, forward and backward: the fused
    /// builds bit for bit, the portable one within rounding.
    #[test]
    fn every_build_gives_the_same_tiles() {
        let scene = Scene::random_with_opacity(3, 150, 16, (-1.0, 6.0));
        let arrays = scene.to_f32();
        let cam = camera();
        let (_, ctx) = forward(&f32_refs(&arrays, 16), &cam, &settings());
        const L: usize = SplatGrad::<f32>::LEN;
        let run = |build: KernelBuild| -> Vec<f32> {
            let mut values = Vec::new();
            for t in 0..ctx.bins.num_tiles() {
                let geo = tile_geometry(&cam, t, ctx.bins.tiles_x);
                let list = ctx.bins.tile_entries(t);
                let mut state = TileState::default();
                forward_tile_with(build, &geo, list, &ctx.splats, &mut state);
                let mut grad = TileGrad::<f32>::default();
                for (k, v) in grad.color[0].iter_mut().flatten().enumerate() {
                    *v = ((k * 7919 + t) % 13) as f32 / 13.0 - 0.5;
                }
                grad.alpha = grad.color[0];
                let mut out = vec![0.0f32; list.len() * L];
                backward_tile_with(
                    build,
                    &geo,
                    list,
                    &ctx.splats,
                    &state,
                    [0.2; 3],
                    &grad,
                    &mut out,
                );
                values.extend(state.color.iter().flatten().flatten());
                values.extend(state.transmittance.iter().flatten());
                values.extend(out);
            }
            values
        };
        let best = run(KernelBuild::best());
        assert!(
            best.len() > 10 * TILE_PIXELS,
            "too few values: {}",
            best.len()
        );
        let fused = [KernelBuild::Avx2, KernelBuild::Avx512];
        for build in fused.into_iter().filter(|b| b.available()) {
            assert_eq!(
                run(build),
                best,
                "{build:?} differs from {:?}",
                KernelBuild::best()
            );
        }
        let portable = run(KernelBuild::Portable);
        let worst = portable
            .iter()
            .zip(&best)
            .map(|(a, b)| (a - b).abs() / (1.0 + b.abs()))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-3, "portable build differs by {worst}");
    }
}
