//! Tile binning: which splats touch which 16×16 tile, each tile's list in front-to-back order.
//!
//! Instead of one global sort of (tile, depth) keys, splats are sorted once by depth (ties by
//! index, so the order is deterministic) and then scattered into per-tile ranges in that order
//! (a counting sort by tile), which leaves every tile's list depth-sorted.

use rayon::prelude::*;

use super::TILE;
use super::project::Splat;
use crate::real::Real;

/// Per-tile, depth-sorted lists of splat indices.
#[derive(Clone, Debug, Default)]
pub struct TileBins {
    pub tiles_x: usize,
    pub tiles_y: usize,
    /// `offsets[t]..offsets[t + 1]` is tile `t`'s range in `entries`.
    pub offsets: Vec<usize>,
    /// Splat indices, grouped by tile, front to back within a tile.
    pub entries: Vec<u32>,
    /// For splat `s` (in depth order, see `depth_order`), the positions in `entries` of its
    /// occurrences are `pair_slots[pair_offsets[k]..pair_offsets[k + 1]]` where `k` is the splat's
    /// rank in depth order. Used by the backward pass to sum per-tile gradients in a fixed order.
    pub pair_offsets: Vec<usize>,
    pub pair_slots: Vec<u32>,
    /// Splat indices sorted front to back.
    pub depth_order: Vec<u32>,
}

impl TileBins {
    pub fn num_tiles(&self) -> usize {
        self.tiles_x * self.tiles_y
    }

    pub fn tile_entries(&self, t: usize) -> &[u32] {
        &self.entries[self.offsets[t]..self.offsets[t + 1]]
    }
}

/// Tile range `[t0, t1)` covered by a pixel range `[p0, p1)`.
#[inline]
fn tile_span(px: [u32; 2]) -> [usize; 2] {
    [px[0] as usize / TILE, (px[1] as usize - 1) / TILE + 1]
}

/// Bins splats into the `tiles_x × tiles_y` grid.
pub fn bin<F: Real>(splats: &[Splat<F>], tiles_x: usize, tiles_y: usize) -> TileBins {
    let mut order: Vec<u32> = (0..splats.len() as u32).collect();
    order.par_sort_unstable_by(|&a, &b| {
        splats[a as usize]
            .depth
            .partial_cmp(&splats[b as usize].depth)
            .unwrap_or(std::cmp::Ordering::Equal)
            .then(a.cmp(&b))
    });

    let num_tiles = tiles_x * tiles_y;
    let mut counts = vec![0usize; num_tiles + 1];
    let mut pair_offsets = Vec::with_capacity(order.len() + 1);
    pair_offsets.push(0);
    for &s in &order {
        let sp = &splats[s as usize];
        let [tx0, tx1] = tile_span(sp.cols);
        let [ty0, ty1] = tile_span(sp.rows);
        for ty in ty0..ty1 {
            for tx in tx0..tx1 {
                counts[ty * tiles_x + tx] += 1;
            }
        }
        pair_offsets.push(pair_offsets.last().copied().unwrap_or(0) + (tx1 - tx0) * (ty1 - ty0));
    }
    let mut offsets = Vec::with_capacity(num_tiles + 1);
    let mut acc = 0;
    for &c in &counts[..num_tiles] {
        offsets.push(acc);
        acc += c;
    }
    offsets.push(acc);

    let mut cursor = offsets.clone();
    let mut entries = vec![0u32; acc];
    let mut pair_slots = Vec::with_capacity(acc);
    for &s in &order {
        let sp = &splats[s as usize];
        let [tx0, tx1] = tile_span(sp.cols);
        let [ty0, ty1] = tile_span(sp.rows);
        for ty in ty0..ty1 {
            for tx in tx0..tx1 {
                let t = ty * tiles_x + tx;
                entries[cursor[t]] = s;
                pair_slots.push(cursor[t] as u32);
                cursor[t] += 1;
            }
        }
    }
    TileBins {
        tiles_x,
        tiles_y,
        offsets,
        entries,
        pair_offsets,
        pair_slots,
        depth_order: order,
    }
}
