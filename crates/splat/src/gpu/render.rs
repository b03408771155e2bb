//! The device rasterizer's host side: the order of the kernel launches for one render and its
//! backward pass, and the buffers the backward pass keeps (the twin of
//! [`crate::raster::render`]). Nothing comes back to the host inside [`super::pairs::deferred`];
//! elsewhere one value does, the number of (tile, Gaussian) pairs, which sizes the pair buffers.

use burn::backend::TensorMetadata;
use burn::tensor::{DType, Shape};
use burn_cubecl::CubeDevice;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::tensor::CubeTensor;
use cubecl::features::Plane;
use cubecl::prelude::*;
use cubecl::server::Handle;

use super::blend::{TILE_UNITS, blend_backward, blend_forward};
use super::launch::{alloc, arg, cubes_for, read_u32_at, upload_f32};
use super::pairs::{self, Pending};
use super::profile::StageClock;
use super::project::{CameraBuffer, GRAD_FLOATS, SPLAT_FLOATS, project_backward, project_forward};
use super::scan::exclusive_scan;
use super::sort::{bits_for, indices, sort_counted_pairs, sort_pairs};
use super::tiles::{emit_pairs, gather_pair_grads, pair_total, tile_counts, tile_ranges};
use crate::op::RenderView;
use crate::raster::render::OUT_CHANNELS;
use crate::raster::{TILE, sh_degree_of};
use crate::sh;

/// Units per cube of the per-Gaussian and per-pair kernels.
const LINEAR_UNITS: usize = 256;

/// A float input as a contiguous device buffer.
struct Input {
    handle: Handle,
    shape: Shape,
}

fn input(tensor: CubeTensor, name: &str) -> Input {
    assert!(
        tensor.dtype == DType::F32,
        "the GPU rasterizer takes f32 tensors; {name} is {:?}",
        tensor.dtype
    );
    let shape = tensor.shape();
    let tensor = into_contiguous(tensor);
    Input {
        handle: tensor.handle,
        shape,
    }
}

/// Everything one render leaves for its backward pass.
pub struct GpuState {
    client: Client,
    device: CubeDevice,
    /// means, log_scales, quats, opacity_logits, sh, means2d
    inputs: [Input; 6],
    camera: Handle,
    background: Handle,
    n: usize,
    sh_coeffs: usize,
    k_used: usize,
    width: usize,
    height: usize,
    rects: Handle,
    splats: Handle,
    order: Handle,
    offsets: Handle,
    /// One `u32`: the number of pairs, which may exceed `capacity` (see [`super::pairs`]).
    total: Handle,
    /// Slots of the pair buffers.
    capacity: usize,
    sorted_slots: Handle,
    slot_gaussian: Handle,
    ranges: Handle,
    final_t: Handle,
    last: Handle,
}

impl GpuState {
    fn tiles(&self) -> (usize, usize) {
        (self.width.div_ceil(TILE), self.height.div_ceil(TILE))
    }

    fn tensor(&self, handle: Handle, shape: Shape) -> CubeTensor {
        CubeTensor::new_contiguous(
            self.client.clone(),
            self.device.clone(),
            shape,
            handle,
            DType::F32,
        )
    }
}

/// Renders on the device: `(image [H, W, 5], radii [N], state)`.
pub fn forward(tensors: [CubeTensor; 6], view: &RenderView) -> (CubeTensor, CubeTensor, GpuState) {
    let client = tensors[0].client.clone();
    let device = tensors[0].device.clone();
    let [means, log_scales, quats, opacity_logits, sh, means2d] = tensors;
    let inputs = [
        input(means, "means"),
        input(log_scales, "log_scales"),
        input(quats, "quats"),
        input(opacity_logits, "opacity_logits"),
        input(sh, "sh"),
        input(means2d, "means2d"),
    ];
    let n = inputs[3].shape.num_elements();
    let sh_coeffs = if n == 0 {
        1
    } else {
        inputs[4].shape.num_elements() / (n * 3)
    };
    let degree = view.settings.sh_degree.min(sh_degree_of(sh_coeffs));
    let cam = &view.camera;
    let mut state = GpuState {
        camera: upload_f32(
            &client,
            &CameraBuffer::values(cam, view.settings.near_plane),
        ),
        background: upload_f32(&client, &view.settings.background),
        client: client.clone(),
        device,
        inputs,
        n,
        sh_coeffs,
        k_used: sh::num_coeffs(degree),
        width: cam.width,
        height: cam.height,
        rects: alloc(&client, 4 * n),
        splats: alloc(&client, SPLAT_FLOATS * n),
        order: alloc(&client, n),
        offsets: alloc(&client, n + 1),
        total: alloc(&client, 1),
        capacity: 0,
        sorted_slots: alloc(&client, 1),
        slot_gaussian: alloc(&client, 1),
        ranges: alloc(&client, 1),
        final_t: alloc(&client, cam.num_pixels()),
        last: alloc(&client, cam.num_pixels()),
    };
    let radii = alloc(&client, n);
    let mut clock = StageClock::start(&client);
    project(&mut state, &radii, &mut clock);
    bin(&mut state, &mut clock);
    let image = alloc(&client, cam.num_pixels() * OUT_CHANNELS);
    blend(&state, &image);
    clock.stage("blend");
    let image = state.tensor(image, Shape::new([cam.height, cam.width, OUT_CHANNELS]));
    let radii = state.tensor(radii, Shape::new([n]));
    (image, radii, state)
}

