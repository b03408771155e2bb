//! The rasterizer on the GPU (feature `gpu`): CubeCL kernels behind the same Burn op as the CPU
//! rasterizer, run by Burn's cube backend on wgpu (Vulkan on NVIDIA and AMD, Metal, DX12; Mesa's
//! lavapipe on machines without a GPU).
//!
//! Stages, each in its own module, the twins of [`crate::raster`]'s:
//! 1. [`project`]: per Gaussian, the EWA projection, conic, SH colour, opacity, tile rectangle;
//! 2. [`sort`] (on [`scan`]) and [`tiles`]: a stable radix sort by depth, one pair per covered
//!    tile, a stable radix sort of the pairs by tile, each tile's range, in buffers sized by
//!    [`pairs`];
//! 3. [`blend`]: per 16×16 tile, front-to-back blending with the same thresholds.
//!
//! The backward pass runs them in reverse with exact gradients and without floating-point
//! atomics (WGSL has none): each (tile, Gaussian) pair's gradient is reduced across its tile
//! and written to the pair's own slot, then summed per Gaussian in a fixed order. The CPU
//! rasterizer is the oracle: the module's tests compare images and every gradient.

pub mod blend;
mod launch;
pub mod pairs;
pub mod profile;
pub mod project;
pub mod render;
pub mod scan;
mod sh;
pub mod sort;
pub mod tiles;

#[cfg(test)]
mod tests;

pub use pairs::{PairCountCheck, deferred};
pub use render::{GpuState, backward, forward};
