//! Benchmarks the lead wires into `fewview bench`: plain figures, each with a reference measured
//! in the same run.

use std::time::Instant;

use fewview_scene::cputime::measure;
use fewview_scene::{Camera, Image, Intrinsics, Se3};
use nalgebra::{Rotation3, Vector3};
use serde::Serialize;

use crate::blend::{PoissonOptions, Solver, Weights, occlusion_aware_poisson_with};
use crate::depth::depth_to_mesh;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::raster::rasterize_mesh_colors;
use crate::stereo::pairs::StereoView;
use crate::stereo::refine::RefineOptions;
use crate::stereo::sgm::{Border, GrayOrRgb, Paths, SgmParams, match_left};
use crate::stereo::source::{DisparityRange, Photometry, eight_bit_rgb, match_pair};

/// Figures of the occlusion-aware Poisson blend benchmark.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BlendBench {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    /// Overlap pixels (unknowns per channel).
    pub unknowns: usize,
    /// Wall time of the default solver (multigrid-preconditioned CG), all channels.
    pub seconds: f64,
    /// CPU time (all threads) of the same run, from `/proc/self/stat` (Linux; `None`
    /// elsewhere). On a shared machine wall time inflates; `cpu_seconds / threads` is what the
    /// run costs on idle cores.
    pub cpu_seconds: Option<f64>,
    pub iterations: usize,
    pub relative_residual: f64,
    /// The reference: `faer`'s sparse Cholesky on the same problem at half resolution
    /// (`reference_width × reference_height`; at full size it takes several seconds).
    pub reference_width: usize,
    pub reference_height: usize,
    pub reference_unknowns: usize,
    pub reference_seconds: f64,
    /// The default solver on the half-resolution problem, for a like-for-like comparison.
    pub ours_at_reference_size_seconds: f64,
    /// Unknowns × channels solved per second per thread by the default solver at full size.
    pub unknowns_per_second_per_thread: f64,
    pub threads: usize,
}

/// The benchmark problem: two reprojected views of a textured scene; `f` misses the right 10 %
/// and some occluded discs, `g` the left 10 % and other discs, so about 75 % of the pixels are
/// overlap unknowns.
pub fn blend_problem(w: usize, h: usize) -> (Image, Image, Vec<bool>, Vec<bool>) {
    let mut f = Image::new(w, h, 3);
    let mut g = Image::new(w, h, 3);
    let mut mf = vec![true; w * h];
    let mut mg = vec![true; w * h];
    let disc = |i: usize, j: usize, cx: f64, cy: f64, r: f64| {
        let (x, y) = (i as f64 / w as f64 - cx, j as f64 / h as f64 - cy);
        x * x + y * y < r * r
    };
    for j in 0..h {
        for i in 0..w {
            let p = j * w + i;
            let (x, y) = (i as f32 / w as f32, j as f32 / h as f32);
            for c in 0..3 {
                let tex = 0.5 + 0.25 * ((40.0 + 7.0 * c as f32) * x).sin() * (31.0 * y).cos();
                f.data[p * 3 + c] = tex;
                // g sees the same texture under different exposure and a colour shift.
                g.data[p * 3 + c] = 0.8 * tex + 0.1 + 0.05 * c as f32;
            }
            mf[p] = x < 0.9 && !disc(i, j, 0.3, 0.4, 0.08) && !disc(i, j, 0.6, 0.7, 0.05);
            mg[p] = x >= 0.1 && !disc(i, j, 0.5, 0.3, 0.07) && !disc(i, j, 0.75, 0.6, 0.06);
        }
    }
    (f, g, mf, mg)
}

fn timed(w: usize, h: usize, solver: Solver) -> Result<(f64, crate::blend::PoissonStats)> {
    let (f, g, mf, mg) = blend_problem(w, h);
    let opts = PoissonOptions {
        solver,
        ..Default::default()
    };
    let t = Instant::now();
    let (_, stats) = occlusion_aware_poisson_with(&f, &g, &mf, &mg, Weights::Constant(0.5), &opts)?;
    Ok((t.elapsed().as_secs_f64(), stats))
}

/// Occlusion-aware Poisson blend of a 1024×1024 three-channel pair (see [`blend_problem`]).
pub fn blend_1024() -> Result<BlendBench> {
    blend_bench(1024)
}

/// [`blend_1024`] at `size × size` (the reference at half that).
pub fn blend_bench(size: usize) -> Result<BlendBench> {
    let (w, h) = (size, size);
    let (timed_run, _, cpu) = measure(|| timed(w, h, Solver::MultigridCg));
    let (seconds, stats) = timed_run?;
    let cpu_seconds = Some(cpu).filter(|c| c.is_finite());
    let (rw, rh) = (w / 2, h / 2);
    let (reference_seconds, rstats) = timed(rw, rh, Solver::Direct)?;
    let (ours_small, _) = timed(rw, rh, Solver::MultigridCg)?;
    let threads = rayon::current_num_threads();
    Ok(BlendBench {
        width: w,
        height: h,
        channels: 3,
        unknowns: stats.solve.unknowns,
        seconds,
        cpu_seconds,
        iterations: stats.solve.iterations,
        relative_residual: stats.solve.relative_residual,
        reference_width: rw,
        reference_height: rh,
        reference_unknowns: rstats.solve.unknowns,
        reference_seconds,
        ours_at_reference_size_seconds: ours_small,
        unknowns_per_second_per_thread: (stats.solve.unknowns * 3) as f64
            / seconds
            / threads as f64,
        threads,
    })
}

