//! Tests of the blends against independent computations.

use super::poisson::occlusion_aware_planes;
use super::*;
use fewview_scene::Image;
use rand::{RngExt, SeedableRng};

/// Smooth-ish random test image.
fn image(w: usize, h: usize, ch: usize, seed: u64) -> Image {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let (a, b, c): (f32, f32, f32) = (rng.random(), rng.random(), rng.random());
    let mut img = Image::new(w, h, ch);
    for j in 0..h {
        for i in 0..w {
            for k in 0..ch {
                let x = i as f32 / w as f32;
                let y = j as f32 / h as f32;
                let v = 0.5
                    + 0.3 * ((a * 7.0 + k as f32) * x + b * 5.0 * y).sin() * (c * 3.0 * y).cos()
                    + 0.05 * rng.random::<f32>();
                img.set(i, j, k, v);
            }
        }
    }
    img
}

/// f valid on the left 60 %, g on the right 60 %, plus a hole valid in neither.
fn masks(w: usize, h: usize) -> (Vec<bool>, Vec<bool>) {
    let mut mf = vec![false; w * h];
    let mut mg = vec![false; w * h];
    for j in 0..h {
        for i in 0..w {
            let hole =
                (i as isize - w as isize / 2).abs() < 3 && (j as isize - h as isize / 3).abs() < 3;
            mf[j * w + i] = i < w * 6 / 10 && !hole;
            mg[j * w + i] = i >= w * 4 / 10 && !hole;
        }
    }
    (mf, mg)
}

/// Naive residual of Eq. (3) at the overlap pixels, straight from the definition.
fn naive_residual(
    f: &Image,
    g: &Image,
    mf: &[bool],
    mg: &[bool],
    wf: f64,
    planes: &[Vec<f64>],
) -> f64 {
    let (w, h, ch) = (f.width, f.height, f.channels);
    let (mut r2, mut b2) = (0.0, 0.0);
    for c in 0..ch {
        for j in 0..h {
            for i in 0..w {
                let p = j * w + i;
                if !(mf[p] && mg[p]) {
                    continue;
                }
                let (mut lap, mut div) = (0.0, 0.0);
                for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (a, b) = (i as i64 + di, j as i64 + dj);
                    if a < 0 || b < 0 || a >= w as i64 || b >= h as i64 {
                        continue;
                    }
                    let q = b as usize * w + a as usize;
                    if !(mf[q] || mg[q]) {
                        continue;
                    }
                    let fv = |img: &Image, x: usize| img.data[x * ch + c] as f64;
                    lap += planes[c][p] - planes[c][q];
                    let df = fv(f, p) - fv(f, q);
                    let dg = fv(g, p) - fv(g, q);
                    div += match (mf[q], mg[q]) {
                        (true, true) => wf * df + (1.0 - wf) * dg,
                        (true, false) => df,
                        _ => dg,
                    };
                }
                r2 += (lap - div).powi(2);
                b2 += div * div;
            }
        }
    }
    (r2 / b2).sqrt()
}

