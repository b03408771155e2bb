//! Front-to-back alpha blending on the device, one cube per 16×16 tile and one unit per pixel,
//! as [`crate::raster::blend`]: the tile's splats are staged in shared memory a batch at a time;
//! the forward pass stops a pixel before its transmittance would fall below 1e-4 and the whole
//! tile once every pixel has stopped. The backward pass walks each tile's list back to front,
//! recovering the transmittance by division as the CPU code does, and reduces each splat's
//! per-pixel gradients across the tile (plane sums where the device has them, else a
//! shared-memory tree) into the splat's pair slot. The plane sums come in two orders with the
//! same sums: one splat at a time (two barriers per splat), or `grouped`, as many splats as a
//! plane has units summed across planes in one pass (two barriers per group; a plane with no
//! contribution skips its sums).
// Device code: CubeCL's expanded struct types are not `Copy` (a struct passed twice is cloned)
// and its macro cannot infer the type of a unary minus on some expressions (written as `* -1`).
#![allow(clippy::clone_on_copy, clippy::neg_multiply)]

use cubecl::prelude::*;

use super::project::{GRAD_FLOATS, SPLAT_FLOATS};
use crate::raster::{ALPHA_MAX, ALPHA_MIN, T_MIN, TILE};

/// Pixels per tile, units per cube, and splats staged per batch.
pub const TILE_UNITS: usize = TILE * TILE;
const _: () = assert!(
    TILE_UNITS == 256,
    "the tree reduction starts at half of 256 units"
);

/// One splat as the blend kernels read it.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone))]
struct Staged {
    mean_x: f32,
    mean_y: f32,
    conic_a: f32,
    conic_b: f32,
    conic_c: f32,
    opacity: f32,
    red: f32,
    green: f32,
    blue: f32,
    depth: f32,
}

#[cube]
fn stage(splats: &[f32], g: usize, cache: &mut [f32], unit: usize) {
    #[unroll]
    for k in 0..SPLAT_FLOATS {
        cache[unit * SPLAT_FLOATS + k] = splats[g * SPLAT_FLOATS + k];
    }
}

#[cube]
fn staged(cache: &[f32], j: usize) -> Staged {
    let o = j * SPLAT_FLOATS;
    Staged {
        mean_x: cache[o],
        mean_y: cache[o + 1],
        conic_a: cache[o + 2],
        conic_b: cache[o + 3],
        conic_c: cache[o + 4],
        opacity: cache[o + 5],
        red: cache[o + 6],
        green: cache[o + 7],
        blue: cache[o + 8],
        depth: cache[o + 9],
    }
}

/// The Gaussian falloff exponent at pixel offset `(dx, dy)`: `−½(a dx² + c dy²) − b dx dy`,
/// grouped and fused as the CPU code's FMA path, so that both make the same threshold decisions.
#[cube]
fn power_at(s: Staged, dx: f32, dy: f32) -> f32 {
    let ha: f32 = s.conic_a * -0.5f32;
    let k1: f32 = (s.conic_b * dy) * -1.0f32;
    let k0: f32 = s.conic_c * -0.5f32 * dy * dy;
    fma(dx, fma(ha, dx, k1), k0)
}

/// `exp(x)` as the CPU rasterizer's blend computes it ([`crate::real::exp_f32`] with fused
/// multiply-adds): a degree-6 polynomial after range reduction, scaled by `2ⁿ` built from the
/// exponent bits. The same operations in the same order give the CPU's value.
const NEG_LN2_HI: f32 = -0.693_145_75;
const NEG_LN2_LO: f32 = -1.428_606_8e-6;
const INV_6: f32 = 1.0 / 6.0;
const INV_24: f32 = 1.0 / 24.0;
const INV_120: f32 = 1.0 / 120.0;
const INV_720: f32 = 1.0 / 720.0;

