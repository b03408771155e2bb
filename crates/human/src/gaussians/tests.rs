//! Per-pixel Gaussians against independent references: fewview-scene's own back-projection,
//! nalgebra's rotations, the source image itself (a plane rendered back into its camera), finite
//! differences of the render, and the seq_a rig's geometry from the capture's README.

use burn::tensor::{Device, Tensor, TensorData};
use fewview_scene::{Camera, Image, Intrinsics};
use nalgebra::{UnitQuaternion, Vector3};

use super::*;
use crate::maps::Mask;
use crate::net::HeadOutputs;

fn host<const D: usize>(t: &Tensor<D>) -> Vec<f32> {
    t.to_data().try_to_vec::<f32>().unwrap()
}

fn tensor3(v: Vec<f32>, shape: [usize; 3], device: &Device) -> Tensor<3> {
    Tensor::from_data(TensorData::new(v, shape), device)
}

/// A camera at `eye` looking at the origin, `size`² pixels, focal length `f`.
fn camera(eye: [f64; 3], size: u32, f: f64) -> Camera {
    let k = Intrinsics::centered(f, size, size);
    Camera::look_at(k, Vector3::from(eye), Vector3::zeros(), Vector3::z())
}

/// A smooth colour pattern: per channel a product of sines with periods of `period` pixels.
fn pattern(size: usize, period: f64) -> Image {
    let mut data = Vec::with_capacity(size * size * 3);
    for y in 0..size {
        for x in 0..size {
            for c in 0..3 {
                let (u, v) = (x as f64 / period, y as f64 / period);
                let a = std::f64::consts::TAU * (u + 0.3 * c as f64);
                let b = std::f64::consts::TAU * (v * 0.8 + 0.2 * c as f64);
                data.push((0.5 + 0.35 * a.sin() * b.cos()) as f32);
            }
        }
    }
    Image::from_vec(size, size, 3, data)
}

/// Pixels inside the disk of radius `r` about the image centre.
fn disk(size: usize, r: f64) -> Mask {
    let c = size as f64 / 2.0;
    let data = (0..size * size)
        .map(|p| {
            let (x, y) = ((p % size) as f64 + 0.5 - c, (p / size) as f64 + 0.5 - c);
            x * x + y * y <= r * r
        })
        .collect();
    Mask::new(size, size, data)
}

/// Maps of constant isotropic `scale`, identity rotation and `opacity`, with `depth`.
fn constant_maps(
    depth: Vec<f32>,
    size: usize,
    scale: f32,
    opacity: f32,
    dev: &Device,
) -> PixelMaps {
    let px = size * size;
    let rotation = (0..4 * px)
        .map(|i| if i < px { 1.0 } else { 0.0 })
        .collect();
    PixelMaps {
        depth: tensor3(depth, [1, size, size], dev),
        scale: tensor3(vec![scale; 3 * px], [3, size, size], dev),
        rotation: tensor3(rotation, [4, size, size], dev),
        opacity: tensor3(vec![opacity; px], [1, size, size], dev),
    }
}

/// Masked PSNR of the render against the source image.
fn masked_psnr(rendered: &Rendered, image: &Image, mask: &Mask) -> f64 {
    let [h, w, _] = rendered.rgb.dims();
    let got = Image::from_vec(w, h, 3, host(&rendered.rgb));
    let m = mask.data.iter().map(|&b| b as u8 as f32).collect();
    fewview_metrics::psnr_masked(&got, image, &Image::from_vec(w, h, 1, m)).unwrap()
}

/// Renders a fronto-parallel plane at depth `z` whose Gaussians have `k` pixel footprints
/// (σ = k z / f), opacity 1 and the colours of a `period`-pixel pattern, back into its own
/// camera, whose principal point is first moved by `shift` pixels.
fn plane_psnr(k: f32, period: f64, shift: f64) -> f64 {
    let (size, f, z) = (96usize, 120.0, 2.5f32);
    let dev = Device::flex();
    let target = camera([0.4, -2.0, 0.7], size as u32, f);
    let mut source = target.clone();
    source.intrinsics.cx += shift;
    let (image, mask) = (pattern(size, period), disk(size, 40.0));
    let maps = constant_maps(vec![z; size * size], size, k * z / f as f32, 1.0, &dev);
    let view = SourceView {
        image: &image,
        mask: &mask,
        camera: &source,
    };
    let options = GaussianOptions {
        max_scale: None,
        ..GaussianOptions::default()
    };
    let g = pixel_gaussians(&view, &maps, &options).unwrap();
    masked_psnr(&render_gaussians(&g, &target), &image, &mask)
}

