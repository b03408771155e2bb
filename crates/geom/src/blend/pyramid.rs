//! Laplacian-pyramid blending (Burt & Adelson 1983): blend each band of the two images'
//! Laplacian pyramids with the Gaussian pyramid of the weight mask, then collapse.
//!
//! The weight mask is 1 where only `f` is valid, 0 where only `g` is, `w_f` in the overlap.
//! Before building the pyramids each image is completed with the other where it is invalid, so
//! no black leaks in across a mask border. REDUCE/EXPAND use the 5-tap kernel
//! `[1, 4, 6, 4, 1]/16` (Burt & Adelson's a = 0.375) with mirrored borders; odd sizes are
//! handled by rounding up.

use fewview_scene::Image;

use super::inputs::{Weights, check_images, check_mask};
use crate::error::{GeomError, Result};

const KERNEL: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

#[derive(Clone)]
struct Plane {
    w: usize,
    h: usize,
    v: Vec<f32>,
}

fn mirror(x: isize, n: usize) -> usize {
    let n = n as isize;
    let mut x = x;
    loop {
        if x < 0 {
            x = -x;
        } else if x >= n {
            x = 2 * (n - 1) - x;
        } else {
            return x as usize;
        }
        if n == 1 {
            return 0;
        }
    }
}

/// Blur with the 5-tap kernel and keep every second sample.
fn reduce(p: &Plane) -> Plane {
    let (w2, h2) = (p.w.div_ceil(2), p.h.div_ceil(2));
    let mut tmp = vec![0.0; w2 * p.h];
    for j in 0..p.h {
        for i in 0..w2 {
            tmp[j * w2 + i] = (0..5)
                .map(|k| KERNEL[k] * p.v[j * p.w + mirror(2 * i as isize + k as isize - 2, p.w)])
                .sum();
        }
    }
    let mut v = vec![0.0; w2 * h2];
    for j in 0..h2 {
        for i in 0..w2 {
            v[j * w2 + i] = (0..5)
                .map(|k| KERNEL[k] * tmp[mirror(2 * j as isize + k as isize - 2, p.h) * w2 + i])
                .sum();
        }
    }
    Plane { w: w2, h: h2, v }
}

/// Upsample to `w × h`: zero-insertion followed by the kernel ×2 per axis.
fn expand(p: &Plane, w: usize, h: usize) -> Plane {
    // Along x: out(i) = 2 Σ_k K[k] · in((i + k − 2)/2) over the k with i + k − 2 even.
    let sample = |n_in: usize, i: usize, get: &dyn Fn(usize) -> f32| -> f32 {
        let mut s = 0.0;
        for k in 0..5 {
            let t = i as isize + k as isize - 2;
            if t.rem_euclid(2) == 0 {
                s += 2.0 * KERNEL[k] * get(mirror(t / 2, n_in).min(n_in - 1));
            }
        }
        s
    };
    let mut tmp = vec![0.0; w * p.h];
    for j in 0..p.h {
        for i in 0..w {
            tmp[j * w + i] = sample(p.w, i, &|x| p.v[j * p.w + x]);
        }
    }
    let mut v = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            v[j * w + i] = sample(p.h, j, &|y| tmp[y * w + i]);
        }
    }
    Plane { w, h, v }
}

/// Laplacian-pyramid blending with `levels` pyramid levels (1 = plain weighted average).
pub fn laplacian_pyramid_blend(
    f: &Image,
    g: &Image,
    mask_f: &[bool],
    mask_g: &[bool],
    levels: usize,
    weights: Weights,
) -> Result<Image> {
    let (w, h, ch) = check_images(f, g)?;
    check_mask(mask_f, w, h, "mask of f")?;
    check_mask(mask_g, w, h, "mask of g")?;
    weights.check(w, h)?;
    if levels == 0 {
        return Err(GeomError::invalid("levels", "must be at least 1"));
    }
    let max_levels = (w.min(h) as f64).log2().floor() as usize + 1;
    let levels = levels.min(max_levels.max(1));
    let weight = Plane {
        w,
        h,
        v: (0..w * h)
            .map(|p| match (mask_f[p], mask_g[p]) {
                (true, false) => 1.0,
                (false, true) => 0.0,
                (true, true) => weights.at(p) as f32,
                (false, false) => 0.5,
            })
            .collect(),
    };
    let mut gw = vec![weight];
    for _ in 1..levels {
        let next = reduce(gw.last().expect("nonempty"));
        gw.push(next);
    }
    let mut out = Image::new(w, h, ch);
    for c in 0..ch {
        let plane = |img: &Image, other: &Image, own: &[bool]| Plane {
            w,
            h,
            v: (0..w * h)
                .map(|p| {
                    if own[p] {
                        img.data[p * ch + c]
                    } else {
                        other.data[p * ch + c]
                    }
                })
                .collect(),
        };
        let pf = plane(f, g, mask_f);
        let pg = plane(g, f, mask_g);
        // Gaussian pyramids, then blend Laplacian bands from coarse to fine while collapsing.
        let gauss = |p0: Plane| {
            let mut v = vec![p0];
            for _ in 1..levels {
                let next = reduce(v.last().expect("nonempty"));
                v.push(next);
            }
            v
        };
        let (gf, gg) = (gauss(pf), gauss(pg));
        let top = levels - 1;
        let mut acc = Plane {
            w: gf[top].w,
            h: gf[top].h,
            v: (0..gf[top].v.len())
                .map(|p| gw[top].v[p] * gf[top].v[p] + (1.0 - gw[top].v[p]) * gg[top].v[p])
                .collect(),
        };
        for l in (0..top).rev() {
            let (lw, lh) = (gf[l].w, gf[l].h);
            let ef = expand(&gf[l + 1], lw, lh);
            let eg = expand(&gg[l + 1], lw, lh);
            let up = expand(&acc, lw, lh);
            acc = Plane {
                w: lw,
                h: lh,
                v: (0..lw * lh)
                    .map(|p| {
                        let lf = gf[l].v[p] - ef.v[p];
                        let lg = gg[l].v[p] - eg.v[p];
                        up.v[p] + gw[l].v[p] * lf + (1.0 - gw[l].v[p]) * lg
                    })
                    .collect(),
            };
        }
        for p in 0..w * h {
            if mask_f[p] || mask_g[p] {
                out.data[p * ch + c] = acc.v[p];
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expand_of_reduce_keeps_constants_and_ramps() {
        let p = Plane {
            w: 9,
            h: 7,
            v: (0..63).map(|i| (i % 9) as f32 * 0.1 + 1.0).collect(),
        };
        let r = reduce(&p);
        assert_eq!((r.w, r.h), (5, 4));
        let e = expand(&r, 9, 7);
        // A linear ramp (along x) survives REDUCE+EXPAND away from the mirrored borders.
        for j in 2..5 {
            for i in 3..6 {
                assert!((e.v[j * 9 + i] - p.v[j * 9 + i]).abs() < 1e-5, "{i},{j}");
            }
        }
        let c = Plane {
            w: 6,
            h: 5,
            v: vec![2.0; 30],
        };
        assert!(
            expand(&reduce(&c), 6, 5)
                .v
                .iter()
                .all(|v| (v - 2.0).abs() < 1e-6)
        );
    }
}
