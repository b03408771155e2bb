//! The visual hull against analytic references: a sphere seen by cameras spread over a sphere of
//! directions (a single ring leaves the poles uncarved: the hull of a sphere of radius R seen from
//! a ring at distance D reaches R / √(1 − R²/D²) on the axis), and, with `FEWVIEW_DATA`, the
//! exact depth of seq_a.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod common;

use fewview_human::hull::{Bounds, Footprint, Hull, HullConfig};
use fewview_human::{HumanDataset, Mask, MultiView, Split};
use fewview_scene::{Camera, Intrinsics};
use nalgebra::Vector3;

const RADIUS: f64 = 0.5;
const DISTANCE: f64 = 3.0;
const SIZE: u32 = 256;
const FOCAL: f64 = 320.0;

/// `n` directions of a Fibonacci lattice on the unit sphere.
fn fibonacci(n: usize) -> Vec<Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            Vector3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

fn looking_at_origin(dir: &Vector3<f64>) -> Camera {
    let up = if dir.z.abs() > 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    Camera::look_at(
        Intrinsics::centered(FOCAL, SIZE, SIZE),
        dir * DISTANCE,
        Vector3::zeros(),
        up,
    )
}

/// Distance along the ray through pixel `(x, y)`'s centre to the sphere, if it hits.
fn hit(camera: &Camera, x: usize, y: usize) -> Option<f64> {
    let (o, d) = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
    let b = o.dot(&d);
    let disc = b * b - (o.norm_squared() - RADIUS * RADIUS);
    (disc >= 0.0).then(|| -b - disc.sqrt())
}

fn sphere_mask(camera: &Camera) -> Mask {
    let n = SIZE as usize;
    Mask::new(
        n,
        n,
        (0..n * n)
            .map(|i| hit(camera, i % n, i / n).is_some())
            .collect(),
    )
}

fn sphere_hull(config: &HullConfig) -> (Vec<Camera>, Hull) {
    let cameras: Vec<Camera> = fibonacci(60).iter().map(looking_at_origin).collect();
    let masks: Vec<Mask> = cameras.iter().map(sphere_mask).collect();
    let hull = Hull::carve(&cameras, &masks, config).unwrap();
    (cameras, hull)
}

/// Radii of the kept samples that have a carved 6-neighbour (the hull's boundary voxels).
fn boundary_radii(hull: &Hull, kept: &[bool]) -> Vec<f64> {
    let [nx, ny, nz] = hull.spec.dims;
    let idx = |i: usize, j: usize, k: usize| (i * ny + j) * nz + k;
    let mut radii = Vec::new();
    for i in 1..nx - 1 {
        for j in 1..ny - 1 {
            for k in 1..nz - 1 {
                let neighbours = [
                    idx(i - 1, j, k),
                    idx(i + 1, j, k),
                    idx(i, j - 1, k),
                    idx(i, j + 1, k),
                    idx(i, j, k - 1),
                    idx(i, j, k + 1),
                ];
                if kept[idx(i, j, k)] && neighbours.iter().any(|&n| !kept[n]) {
                    radii.push(hull.position(i, j, k).norm());
                }
            }
        }
    }
    radii
}

