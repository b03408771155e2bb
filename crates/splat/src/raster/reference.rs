//! A naive, independent renderer used as the test oracle: per pixel, every Gaussian in depth
//! order, `f64`, projection written with `nalgebra` matrices straight from the formulas (no
//! tiles, no bounding boxes, no vectorised kernels). Slow (O(pixels × Gaussians)); for tests
//! and small scenes only. Loops use the formulas' indices (clippy's `needless_range_loop` off).
#![allow(clippy::needless_range_loop)]

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Quaternion, UnitQuaternion, Vector3};

use super::inputs::{
    ALPHA_MAX, ALPHA_MIN, DILATION, FOV_CLAMP, GaussianRefs, RenderCamera, RenderSettings, T_MIN,
    sh_degree_of,
};
use crate::sh;

struct Projected {
    depth: f64,
    mean: [f64; 2],
    conic: Matrix2<f64>,
    opacity: f64,
    color: [f64; 3],
}

fn project(
    g: &GaussianRefs<'_, f64>,
    i: usize,
    cam: &RenderCamera,
    settings: &RenderSettings,
) -> Option<Projected> {
    let w = Matrix3::from_fn(|r, c| cam.rotation[r][c]);
    let t0 = Vector3::from(cam.translation);
    let p = Vector3::new(g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]);
    let t = w * p + t0;
    if t.z < settings.near_plane {
        return None;
    }
    let q = Quaternion::new(
        g.quats[4 * i],
        g.quats[4 * i + 1],
        g.quats[4 * i + 2],
        g.quats[4 * i + 3],
    );
    if q.norm() <= 1e-12 {
        return None;
    }
    let r = UnitQuaternion::from_quaternion(q)
        .to_rotation_matrix()
        .into_inner();
    let s = Matrix3::from_diagonal(&Vector3::new(
        g.log_scales[3 * i].exp(),
        g.log_scales[3 * i + 1].exp(),
        g.log_scales[3 * i + 2].exp(),
    ));
    let sigma = r * s * s.transpose() * r.transpose();
    let rx = (t.x / t.z).clamp(
        -FOV_CLAMP * cam.cx / cam.fx,
        FOV_CLAMP * (cam.width as f64 - cam.cx) / cam.fx,
    );
    let ry = (t.y / t.z).clamp(
        -FOV_CLAMP * cam.cy / cam.fy,
        FOV_CLAMP * (cam.height as f64 - cam.cy) / cam.fy,
    );
    let j = Matrix2x3::new(
        cam.fx / t.z,
        0.0,
        -cam.fx * rx / t.z,
        0.0,
        cam.fy / t.z,
        -cam.fy * ry / t.z,
    );
    let cov = j * w * sigma * w.transpose() * j.transpose() + Matrix2::identity() * DILATION;
    if cov.determinant() <= 0.0 {
        return None;
    }
    let conic = cov.try_inverse()?;
    let center = cam.center();
    let d = (p - Vector3::from(center)).normalize();
    let degree = settings.sh_degree.min(sh_degree_of(g.sh_coeffs));
    let mut y = [0.0; 16];
    sh::basis(degree, [d.x, d.y, d.z], &mut y, None);
    let mut color = [0.5; 3];
    for (k, yk) in y.iter().enumerate().take(sh::num_coeffs(degree)) {
        for (ch, c) in color.iter_mut().enumerate() {
            *c += yk * g.sh[(i * g.sh_coeffs + k) * 3 + ch];
        }
    }
    Some(Projected {
        depth: t.z,
        mean: [cam.fx * t.x / t.z + cam.cx, cam.fy * t.y / t.z + cam.cy],
        conic,
        opacity: 1.0 / (1.0 + (-g.opacity_logits[i]).exp()),
        color: color.map(|c| c.max(0.0)),
    })
}

/// Renders H×W×5 (R, G, B, depth, alpha), the same layout as the fast path.
pub fn render(
    g: &GaussianRefs<'_, f64>,
    cam: &RenderCamera,
    settings: &RenderSettings,
) -> Vec<f64> {
    let mut list: Vec<(usize, Projected)> = (0..g.len())
        .filter_map(|i| project(g, i, cam, settings).map(|p| (i, p)))
        .collect();
    list.sort_by(|a, b| {
        a.1.depth
            .partial_cmp(&b.1.depth)
            .unwrap()
            .then(a.0.cmp(&b.0))
    });
    let mut out = vec![0.0; cam.width * cam.height * 5];
    for y in 0..cam.height {
        for x in 0..cam.width {
            let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
            let mut t = 1.0;
            let mut c = [0.0; 3];
            let mut depth = 0.0;
            for (_, p) in &list {
                let d = nalgebra::Vector2::new(px - p.mean[0], py - p.mean[1]);
                let power = -0.5 * (d.transpose() * p.conic * d)[(0, 0)];
                if power > 0.0 {
                    continue;
                }
                let alpha = (p.opacity * power.exp()).min(ALPHA_MAX);
                if alpha < ALPHA_MIN {
                    continue;
                }
                let next = t * (1.0 - alpha);
                if next < T_MIN {
                    break;
                }
                for ch in 0..3 {
                    c[ch] += p.color[ch] * alpha * t;
                }
                depth += p.depth * alpha * t;
                t = next;
            }
            let o = (y * cam.width + x) * 5;
            for ch in 0..3 {
                out[o + ch] = c[ch] + t * settings.background[ch] as f64;
            }
            out[o + 3] = depth;
            out[o + 4] = 1.0 - t;
        }
    }
    out
}
