//! Rays and projections as differentiable functions of the camera poses: each camera's
//! world-to-camera pose is a row of `[V, 12]` (`r₀, r₁, r₂` rows of `R`, then `t`, from
//! [`crate::pose::d9_to_rows`]), so gradients of anything rendered reach the pose parameters.
//!
//! Pixel coordinates follow the crate convention (pixel `(i, j)` covers `[i, i+1) × [j, j+1)`).

use burn::tensor::{Int, Tensor, TensorData};
use fewview_scene::Intrinsics;

/// Per-ray selection of the pose rows: `[R, 12]`.
pub fn select_rows(rows: &Tensor<2>, views: &[usize]) -> Tensor<2> {
    let device = rows.device();
    let idx: Vec<i64> = views.iter().map(|v| *v as i64).collect();
    let n = idx.len();
    rows.clone().select(
        0,
        Tensor::<1, Int>::from_data(TensorData::new(idx, [n]), &device),
    )
}

fn col(t: &Tensor<2>, a: usize, b: usize) -> Tensor<2> {
    let [n, _] = t.dims();
    t.clone().slice([0..n, a..b])
}

/// Unit camera-frame directions of pixels, `K⁻¹ (u, v, 1)` normalised.
pub fn camera_dirs(intrinsics: &[Intrinsics], views: &[usize], uv: &[[f32; 2]]) -> Vec<[f32; 3]> {
    views
        .iter()
        .zip(uv)
        .map(|(&v, p)| {
            let k = &intrinsics[v];
            let d = [
                ((p[0] as f64 - k.cx) / k.fx) as f32,
                ((p[1] as f64 - k.cy) / k.fy) as f32,
                1.0f32,
            ];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            [d[0] / n, d[1] / n, d[2] / n]
        })
        .collect()
}

/// World-space origins and unit directions `[R, 3]` of rays with camera-frame directions
/// `dirs_cam` and selected pose rows `sel` (`[R, 12]`): `o = −Rᵀt`, `d = Rᵀ d_cam`.
pub fn world_rays(sel: &Tensor<2>, dirs_cam: &[[f32; 3]]) -> (Tensor<2>, Tensor<2>) {
    let device = sel.device();
    let n = dirs_cam.len();
    let dc = Tensor::<2>::from_data(TensorData::new(dirs_cam.concat(), [n, 3]), &device);
    let (r0, r1, r2) = (col(sel, 0, 3), col(sel, 3, 6), col(sel, 6, 9));
    let (tx, ty, tz) = (col(sel, 9, 10), col(sel, 10, 11), col(sel, 11, 12));
    let dirs =
        r0.clone() * col(&dc, 0, 1) + r1.clone() * col(&dc, 1, 2) + r2.clone() * col(&dc, 2, 3);
    let origins = (r0 * tx + r1 * ty + r2 * tz).neg();
    (origins, dirs)
}

/// Camera-frame coordinates `[R, 3]` of world points `x` (`[R, 3]`) under pose rows `sel`.
pub fn to_camera(sel: &Tensor<2>, x: &Tensor<2>) -> Tensor<2> {
    let dot = |r: Tensor<2>| (r * x.clone()).sum_dim(1);
    Tensor::cat(
        vec![
            dot(col(sel, 0, 3)) + col(sel, 9, 10),
            dot(col(sel, 3, 6)) + col(sel, 10, 11),
            dot(col(sel, 6, 9)) + col(sel, 11, 12),
        ],
        1,
    )
}

/// Intrinsics of each row as `[R, 4]` (`fx, fy, cx, cy`).
pub fn intrinsics_rows(
    intrinsics: &[Intrinsics],
    views: &[usize],
    device: &burn::tensor::Device,
) -> Tensor<2> {
    let data: Vec<f32> = views
        .iter()
        .flat_map(|&v| {
            let k = &intrinsics[v];
            [k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32]
        })
        .collect();
    Tensor::from_data(TensorData::new(data, [views.len(), 4]), device)
}

