//! Exclusive prefix sums of `u32` arrays on the device (block scans, then the block totals
//! scanned recursively and added back), the building block of tile binning and radix sorting.

use cubecl::prelude::*;
use cubecl::server::Handle;

use super::launch::{alloc, arg, cubes_for};

/// Units per cube of the scan kernels (and elements per block).
pub const SCAN_BLOCK: usize = 256;

/// Inclusive Hillis–Steele scan of one value per unit across the cube, in shared memory.
#[cube]
pub fn cube_inclusive_scan(value: u32, shared: &mut [u32]) -> u32 {
    let unit = UNIT_POS as usize;
    shared[unit] = value;
    let mut offset = 1usize;
    while offset < CUBE_DIM as usize {
        sync_cube();
        let mut add = 0u32;
        if unit >= offset {
            add = shared[unit - offset];
        }
        sync_cube();
        shared[unit] += add;
        offset *= 2;
    }
    sync_cube();
    shared[unit]
}

/// Exclusive scan of each block of `input` into `output`; each block's total goes to `totals`.
#[cube(launch)]
fn scan_blocks(input: &[u32], output: &mut [u32], totals: &mut [u32], len: u32, blocks: u32) {
    let mut shared = Shared::<[u32]>::new_slice(SCAN_BLOCK);
    let i = ABSOLUTE_POS;
    let mut value = 0u32;
    if i < len as usize {
        value = input[i];
    }
    let inclusive = cube_inclusive_scan(value, &mut shared);
    if i < len as usize {
        output[i] = inclusive - value;
    }
    if UNIT_POS == CUBE_DIM - 1 && CUBE_POS < blocks as usize {
        totals[CUBE_POS] = inclusive;
    }
}

/// Adds each block's scanned total to the block's elements.
#[cube(launch)]
fn add_block_offsets(output: &mut [u32], offsets: &[u32], len: u32) {
    let i = ABSOLUTE_POS;
    if i < len as usize {
        output[i] += offsets[CUBE_POS];
    }
}

/// Exclusive scan of the first `len` values of `input` (a `u32` buffer); returns a new buffer.
pub fn exclusive_scan(client: &Client, input: &Handle, len: usize) -> Handle {
    let output = alloc(client, len);
    if len == 0 {
        return output;
    }
    let blocks = len.div_ceil(SCAN_BLOCK);
    let totals = alloc(client, blocks);
    scan_blocks::launch(
        client,
        cubes_for(len, SCAN_BLOCK),
        CubeDim::new_1d(SCAN_BLOCK as u32),
        arg(input, len),
        arg(&output, len),
        arg(&totals, blocks),
        len as u32,
        blocks as u32,
    );
    if blocks > 1 {
        let offsets = exclusive_scan(client, &totals, blocks);
        add_block_offsets::launch(
            client,
            cubes_for(len, SCAN_BLOCK),
            CubeDim::new_1d(SCAN_BLOCK as u32),
            arg(&output, len),
            arg(&offsets, blocks),
            len as u32,
        );
    }
    output
}
