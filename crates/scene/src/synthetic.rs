//! A small textured scene built in-process and rendered by ray tracing (an independent reference
//! path: analytic ray–surface intersections, no Gaussians), so `fewview demo` and the tests run
//! without any downloaded data.
//!
//! The scene: a checkered ground plane, a textured back wall, two textured spheres, Lambertian
//! shading with hard shadows from one directional light plus ambient light. Cameras sit on an arc
//! in front of it, looking at its centre (a forward-facing capture, like LLFF).

use nalgebra::Vector3;

use crate::camera::{Camera, Intrinsics};
use crate::dataset::{Dataset, View};
use crate::image::Image;

/// Size and views of the demo scene.
#[derive(Clone, Debug, PartialEq)]
pub struct DemoOptions {
    pub width: usize,
    pub height: usize,
    /// Cameras on the arc.
    pub views: usize,
    /// Indices of the training views (the rest are held out).
    pub train: Vec<usize>,
    /// Supersampling per pixel axis (anti-aliasing of the ground truth).
    pub supersample: usize,
}

impl Default for DemoOptions {
    fn default() -> Self {
        Self {
            width: 200,
            height: 150,
            views: 24,
            train: vec![2, 11, 21],
            supersample: 3,
        }
    }
}

#[derive(Clone, Copy)]
enum Surface {
    Ground,
    Wall,
    Sphere(usize),
}

struct Sphere {
    center: Vector3<f64>,
    radius: f64,
    colors: [[f64; 3]; 2],
    stripes: f64,
}

struct Scene {
    spheres: [Sphere; 2],
    light: Vector3<f64>,
}

/// The back wall is the plane y = WALL_Y; ground and wall span |x| ≤ HALF_WIDTH.
const WALL_Y: f64 = 2.5;
const HALF_WIDTH: f64 = 3.5;
const WALL_HEIGHT: f64 = 6.0;
const EPS: f64 = 1e-9;

impl Scene {
    fn new() -> Self {
        Self {
            spheres: [
                Sphere {
                    center: Vector3::new(-0.45, 0.0, 0.6),
                    radius: 0.6,
                    colors: [[0.85, 0.25, 0.2], [0.95, 0.85, 0.3]],
                    stripes: 8.0,
                },
                Sphere {
                    center: Vector3::new(0.75, -0.45, 0.35),
                    radius: 0.35,
                    colors: [[0.2, 0.45, 0.85], [0.9, 0.92, 0.95]],
                    stripes: 5.0,
                },
            ],
            light: Vector3::new(-0.4, -0.5, 1.0).normalize(),
        }
    }

