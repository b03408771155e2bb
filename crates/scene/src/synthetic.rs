//! A small textured scene built in-process and rendered by ray tracing (an independent reference
//! path: analytic ray–surface intersections, no Gaussians), so `fewview demo` and the tests run
//! without any downloaded data.
//!
//! The scene: a checkered ground plane, a textured back wall, two textured spheres, Lambertian
//! shading with hard shadows from one directional light plus ambient light, and (by default, see
//! [`DemoShading`]) a Blinn–Phong highlight of the same light on the spheres and the ground, so
//! that colours change with the viewpoint as they do in real captures. Cameras sit on an arc in
//! front of it, looking at its centre (a forward-facing capture, like LLFF); [`demo_render`]
//! renders the same ground truth for any other camera, e.g. the frames of a camera path.
//!
//! Two conditions of real captures can be switched on ([`DemoOptions::gloss`],
//! [`DemoOptions::jitter`]): a strong highlight and a mirror-like floor, so that colours really
//! change with the viewpoint, and photos whose exposure, white balance and vignetting differ
//! ([`crate::photometric`]), applied to the training photos only (held-out views keep one
//! neutral exposure).

use nalgebra::Vector3;

use crate::camera::{Camera, Intrinsics};
use crate::dataset::{Dataset, View};
use crate::distortion::LensCamera;
use crate::image::Image;
use crate::photometric::{PhotoJitter, jitter_training_photos};

/// Size and views of the demo scene.
#[derive(Clone, Debug, PartialEq)]
pub struct DemoOptions {
    pub width: usize,
    pub height: usize,
    /// Cameras on the arc.
    pub views: usize,
    /// The arc's width relative to the default 50° of azimuth (2: 100°, a wide baseline).
    pub baseline_scale: f64,
    /// Indices of the training views (the rest are held out).
    pub train: Vec<usize>,
    /// Supersampling per pixel axis (anti-aliasing of the ground truth).
    pub supersample: usize,
    /// How surfaces reflect the light: view-independent or with a moving highlight.
    pub shading: DemoShading,
    /// The highlights' strength and the floor's reflectance under [`DemoShading::Specular`].
    pub gloss: DemoGloss,
    /// Per-photo exposure, white balance and vignetting of the training photos.
    pub jitter: PhotoJitter,
}

/// How glossy the demo scene is under [`DemoShading::Specular`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DemoGloss {
    /// Blinn–Phong `(ks, exponent)` of the spheres.
    pub sphere: (f64, f64),
    /// Blinn–Phong `(ks, exponent)` of the ground.
    pub ground: (f64, f64),
    /// Mirror reflectance of the ground in `[0, 1)`: its colour is `(1 − m)·shaded + m·(what the
    /// mirrored ray sees)`, so the reflections of the spheres move over the floor with the
    /// camera.
    pub mirror: f64,
}

impl Default for DemoGloss {
    fn default() -> Self {
        Self {
            sphere: SPHERE_GLOSS,
            ground: GROUND_GLOSS,
            mirror: 0.0,
        }
    }
}

impl DemoGloss {
    /// Checks the values; the message names the setting.
    pub fn validate(&self) -> Result<(), String> {
        for (name, (ks, exponent)) in [("sphere", self.sphere), ("ground", self.ground)] {
            if !(ks.is_finite() && (0.0..=1.0).contains(&ks)) {
                return Err(format!("{name} highlight strength {ks} is not in [0, 1]"));
            }
            if !(exponent.is_finite() && (1.0..=10_000.0).contains(&exponent)) {
                return Err(format!(
                    "{name} highlight exponent {exponent} is not in [1, 10000]"
                ));
            }
        }
        if !(self.mirror.is_finite() && (0.0..1.0).contains(&self.mirror)) {
            return Err(format!(
                "floor mirror reflectance {} is not in [0, 1)",
                self.mirror
            ));
        }
        Ok(())
    }
}

