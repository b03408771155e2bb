//! Tile binning on the device, as [`crate::raster::tiles`]: Gaussians in depth order, each
//! emitting one (tile, Gaussian) pair per tile its rectangle covers, then a stable sort of the
//! pairs by tile, so every tile's list stays front to back.
//!
//! A pair is known by its *emit slot*, its position before the tile sort: the slots of the
//! Gaussian of depth rank `r` are `offsets[r]..offsets[r + 1]`. The blend kernels read pairs in
//! tile order and the backward pass writes each pair's gradient at its emit slot, so summing a
//! Gaussian's gradient is a contiguous sum (no atomics, the same result every run).
//!
//! The pair buffers have a fixed number of slots, the *capacity*, chosen before the number of
//! pairs is known on the host (see [`super::pairs`]): the number stays on the device
//! ([`pair_total`]), every kernel here stops at the capacity, and a render whose pairs did not
//! fit is marked by its blend (see [`super::blend::blend_forward`]).

use cubecl::prelude::*;

/// Number of tiles of the rectangle of the Gaussian of each depth rank (0 when culled), and a
/// 0 after the last rank, so that the exclusive scan's last entry is the total.
#[cube(launch)]
pub fn tile_counts(order: &[u32], rects: &[u32], counts: &mut [u32], n: u32) {
    let r = ABSOLUTE_POS;
    if r > n as usize {
        terminate!();
    }
    if r == n as usize {
        counts[r] = 0u32;
        terminate!();
    }
    let g = order[r] as usize;
    let (tx0, tx1, ty0, ty1) = (
        rects[4 * g],
        rects[4 * g + 1],
        rects[4 * g + 2],
        rects[4 * g + 3],
    );
    counts[r] = (tx1 - tx0) * (ty1 - ty0);
}

/// Copies the number of pairs, the last entry of the scanned counts, to `total[0]`.
#[cube(launch)]
pub fn pair_total(offsets: &[u32], total: &mut [u32], n: u32) {
    if ABSOLUTE_POS == 0 {
        total[0] = offsets[n as usize];
    }
}

/// Writes the pairs of the Gaussian of each depth rank at its emit slots: the tile id as the
/// sort key, the emit slot as the sorted value, and the Gaussian at `slot_gaussian[slot]`.
/// Slots from `capacity` on are not written (the pairs did not fit).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn emit_pairs(
    order: &[u32],
    rects: &[u32],
    offsets: &[u32],
    tile_keys: &mut [u32],
    slots: &mut [u32],
    slot_gaussian: &mut [u32],
    n: u32,
    tiles_x: u32,
    capacity: u32,
) {
    let r = ABSOLUTE_POS;
    if r >= n as usize {
        terminate!();
    }
    let g = order[r];
    let gi = g as usize;
    let (tx0, tx1, ty0, ty1) = (
        rects[4 * gi],
        rects[4 * gi + 1],
        rects[4 * gi + 2],
        rects[4 * gi + 3],
    );
    let mut slot = offsets[r];
    for ty in ty0..ty1 {
        for tx in tx0..tx1 {
            if slot < capacity {
                let s = slot as usize;
                tile_keys[s] = ty * tiles_x + tx;
                slots[s] = slot;
                slot_gaussian[s] = g;
            }
            slot += 1;
        }
    }
}

/// First index in `keys[0..len]` (sorted) whose key is `≥ value`.
#[cube]
fn lower_bound(keys: &[u32], len: u32, value: u32) -> u32 {
    let mut lo = 0u32;
    let mut hi = len;
    while lo < hi {
        let mid = (lo + hi) / 2;
        if keys[mid as usize] < value {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Each tile's range `[start, end)` in the tile-sorted pairs, of which there are `total[0]`
/// (at most `capacity`).
#[cube(launch)]
pub fn tile_ranges(
    sorted_keys: &[u32],
    total: &[u32],
    ranges: &mut [u32],
    capacity: u32,
    num_tiles: u32,
) {
    let t = ABSOLUTE_POS;
    if t >= num_tiles as usize {
        terminate!();
    }
    let pairs = total[0].min(capacity);
    ranges[2 * t] = lower_bound(sorted_keys, pairs, t as u32);
    ranges[2 * t + 1] = lower_bound(sorted_keys, pairs, t as u32 + 1);
}

/// Sums each Gaussian's pair gradients (`grads` at emit slots, `width` floats each) into
/// `out[g * width ..]`, for the Gaussian `g` of each depth rank, over the slots below
/// `capacity`.
#[cube(launch)]
pub fn gather_pair_grads(
    order: &[u32],
    offsets: &[u32],
    grads: &[f32],
    out: &mut [f32],
    n: u32,
    capacity: u32,
    #[comptime] width: usize,
) {
    let r = ABSOLUTE_POS;
    if r >= n as usize {
        terminate!();
    }
    let g = order[r] as usize;
    let start = offsets[r].min(capacity) as usize;
    let end = offsets[r + 1].min(capacity) as usize;
    #[unroll]
    for k in 0..width {
        let mut sum = 0.0f32;
        for s in start..end {
            sum += grads[s * width + k];
        }
        out[g * width + k] = sum;
    }
}