    /// Nearest hit along the ray `o + t d`, `t > EPS`.
    fn intersect(&self, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<(f64, Surface)> {
        let mut best: Option<(f64, Surface)> = None;
        let mut consider = |t: f64, s: Surface| {
            if t > EPS && best.is_none_or(|(b, _)| t < b) {
                best = Some((t, s));
            }
        };
        if d.z.abs() > 1e-12 {
            let t = -o.z / d.z;
            let p = o + d * t;
            if p.x.abs() <= HALF_WIDTH && p.y <= WALL_Y && p.y >= -WALL_Y {
                consider(t, Surface::Ground);
            }
        }
        if d.y.abs() > 1e-12 {
            let t = (WALL_Y - o.y) / d.y;
            let p = o + d * t;
            if p.x.abs() <= HALF_WIDTH && (0.0..=WALL_HEIGHT).contains(&p.z) {
                consider(t, Surface::Wall);
            }
        }
        for (i, s) in self.spheres.iter().enumerate() {
            let oc = o - s.center;
            let b = oc.dot(d);
            let c = oc.norm_squared() - s.radius * s.radius;
            let disc = b * b - c;
            if disc >= 0.0 {
                let r = disc.sqrt();
                let t = if -b - r > EPS { -b - r } else { -b + r };
                consider(t, Surface::Sphere(i));
            }
        }
        best
    }

    fn albedo(&self, p: &Vector3<f64>, s: Surface) -> ([f64; 3], Vector3<f64>) {
        match s {
            Surface::Ground => {
                let check = ((p.x / 0.4).floor() + (p.y / 0.4).floor()).rem_euclid(2.0);
                let g = 0.35 + 0.5 * check;
                let tint = 0.5 + 0.5 * (0.7 * p.x).sin();
                (
                    [g, g * (0.8 + 0.2 * tint), g * (0.6 + 0.3 * tint)],
                    Vector3::z(),
                )
            }
            Surface::Wall => {
                let u = (p.x * 2.0).sin() * (p.z * 3.0).cos();
                let band = if (p.z * 2.5).rem_euclid(1.0) < 0.5 {
                    0.15
                } else {
                    0.0
                };
                ([0.45 + 0.2 * u, 0.6 + band, 0.5 - 0.15 * u], -Vector3::y())
            }
            Surface::Sphere(i) => {
                let sp = &self.spheres[i];
                let n = (p - sp.center) / sp.radius;
                let lat = n.z.asin();
                let lon = n.y.atan2(n.x);
                let k = ((lat * sp.stripes).sin() * (lon * 3.0).cos() > 0.0) as usize;
                (sp.colors[k], n)
            }
        }
    }

    /// Radiance along a ray (shaded albedo, or the sky when nothing is hit).
    fn shade(&self, o: &Vector3<f64>, d: &Vector3<f64>) -> [f64; 3] {
        let Some((t, s)) = self.intersect(o, d) else {
            let h = d.z.clamp(-1.0, 1.0) * 0.5 + 0.5;
            return [0.55 + 0.3 * h, 0.7 + 0.2 * h, 0.95];
        };
        let p = o + d * t;
        let (albedo, n) = self.albedo(&p, s);
        let lit = n.dot(&self.light).max(0.0);
        let shadowed = self.intersect(&(p + n * 1e-6), &self.light).is_some();
        let k = 0.35 + if shadowed { 0.0 } else { 0.65 * lit };
        albedo.map(|a| (a * k).clamp(0.0, 1.0))
    }
}

/// The demo dataset: `views` cameras on an arc, ray-traced images, the chosen training views and
/// the rest held out. Depth bounds come from the rendered depths (for frustum initialisation).
pub fn demo_dataset(opts: &DemoOptions) -> Dataset {
    let scene = Scene::new();
    let focal = 0.9 * opts.width as f64;
    let intrinsics = Intrinsics::centered(focal, opts.width as u32, opts.height as u32);
    let target = Vector3::new(0.1, 0.3, 0.45);
    let mut views = Vec::with_capacity(opts.views);
    for i in 0..opts.views {
        let s = if opts.views > 1 {
            i as f64 / (opts.views - 1) as f64
        } else {
            0.5
        };
        let azimuth = (-25.0 + 50.0 * s).to_radians();
        let elevation = (18.0 + 8.0 * (s * std::f64::consts::PI).sin()).to_radians();
        let radius = 4.2;
        let eye = target
            + Vector3::new(
                radius * azimuth.sin() * elevation.cos(),
                -radius * azimuth.cos() * elevation.cos(),
                radius * elevation.sin(),
            );
        let camera = Camera::look_at(intrinsics, eye, target, Vector3::z());
        let (image, near, far) = render_view(&scene, &camera, opts.supersample.max(1));
        views.push(View {
            name: format!("view_{i:02}"),
            camera,
            image,
            mask: None,
            depth_bounds: Some((near * 0.9, far * 1.1)),
            mask_is_alpha: false,
            source_index: i,
        });
    }
    let train: Vec<usize> = opts
        .train
        .iter()
        .copied()
        .filter(|&i| i < opts.views)
        .collect();
    let test = (0..opts.views).filter(|i| !train.contains(i)).collect();
    Dataset {
        name: "demo".into(),
        views,
        train,
        test,
        points: None,
        background: [0.0; 3],
        to_source_world: None,
    }
}

/// The exact z-depth (along the optical axis) of the demo scene through every pixel centre of
/// `camera`, row-major, 0 where the ray meets nothing (sky): the ground truth of depth and
/// stereo tests.
pub fn demo_depth(camera: &Camera) -> Vec<f32> {
    let scene = Scene::new();
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let forward = camera.forward();
    let mut depth = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let (o, d) = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
            if let Some((t, _)) = scene.intersect(&o, &d) {
                depth[y * w + x] = (t * d.dot(&forward)) as f32;
            }
        }
    }
    depth
}