#[cube]
fn exp_blend(x_in: f32) -> f32 {
    let x = clamp(x_in, f32::new(-87.0f32), f32::new(88.0f32));
    // The CPU code rounds with the 1.5·2²³ trick; device compilers may fold `(a + c) − c`, so
    // round directly (both round half to even).
    let n = (x * f32::new(std::f32::consts::LOG2_E)).round();
    let r = fma(n, f32::new(NEG_LN2_LO), fma(n, f32::new(NEG_LN2_HI), x));
    let r2 = r * r;
    let r4 = r2 * r2;
    let p01 = r + 1.0f32;
    let p23 = fma(r, f32::new(INV_6), f32::new(0.5f32));
    let p45 = fma(r, f32::new(INV_120), f32::new(INV_24));
    let p = fma(r4, fma(r2, f32::new(INV_720), p45), fma(r2, p23, p01));
    let bits = u32::cast_from(i32::cast_from(n) + 127i32) << 23u32;
    p * f32::reinterpret(bits)
}

/// This cube's tile and this unit's pixel `(x, y)`. Cubes are one-dimensional (subgroup builtins
/// require them): unit u is pixel (u mod 16, u / 16) of the tile.
#[cube]
fn tile_and_pixel(tiles_x: u32) -> (usize, u32, u32) {
    let tile = (CUBE_POS_Y * tiles_x + CUBE_POS_X) as usize;
    let px = CUBE_POS_X * TILE as u32 + UNIT_POS % TILE as u32;
    let py = CUBE_POS_Y * TILE as u32 + UNIT_POS / TILE as u32;
    (tile, px, py)
}

/// The tile's pair range, read once and made uniform across the cube.
#[cube]
fn tile_range(ranges: &[u32], tile: usize) -> (u32, u32) {
    let mut bounds = Shared::<[u32]>::new_slice(2usize);
    if UNIT_POS == 0 {
        bounds[0] = ranges[2 * tile];
        bounds[1] = ranges[2 * tile + 1];
    }
    sync_cube();
    (
        workgroup_uniform_load(&bounds[0]),
        workgroup_uniform_load(&bounds[1]),
    )
}

/// Renders `image` (`[H, W, 5]`: RGB + background, expected depth, alpha) and keeps, per pixel,
/// the final transmittance and the 1-based rank of the last splat that contributed.
///
/// When the render's `pair_count[0]` pairs did not fit in its `capacity` slots, every image
/// value is `unfit` instead (the host passes NaN, so that any loss of the image is NaN and the
/// render cannot pass for a good one; see [`super::pairs`]).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn blend_forward(
    splats: &[f32],
    ranges: &[u32],
    sorted_slots: &[u32],
    slot_gaussian: &[u32],
    background: &[f32],
    pair_count: &[u32],
    image: &mut [f32],
    final_t: &mut [f32],
    last: &mut [u32],
    width: u32,
    height: u32,
    tiles_x: u32,
    capacity: u32,
    unfit: f32,
) {
    let (tile, px, py) = tile_and_pixel(tiles_x);
    let inside = px < width && py < height;
    let unit = UNIT_POS as usize;
    let mut cache = Shared::<[f32]>::new_slice(TILE_UNITS * SPLAT_FLOATS);
    let stopped = Shared::<[Atomic<u32>]>::new_slice(1usize);
    if unit == 0 {
        stopped[0].store(0u32);
    }
    let (start, end) = tile_range(ranges, tile);
    if !inside {
        stopped[0].fetch_add(1u32);
    }
    let (xf, yf) = (px as f32 + 0.5, py as f32 + 0.5);
    let mut t = 1.0f32;
    let mut red = 0.0f32;
    let mut green = 0.0f32;
    let mut blue = 0.0f32;
    let mut depth = 0.0f32;
    let mut last_rank = 0u32;
    let mut alive = inside;
    let total = end - start;
    let batches = total.div_ceil(TILE_UNITS as u32);
    for b in 0..batches {
        sync_cube();
        if workgroup_uniform_load_atomic(&stopped[0]) == TILE_UNITS as u32 {
            break;
        }
        let first = b * TILE_UNITS as u32;
        let k = first + unit as u32;
        if k < total {
            let slot = sorted_slots[(start + k) as usize] as usize;
            stage(splats, slot_gaussian[slot] as usize, &mut cache, unit);
        }
        sync_cube();
        let count = (total - first).min(TILE_UNITS as u32);
        let mut j = 0u32;
        while alive && j < count {
            let s = staged(&cache, j as usize);
            let dy = yf - s.mean_y;
            let dx = xf - s.mean_x;
            let power = power_at(s.clone(), dx, dy);
            let alpha = (s.opacity * exp_blend(power)).min(ALPHA_MAX as f32);
            if power <= 0.0 && alpha >= ALPHA_MIN as f32 {
                if t * (1.0 - alpha) < T_MIN as f32 {
                    alive = false;
                    stopped[0].fetch_add(1u32);
                } else {
                    let w = alpha * t;
                    red = fma(w, s.red, red);
                    green = fma(w, s.green, green);
                    blue = fma(w, s.blue, blue);
                    depth = fma(w, s.depth, depth);
                    t -= w;
                    last_rank = first + j + 1;
                }
            }
            j += 1;
        }
    }
    if inside {
        let p = (py * width + px) as usize;
        image[5 * p] = red + t * background[0];
        image[5 * p + 1] = green + t * background[1];
        image[5 * p + 2] = blue + t * background[2];
        image[5 * p + 3] = depth;
        image[5 * p + 4] = 1.0 - t;
        final_t[p] = t;
        last[p] = last_rank;
        if pair_count[0] > capacity {
            #[unroll]
            for c in 0..5 {
                image[5 * p + c] = unfit;
            }
        }
    }
}