#[test]
fn occlusion_aware_keeps_single_mask_pixels_and_solves_eq3() {
    let (w, h) = (70, 50);
    let f = image(w, h, 3, 1);
    let g = image(w, h, 3, 2);
    let (mf, mg) = masks(w, h);
    for solver in [Solver::MultigridCg, Solver::Direct] {
        let opts = PoissonOptions {
            solver,
            ..Default::default()
        };
        let s = occlusion_aware_planes(&f, &g, &mf, &mg, Weights::Constant(0.3), &opts).unwrap();
        let res = naive_residual(&f, &g, &mf, &mg, 0.3, &s.planes);
        assert!(res < 1e-6, "{solver:?}: residual {res}");
        assert!(s.stats.solve.relative_residual < 1e-6);
        let (img, _) =
            occlusion_aware_poisson_with(&f, &g, &mf, &mg, Weights::Constant(0.3), &opts).unwrap();
        for p in 0..w * h {
            for c in 0..3 {
                let v = img.data[p * 3 + c];
                match (mf[p], mg[p]) {
                    (true, false) => assert_eq!(v, f.data[p * 3 + c]),
                    (false, true) => assert_eq!(v, g.data[p * 3 + c]),
                    (false, false) => assert_eq!(v, 0.0),
                    _ => {}
                }
            }
        }
    }
    // The two solvers agree.
    let a = occlusion_aware_planes(
        &f,
        &g,
        &mf,
        &mg,
        Weights::Constant(0.3),
        &PoissonOptions::default(),
    )
    .unwrap();
    let b = occlusion_aware_planes(
        &f,
        &g,
        &mf,
        &mg,
        Weights::Constant(0.3),
        &PoissonOptions {
            solver: Solver::Direct,
            ..Default::default()
        },
    )
    .unwrap();
    let diff = a
        .planes
        .iter()
        .flatten()
        .zip(b.planes.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(diff < 1e-6, "{diff}");
}

#[test]
fn a_conservative_guidance_is_reproduced_exactly() {
    // f and g are the same image up to a constant offset; with Dirichlet values from f on both
    // sides (g = f there too) the guidance ∇f is integrable and the solution is f itself.
    let (w, h) = (40, 30);
    let f = image(w, h, 1, 3);
    let g = f.clone();
    let (mf, mg) = masks(w, h);
    let img = occlusion_aware_poisson(&f, &g, &mf, &mg, Weights::Constant(0.5)).unwrap();
    for p in 0..w * h {
        if mf[p] || mg[p] {
            assert!((img.data[p] - f.data[p]).abs() < 1e-5);
        }
    }
}

#[test]
fn isolated_overlap_is_pinned_and_per_pixel_weights_work() {
    let (w, h) = (20, 20);
    let f = image(w, h, 2, 4);
    let g = image(w, h, 2, 5);
    // Both masks cover everything: no Dirichlet pixel at all.
    let all = vec![true; w * h];
    let wts: Vec<f32> = (0..w * h)
        .map(|p| (p % w) as f32 / (w - 1) as f32)
        .collect();
    let s = occlusion_aware_planes(
        &f,
        &g,
        &all,
        &all,
        Weights::PerPixel(&wts),
        &PoissonOptions::default(),
    )
    .unwrap();
    assert_eq!(s.stats.pinned, 1);
    let p0 = 0;
    let expect = wts[0] as f64 * f.data[0] as f64 + (1.0 - wts[0] as f64) * g.data[0] as f64;
    assert!((s.planes[0][p0] - expect).abs() < 1e-6);
}

#[test]
fn standard_poisson_matches_the_direct_solution_and_keeps_the_outside() {
    let (w, h) = (48, 40);
    let target = image(w, h, 3, 6);
    let source = image(w, h, 3, 7);
    let mask: Vec<bool> = (0..w * h)
        .map(|p| {
            let (i, j) = ((p % w) as f64, (p / w) as f64);
            (i - 24.0).powi(2) + (j - 20.0).powi(2) < 100.0
        })
        .collect();
    let (a, sa) =
        poisson_blend(&target, &source, &mask, false, &PoissonOptions::default()).unwrap();
    let (b, _) = poisson_blend(
        &target,
        &source,
        &mask,
        false,
        &PoissonOptions {
            solver: Solver::Direct,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(sa.solve.relative_residual < 1e-6);
    for p in 0..w * h {
        for c in 0..3 {
            assert!((a.data[p * 3 + c] - b.data[p * 3 + c]).abs() < 1e-5);
            if !mask[p] {
                assert_eq!(a.data[p * 3 + c], target.data[p * 3 + c]);
            }
        }
    }
    // Inside, the result differs from the source by a harmonic function: the Laplacians match.
    let lap = |img: &Image, i: usize, j: usize| {
        let v = |x: usize, y: usize| img.get(x, y, 0) as f64;
        4.0 * v(i, j) - v(i - 1, j) - v(i + 1, j) - v(i, j - 1) - v(i, j + 1)
    };
    assert!((lap(&a, 24, 20) - lap(&source, 24, 20)).abs() < 1e-4);
    let (m, _) = poisson_blend(&target, &source, &mask, true, &PoissonOptions::default()).unwrap();
    assert!(m.is_finite());
}

#[test]
fn feather_and_pyramid_respect_masks() {
    let (w, h) = (64, 48);
    let f = image(w, h, 3, 8);
    let g = image(w, h, 3, 9);
    let (mf, mg) = masks(w, h);
    let fe = gaussian_feather_blend(&f, &g, &mf, &mg, 4.0, Weights::default()).unwrap();
    for p in 0..w * h {
        let v = fe.data[p * 3];
        match (mf[p], mg[p]) {
            (true, false) => assert_eq!(v, f.data[p * 3]),
            (false, true) => assert_eq!(v, g.data[p * 3]),
            (false, false) => assert_eq!(v, 0.0),
            _ => {
                let (lo, hi) = (
                    f.data[p * 3].min(g.data[p * 3]),
                    f.data[p * 3].max(g.data[p * 3]),
                );
                assert!(v >= lo - 1e-6 && v <= hi + 1e-6);
            }
        }
    }
    // Pyramid: one level is the plain weighted average; identical inputs come back unchanged.
    let one = laplacian_pyramid_blend(&f, &g, &mf, &mg, 1, Weights::Constant(0.25)).unwrap();
    for p in 0..w * h {
        let want = match (mf[p], mg[p]) {
            (true, false) => f.data[p * 3],
            (false, true) => g.data[p * 3],
            (true, true) => 0.25 * f.data[p * 3] + 0.75 * g.data[p * 3],
            _ => 0.0,
        };
        assert!((one.data[p * 3] - want).abs() < 1e-6);
    }
    let same = laplacian_pyramid_blend(&f, &f, &mf, &mg, 5, Weights::default()).unwrap();
    for p in 0..w * h {
        if mf[p] || mg[p] {
            assert!((same.data[p * 3] - f.data[p * 3]).abs() < 1e-4);
        }
    }
    // Far from the overlap the pyramid blend is the image itself.
    let py = laplacian_pyramid_blend(&f, &g, &mf, &mg, 4, Weights::default()).unwrap();
    assert!((py.get(2, 10, 0) - f.get(2, 10, 0)).abs() < 1e-4);
}

/// The blur as first written: a kernel of radius ⌈3σ⌉ over an index mirrored one bounce at a
/// time (slow for wide kernels, exact).
fn reference_blur(plane: &[f32], w: usize, h: usize, sigma: f32) -> Vec<f64> {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f64> = (-r..=r)
        .map(|x| (-(x * x) as f64 / (2.0 * sigma as f64 * sigma as f64)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    let reflect = |mut x: isize, n: usize| -> usize {
        let n = n as isize;
        loop {
            if x < 0 {
                x = -x - 1;
            } else if x >= n {
                x = 2 * n - x - 1;
            } else {
                return x as usize;
            }
        }
    };
    let mut tmp = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            tmp[j * w + i] = (-r..=r)
                .map(|d| k[(d + r) as usize] / s * plane[j * w + reflect(i as isize + d, w)] as f64)
                .sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            out[j * w + i] = (-r..=r)
                .map(|d| k[(d + r) as usize] / s * tmp[reflect(j as isize + d, h) * w + i])
                .sum();
        }
    }
    out
}

/// σ = 10⁴ used to hang (a 3·10⁴ kernel, each tap mirrored one width at a time); a kernel wider
/// than the mirrored image is now folded onto it, and a huge σ averages the whole plane.
#[test]
fn feather_with_a_huge_sigma_finishes_and_matches_the_plain_blur() {
    let (w, h) = (12, 9);
    let plane: Vec<f32> = (0..w * h).map(|p| ((p * 37) % 11) as f32 / 10.0).collect();
    for sigma in [0.7, 2.5, 3.0, 5.0, 40.0] {
        let got = gaussian_blur(&plane, w, h, sigma);
        let want = reference_blur(&plane, w, h, sigma);
        for (a, b) in got.iter().zip(&want) {
            assert!((*a as f64 - b).abs() < 1e-5, "σ {sigma}: {a} vs {b}");
        }
    }
    let mean = plane.iter().sum::<f32>() / plane.len() as f32;
    for sigma in [1e6, 1e30, f32::MAX] {
        let flat = gaussian_blur(&plane, w, h, sigma);
        assert!(flat.iter().all(|v| (v - mean).abs() < 1e-3), "σ {sigma}");
    }
    let f = image(40, 30, 3, 8);
    let g = image(40, 30, 3, 9);
    let (mf, mg) = masks(40, 30);
    let out = gaussian_feather_blend(&f, &g, &mf, &mg, 1e6, Weights::default()).unwrap();
    assert!(out.data.iter().all(|v| v.is_finite()));
}

#[test]
fn bad_inputs_give_clear_errors() {
    let f = image(10, 8, 3, 1);
    let g = image(12, 8, 3, 2);
    let m = vec![true; 80];
    let e = occlusion_aware_poisson(&f, &g, &m, &m, Weights::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("10×8 vs 12×8"), "{e}");
    let g = image(10, 8, 3, 2);
    let empty = vec![false; 80];
    let e = occlusion_aware_poisson(&f, &g, &m, &empty, Weights::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("mask of g: is empty"), "{e}");
    let e = occlusion_aware_poisson(&f, &g, &m[..50], &m, Weights::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("50 values"), "{e}");
    let mut nan = f.clone();
    nan.data[5] = f32::NAN;
    let e = gaussian_feather_blend(&nan, &g, &m, &m, 2.0, Weights::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("(1, 0)") && e.contains("not finite"), "{e}");
    let e = laplacian_pyramid_blend(&f, &g, &m, &m, 3, Weights::Constant(1.5))
        .unwrap_err()
        .to_string();
    assert!(e.contains("1.5"), "{e}");
}