/// Figures of the stereo benchmark: Semi-Global Matching of one rectified pair.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StereoBench {
    pub width: usize,
    pub height: usize,
    pub disparities: usize,
    /// OpenCV's configuration (5 paths, its border): median wall and CPU seconds of `runs`.
    pub opencv_mode_seconds: f64,
    pub opencv_mode_cpu_seconds: f64,
    /// Pixel·disparities per CPU-second in OpenCV's configuration.
    pub pixel_disparities_per_cpu_second: f64,
    /// The reference: the same matching on one thread (wall seconds).
    pub one_thread_seconds: f64,
    /// The stereo start's configuration (8 paths, partial border), wall seconds.
    pub default_seconds: f64,
    /// The whole pair as the stereo start runs it (rectification, both directions, refinement,
    /// depth maps) at the pair's own size and disparity range, wall seconds.
    pub pair_seconds: f64,
    pub pair_width: usize,
    pub pair_height: usize,
    pub pair_disparities: usize,
    pub threads: usize,
}

/// Times the matcher on the central `width × height` of the rectified pair of `first` and
/// `second` with `disparities` disparities from the pair's smallest one, and the whole pair.
pub fn stereo_bench(
    first: &StereoView,
    second: &StereoView,
    (width, height, disparities): (usize, usize, usize),
    runs: usize,
) -> Result<StereoBench> {
    let init = SgmParams::default();
    let t = Instant::now();
    let pair = match_pair(
        first,
        second,
        &SgmParams {
            paths: Paths::Eight,
            ..init.clone()
        },
        DisparityRange::FromDepthBounds,
        Some(&RefineOptions::default()),
        Photometry::GainMatched,
    )?;
    let pair_seconds = t.elapsed().as_secs_f64();
    let crop = |img: &Image| -> Vec<u8> {
        let (x0, y0) = (
            img.width.saturating_sub(width) / 2,
            img.height.saturating_sub(height) / 2,
        );
        let mut out = Image::new(width, height, 3);
        for y in 0..height.min(img.height) {
            for x in 0..width.min(img.width) {
                for c in 0..3 {
                    out.set(x, y, c, img.get(x0 + x, y0 + y, c.min(img.channels - 1)));
                }
            }
        }
        eight_bit_rgb(&out)
    };
    let (l8, r8) = (crop(&pair.left.image), crop(&pair.right.image));
    let l = GrayOrRgb::new(width, height, 3, &l8)?;
    let r = GrayOrRgb::new(width, height, 3, &r8)?;
    let opencv = SgmParams {
        min_disparity: pair.params.min_disparity,
        num_disparities: disparities,
        border: Border::OpenCv,
        ..init.clone()
    };
    let ours = SgmParams {
        paths: Paths::Eight,
        border: Border::Partial,
        ..opencv.clone()
    };
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut wall = Vec::new();
    let mut cpu = Vec::new();
    for _ in 0..runs.max(1) {
        let (out, w, c) = measure(|| match_left(&l, &r, &opencv));
        out?;
        wall.push(w);
        cpu.push(c);
    }
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| crate::error::GeomError::numerical(e.to_string()))?;
    let (out, one_thread_seconds, _) = one.install(|| measure(|| match_left(&l, &r, &opencv)));
    out?;
    let (out, default_seconds, _) = measure(|| match_left(&l, &r, &ours));
    out?;
    let (opencv_mode_seconds, opencv_mode_cpu_seconds) = (median(wall), median(cpu));
    Ok(StereoBench {
        width,
        height,
        disparities,
        opencv_mode_seconds,
        opencv_mode_cpu_seconds,
        pixel_disparities_per_cpu_second: (width * height * disparities) as f64
            / opencv_mode_cpu_seconds,
        one_thread_seconds,
        default_seconds,
        pair_seconds,
        pair_width: pair.left.image.width,
        pair_height: pair.left.image.height,
        pair_disparities: pair.params.num_disparities,
        threads: rayon::current_num_threads(),
    })
}

/// The triangle rasterisation problem: a sphere before a slanted plane, ray-cast exactly in
/// `camera`, meshed without the depth-edge filter (two triangles per pixel block), to be
/// reprojected into `virtual_camera` (turned by a few degrees, 0.2 units to the side).
#[derive(Clone, Debug)]
pub struct RasterProblem {
    pub camera: Camera,
    /// z-depth of every pixel centre of `camera` (row-major).
    pub depth: Vec<f32>,
    /// A smooth colour texture in `camera`; the mesh's vertex colours.
    pub image: Image,
    pub mesh: Mesh,
    pub virtual_camera: Camera,
}