/// Sums `value` over the cube into `out` (valid in unit 0 after the call... read by the caller
/// through shared memory); see [`blend_backward`].
#[cube]
fn cube_sum_into(lanes: &mut [f32], value: f32, c: usize, #[comptime] plane: bool) {
    let unit = UNIT_POS as usize;
    if plane {
        let v = plane_sum(value);
        if UNIT_POS_PLANE == 0 {
            lanes[(unit / PLANE_DIM as usize) * GRAD_FLOATS + c] = v;
        }
    } else {
        lanes[c * TILE_UNITS + unit] = value;
    }
}

/// Reduces the staged lanes of one splat across the cube: unit `c < 10` returns gradient value
/// `c` (the others return 0). Ends with a barrier, so the lanes can be refilled.
#[cube]
fn finish_sum(lanes: &mut [f32], #[comptime] plane: bool) -> f32 {
    let unit = UNIT_POS as usize;
    let mut sum = 0.0f32;
    if plane {
        sync_cube();
        if unit < GRAD_FLOATS {
            let planes = (CUBE_DIM / PLANE_DIM) as usize;
            for p in 0..planes {
                sum += lanes[p * GRAD_FLOATS + unit];
            }
        }
    } else {
        // Half the cube (a literal: a mutable variable must start from a runtime value).
        let mut stride = 128usize;
        while stride > 0 {
            sync_cube();
            if unit < stride {
                #[unroll]
                for c in 0..GRAD_FLOATS {
                    let v = lanes[c * TILE_UNITS + unit + stride];
                    lanes[c * TILE_UNITS + unit] += v;
                }
            }
            stride /= 2;
        }
        sync_cube();
        if unit < GRAD_FLOATS {
            sum = lanes[unit * TILE_UNITS];
        }
    }
    sync_cube();
    sum
}

/// Writes this plane's sum of `value` (gradient value `c` of the `member`-th splat of the
/// current group) to `lanes[plane][member][c]`. `any`: whether some unit of the plane has a
/// contribution; a plane without one writes 0 and skips the sum.
#[cube]
fn plane_partial(lanes: &mut [f32], value: f32, c: usize, member: u32, any: bool) {
    let mut v = 0.0f32;
    if any {
        v = plane_sum(value);
    }
    if UNIT_POS_PLANE == 0 {
        let plane = UNIT_POS / PLANE_DIM;
        lanes[((plane * PLANE_DIM + member) as usize) * GRAD_FLOATS + c] = v;
    }
}