/// Projection and the depth sort: fills `splats`, `rects`, `radii` and `order`.
fn project(s: &mut GpuState, radii: &Handle, clock: &mut StageClock) {
    let (client, n) = (&s.client, s.n);
    if n == 0 {
        return;
    }
    let depth_keys = alloc(client, n);
    let [means, scales, quats, opacity, sh, _] = &s.inputs;
    project_forward::launch(
        client,
        cubes_for(n, LINEAR_UNITS),
        CubeDim::new_1d(LINEAR_UNITS as u32),
        arg(&means.handle, 3 * n),
        arg(&scales.handle, 3 * n),
        arg(&quats.handle, 4 * n),
        arg(&opacity.handle, n),
        arg(&sh.handle, 3 * s.sh_coeffs * n),
        arg(&s.camera, CameraBuffer::LEN),
        arg(&s.splats, SPLAT_FLOATS * n),
        arg(&s.rects, 4 * n),
        arg(radii, n),
        arg(&depth_keys, n),
        n as u32,
        s.sh_coeffs as u32,
        s.k_used as u32,
        s.width as u32,
        s.height as u32,
    );
    clock.stage("project");
    let (_, order) = sort_pairs(client, &depth_keys, &indices(client, n), n, 32);
    s.order = order;
    clock.stage("depth sort");
}

/// Tile binning: pair offsets per depth rank, the pairs sorted by tile, and each tile's range,
/// in as many pair slots as [`pairs::capacity`] gives (or, read now, as there are pairs).
fn bin(s: &mut GpuState, clock: &mut StageClock) {
    let (client, n) = (s.client.clone(), s.n);
    let (tiles_x, tiles_y) = s.tiles();
    let num_tiles = tiles_x * tiles_y;
    let counts = alloc(&client, n + 1);
    tile_counts::launch(
        &client,
        cubes_for(n + 1, LINEAR_UNITS),
        CubeDim::new_1d(LINEAR_UNITS as u32),
        arg(&s.order, n),
        arg(&s.rects, 4 * n),
        arg(&counts, n + 1),
        n as u32,
    );
    s.offsets = exclusive_scan(&client, &counts, n + 1);
    pair_total::launch(
        &client,
        CubeCount::Static(1, 1, 1),
        CubeDim::new_1d(1),
        arg(&s.offsets, n + 1),
        arg(&s.total, 1),
        n as u32,
    );
    s.capacity = pair_capacity(s);
    clock.stage("tile counts");
    let capacity = s.capacity;
    let (keys, slots) = (alloc(&client, capacity), alloc(&client, capacity));
    s.slot_gaussian = alloc(&client, capacity);
    if n > 0 && capacity > 0 {
        emit_pairs::launch(
            &client,
            cubes_for(n, LINEAR_UNITS),
            CubeDim::new_1d(LINEAR_UNITS as u32),
            arg(&s.order, n),
            arg(&s.rects, 4 * n),
            arg(&s.offsets, n + 1),
            arg(&keys, capacity),
            arg(&slots, capacity),
            arg(&s.slot_gaussian, capacity),
            n as u32,
            tiles_x as u32,
            capacity as u32,
        );
    }
    clock.stage("pair emission");
    let (sorted_keys, sorted_slots) = sort_counted_pairs(
        &client,
        &keys,
        &slots,
        capacity,
        Some(&s.total),
        bits_for(num_tiles),
    );
    s.sorted_slots = sorted_slots;
    clock.stage("tile sort");
    s.ranges = alloc(&client, 2 * num_tiles);
    tile_ranges::launch(
        &client,
        cubes_for(num_tiles, LINEAR_UNITS),
        CubeDim::new_1d(LINEAR_UNITS as u32),
        arg(&sorted_keys, capacity),
        arg(&s.total, 1),
        arg(&s.ranges, 2 * num_tiles),
        capacity as u32,
        num_tiles as u32,
    );
    clock.stage("tile ranges");
}

/// The render's pair slots: a deferred render's capacity (its count left on the device for the
/// check), or the count of pairs, read now.
fn pair_capacity(s: &GpuState) -> usize {
    match pairs::capacity() {
        Some(capacity) => {
            pairs::leave(Pending {
                client: s.client.clone(),
                total: s.total.clone(),
                capacity,
            });
            capacity
        }
        None => {
            let count = read_u32_at(&s.client, &s.total, 0) as usize;
            pairs::needed(count);
            count
        }
    }
}

fn tile_cubes(s: &GpuState) -> (CubeCount, CubeDim) {
    let (tiles_x, tiles_y) = s.tiles();
    (
        CubeCount::Static(tiles_x as u32, tiles_y as u32, 1),
        CubeDim::new_1d(TILE_UNITS as u32),
    )
}

