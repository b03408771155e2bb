//! Buffers and launch sizes shared by the kernels: typed uploads and read-backs of plain
//! `u32`/`f32` device buffers, and the kernel arguments that view them.

use cubecl::prelude::*;
use cubecl::server::Handle;

/// A device buffer as a kernel argument of `len` elements.
///
/// Every buffer the rasterizer passes was allocated by this module with at least `len` elements
/// of 4 bytes, which is what makes the unchecked construction sound.
pub fn arg(handle: &Handle, len: usize) -> BufferArg {
    debug_assert!(
        handle.size() as usize >= len * 4,
        "buffer shorter than its argument"
    );
    // SAFETY: the buffer holds at least `len` 4-byte elements (checked above in debug builds,
    // and guaranteed by the allocations of this module).
    unsafe { BufferArg::from_raw_parts(handle.clone(), len.max(1)) }
}

/// Uploads `f32` values.
pub fn upload_f32(client: &Client, values: &[f32]) -> Handle {
    client.create_from_slice(f32::as_bytes(values))
}

/// A buffer of `len` 4-byte elements (at least one, so that an empty render still binds).
pub fn alloc(client: &Client, len: usize) -> Handle {
    client.empty(len.max(1) * 4)
}

/// Reads the one `u32` at `index` back to the host (waits for the device), copying 4 bytes
/// rather than the whole buffer.
/// Counted in [`fewview_optim::read_backs`].
pub fn read_u32_at(client: &Client, handle: &Handle, index: usize) -> u32 {
    fewview_optim::note_read_back();
    let bytes = client.read_one_unchecked(handle.clone().offset_start(4 * index as u64));
    u32::from_bytes(&bytes)[0]
}

/// The most cubes a launch may have along one axis (WebGPU's and Vulkan's usual limit).
pub const MAX_CUBES_PER_AXIS: usize = 65_535;

/// Cubes of `units` units covering `n` elements, one element per unit. Beyond
/// [`MAX_CUBES_PER_AXIS`] cubes (16.7M elements at 256 units) the grid is two-dimensional; the
/// kernels read their linear `CUBE_POS` and `ABSOLUTE_POS`, and the few surplus cubes at the end
/// of the grid find no element (kernels that write per cube check `CUBE_POS` against their block
/// count).
pub fn cubes_for(n: usize, units: usize) -> CubeCount {
    let (x, y) = grid(n.div_ceil(units).max(1));
    CubeCount::Static(x as u32, y as u32, 1)
}

/// `(x, y)` with `x ≤ MAX_CUBES_PER_AXIS` and `x·y ≥ cubes`, the surplus below `y`.
fn grid(cubes: usize) -> (usize, usize) {
    let y = cubes.div_ceil(MAX_CUBES_PER_AXIS);
    (cubes.div_ceil(y), y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_launches_become_two_dimensional_grids_with_little_surplus() {
        assert_eq!(grid(1), (1, 1));
        assert_eq!(grid(MAX_CUBES_PER_AXIS), (MAX_CUBES_PER_AXIS, 1));
        assert_eq!(grid(MAX_CUBES_PER_AXIS + 1), (32_768, 2));
        for cubes in [70_000, 1_000_000, 4_000_003] {
            let (x, y) = grid(cubes);
            assert!(x <= MAX_CUBES_PER_AXIS && x * y >= cubes && x * y - cubes < y);
        }
    }
}