#[test]
fn sphere_hull_is_within_one_voxel_of_the_sphere() {
    let voxel = 0.025;
    let config = HullConfig {
        voxel,
        bounds: Some(Bounds {
            min: [-0.7; 3],
            max: [0.7; 3],
        }),
        min_views: None,
    };
    let (cameras, hull) = sphere_hull(&config);
    let centre = hull.occupied(Footprint::Centre);
    let radii = boundary_radii(&hull, &centre);
    let (lo, hi) = radii
        .iter()
        .fold((f64::MAX, 0f64), |(l, h), &r| (l.min(r), h.max(r)));
    println!(
        "sphere R = {RADIUS}, voxel {voxel}: {} boundary voxels at radius {lo:.4}-{hi:.4}",
        radii.len()
    );
    assert!(radii.len() > 1000);
    // A kept voxel with a carved neighbour lies within one voxel of the surface, give or take
    // the masks' quantisation: half a pixel's footprint at the sphere's nearest point.
    let half_pixel = 0.5 * (DISTANCE - RADIUS) / FOCAL;
    assert!(
        lo >= RADIUS - voxel - half_pixel && hi <= RADIUS + voxel + half_pixel,
        "{lo} {hi}"
    );
    // No holes: every sample a voxel inside the sphere is kept; none is kept outside it (beyond
    // the masks' quantisation).
    let [_, ny, nz] = hull.spec.dims;
    for (i, &kept) in centre.iter().enumerate() {
        let r = hull.position(i / (ny * nz), (i / nz) % ny, i % nz).norm();
        assert!(r > RADIUS - voxel || kept, "hole at radius {r}");
        assert!(r < RADIUS + half_pixel || !kept, "kept at radius {r}");
    }
    // The conservative footprint is a superset, at most two voxels out.
    let wide = hull.occupied(Footprint::Conservative);
    assert!(centre.iter().zip(&wide).all(|(c, w)| !c || *w));
    let wide_hi = boundary_radii(&hull, &wide)
        .into_iter()
        .fold(0f64, f64::max);
    println!("conservative footprint: boundary up to radius {wide_hi:.4}");
    assert!(wide_hi <= RADIUS + 2.0 * voxel);
    // Depth of the hull in a view between the carving cameras, against the sphere's exact depth.
    let probe = looking_at_origin(&Vector3::new(0.3, -0.8, 0.52).normalize());
    assert!(
        cameras
            .iter()
            .all(|c| (c.center() - probe.center()).norm() > 0.1)
    );
    let depth = hull
        .source_depths(std::slice::from_ref(&probe))
        .unwrap()
        .remove(0);
    let n = SIZE as usize;
    let mut errors = Vec::new();
    for i in 0..n * n {
        if let (Some(t), true) = (hit(&probe, i % n, i / n), depth.data[i] > 0.0) {
            let (_, d) = probe.ray((i % n) as f64 + 0.5, (i / n) as f64 + 0.5);
            let z = t * d.dot(&probe.forward());
            errors.push(depth.data[i] as f64 - z);
        }
    }
    errors.sort_by(f64::total_cmp);
    let median_abs = {
        let mut a: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
        a.sort_by(f64::total_cmp);
        a[a.len() / 2]
    };
    println!(
        "hull depth vs sphere: {} pixels, median |error| {median_abs:.4} m, range {:.4} to {:.4}",
        errors.len(),
        errors[0],
        errors[errors.len() - 1]
    );
    assert!(median_abs < 0.25 * voxel);
}

#[test]
fn bounds_from_the_cameras_contain_the_sphere() {
    let (_, auto) = sphere_hull(&HullConfig {
        voxel: 0.04,
        ..HullConfig::default()
    });
    let o = auto.spec.origin;
    let far = [0, 1, 2].map(|a| o[a] + auto.spec.voxel[a] * (auto.spec.dims[a] - 1) as f64);
    for a in 0..3 {
        assert!(o[a] < -RADIUS && o[a] > -RADIUS - 0.5, "{o:?}");
        assert!(far[a] > RADIUS && far[a] < RADIUS + 0.5, "{far:?}");
    }
    assert!(
        auto.contains(&Vector3::zeros(), 0.0) && !auto.contains(&Vector3::new(0.0, 0.0, 0.6), 0.0)
    );
}