/// Acceptance: a plane at its true depth rendered into its own camera gives back the source
/// image inside the mask (measured 43.0 dB).
///
/// All Gaussians lie at one depth, so the blending order among neighbours is arbitrary
/// (rounding decides it) and every pixel mixes in some of its neighbours' colours, the more the
/// wider the Gaussians: with σ = k z / f and this 48-pixel pattern, k = 0.1, 0.25, 0.5, 1 gave
/// 44.9, 43.0, 38.3 and 31.0 dB (on a 24-pixel pattern 6 dB less each). So σ is a quarter of
/// the pixel footprint; the rasterizer's 0.3 px² screen dilation still covers every pixel
/// centre. The control shows the test sees half a pixel: the same render from a source
/// camera whose pixel centres are off by ½ (the integer-centre convention) gives 32.4 dB.
#[test]
fn plane_at_true_depth_reproduces_the_source_image() {
    let psnr = plane_psnr(0.25, 48.0, 0.0);
    assert!(psnr >= 40.0, "masked PSNR {psnr:.2} dB");
    let shifted = plane_psnr(0.25, 48.0, 0.5);
    assert!(
        shifted < psnr - 6.0,
        "half-pixel shift: {shifted:.2} dB vs {psnr:.2} dB"
    );
}

/// A tilted depth map with some pixels masked out, seen by a camera off every axis.
fn depth_scene(size: usize) -> (Camera, Vec<f32>, Mask) {
    let cam = camera([1.3, -2.2, 0.9], size as u32, 37.0);
    let depth = (0..size * size)
        .map(|p| 2.0 + 0.02 * (p % size) as f32 - 0.015 * (p / size) as f32)
        .collect();
    let mask = Mask::new(size, size, (0..size * size).map(|p| p % 5 != 2).collect());
    (cam, depth, mask)
}

/// The means are the depth map's points by fewview-scene's own back-projection,
/// `Camera::unproject` at the pixel centres `(x + ½, y + ½)`, in row-major order of the mask.
#[test]
fn means_back_project_to_the_analytic_points() {
    let size = 12;
    let dev = Device::flex();
    let (cam, depth, mask) = depth_scene(size);
    let image = pattern(size, 5.0);
    let maps = constant_maps(depth.clone(), size, 0.01, 0.5, &dev);
    let view = SourceView {
        image: &image,
        mask: &mask,
        camera: &cam,
    };
    let g = pixel_gaussians(&view, &maps, &GaussianOptions::default()).unwrap();
    let means = host(&g.means);
    let pixels: Vec<usize> = (0..size * size).filter(|&p| mask.data[p]).collect();
    assert_eq!(means.len(), 3 * pixels.len());
    for (i, &p) in pixels.iter().enumerate() {
        let (u, v) = ((p % size) as f64 + 0.5, (p / size) as f64 + 0.5);
        let want = cam.unproject(u, v, depth[p] as f64);
        for a in 0..3 {
            let got = means[3 * i + a] as f64;
            assert!(
                (got - want[a]).abs() < 1e-5,
                "pixel {p}: {got} vs {}",
                want[a]
            );
        }
    }
}

/// Random unit quaternions in the camera frame become `R_c2w · R(q)` in the world (nalgebra's
/// matrices), colours come back through SH C0, and scales and opacity through their
/// activations (log and logit), the scale capped at `max_scale`.
#[test]
fn parameters_follow_the_maps() {
    let size = 4;
    let px = size * size;
    let dev = Device::flex();
    let (cam, depth, _) = depth_scene(size);
    let mask = Mask::new(size, size, vec![true; px]);
    let image = pattern(size, 3.0);
    let q: Vec<UnitQuaternion<f64>> = (0..px)
        .map(|p| UnitQuaternion::from_scaled_axis(Vector3::new(0.3, -1.1, 0.7) * (p as f64 * 0.21)))
        .collect();
    let mut rot = vec![0.0f32; 4 * px];
    for (p, qp) in q.iter().enumerate() {
        for (c, v) in [qp.w, qp.i, qp.j, qp.k].into_iter().enumerate() {
            rot[c * px + p] = v as f32;
        }
    }
    let scales: Vec<f32> = (0..3 * px)
        .map(|i| 0.001 * (i % 17) as f32 + 0.0005)
        .collect();
    let opacity: Vec<f32> = (0..px).map(|p| 0.05 + 0.9 * p as f32 / px as f32).collect();
    let maps = PixelMaps {
        depth: tensor3(depth, [1, size, size], &dev),
        scale: tensor3(scales.clone(), [3, size, size], &dev),
        rotation: tensor3(rot, [4, size, size], &dev),
        opacity: tensor3(opacity.clone(), [1, size, size], &dev),
    };
    let view = SourceView {
        image: &image,
        mask: &mask,
        camera: &cam,
    };
    let options = GaussianOptions {
        max_scale: Some(0.01),
        ..GaussianOptions::default()
    };
    let g = pixel_gaussians(&view, &maps, &options).unwrap();
    let (quats, logs, logits, sh) = (
        host(&g.quats),
        host(&g.log_scales),
        host(&g.opacity_logits),
        host(&g.sh),
    );
    let c2w = cam.camera_to_world().rotation;
    for p in 0..px {
        let got = &quats[4 * p..4 * p + 4];
        let got = nalgebra::Quaternion::new(got[0], got[1], got[2], got[3]).cast::<f64>();
        let got = UnitQuaternion::new_unchecked(got).to_rotation_matrix();
        let want = c2w * q[p].to_rotation_matrix().matrix();
        assert!((got.matrix() - want).abs().max() < 1e-5, "pixel {p}");
        for c in 0..3 {
            let s = logs[3 * p + c].exp();
            assert!(
                (s - scales[c * px + p].min(0.01)).abs() < 1e-6,
                "scale {p} {c}"
            );
            let colour = sh[3 * p + c] as f64 * fewview_splat::sh::SH_C0 + 0.5;
            assert!(
                (colour - image.data[3 * p + c] as f64).abs() < 1e-6,
                "colour {p}"
            );
        }
        let o = 1.0 / (1.0 + (-logits[p]).exp());
        assert!((o - opacity[p]).abs() < 1e-6, "opacity {p}: {o}");
    }
}

