//! A stable least-significant-digit radix sort of `(u32 key, u32 value)` pairs on the device.
//!
//! Each pass sorts by one 8-bit digit in three kernels: per-block digit histograms (laid out
//! digit-major, so that one exclusive scan of the table gives every block's first slot for every
//! digit), the scan ([`super::scan`]), and a stable scatter that ranks each element among the
//! earlier elements of its block with the same digit (per-segment digit counts plus a scan of
//! the element's own 16-unit segment). Stability across passes makes the result equal to a
//! stable sort by key, so equal keys keep their input order (the CPU rasterizer breaks depth
//! ties by Gaussian index the same way).

use cubecl::prelude::*;
use cubecl::server::Handle;

use super::launch::{alloc, arg, cubes_for};
use super::scan::exclusive_scan;

/// Elements per block (one per unit).
pub const SORT_BLOCK: usize = 256;
/// Bits sorted per pass.
pub const DIGIT_BITS: u32 = 8;
const BINS: usize = 1 << DIGIT_BITS;
const _: () = assert!(
    BINS == 256 && BINS == SORT_BLOCK,
    "the scatter kernel's out-of-range digit is 256, and its unit u scans digit u"
);

/// The number of elements a pass sorts: `len`, or, when `counted`, the smaller of `len` and the
/// count the device holds in `count[0]` (the elements after it are left out).
#[cube]
fn sorted_len(len: u32, count: &[u32], #[comptime] counted: bool) -> u32 {
    let mut active = len;
    if counted {
        active = count[0].min(len);
    }
    active
}

/// Counts each digit in each block into `hist[digit * blocks + block]`.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
fn digit_histogram(
    keys: &[u32],
    count: &[u32],
    hist: &mut [u32],
    len: u32,
    shift: u32,
    blocks: u32,
    #[comptime] counted: bool,
) {
    let counts = Shared::<[Atomic<u32>]>::new_slice(BINS);
    let unit = UNIT_POS as usize;
    counts[unit].store(0u32);
    sync_cube();
    let i = ABSOLUTE_POS;
    if i < sorted_len(len, count, counted) as usize {
        let digit = (keys[i] >> shift) & (BINS as u32 - 1);
        counts[digit as usize].fetch_add(1u32);
    }
    sync_cube();
    if CUBE_POS < blocks as usize {
        hist[unit * blocks as usize + CUBE_POS] = counts[unit].load();
    }
}

/// Units per segment of a block in the scatter's ranking.
const SEGMENT: usize = 16;
const SEGMENTS: usize = SORT_BLOCK / SEGMENT;

/// Moves each pair to its slot: the block's first slot for its digit plus the number of earlier
/// elements of the block with the same digit. That rank is counted in two parts: the earlier
/// 16-unit segments' counts of the digit (per-segment digit counts, scanned across segments),
/// and the earlier units of the element's own segment, so that no unit scans the whole block.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
fn stable_scatter(
    keys: &[u32],
    values: &[u32],
    count: &[u32],
    starts: &[u32],
    keys_out: &mut [u32],
    values_out: &mut [u32],
    len: u32,
    shift: u32,
    blocks: u32,
    #[comptime] counted: bool,
) {
    let mut digits = Shared::<[u32]>::new_slice(SORT_BLOCK);
    // `before[segment * BINS + digit]`: elements with the digit in the segment, then (after the
    // scan) in the earlier segments.
    let before = Shared::<[Atomic<u32>]>::new_slice(SEGMENTS * BINS);
    let unit = UNIT_POS as usize;
    let segment = unit / SEGMENT;
    #[unroll]
    for s in 0..SEGMENTS {
        before[s * BINS + unit].store(0u32);
    }
    let i = ABSOLUTE_POS;
    let inside = i < sorted_len(len, count, counted) as usize;
    let mut key = 0u32;
    // Out-of-range units take a digit no element has, so they never count as "earlier".
    let mut digit = 256u32;
    if inside {
        key = keys[i];
        digit = (key >> shift) & (BINS as u32 - 1);
    }
    digits[unit] = digit;
    sync_cube();
    if inside {
        before[segment * BINS + digit as usize].fetch_add(1u32);
    }
    sync_cube();
    // Unit u scans digit u's counts across the segments.
    let mut running = 0u32;
    #[unroll]
    for s in 0..SEGMENTS {
        let count = before[s * BINS + unit].load();
        before[s * BINS + unit].store(running);
        running += count;
    }
    sync_cube();
    if inside {
        let mut rank = before[segment * BINS + digit as usize].load();
        for j in segment * SEGMENT..unit {
            if digits[j] == digit {
                rank += 1;
            }
        }
        let slot = starts[digit as usize * blocks as usize + CUBE_POS] + rank;
        keys_out[slot as usize] = key;
        values_out[slot as usize] = values[i];
    }
}