/// The reflectance model of the demo scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DemoShading {
    /// Diffuse only: a surface point has the same colour from every viewpoint.
    Lambertian,
    /// Diffuse plus a white Blinn–Phong highlight of the directional light (where it is not in
    /// shadow): a small highlight on the spheres ([`SPHERE_GLOSS`]) and a broad weak sheen on
    /// the ground ([`GROUND_GLOSS`]); the back wall stays matte. The highlight moves with the
    /// camera, so the colour seen along a camera path is view-dependent, as in real scenes.
    #[default]
    Specular,
}

impl Default for DemoOptions {
    fn default() -> Self {
        Self {
            width: 200,
            height: 150,
            views: 24,
            baseline_scale: 1.0,
            train: vec![2, 11, 21],
            supersample: 3,
            shading: DemoShading::default(),
            gloss: DemoGloss::default(),
            jitter: PhotoJitter::default(),
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
    gloss: DemoGloss,
}

/// Blinn–Phong `(ks, exponent)` of the spheres under [`DemoShading::Specular`]. Kept weak: a
/// highlight slides over the surface between views, so stereo matching it puts points at the
/// wrong depth, and a stronger one (`ks` ≥ 0.15) drops the stereo start's accuracy on this scene
/// (points within 1 % of the true depth) below the 95 % its test requires.
pub const SPHERE_GLOSS: (f64, f64) = (0.1, 60.0);

/// Blinn–Phong `(ks, exponent)` of the ground plane under [`DemoShading::Specular`]: a broad,
/// weak sheen that changes the colour of a large area with the viewpoint.
pub const GROUND_GLOSS: (f64, f64) = (0.12, 8.0);

/// The back wall is the plane y = WALL_Y; ground and wall span |x| ≤ HALF_WIDTH.
const WALL_Y: f64 = 2.5;
const HALF_WIDTH: f64 = 3.5;
const WALL_HEIGHT: f64 = 6.0;
const EPS: f64 = 1e-9;

impl Scene {
    fn new(gloss: DemoGloss) -> Self {
        Self {
            gloss,
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

    /// Blinn–Phong `(ks, exponent)` of a surface; `None` for a matte one.
    fn gloss(&self, s: Surface) -> Option<(f64, f64)> {
        match s {
            Surface::Sphere(_) => Some(self.gloss.sphere),
            Surface::Ground => Some(self.gloss.ground),
            Surface::Wall => None,
        }
    }

    /// Radiance along a ray (shaded albedo, or the sky when nothing is hit), clamped to [0, 1];
    /// under [`DemoShading::Specular`] the ground mixes in what its mirror image of the ray sees.
    fn shade(&self, o: &Vector3<f64>, d: &Vector3<f64>, shading: DemoShading) -> [f64; 3] {
        let local = self.shade_local(o, d, shading);
        let m = self.gloss.mirror;
        if shading == DemoShading::Lambertian || m == 0.0 {
            return local;
        }
        match self.intersect(o, d) {
            Some((t, Surface::Ground)) => {
                let p = o + d * t;
                let mirrored = Vector3::new(d.x, d.y, -d.z);
                let seen = self.shade_local(&(p + Vector3::z() * 1e-6), &mirrored, shading);
                [0, 1, 2].map(|k| (1.0 - m) * local[k] + m * seen[k])
            }
            _ => local,
        }
    }

    /// Radiance along a ray without the floor's mirror image.
    fn shade_local(&self, o: &Vector3<f64>, d: &Vector3<f64>, shading: DemoShading) -> [f64; 3] {
        let Some((t, s)) = self.intersect(o, d) else {
            let h = d.z.clamp(-1.0, 1.0) * 0.5 + 0.5;
            return [0.55 + 0.3 * h, 0.7 + 0.2 * h, 0.95];
        };
        let p = o + d * t;
        let (albedo, n) = self.albedo(&p, s);
        let lit = n.dot(&self.light).max(0.0);
        let shadowed = self.intersect(&(p + n * 1e-6), &self.light).is_some();
        let k = 0.35 + if shadowed { 0.0 } else { 0.65 * lit };
        // The white highlight: the half vector between the light and the direction to the eye.
        let highlight = match (shading, self.gloss(s)) {
            (DemoShading::Specular, Some((ks, exponent))) if !shadowed && lit > 0.0 => {
                let half = (self.light - d).normalize();
                ks * n.dot(&half).max(0.0).powf(exponent)
            }
            _ => 0.0,
        };
        albedo.map(|a| (a * k + highlight).clamp(0.0, 1.0))
    }
}

/// The demo dataset: `views` cameras on an arc, ray-traced images, the chosen training views and
/// the rest held out. Depth bounds come from the rendered depths (for frustum initialisation).
/// With [`DemoOptions::jitter`], the training photos are jittered ([`jitter_training_photos`]).
pub fn demo_dataset(opts: &DemoOptions) -> Dataset {
    let scene = Scene::new(opts.gloss);
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
        let azimuth = (opts.baseline_scale * (-25.0 + 50.0 * s)).to_radians();
        let elevation = (18.0 + 8.0 * (s * std::f64::consts::PI).sin()).to_radians();
        let radius = 4.2;
        let eye = target
            + Vector3::new(
                radius * azimuth.sin() * elevation.cos(),
                -radius * azimuth.cos() * elevation.cos(),
                radius * elevation.sin(),
            );
        let camera = Camera::look_at(intrinsics, eye, target, Vector3::z());
        let (image, near, far) = render_view(&scene, &camera, opts);
        views.push(View {
            name: format!("view_{i:02}"),
            camera,
            image,
            mask: None,
            depth_bounds: Some((near * 0.9, far * 1.1)),
            mask_is_alpha: false,
            valid: None,
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
    let mut ds = Dataset {
        name: "demo".into(),
        views,
        train,
        test,
        points: None,
        background: [0.0; 3],
        to_source_world: None,
    };
    jitter_training_photos(&mut ds, &opts.jitter);
    ds
}

/// The exact z-depth (along the optical axis) of the demo scene through every pixel centre of
/// `camera`, row-major, 0 where the ray meets nothing (sky): the ground truth of depth and
/// stereo tests.
pub fn demo_depth(camera: &Camera) -> Vec<f32> {
    let scene = Scene::new(DemoGloss::default());
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

/// The demo scene seen by any `camera` (its own size and intrinsics), with the supersampling,
/// shading and gloss of `opts` at the neutral exposure (the other fields are unused): the ground
/// truth of novel views, e.g. every frame of a path between the dataset's cameras. For a camera
/// of [`demo_dataset`] with the same options it is that view's image, bit for bit (before the
/// jitter of a training photo).
pub fn demo_render(camera: &Camera, opts: &DemoOptions) -> Image {
    render_view(&Scene::new(opts.gloss), camera, opts).0
}

/// The demo scene photographed through a lens from `camera`'s pose: `lens` gives the
/// intrinsics, the image size and the distortion. Each (supersampled) pixel position is
/// undistorted through the lens ([`LensCamera::undistort_normalized`]) and the pinhole ray
/// through that ideal point is traced, so the image is what a real camera with this lens
/// records. Positions the lens does not map stay black.
pub fn demo_render_through(camera: &Camera, lens: &LensCamera, opts: &DemoOptions) -> Image {
    let k = &lens.intrinsics;
    let ideal = Camera::new(*k, camera.world_to_camera);
    let ray = |u: f64, v: f64| {
        lens.undistort_normalized(u, v)
            .map(|(x, y)| ideal.ray(k.fx * x + k.cx, k.fy * y + k.cy))
    };
    render_rays(&Scene::new(opts.gloss), &ideal, opts, ray).0
}

fn render_view(scene: &Scene, camera: &Camera, opts: &DemoOptions) -> (Image, f64, f64) {
    render_rays(scene, camera, opts, |u, v| Some(camera.ray(u, v)))
}

/// Ray-traced image (box-filtered `ss × ss` samples per pixel, `ss = opts.supersample`, each
/// along `ray(u, v)` of its position; `None` adds black) and the range of hit depths.
fn render_rays(
    scene: &Scene,
    camera: &Camera,
    opts: &DemoOptions,
    ray: impl Fn(f64, f64) -> Option<(Vector3<f64>, Vector3<f64>)>,
) -> (Image, f64, f64) {
    let ss = opts.supersample.max(1);
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
                    let Some((o, d)) = ray(u, v) else {
                        continue;
                    };
                    let c = scene.shade(&o, &d, opts.shading);
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
        let s = Scene::new(DemoGloss::default());
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
            ..DemoOptions::default()
        });
        let cam = &ds.views[1].camera;
        let depth = demo_depth(cam);
        let scene = Scene::new(DemoGloss::default());
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
            ..DemoOptions::default()
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

    /// The colour `camera` sees at the world point `p` (through the ray to `p`'s projection),
    /// after checking that `p` is the first surface along that ray.
    fn colour_of(
        scene: &Scene,
        camera: &Camera,
        p: &Vector3<f64>,
        shading: DemoShading,
    ) -> [f64; 3] {
        let (u, v, _) = camera.project(p).unwrap();
        let (o, d) = camera.ray(u, v);
        let (t, _) = scene.intersect(&o, &d).unwrap();
        assert!(
            (o + d * t - p).norm() < 1e-9,
            "{p:?} is hidden from the camera"
        );
        scene.shade(&o, &d, shading)
    }

    fn max_difference(a: [f64; 3], b: [f64; 3]) -> f64 {
        (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max)
    }

    /// Two cameras far apart on the arc (views 2 and 21 of 24), and a point of the large sphere
    /// where the first camera sees the highlight's peak: its normal is the half vector between
    /// the light and the direction to that camera.
    fn two_cameras_and_a_highlight() -> (Scene, Camera, Camera, Vector3<f64>) {
        let ds = demo_dataset(&DemoOptions {
            width: 40,
            height: 30,
            supersample: 1,
            ..DemoOptions::default()
        });
        let (a, b) = (ds.views[2].camera.clone(), ds.views[21].camera.clone());
        let scene = Scene::new(DemoGloss::default());
        let sphere = &scene.spheres[0];
        let n = (scene.light + (a.center() - sphere.center).normalize()).normalize();
        let p = sphere.center + n * sphere.radius;
        (scene, a, b, p)
    }

    #[test]
    fn lambertian_colour_does_not_depend_on_the_camera() {
        let (scene, a, b, on_sphere) = two_cameras_and_a_highlight();
        let on_wall = Vector3::new(1.5, WALL_Y, 1.5);
        let on_ground = Vector3::new(1.9, -0.6, 0.0);
        for p in [on_wall, on_ground, on_sphere] {
            let ca = colour_of(&scene, &a, &p, DemoShading::Lambertian);
            let cb = colour_of(&scene, &b, &p, DemoShading::Lambertian);
            assert!(max_difference(ca, cb) < 1e-9, "{p:?}: {ca:?} vs {cb:?}");
        }
    }

    #[test]
    fn specular_highlight_moves_with_the_camera_but_not_on_the_wall() {
        let (scene, a, b, on_sphere) = two_cameras_and_a_highlight();
        let spec_a = colour_of(&scene, &a, &on_sphere, DemoShading::Specular);
        let spec_b = colour_of(&scene, &b, &on_sphere, DemoShading::Specular);
        let matte = colour_of(&scene, &a, &on_sphere, DemoShading::Lambertian);
        // Camera a sees nearly the highlight's peak `ks` (the normal is aimed from the sphere's
        // centre, not from the point); camera b, 50° away on the arc, sees almost none of it.
        let ks = SPHERE_GLOSS.0;
        let gain_a = (0..3).map(|k| spec_a[k] - matte[k]).fold(0.0, f64::max);
        assert!(
            gain_a > 0.9 * ks && gain_a <= ks,
            "{spec_a:?} vs matte {matte:?}"
        );
        let change = max_difference(spec_a, spec_b);
        assert!(change > 0.8 * ks, "{spec_a:?} vs {spec_b:?}");
        eprintln!("sphere point: {spec_a:?} from a, {spec_b:?} from b, matte {matte:?}");
        // The matte wall looks the same from both cameras, and as without the highlight.
        let on_wall = Vector3::new(1.5, WALL_Y, 1.5);
        let wa = colour_of(&scene, &a, &on_wall, DemoShading::Specular);
        let wb = colour_of(&scene, &b, &on_wall, DemoShading::Specular);
        assert!(max_difference(wa, wb) < 1e-9, "{wa:?} vs {wb:?}");
        assert_eq!(wa, colour_of(&scene, &a, &on_wall, DemoShading::Lambertian));
    }

    #[test]
    fn demo_render_of_a_dataset_camera_is_the_dataset_image() {
        let opts = DemoOptions {
            width: 40,
            height: 30,
            views: 5,
            train: vec![0, 4],
            supersample: 2,
            ..DemoOptions::default()
        };
        let ds = demo_dataset(&opts);
        for v in [&ds.views[1], &ds.views[4]] {
            assert_eq!(demo_render(&v.camera, &opts), v.image, "{}", v.name);
        }
        // The default is view-dependent: it differs from the Lambertian render somewhere.
        let matte = demo_render(
            &ds.views[1].camera,
            &DemoOptions {
                shading: DemoShading::Lambertian,
                ..opts.clone()
            },
        );
        assert_ne!(matte, ds.views[1].image);
        // A camera between two views (not a dataset camera) renders too.
        let mid = ds.views[1].camera.interpolate(&ds.views[2].camera, 0.5);
        let img = demo_render(&mid, &opts);
        assert_eq!((img.width, img.height, img.channels), (40, 30, 3));
    }

    #[test]
    fn a_mirror_floor_reflects_the_spheres_and_changes_with_the_viewpoint() {
        let mirror = Scene::new(DemoGloss {
            mirror: 0.5,
            ..DemoGloss::default()
        });
        let plain = Scene::new(DemoGloss::default());
        let (_, a, b, _) = two_cameras_and_a_highlight();
        // A floor point in front of the large sphere: the mirrored ray from camera a meets it.
        let sphere = &plain.spheres[0];
        let eye = a.center();
        // Where the ray from the eye to the sphere's centre's mirror image crosses the floor.
        let image = Vector3::new(sphere.center.x, sphere.center.y, -sphere.center.z);
        let s = eye.z / (eye.z - image.z);
        let p = eye + (image - eye) * s;
        let d = (p - eye).normalize();
        let reflected = mirror.shade(&eye, &d, DemoShading::Specular);
        let matte = plain.shade(&eye, &d, DemoShading::Specular);
        let seen = plain.shade(
            &(p + Vector3::z() * 1e-6),
            &Vector3::new(d.x, d.y, -d.z),
            DemoShading::Specular,
        );
        for k in 0..3 {
            assert!((reflected[k] - (0.5 * matte[k] + 0.5 * seen[k])).abs() < 1e-12);
        }
        assert!(
            max_difference(reflected, matte) > 0.05,
            "{reflected:?} {matte:?}"
        );
        // Without the highlight model the floor is matte.
        assert_eq!(
            mirror.shade(&eye, &d, DemoShading::Lambertian),
            plain.shade(&eye, &d, DemoShading::Lambertian)
        );
        // The same floor point seen from camera b reflects something else.
        let from_b = mirror.shade(
            &b.center(),
            &(p - b.center()).normalize(),
            DemoShading::Specular,
        );
        let matte_b = plain.shade(
            &b.center(),
            &(p - b.center()).normalize(),
            DemoShading::Specular,
        );
        assert!(max_difference(from_b, matte_b) > 1e-3);
        assert!(max_difference(from_b, reflected) > 0.05);
    }

    #[test]
    fn jitter_touches_only_the_training_photos() {
        let opts = DemoOptions {
            width: 32,
            height: 24,
            views: 4,
            train: vec![1, 3],
            supersample: 1,
            jitter: PhotoJitter {
                exposure_ev: 0.5,
                white_balance: 0.05,
                vignetting: 0.2,
                seed: 3,
            },
            ..DemoOptions::default()
        };
        let ds = demo_dataset(&opts);
        for (i, v) in ds.views.iter().enumerate() {
            let neutral = demo_render(&v.camera, &opts);
            if opts.train.contains(&i) {
                assert_eq!(v.image, opts.jitter.gain(i).apply(&neutral), "{}", v.name);
                assert_ne!(v.image, neutral);
            } else {
                assert_eq!(v.image, neutral, "{}", v.name);
            }
        }
    }
}