/// Heads of one 16×16 source view: the given normalised depth, scales of 1.5 pixel footprints,
/// identity rotation, α 0.8 and person probability 0.9.
fn heads(depth: Tensor<4>, near: f32, far: f32, f: f32) -> HeadOutputs {
    let [_, _, h, w] = depth.dims();
    let dev = depth.device();
    let rotation: Vec<f32> = (0..4 * h * w).map(|i| (i < h * w) as u8 as f32).collect();
    let opacity: Vec<f32> = (0..2 * h * w)
        .map(|i| if i < h * w { 0.8 } else { 0.9 })
        .collect();
    HeadOutputs {
        scale: Tensor::full([1, 3, h, w], 1.5 * 0.5 * (near + far) / f, &dev),
        rotation: Tensor::from_data(TensorData::new(rotation, [1, 4, h, w]), &dev),
        opacity: Tensor::from_data(TensorData::new(opacity, [1, 2, h, w]), &dev),
        depth,
        uncertainty: Tensor::zeros([1, 2, h, w], &dev),
    }
}

/// `Σ weight · rgb` of the render of a tilted surface, seen by a camera beside the source, on
/// `device`; with the autodiff gradient w.r.t. the normalised depth when `device` tracks it.
fn weighted_render(depth: &[f32], device: &Device) -> (f64, Option<Vec<f32>>) {
    let (size, f, near, far) = (16usize, 20.0f32, 1.0, 4.0);
    let source = camera([0.4, -2.0, 0.7], size as u32, f as f64);
    let target = camera([0.9, -1.9, 0.8], size as u32, f as f64);
    let (image, mask) = (pattern(size, 6.0), disk(size, 7.0));
    let d = Tensor::<4>::from_data(TensorData::new(depth.to_vec(), [1, 1, size, size]), device);
    let d = if device.is_autodiff() {
        d.require_grad()
    } else {
        d
    };
    let maps = PixelMaps::from_heads(&heads(d.clone(), near, far, f), 0, near, far).unwrap();
    let view = SourceView {
        image: &image,
        mask: &mask,
        camera: &source,
    };
    let options = GaussianOptions {
        max_scale: None,
        ..GaussianOptions::default()
    };
    let g = pixel_gaussians(&view, &maps, &options).unwrap();
    let rgb = render_gaussians(&g, &target).rgb;
    let weights: Vec<f32> = (0..size * size * 3)
        .map(|i| ((i * 7) % 11) as f32 / 11.0)
        .collect();
    let sum: f64 = host(&rgb)
        .iter()
        .zip(&weights)
        .map(|(&a, &b)| a as f64 * b as f64)
        .sum();
    if !device.is_autodiff() {
        return (sum, None);
    }
    let w = Tensor::<3>::from_data(TensorData::new(weights, [size, size, 3]), device);
    let grads = (rgb * w).sum().backward();
    (sum, Some(host(&d.grad(&grads).unwrap())))
}