/// Writes `0, 1, …, len − 1`.
#[cube(launch)]
fn iota(out: &mut [u32], len: u32) {
    let i = ABSOLUTE_POS;
    if i < len as usize {
        out[i] = i as u32;
    }
}

/// The buffer `0, 1, …, len − 1` (the values that make a sort return its permutation).
pub fn indices(client: &Client, len: usize) -> Handle {
    let out = alloc(client, len);
    iota::launch(
        client,
        cubes_for(len, SORT_BLOCK),
        CubeDim::new_1d(SORT_BLOCK as u32),
        arg(&out, len),
        len as u32,
    );
    out
}

/// Sorts the first `len` pairs stably by the low `key_bits` bits of their keys. Returns the
/// sorted `(keys, values)` as new buffers.
pub fn sort_pairs(
    client: &Client,
    keys: &Handle,
    values: &Handle,
    len: usize,
    key_bits: u32,
) -> (Handle, Handle) {
    sort_counted_pairs(client, keys, values, len, None, key_bits)
}

/// [`sort_pairs`] of the first `count[0]` pairs (at most `len`) where `count` is a one-element
/// device buffer: the number of pairs need not come back to the host. The sorted pairs fill
/// the first `count[0]` slots of the outputs; the slots after them hold nothing meaningful.
pub fn sort_counted_pairs(
    client: &Client,
    keys: &Handle,
    values: &Handle,
    len: usize,
    count: Option<&Handle>,
    key_bits: u32,
) -> (Handle, Handle) {
    // Without a count the kernels never read it; the keys stand in for the binding.
    let (count, counted) = match count {
        Some(count) => (count, true),
        None => (keys, false),
    };
    let mut keys = keys.clone();
    let mut values = values.clone();
    if len <= 1 {
        return (keys, values);
    }
    let blocks = len.div_ceil(SORT_BLOCK);
    let hist = alloc(client, BINS * blocks);
    let mut shift = 0;
    while shift < key_bits.max(1) {
        digit_histogram::launch(
            client,
            cubes_for(len, SORT_BLOCK),
            CubeDim::new_1d(SORT_BLOCK as u32),
            arg(&keys, len),
            arg(count, 1),
            arg(&hist, BINS * blocks),
            len as u32,
            shift,
            blocks as u32,
            counted,
        );
        let starts = exclusive_scan(client, &hist, BINS * blocks);
        let (keys_out, values_out) = (alloc(client, len), alloc(client, len));
        stable_scatter::launch(
            client,
            cubes_for(len, SORT_BLOCK),
            CubeDim::new_1d(SORT_BLOCK as u32),
            arg(&keys, len),
            arg(&values, len),
            arg(count, 1),
            arg(&starts, BINS * blocks),
            arg(&keys_out, len),
            arg(&values_out, len),
            len as u32,
            shift,
            blocks as u32,
            counted,
        );
        keys = keys_out;
        values = values_out;
        shift += DIGIT_BITS;
    }
    (keys, values)
}

/// Bits needed to write every value below `n` (at least 1).
pub fn bits_for(n: usize) -> u32 {
    (usize::BITS - n.saturating_sub(1).leading_zeros()).max(1)
}
