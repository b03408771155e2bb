//! Exact Euclidean distance transforms of masks (Felzenszwalb & Huttenlocher, "Distance
//! Transforms of Sampled Functions", 2012): the lower envelope of parabolas, one pass per axis,
//! linear in the number of pixels. The visual hull turns each mask into a signed distance to its
//! silhouette, so that its field can be interpolated and its surface extracted below a voxel.

use crate::maps::Mask;

/// Squared distance standing in for "no such pixel": far beyond any image, still finite.
const FAR2: f64 = 1e20;

/// The 1D squared distance transform of `f` into `d`: `d[q] = min_p (q − p)² + f[p]`.
fn transform_1d(f: &[f64], d: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut v = vec![0usize; n];
    let mut z = vec![0f64; n + 1];
    let mut k = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    let intersect = |q: usize, p: usize| {
        let (qf, pf) = (q as f64, p as f64);
        ((f[q] + qf * qf) - (f[p] + pf * pf)) / (2.0 * (qf - pf))
    };
    for q in 1..n {
        let mut s = intersect(q, v[k]);
        while s <= z[k] {
            k -= 1;
            s = intersect(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, dq) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let dx = q as f64 - v[k] as f64;
        *dq = dx * dx + f[v[k]];
    }
}

/// For every pixel, the squared distance in pixels to the nearest pixel where `target` holds
/// (`FAR2`-sized where none does).
pub fn squared_distance(target: &[bool], width: usize, height: usize) -> Vec<f64> {
    let mut grid: Vec<f64> = target.iter().map(|&t| if t { 0.0 } else { FAR2 }).collect();
    let mut col = vec![0.0; height];
    let mut out = vec![0.0; height.max(width)];
    for x in 0..width {
        for y in 0..height {
            col[y] = grid[y * width + x];
        }
        transform_1d(&col, &mut out[..height]);
        for y in 0..height {
            grid[y * width + x] = out[y];
        }
    }
    for row in grid.chunks_exact_mut(width.max(1)) {
        transform_1d(row, &mut out[..width]);
        row.copy_from_slice(&out[..width]);
    }
    grid
}

/// Signed distance in pixels from each pixel centre to the mask's silhouette: negative inside,
/// positive outside, ±0.5 on the pixels along the boundary (the boundary lies half-way between
/// an inside and an outside pixel centre).
pub fn signed_distance(mask: &Mask) -> Vec<f32> {
    let (w, h) = (mask.width, mask.height);
    let outside: Vec<bool> = mask.data.iter().map(|&m| !m).collect();
    let to_inside = squared_distance(&mask.data, w, h);
    let to_outside = squared_distance(&outside, w, h);
    mask.data
        .iter()
        .zip(to_inside.iter().zip(&to_outside))
        .map(|(&m, (&di, &dout))| {
            if m {
                -(dout.sqrt() - 0.5) as f32
            } else {
                (di.sqrt() - 0.5) as f32
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: the squared distance to the nearest target pixel.
    fn naive(target: &[bool], w: usize, h: usize) -> Vec<f64> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                (0..w * h)
                    .filter(|&j| target[j])
                    .map(|j| ((j % w) as f64 - x).powi(2) + ((j / w) as f64 - y).powi(2))
                    .fold(FAR2, f64::min)
            })
            .collect()
    }

    #[test]
    fn matches_brute_force_on_a_scattered_mask() {
        let (w, h) = (23, 17);
        let target: Vec<bool> = (0..w * h)
            .map(|i| (i * 7919) % 31 == 0 || i == 200)
            .collect();
        let fast = squared_distance(&target, w, h);
        let slow = naive(&target, w, h);
        for (a, b) in fast.iter().zip(&slow) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
    }

    #[test]
    fn signed_distance_of_a_disc_is_its_radius_minus_the_distance() {
        let (w, h, r) = (41usize, 41usize, 12.0f64);
        let c = 20.0;
        let inside = |i: usize| ((i % w) as f64 - c).hypot((i / w) as f64 - c) <= r;
        let mask = Mask::new(w, h, (0..w * h).map(inside).collect());
        let sd = signed_distance(&mask);
        for i in 0..w * h {
            let d = ((i % w) as f64 - c).hypot((i / w) as f64 - c) - r;
            // Pixel sampling puts the silhouette within a pixel of the true circle.
            assert!(
                (sd[i] as f64 - d).abs() <= 1.0,
                "pixel {i}: {} vs {d}",
                sd[i]
            );
            assert_eq!(sd[i] < 0.0, mask.data[i]);
        }
    }
}
