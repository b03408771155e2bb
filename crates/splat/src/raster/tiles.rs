//! Tile binning: which splats touch which 16×16 tile, each tile's list in front-to-back order.
//!
//! Instead of one global sort of (tile, depth) keys, splats are sorted once by depth (ties by
//! index, so the order is deterministic) and then scattered into per-tile ranges in that order
//! (a counting sort by tile), which leaves every tile's list depth-sorted.

use rayon::prelude::*;

use super::inputs::TILE;
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
///
/// Parallel in three passes over chunks of the depth order: count each chunk's tiles, give every
/// (chunk, tile) a disjoint range of its tile's entries, then fill those ranges (each in depth
/// order, so every tile's list is depth-sorted).
pub fn bin<F: Real>(splats: &[Splat<F>], tiles_x: usize, tiles_y: usize) -> TileBins {
    // Depths are positive (splats lie beyond the near plane), so the bit patterns of their f64
    // values order like the values; sorting plain (bits, index) keys avoids an indirect float
    // comparison per step.
    let mut keys: Vec<(u64, u32)> = splats
        .par_iter()
        .enumerate()
        .map(|(i, s)| (s.depth.to_f64_lossy().max(0.0).to_bits(), i as u32))
        .collect();
    keys.par_sort_unstable();
    let order: Vec<u32> = keys.into_par_iter().map(|(_, i)| i).collect();
    let num_tiles = tiles_x * tiles_y;
    let spans: Vec<([usize; 2], [usize; 2])> = order
        .par_iter()
        .map(|&s| {
            let sp = &splats[s as usize];
            (tile_span(sp.cols), tile_span(sp.rows))
        })
        .collect();
    let chunk = order
        .len()
        .div_ceil(rayon::current_num_threads() * 4)
        .max(1024);

    // Pass 1: tile counts per chunk.
    let chunk_counts: Vec<Vec<u32>> = spans
        .par_chunks(chunk)
        .map(|part| {
            let mut counts = vec![0u32; num_tiles];
            for &([tx0, tx1], [ty0, ty1]) in part {
                for ty in ty0..ty1 {
                    for c in &mut counts[ty * tiles_x + tx0..ty * tiles_x + tx1] {
                        *c += 1;
                    }
                }
            }
            counts
        })
        .collect();
    // Tile offsets, and each chunk's starting cursor within every tile.
    let mut offsets = Vec::with_capacity(num_tiles + 1);
    let mut cursors = vec![vec![0usize; num_tiles]; chunk_counts.len()];
    let mut acc = 0usize;
    for t in 0..num_tiles {
        offsets.push(acc);
        for (k, counts) in chunk_counts.iter().enumerate() {
            cursors[k][t] = acc;
            acc += counts[t] as usize;
        }
    }
    offsets.push(acc);
    let mut pair_offsets = Vec::with_capacity(order.len() + 1);
    pair_offsets.push(0usize);
    for &([tx0, tx1], [ty0, ty1]) in &spans {
        let last = pair_offsets[pair_offsets.len() - 1];
        pair_offsets.push(last + (tx1 - tx0) * (ty1 - ty0));
    }

    // Pass 2: fill. Chunk k writes entries only at its own cursors (disjoint ranges).
    let mut entries = vec![0u32; acc];
    let mut pair_slots = vec![0u32; acc];
    let entries_ptr = fewview_scene::cpu::SharedMut(entries.as_mut_ptr());
    let mut slot_parts = Vec::with_capacity(cursors.len());
    let mut rest = pair_slots.as_mut_slice();
    for k in 0..cursors.len() {
        let (lo, hi) = (k * chunk, ((k + 1) * chunk).min(order.len()));
        let (part, tail) = rest.split_at_mut(pair_offsets[hi] - pair_offsets[lo]);
        slot_parts.push(part);
        rest = tail;
    }
    cursors
        .into_par_iter()
        .zip(slot_parts)
        .enumerate()
        .for_each(|(k, (mut cursor, slots))| {
            let lo = k * chunk;
            let hi = (lo + chunk).min(order.len());
            let mut n = 0;
            for rank in lo..hi {
                let ([tx0, tx1], [ty0, ty1]) = spans[rank];
                for ty in ty0..ty1 {
                    for tx in tx0..tx1 {
                        let t = ty * tiles_x + tx;
                        let pos = cursor[t];
                        // SAFETY: `pos` lies in this chunk's range of tile `t`
                        // (`cursors[k][t]..cursors[k][t] + chunk_counts[k][t]`), disjoint from
                        // every other chunk's ranges, and inside `entries`.
                        unsafe { *entries_ptr.get().add(pos) = order[rank] };
                        slots[n] = pos as u32;
                        n += 1;
                        cursor[t] += 1;
                    }
                }
            }
        });
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Naive binning: for every tile, all splats whose span covers it, sorted by (depth, index).
    #[test]
    fn matches_naive_binning() {
        let mut splats = Vec::new();
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        for _ in 0..5000 {
            let x0 = next() % 300;
            let y0 = next() % 200;
            splats.push(Splat::<f32> {
                depth: (next() % 50) as f32, // many ties
                cols: [x0, (x0 + 1 + next() % 40).min(300)],
                rows: [y0, (y0 + 1 + next() % 40).min(200)],
                ..Default::default()
            });
        }
        let (tx, ty) = (300usize.div_ceil(TILE), 200usize.div_ceil(TILE));
        let bins = bin(&splats, tx, ty);
        for t in 0..tx * ty {
            let (x, y) = (t % tx, t / tx);
            let mut want: Vec<u32> = (0..splats.len() as u32)
                .filter(|&i| {
                    let s = &splats[i as usize];
                    let [a, b] = tile_span(s.cols);
                    let [c, d] = tile_span(s.rows);
                    (a..b).contains(&x) && (c..d).contains(&y)
                })
                .collect();
            want.sort_by(|&a, &b| {
                splats[a as usize]
                    .depth
                    .partial_cmp(&splats[b as usize].depth)
                    .unwrap()
                    .then(a.cmp(&b))
            });
            assert_eq!(bins.tile_entries(t), want.as_slice(), "tile {t}");
        }
        // Every pair slot points back at its splat.
        for (rank, &s) in bins.depth_order.iter().enumerate() {
            for &slot in &bins.pair_slots[bins.pair_offsets[rank]..bins.pair_offsets[rank + 1]] {
                assert_eq!(bins.entries[slot as usize], s);
            }
        }
    }
}