/// Sums the plane partials of a group of `members` splats (in the order they were processed,
/// the `m`-th at local index `first_local − m` of the cache) and writes each splat's gradient at
/// its pair slot. Starts and ends with a barrier.
#[cube]
fn flush_plane_partials(
    lanes: &[f32],
    cache_slot: &[u32],
    pair_grads: &mut [f32],
    first_local: u32,
    members: u32,
) {
    sync_cube();
    let planes = CUBE_DIM / PLANE_DIM;
    let outputs = members * GRAD_FLOATS as u32;
    let mut u = UNIT_POS;
    while u < outputs {
        let m = u / GRAD_FLOATS as u32;
        let c = (u % GRAD_FLOATS as u32) as usize;
        let mut sum = 0.0f32;
        for p in 0..planes {
            sum += lanes[((p * PLANE_DIM + m) as usize) * GRAD_FLOATS + c];
        }
        let slot = cache_slot[(first_local - m) as usize] as usize;
        pair_grads[slot * GRAD_FLOATS + c] = sum;
        u += CUBE_DIM;
    }
    sync_cube();
}

/// Gradients of every (tile, splat) pair's blending inputs, written at the pair's emit slot in
/// `pair_grads` (`[slot, 10]`, the layout of [`GRAD_FLOATS`]), from the image gradient
/// `grad_image` (`[H, W, 5]`).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn blend_backward(
    splats: &[f32],
    ranges: &[u32],
    sorted_slots: &[u32],
    slot_gaussian: &[u32],
    background: &[f32],
    final_t: &[f32],
    last: &[u32],
    grad_image: &[f32],
    pair_grads: &mut [f32],
    width: u32,
    height: u32,
    tiles_x: u32,
    #[comptime] plane: bool,
    #[comptime] grouped: bool,
) {
    let (tile, px, py) = tile_and_pixel(tiles_x);
    let inside = px < width && py < height;
    let unit = UNIT_POS as usize;
    let mut cache = Shared::<[f32]>::new_slice(TILE_UNITS * SPLAT_FLOATS);
    let mut cache_slot = Shared::<[u32]>::new_slice(TILE_UNITS);
    let mut lanes = Shared::<[f32]>::new_slice(TILE_UNITS * GRAD_FLOATS);
    let deepest = Shared::<[Atomic<u32>]>::new_slice(1usize);
    if unit == 0 {
        deepest[0].store(0u32);
    }
    let (start, end) = tile_range(ranges, tile);
    let p = (py * width + px) as usize;
    let mut t = 1.0f32;
    let mut my_last = 0u32;
    let mut g_r = 0.0f32;
    let mut g_g = 0.0f32;
    let mut g_b = 0.0f32;
    let mut g_d = 0.0f32;
    let mut g_a = 0.0f32;
    if inside {
        t = final_t[p];
        my_last = last[p];
        g_r = grad_image[5 * p];
        g_g = grad_image[5 * p + 1];
        g_b = grad_image[5 * p + 2];
        g_d = grad_image[5 * p + 3];
        g_a = grad_image[5 * p + 4];
    }
    deepest[0].fetch_max(my_last);
    sync_cube();
    let n_iter = workgroup_uniform_load_atomic(&deepest[0]).min(end - start);
    // Pairs behind every pixel's last contributor get no gradient: zero their slots.
    let mut k = n_iter + UNIT_POS;
    while k < end - start {
        let slot = sorted_slots[(start + k) as usize] as usize;
        #[unroll]
        for c in 0..GRAD_FLOATS {
            pair_grads[slot * GRAD_FLOATS + c] = 0.0;
        }
        k += TILE_UNITS as u32;
    }
    let (xf, yf) = (px as f32 + 0.5, py as f32 + 0.5);
    let mut acc_r = background[0];
    let mut acc_g = background[1];
    let mut acc_b = background[2];
    let mut acc_d = 0.0f32;
    let mut acc_a = 0.0f32;
    let batches = n_iter.div_ceil(TILE_UNITS as u32);
    for b in 0..batches {
        // Batch b covers ranks [lo, hi), taken from the back.
        let hi = n_iter - b * TILE_UNITS as u32;
        let lo = hi - hi.min(TILE_UNITS as u32);
        sync_cube();
        let k = lo + unit as u32;
        if k < hi {
            let slot = sorted_slots[(start + k) as usize];
            cache_slot[unit] = slot;
            stage(
                splats,
                slot_gaussian[slot as usize] as usize,
                &mut cache,
                unit,
            );
        }
        sync_cube();
        let mut rank = hi;
        // Splats of the current group so far (`grouped`).
        let mut member = 0u32;
        while rank > lo {
            rank -= 1;
            let local = (rank - lo) as usize;
            let s = staged(&cache, local);
            let dy = yf - s.mean_y;
            let dx = xf - s.mean_x;
            let power = power_at(s.clone(), dx, dy);
            let gauss = exp_blend(power);
            let alpha = (s.opacity * gauss).min(ALPHA_MAX as f32);
            let valid = rank < my_last && power <= 0.0 && alpha >= ALPHA_MIN as f32;
            let one_minus = 1.0 - alpha;
            let t_j = t / one_minus;
            let w = select(valid, alpha * t_j, 0.0f32);
            let mut dot = g_r * (s.red - acc_r);
            dot = fma(g_g, s.green - acc_g, dot);
            dot = fma(g_b, s.blue - acc_b, dot);
            dot = fma(g_d, s.depth - acc_d, dot);
            dot = fma(g_a, 1.0 - acc_a, dot);
            let free = valid && s.opacity * gauss < ALPHA_MAX as f32;
            let dl_dalpha = select(free, t_j * dot, 0.0f32);
            let dpow = dl_dalpha * alpha;
            let v0 = dpow * fma(s.conic_a, dx, s.conic_b * dy);
            let v1 = dpow * fma(s.conic_c, dy, s.conic_b * dx);
            let v2 = dpow * dx * dx * -0.5f32;
            let v3 = dpow * dx * dy * -1.0f32;
            let v4 = dpow * dy * dy * -0.5f32;
            let v5 = dl_dalpha * gauss;
            let v6 = w * g_r;
            let v7 = w * g_g;
            let v8 = w * g_b;
            let v9 = w * g_d;
            if grouped {
                // Plane sums into shared memory for a group of PLANE_DIM splats, then one
                // cross-plane pass for the whole group: two barriers per group.
                let any = plane_any(valid);
                plane_partial(&mut lanes, v0, 0, member, any);
                plane_partial(&mut lanes, v1, 1, member, any);
                plane_partial(&mut lanes, v2, 2, member, any);
                plane_partial(&mut lanes, v3, 3, member, any);
                plane_partial(&mut lanes, v4, 4, member, any);
                plane_partial(&mut lanes, v5, 5, member, any);
                plane_partial(&mut lanes, v6, 6, member, any);
                plane_partial(&mut lanes, v7, 7, member, any);
                plane_partial(&mut lanes, v8, 8, member, any);
                plane_partial(&mut lanes, v9, 9, member, any);
                member += 1;
                if member == PLANE_DIM || rank == lo {
                    let first_local = (rank - lo) + member - 1;
                    flush_plane_partials(&lanes, &cache_slot, pair_grads, first_local, member);
                    member = 0;
                }
            } else {
                cube_sum_into(&mut lanes, v0, 0, plane);
                cube_sum_into(&mut lanes, v1, 1, plane);
                cube_sum_into(&mut lanes, v2, 2, plane);
                cube_sum_into(&mut lanes, v3, 3, plane);
                cube_sum_into(&mut lanes, v4, 4, plane);
                cube_sum_into(&mut lanes, v5, 5, plane);
                cube_sum_into(&mut lanes, v6, 6, plane);
                cube_sum_into(&mut lanes, v7, 7, plane);
                cube_sum_into(&mut lanes, v8, 8, plane);
                cube_sum_into(&mut lanes, v9, 9, plane);
                let sum = finish_sum(&mut lanes, plane);
                if unit < GRAD_FLOATS {
                    pair_grads[cache_slot[local] as usize * GRAD_FLOATS + unit] = sum;
                }
            }
            let keep = select(valid, one_minus, 1.0f32);
            let add = select(valid, alpha, 0.0f32);
            acc_r = fma(add, s.red, keep * acc_r);
            acc_g = fma(add, s.green, keep * acc_g);
            acc_b = fma(add, s.blue, keep * acc_b);
            acc_d = fma(add, s.depth, keep * acc_d);
            acc_a = fma(keep, acc_a, add);
            t = select(valid, t_j, t);
        }
    }
}