/// Pixel coordinates `[R, 2]` and depth `[R, 1]` of world points projected with pose rows
/// `sel` and intrinsics rows `k` (`[R, 4]`). Depths are clamped at 10⁻⁴ to keep the division
/// finite for points behind the camera (callers mask those out).
pub fn project(sel: &Tensor<2>, k: &Tensor<2>, x: &Tensor<2>) -> (Tensor<2>, Tensor<2>) {
    let c = to_camera(sel, x);
    let z = col(&c, 2, 3);
    let zc = z.clone().clamp_min(1e-4);
    let u = col(&c, 0, 1) / zc.clone() * col(k, 0, 1) + col(k, 2, 3);
    let v = col(&c, 1, 2) / zc * col(k, 1, 2) + col(k, 3, 4);
    (Tensor::cat(vec![u, v], 1), z)
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;
    use fewview_scene::{Camera, Se3};
    use nalgebra::Vector3;

    use super::*;
    use crate::pose::{d9_to_rows, pose_to_d9, se3_exp};

    #[test]
    fn rays_and_projection_agree_with_the_camera_model() {
        let k = Intrinsics {
            fx: 300.0,
            fy: 310.0,
            cx: 80.0,
            cy: 61.0,
            width: 160,
            height: 120,
        };
        let poses: Vec<Se3> = (0..3)
            .map(|i| {
                let c = Camera::look_at(
                    k,
                    Vector3::new(2.0 * (i as f64).cos(), 2.5, 1.0 + i as f64 * 0.3),
                    Vector3::zeros(),
                    Vector3::z(),
                );
                c.world_to_camera
                    .compose(&se3_exp(&[0.01, -0.02, 0.03, 0.0, 0.0, 0.0]))
            })
            .collect();
        let d9: Vec<f32> = poses
            .iter()
            .flat_map(|p| pose_to_d9(p).map(|v| v as f32))
            .collect();
        let device = Device::flex();
        let rows = d9_to_rows(Tensor::from_data(TensorData::new(d9, [3, 9]), &device));
        let views = vec![0usize, 2, 1, 2];
        let uv = vec![
            [10.5f32, 20.5],
            [80.0, 60.0],
            [150.25, 100.75],
            [3.0, 117.0],
        ];
        let ks = vec![k; 3];
        let sel = select_rows(&rows, &views);
        let (o, d) = world_rays(&sel, &camera_dirs(&ks, &views, &uv));
        let o = o.into_data().try_to_vec::<f32>().unwrap();
        let d = d.into_data().try_to_vec::<f32>().unwrap();
        for (r, &v) in views.iter().enumerate() {
            let cam = Camera::new(k, poses[v]);
            let (o_ref, d_ref) = cam.ray(uv[r][0] as f64, uv[r][1] as f64);
            for a in 0..3 {
                assert!((o[3 * r + a] as f64 - o_ref[a]).abs() < 1e-5);
                assert!((d[3 * r + a] as f64 - d_ref[a]).abs() < 1e-5);
            }
        }
        // Points 1.7 units along the rays project back onto the pixels, at the right depth.
        let x: Vec<f32> = (0..4)
            .flat_map(|r| (0..3).map(move |a| (r, a)))
            .map(|(r, a)| o[3 * r + a] + 1.7 * d[3 * r + a])
            .collect();
        let xt = Tensor::<2>::from_data(TensorData::new(x.clone(), [4, 3]), &device);
        let (p, z) = project(&sel, &intrinsics_rows(&ks, &views, &device), &xt);
        let p = p.into_data().try_to_vec::<f32>().unwrap();
        let z = z.into_data().try_to_vec::<f32>().unwrap();
        for (r, &v) in views.iter().enumerate() {
            assert!((p[2 * r] - uv[r][0]).abs() < 1e-3 && (p[2 * r + 1] - uv[r][1]).abs() < 1e-3);
            let cam = Camera::new(k, poses[v]);
            let xr = Vector3::new(x[3 * r] as f64, x[3 * r + 1] as f64, x[3 * r + 2] as f64);
            let (_, _, zr) = cam.project(&xr).unwrap();
            assert!((z[r] as f64 - zr).abs() < 1e-4);
        }
    }
}