/// Ray-traced image (box-filtered `ss × ss` samples per pixel) and the range of hit depths.
fn render_view(scene: &Scene, camera: &Camera, ss: usize) -> (Image, f64, f64) {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let mut img = Image::new(w, h, 3);
    let (mut near, mut far) = (f64::INFINITY, 0.0f64);
    let forward = camera.forward();
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0; 3];
            for sy in 0..ss {
                for sx in 0..ss {
                    let u = x as f64 + (sx as f64 + 0.5) / ss as f64;
                    let v = y as f64 + (sy as f64 + 0.5) / ss as f64;
                    let (o, d) = camera.ray(u, v);
                    let c = scene.shade(&o, &d);
                    for k in 0..3 {
                        acc[k] += c[k];
                    }
                    if let Some((t, _)) = scene.intersect(&o, &d) {
                        let z = t * d.dot(&forward);
                        near = near.min(z);
                        far = far.max(z);
                    }
                }
            }
            let n = (ss * ss) as f64;
            for (k, sum) in acc.iter().enumerate() {
                img.set(x, y, k, (sum / n) as f32);
            }
        }
    }
    if !near.is_finite() {
        (near, far) = (0.1, 10.0);
    }
    (img, near, far)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_hit_is_on_the_sphere_and_ground_is_below() {
        let s = Scene::new();
        let o = Vector3::new(-0.45, -5.0, 0.6);
        let d = Vector3::new(0.0, 1.0, 0.0);
        let (t, surf) = s.intersect(&o, &d).unwrap();
        assert!(matches!(surf, Surface::Sphere(0)));
        assert!((t - (5.0 - 0.6)).abs() < 1e-9);
        let (t, surf) = s
            .intersect(&Vector3::new(3.0, 0.0, 2.0), &Vector3::new(0.0, 0.0, -1.0))
            .unwrap();
        assert!(matches!(surf, Surface::Ground) && (t - 2.0).abs() < 1e-12);
    }

    #[test]
    fn demo_depth_back_projects_onto_the_scene() {
        let ds = demo_dataset(&DemoOptions {
            width: 40,
            height: 30,
            views: 3,
            train: vec![0],
            supersample: 1,
        });
        let cam = &ds.views[1].camera;
        let depth = demo_depth(cam);
        let scene = Scene::new();
        let mut hits = 0;
        for (i, &z) in depth.iter().enumerate() {
            if z <= 0.0 {
                continue;
            }
            hits += 1;
            let (u, v) = ((i % 40) as f64 + 0.5, (i / 40) as f64 + 0.5);
            let p = cam.unproject(u, v, z as f64);
            // The point lies on the first surface along its ray.
            let (o, d) = cam.ray(u, v);
            let (t, _) = scene.intersect(&o, &d).unwrap();
            assert!((o + d * t - p).norm() < 1e-4 * t, "pixel {i}");
        }
        assert!(hits > 40 * 30 * 3 / 4, "{hits} pixels hit the scene");
    }

    #[test]
    fn demo_dataset_has_textured_views_and_a_split() {
        let ds = demo_dataset(&DemoOptions {
            width: 40,
            height: 30,
            views: 6,
            train: vec![0, 3],
            supersample: 1,
        });
        assert_eq!(ds.views.len(), 6);
        assert_eq!(ds.train, vec![0, 3]);
        assert_eq!(ds.test, vec![1, 2, 4, 5]);
        for v in &ds.views {
            let mean: f32 = v.image.data.iter().sum::<f32>() / v.image.data.len() as f32;
            let var: f32 = v.image.data.iter().map(|x| (x - mean).powi(2)).sum::<f32>()
                / v.image.data.len() as f32;
            assert!(var > 0.005, "{}: flat image (variance {var})", v.name);
            let (near, far) = v.depth_bounds.unwrap();
            assert!(near > 0.5 && far > near && far < 20.0, "{near} {far}");
        }
        // The scene centre projects near the image centre.
        let (u, v, _) = ds.views[2]
            .camera
            .project(&Vector3::new(0.1, 0.3, 0.45))
            .unwrap();
        assert!((u - 20.0).abs() < 1e-6 && (v - 15.0).abs() < 1e-6);
    }
}