/// A camera at world `centre`, turned by Euler angles `(roll, pitch, yaw)` from looking along +z.
pub(crate) fn turned_camera(k: Intrinsics, angles: [f64; 3], centre: Vector3<f64>) -> Camera {
    let r = Rotation3::from_euler_angles(angles[0], angles[1], angles[2]).into_inner();
    Camera::new(k, Se3::new(r, -(r * centre)))
}

/// Distance along the unit ray `(o, d)` to the nearer of the sphere (centre (0, 0, 1.5), radius
/// 0.6) and the plane `z = 3 + 0.3 x`.
fn sphere_or_plane(o: Vector3<f64>, d: Vector3<f64>) -> f64 {
    let n = Vector3::new(-0.3, 0.0, 1.0);
    let plane = (3.0 - n.dot(&o)) / n.dot(&d);
    let oc = o - Vector3::new(0.0, 0.0, 1.5);
    let b = oc.dot(&d);
    let disc = b * b - (oc.norm_squared() - 0.36);
    let sphere = if disc >= 0.0 {
        -b - disc.sqrt()
    } else {
        f64::INFINITY
    };
    if sphere > 0.0 {
        sphere.min(plane)
    } else {
        plane
    }
}

/// [`RasterProblem`] at `width × height` (focal length 0.9 × width).
pub fn raster_problem(width: usize, height: usize) -> Result<RasterProblem> {
    let k = Intrinsics::centered(0.9 * width as f64, width as u32, height as u32);
    let camera = turned_camera(k, [0.05, -0.03, 0.02], Vector3::new(0.1, -0.2, -1.0));
    let virtual_camera = turned_camera(k, [-0.02, 0.06, 0.03], Vector3::new(0.3, -0.15, -0.95));
    let mut depth = vec![0.0; width * height];
    let mut image = Image::new(width, height, 3);
    for j in 0..height {
        for i in 0..width {
            let (o, d) = camera.ray(i as f64 + 0.5, j as f64 + 0.5);
            let x = o + d * sphere_or_plane(o, d);
            depth[j * width + i] = camera.world_to_camera.transform_point(&x).z as f32;
            for c in 0..3 {
                let v = 0.5 + 0.4 * (7.0 * x.x + 1.3 * c as f64).sin() * (5.0 * x.y).cos();
                image.set(i, j, c, v as f32);
            }
        }
    }
    let mesh = depth_to_mesh(&depth, &camera, Some(&image), 0.0)?;
    Ok(RasterProblem {
        camera,
        depth,
        image,
        mesh,
        virtual_camera,
    })
}

/// Figures of the triangle rasterisation benchmark: a depth mesh reprojected into a virtual
/// camera with its colours ([`raster_problem`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TriangleRasterBench {
    pub width: usize,
    pub height: usize,
    pub triangles: usize,
    pub covered_pixels: usize,
    /// Median wall and CPU seconds of `runs` rasterisations on all threads.
    pub seconds: f64,
    pub cpu_seconds: f64,
    /// Triangles per CPU-second (all threads).
    pub triangles_per_cpu_second: f64,
    /// The reference: the same rasterisation on one thread (wall seconds).
    pub one_thread_seconds: f64,
    pub threads: usize,
}

/// Times [`rasterize_mesh_colors`] on [`raster_problem`] at `width × height`.
pub fn triangle_raster_bench(
    width: usize,
    height: usize,
    runs: usize,
) -> Result<TriangleRasterBench> {
    let p = raster_problem(width, height)?;
    let run = || rasterize_mesh_colors(&p.mesh, &p.virtual_camera, 0.0);
    let mut wall = Vec::new();
    let mut cpu = Vec::new();
    let mut covered_pixels = 0;
    for _ in 0..runs.max(1) {
        let (out, w, c) = measure(run);
        covered_pixels = out?.coverage().iter().filter(|&&c| c).count();
        wall.push(w);
        cpu.push(c);
    }
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| crate::error::GeomError::numerical(e.to_string()))?;
    let (out, one_thread_seconds, _) = one.install(|| measure(run));
    out?;
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (seconds, cpu_seconds) = (median(wall), median(cpu));
    Ok(TriangleRasterBench {
        width,
        height,
        triangles: p.mesh.faces.len(),
        covered_pixels,
        seconds,
        cpu_seconds,
        triangles_per_cpu_second: p.mesh.faces.len() as f64 / cpu_seconds,
        one_thread_seconds,
        threads: rayon::current_num_threads(),
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn small_benchmark_runs_and_both_solvers_converge() {
        let b = super::blend_bench(96).unwrap();
        assert!(b.relative_residual < 1e-6, "{b:?}");
        assert!(b.unknowns > 96 * 96 / 2 && b.reference_unknowns > 48 * 48 / 2);
        assert!(b.seconds > 0.0 && b.reference_seconds > 0.0);
    }

    #[test]
    fn small_triangle_raster_benchmark_runs() {
        let b = super::triangle_raster_bench(40, 30, 1).unwrap();
        assert_eq!(b.triangles, 2 * 39 * 29);
        assert!(b.covered_pixels > 40 * 30 / 2, "{b:?}");
        assert!(b.seconds > 0.0 && b.one_thread_seconds > 0.0);
    }
}