fn blend(s: &GpuState, image: &Handle) {
    let (count, dim) = tile_cubes(s);
    let (n, pairs, pixels) = (s.n, s.capacity, s.width * s.height);
    let (tiles_x, tiles_y) = s.tiles();
    blend_forward::launch(
        &s.client,
        count,
        dim,
        arg(&s.splats, SPLAT_FLOATS * n),
        arg(&s.ranges, 2 * tiles_x * tiles_y),
        arg(&s.sorted_slots, pairs),
        arg(&s.slot_gaussian, pairs),
        arg(&s.background, 3),
        arg(&s.total, 1),
        arg(image, pixels * OUT_CHANNELS),
        arg(&s.final_t, pixels),
        arg(&s.last, pixels),
        s.width as u32,
        s.height as u32,
        tiles_x as u32,
        pairs as u32,
        f32::NAN,
    );
}

/// How the blend backward reduces each splat's per-pixel gradients across a tile, as
/// `(plane, grouped)` for [`blend_backward`]: plane (subgroup) sums where the device has them
/// with one fixed plane size, one splat at a time, else the shared-memory tree.
/// `FEWVIEW_GPU_REDUCTION` overrides it: `tree`, or `grouped` (plane sums a group of splats per
/// cross-plane pass, where plane sums exist). All give the same sums up to rounding; the switch
/// is for comparing them.
fn reduction(client: &Client) -> (bool, bool) {
    let asked = std::env::var("FEWVIEW_GPU_REDUCTION").unwrap_or_default();
    if asked == "tree" {
        return (false, false);
    }
    let props = client.properties();
    let sizes = props.hardware.plane_size_min..=props.hardware.plane_size_max;
    let plane = client.features().plane.contains(Plane::Ops)
        && !sizes.is_empty()
        && (TILE_UNITS as u32).is_multiple_of(props.hardware.plane_size_max)
        && props.hardware.plane_size_min == props.hardware.plane_size_max;
    (plane, plane && asked == "grouped")
}

/// Gradients of `means, log_scales, quats, opacity_logits, sh, means2d` from the image gradient.
pub fn backward(s: &GpuState, grad_image: CubeTensor) -> [CubeTensor; 6] {
    let client = &s.client;
    let grad_image = input(grad_image, "the image gradient");
    let (n, pairs, pixels) = (s.n, s.capacity, s.width * s.height);
    let (tiles_x, tiles_y) = s.tiles();
    let pair_grads = alloc(client, GRAD_FLOATS * pairs);
    let (plane, grouped) = reduction(client);
    let mut clock = StageClock::start(client);
    let (count, dim) = tile_cubes(s);
    blend_backward::launch(
        client,
        count,
        dim,
        arg(&s.splats, SPLAT_FLOATS * n),
        arg(&s.ranges, 2 * tiles_x * tiles_y),
        arg(&s.sorted_slots, pairs),
        arg(&s.slot_gaussian, pairs),
        arg(&s.background, 3),
        arg(&s.final_t, pixels),
        arg(&s.last, pixels),
        arg(&grad_image.handle, pixels * OUT_CHANNELS),
        arg(&pair_grads, GRAD_FLOATS * pairs),
        s.width as u32,
        s.height as u32,
        tiles_x as u32,
        plane,
        grouped,
    );
    clock.stage("blend backward");
    let splat_grads = alloc(client, GRAD_FLOATS * n);
    let k3 = 3 * s.sh_coeffs;
    let outs = [3 * n, 3 * n, 4 * n, n, k3 * n, 2 * n].map(|len| alloc(client, len));
    if n > 0 {
        gather_pair_grads::launch(
            client,
            cubes_for(n, LINEAR_UNITS),
            CubeDim::new_1d(LINEAR_UNITS as u32),
            arg(&s.order, n),
            arg(&s.offsets, n + 1),
            arg(&pair_grads, GRAD_FLOATS * pairs),
            arg(&splat_grads, GRAD_FLOATS * n),
            n as u32,
            pairs as u32,
            GRAD_FLOATS,
        );
        clock.stage("gradient gather");
        let [means, scales, quats, opacity, sh, _] = &s.inputs;
        project_backward::launch(
            client,
            cubes_for(n, LINEAR_UNITS),
            CubeDim::new_1d(LINEAR_UNITS as u32),
            arg(&means.handle, 3 * n),
            arg(&scales.handle, 3 * n),
            arg(&quats.handle, 4 * n),
            arg(&opacity.handle, n),
            arg(&sh.handle, k3 * n),
            arg(&s.camera, CameraBuffer::LEN),
            arg(&s.rects, 4 * n),
            arg(&splat_grads, GRAD_FLOATS * n),
            arg(&outs[0], 3 * n),
            arg(&outs[1], 3 * n),
            arg(&outs[2], 4 * n),
            arg(&outs[3], n),
            arg(&outs[4], k3 * n),
            arg(&outs[5], 2 * n),
            n as u32,
            s.sh_coeffs as u32,
            s.k_used as u32,
            s.width as u32,
            s.height as u32,
        );
        clock.stage("project backward");
    }
    std::array::from_fn(|k| s.tensor(outs[k].clone(), s.inputs[k].shape.clone()))
}