/// The render is differentiable end to end: the autodiff gradient of a weighted sum of the
/// rendered image w.r.t. the depth head's (normalised) output matches a central difference at
/// the pixel of largest gradient (measured: 1.97690 vs 1.97696). The surface is generic (no
/// two Gaussians at one depth in the target) and the step small (1e-3, 1.5 mm), because a step
/// that reorders the blending is a true discontinuity of the rasterizer (1e-2 does).
#[test]
fn render_gradient_reaches_the_depth_head() {
    let size = 16;
    let depth: Vec<f32> = (0..size * size)
        .map(|p| {
            let (x, y) = ((p % size) as f32, (p / size) as f32);
            -0.2 + 0.0123 * x - 0.0071 * y + 0.03 * (0.7 * x + 0.3 * y).sin()
        })
        .collect();
    let (_, grad) = weighted_render(&depth, &Device::flex().autodiff());
    let grad = grad.unwrap();
    let (p, &g) = grad
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .unwrap();
    let eps = 1e-3;
    let at = |e: f32| {
        let mut d = depth.clone();
        d[p] += e;
        weighted_render(&d, &Device::flex()).0
    };
    let numeric = (at(eps) - at(-eps)) / (2.0 * eps as f64);
    let rel = (g as f64 - numeric).abs() / numeric.abs();
    assert!(
        numeric.abs() > 1e-2,
        "gradient too small to test: {numeric}"
    );
    assert!(
        rel < 1e-2,
        "pixel {p}: autodiff {g} vs finite difference {numeric} ({rel:.2e})"
    );
}

/// The seq_a rig from the capture's README: 12 cameras 30° apart on a circle of radius 3 m,
/// 1.35 m high, looking at (0, 0, 0.85); `cam_00` at (0, −3), counter-clockwise from above.
fn seq_a_rig() -> Vec<Camera> {
    (0..12)
        .map(|i| {
            let a = (i as f64 * 30.0).to_radians();
            let eye = Vector3::new(3.0 * a.sin(), -3.0 * a.cos(), 1.35);
            let k = Intrinsics::centered(640.0, 512, 512);
            Camera::look_at(k, eye, Vector3::new(0.0, 0.0, 0.85), Vector3::z())
        })
        .collect()
}

/// Every held-out camera of the protocol's split is rendered from its two ring neighbours, by
/// either measure of nearness; impossible requests are errors.
#[test]
fn nearest_sources_are_the_ring_neighbours() {
    let rig = seq_a_rig();
    let split = crate::Split::seq_a();
    for nearness in [Nearness::ViewDirection, Nearness::CentreDistance] {
        for &c in &split.held_out_cameras {
            let mut got =
                nearest_sources(&rig[c], &rig, &split.input_cameras, 2, nearness).unwrap();
            got.sort();
            let mut want = vec![(c + 11) % 12, (c + 1) % 12];
            want.sort();
            assert_eq!(got, want, "camera {c}, {nearness:?}");
        }
        let three = nearest_sources(&rig[2], &rig, &split.input_cameras, 3, nearness).unwrap();
        // Nearest first: the two neighbours at 30°, then one of the two cameras at 60°.
        let mut first = three[..2].to_vec();
        first.sort();
        assert_eq!(first, [1, 3], "{three:?}");
        assert!([0, 4].contains(&three[2]), "{three:?}");
    }
    assert!(nearest_sources(&rig[2], &rig, &[1, 3], 3, Nearness::ViewDirection).is_err());
    assert!(nearest_sources(&rig[2], &rig, &[1, 12], 1, Nearness::ViewDirection).is_err());
}

/// An empty mask, a raster of another size, a batch index past the end and mismatched source
/// lists are errors that say what is wrong.
#[test]
fn bad_inputs_are_errors() {
    let (size, dev) = (4, Device::flex());
    let (cam, depth, _) = depth_scene(size);
    let maps = constant_maps(depth, size, 0.01, 0.5, &dev);
    let image = pattern(size, 3.0);
    let options = GaussianOptions::default();
    let error = |mask: &Mask| {
        let view = SourceView {
            image: &image,
            mask,
            camera: &cam,
        };
        pixel_gaussians(&view, &maps, &options)
            .unwrap_err()
            .to_string()
    };
    let e = error(&Mask::new(size, size, vec![false; size * size]));
    assert!(e.contains("selects no pixel"), "{e}");
    let e = error(&Mask::new(3, 3, vec![true; 9]));
    assert!(e.contains("mask is 3×3, the maps 4×4"), "{e}");
    let depth = Tensor::<4>::zeros([1, 1, size, size], &dev);
    let heads = HeadOutputs {
        scale: Tensor::zeros([1, 3, size, size], &dev),
        rotation: Tensor::zeros([1, 4, size, size], &dev),
        opacity: Tensor::zeros([1, 2, size, size], &dev),
        depth,
        uncertainty: Tensor::zeros([1, 2, size, size], &dev),
    };
    let e = PixelMaps::from_heads(&heads, 1, 1.0, 4.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("batch item 1 of a batch of 1"), "{e}");
    let e = novel_view(&[], &[maps], &cam, &options)
        .unwrap_err()
        .to_string();
    assert!(e.contains("0 source views with 1 sets of maps"), "{e}");
}