#[test]
fn bad_hull_inputs_are_errors() {
    let cam = looking_at_origin(&Vector3::x());
    let mask = sphere_mask(&cam);
    let cases: [(HullConfig, Vec<Mask>, &str); 4] = [
        (
            HullConfig {
                voxel: 0.0,
                ..HullConfig::default()
            },
            vec![mask.clone()],
            "hull voxel: 0",
        ),
        (
            HullConfig {
                min_views: Some(2),
                ..HullConfig::default()
            },
            vec![mask.clone()],
            "hull min_views: 2 (need 1 to 1)",
        ),
        (
            HullConfig::default(),
            vec![Mask::new(
                SIZE as usize,
                SIZE as usize,
                vec![false; 256 * 256],
            )],
            "empty mask",
        ),
        (
            HullConfig::default(),
            vec![Mask::new(4, 4, vec![true; 16])],
            "mask 4×4 for a 256×256 camera",
        ),
    ];
    for (config, masks, want) in cases {
        let e = Hull::carve(std::slice::from_ref(&cam), &masks, &config)
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{e}");
    }
    let tiny = HullConfig {
        voxel: 1e-4,
        bounds: Some(Bounds {
            min: [-1.0; 3],
            max: [1.0; 3],
        }),
        min_views: None,
    };
    let e = Hull::carve(&[cam], &[mask], &tiny).unwrap_err().to_string();
    assert!(e.contains("use larger voxels"), "{e}");
}

/// The hull of seq_a frame 0 from the 8 input cameras, rendered into a source camera (cam_00),
/// against the capture's exact depth; and the share of that view's true surface points (its
/// depth back-projected) inside the hull. Containment allows a quarter voxel (2.5 mm), about half
/// a pixel's footprint at 3 m (4.7 mm): the masks' own resolution, since the body's front, seen
/// edge-on by the side cameras, lies on the hull's surface to within that.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn seq_a_hull_depth_against_exact_depth() {
    let data = HumanDataset::open(&common::data_root().join("human"), "seq_a").unwrap();
    let split = Split::seq_a();
    let cameras: Vec<Camera> = split
        .input_cameras
        .iter()
        .map(|&c| data.cameras()[c].clone())
        .collect();
    let masks: Vec<Mask> = split
        .input_cameras
        .iter()
        .map(|&c| data.mask(c, 0).unwrap())
        .collect();
    let start = std::time::Instant::now();
    let config = HullConfig::default();
    let hull = Hull::carve(&cameras, &masks, &config).unwrap();
    let carve_s = start.elapsed().as_secs_f64();
    let source = &data.cameras()[0];
    let depth = hull
        .source_depths(std::slice::from_ref(source))
        .unwrap()
        .remove(0);
    let exact = data.depth(0, 0).unwrap();
    let mut errors = Vec::new();
    let (mut points, mut strict, mut inside) = (0usize, 0usize, 0usize);
    for i in 0..exact.data.len() {
        let z = exact.data[i] as f64;
        if z <= 0.0 {
            continue;
        }
        let p = source.unproject(
            (i % exact.width) as f64 + 0.5,
            (i / exact.width) as f64 + 0.5,
            z,
        );
        points += 1;
        strict += hull.contains(&p, 0.0) as usize;
        inside += hull.contains(&p, 0.25 * config.voxel) as usize;
        if depth.data[i] > 0.0 {
            errors.push((depth.data[i] as f64 - z).abs());
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    let p90 = errors[errors.len() * 9 / 10];
    let share = inside as f64 / points as f64;
    println!(
        "seq_a frame 0, hull of {} views ({:?} samples, {carve_s:.2} s), depth in cam_00: {} pixels, \
         median |error| {:.1} mm, 90th percentile {:.1} mm; of {points} surface points {:.2} % inside \
         within 2.5 mm, {:.2} % strictly",
        cameras.len(),
        hull.spec.dims,
        errors.len(),
        median * 1000.0,
        p90 * 1000.0,
        share * 100.0,
        strict as f64 / points as f64 * 100.0
    );
    assert!(errors.len() as f64 > 0.95 * points as f64);
    assert!(median < 0.01, "{median}");
    assert!(share >= 0.99, "{share}");
}
