//! An analytic test scene: a textured solid defined by a signed distance function, rendered by
//! sphere tracing (an independent path: no volume rendering, no learned field), with exact
//! masks, so surface reconstruction can be scored against the true surface.
//!
//! The solid is a torus (major radius 0.45, minor 0.16) smoothly joined (polynomial smooth
//! minimum, k = 0.12) with a sphere of radius 0.3 raised above its hole; it lies well inside the
//! unit sphere. Its albedo is coloured 3D fractal value noise (a random texture for matching);
//! shading is Lambertian under a directional key light from above, a weaker fill light from the
//! opposite direction below, and ambient light, so colours do not depend on the viewing
//! direction. The background is black. Cameras sit on a ring around the object at distance 3,
//! alternating elevation (30°, 15°), looking at the origin (world z up); further rings
//! ([`Ring`], e.g. [`SdfSceneOptions::ring_of_eight_all_around`]) add views from the side and
//! from below.

use fewview_geom::Points;
use fewview_scene::{Camera, Dataset, Image, Intrinsics, View};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Size and views of the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SdfSceneOptions {
    pub width: usize,
    pub height: usize,
    /// Cameras on the ring (elevation alternating 30° and 15°).
    pub views: usize,
    /// Further rings of cameras (numbered after the first ring's, in order); the first ring
    /// sees nothing of the underside.
    pub extra_rings: Vec<Ring>,
    /// Training views (the rest are test views).
    pub train: Vec<usize>,
    /// Supersampling per pixel axis.
    pub supersample: usize,
    /// Camera distance from the origin.
    pub distance: f64,
    /// Horizontal field of view, degrees.
    pub fov_deg: f64,
}

impl Default for SdfSceneOptions {
    fn default() -> Self {
        Self {
            width: 160,
            height: 120,
            views: 12,
            extra_rings: Vec::new(),
            train: vec![0, 2, 4, 6, 8, 10],
            supersample: 2,
            distance: 3.0,
            fov_deg: 34.0,
        }
    }
}

impl SdfSceneOptions {
    /// The scene of `fewview surface --synthetic`: 16 views at 320 × 240 (field of view 30°),
    /// the eight at 30° elevation, 45° apart, for training.
    pub fn ring_of_eight() -> Self {
        Self {
            width: 320,
            height: 240,
            views: 16,
            train: vec![0, 2, 4, 6, 8, 10, 12, 14],
            supersample: 2,
            fov_deg: 30.0,
            ..Default::default()
        }
    }

    /// [`Self::ring_of_eight`] plus two rings of eight training views, at 0° elevation
    /// (staggered by 22.5°, views 16–23) and at −30° (under the first ring's training views,
    /// views 24–31), so that every part of the surface is seen by some training view and every
    /// view has neighbours at most 45° away (`fewview surface --synthetic --synthetic-all-around`).
    /// Neighbouring views are 37–45° apart, as on the first ring, where the matcher works.
    pub fn ring_of_eight_all_around() -> Self {
        let ring = Self::ring_of_eight();
        let extra_rings = vec![
            Ring {
                views: 8,
                elevation_deg: 0.0,
                offset: 0.5,
            },
            Ring {
                views: 8,
                elevation_deg: -30.0,
                offset: 0.0,
            },
        ];
        let mut train = ring.train.clone();
        train.extend(ring.views..ring.views + 16);
        Self {
            extra_rings,
            train,
            ..ring
        }
    }

    /// Cameras in all rings.
    pub fn total_views(&self) -> usize {
        self.views + self.extra_rings.iter().map(|r| r.views).sum::<usize>()
    }
}

/// A ring of training cameras at one elevation, evenly spaced in azimuth.
#[derive(Clone, Debug, PartialEq)]
pub struct Ring {
    pub views: usize,
    /// Degrees above (negative: below) the object's equator.
    pub elevation_deg: f64,
    /// Azimuth of the first camera (from the x axis) as a fraction of this ring's spacing.
    pub offset: f64,
}

const TORUS_MAJOR: f64 = 0.45;
const TORUS_MINOR: f64 = 0.16;
const BALL_RADIUS: f64 = 0.3;
const BALL_CENTER_Z: f64 = 0.12;
const SMOOTH_K: f64 = 0.12;

/// Polynomial smooth minimum (Quílez): a conservative bound of the union's distance.
fn smin(a: f64, b: f64, k: f64) -> f64 {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b * (1.0 - h) + a * h - k * h * (1.0 - h)
}

/// The scene's signed distance (negative inside).
pub fn sdf(p: &Vector3<f64>) -> f64 {
    let q = ((p.x * p.x + p.y * p.y).sqrt() - TORUS_MAJOR, p.z);
    let torus = (q.0 * q.0 + q.1 * q.1).sqrt() - TORUS_MINOR;
    let ball = (p - Vector3::new(0.0, 0.0, BALL_CENTER_Z)).norm() - BALL_RADIUS;
    smin(torus, ball, SMOOTH_K)
}

/// Gradient of [`sdf`] by central differences (unit length away from the blend).
pub fn sdf_normal(p: &Vector3<f64>) -> Vector3<f64> {
    let h = 1e-6;
    let d = |a: usize| {
        let mut e = Vector3::zeros();
        e[a] = h;
        (sdf(&(p + e)) - sdf(&(p - e))) / (2.0 * h)
    };
    Vector3::new(d(0), d(1), d(2)).normalize()
}

/// A lattice hash in `[0, 1)`: the coordinates and salt folded in one at a time, each fold
/// followed by a full 64-bit avalanche (SplitMix64's finaliser). Folding them all in with one
/// XOR made `(x, −y, −z)` hash almost as `(x, y, z)` (two's complement: `−a = !a + 1`), so the
/// texture nearly repeated under a half turn about the x axis, and views from below matched
/// half-turned views from above with correlation 0.9–1.0.
fn hash3(x: i64, y: i64, z: i64, salt: u64) -> f64 {
    fn avalanche(mut h: u64) -> u64 {
        h ^= h >> 30;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 27;
        h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^ (h >> 31)
    }
    let mut h = avalanche(salt.wrapping_add(0x9E37_79B9_7F4A_7C15));
    for c in [x, y, z] {
        h = avalanche(h ^ (c as u64).wrapping_add(0x9E37_79B9_7F4A_7C15));
    }
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Value noise: smooth (quintic) interpolation of lattice hashes.
fn value_noise(p: &Vector3<f64>, salt: u64) -> f64 {
    let f = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (ix, iy, iz) = (p.x.floor(), p.y.floor(), p.z.floor());
    let (fx, fy, fz) = (f(p.x - ix), f(p.y - iy), f(p.z - iz));
    let (ix, iy, iz) = (ix as i64, iy as i64, iz as i64);
    let mut acc = 0.0;
    for c in 0..8 {
        let (dx, dy, dz) = ((c & 1) as i64, ((c >> 1) & 1) as i64, ((c >> 2) & 1) as i64);
        let w = (if dx == 1 { fx } else { 1.0 - fx })
            * (if dy == 1 { fy } else { 1.0 - fy })
            * (if dz == 1 { fz } else { 1.0 - fz });
        acc += w * hash3(ix + dx, iy + dy, iz + dz, salt);
    }
    acc
}

/// Fractal sum of value noise, four octaves from `freq`, in about `[0, 1]`.
fn fbm(p: &Vector3<f64>, freq: f64, salt: u64) -> f64 {
    let (mut sum, mut amp, mut norm, mut f) = (0.0, 1.0, 0.0, freq);
    for o in 0..4 {
        sum += amp * value_noise(&(p * f), salt + o);
        norm += amp;
        amp *= 0.5;
        f *= 2.0;
    }
    sum / norm
}

/// The albedo at a surface point: coloured fractal noise (a random, non-repeating texture, so
/// that feature matching has something to hold on to).
pub fn albedo(p: &Vector3<f64>) -> [f64; 3] {
    // Crisp random blobs: a smooth step across the median of the noise.
    let t = ((fbm(p, 10.0, 1) - 0.42) / 0.16).clamp(0.0, 1.0);
    let l = 0.2 + 0.8 * t * t * (3.0 - 2.0 * t);
    let c = [fbm(p, 4.0, 11), fbm(p, 4.0, 23), fbm(p, 4.0, 37)];
    [
        l * (0.25 + 0.9 * c[0]).min(1.0),
        l * (0.25 + 0.9 * c[1]).min(1.0),
        l * (0.25 + 0.9 * c[2]).min(1.0),
    ]
}

fn light() -> Vector3<f64> {
    Vector3::new(0.4, -0.5, 0.75).normalize()
}

/// Sphere-traces one ray (unit `d`); the hit distance, if any.
pub fn trace(o: &Vector3<f64>, d: &Vector3<f64>) -> Option<f64> {
    // Start where the ray enters the unit sphere.
    let b = o.dot(d);
    let c = o.dot(o) - 1.0;
    let disc = b * b - c;
    if disc <= 0.0 {
        return None;
    }
    let (t0, t1) = (-b - disc.sqrt(), -b + disc.sqrt());
    let mut t = t0.max(0.0);
    for _ in 0..512 {
        let dist = sdf(&(o + d * t));
        if dist < 1e-7 {
            return Some(t);
        }
        t += dist;
        if t > t1 {
            return None;
        }
    }
    None
}

/// Colour and coverage (0/1) of one ray.
fn shade(o: &Vector3<f64>, d: &Vector3<f64>) -> ([f64; 3], f64) {
    match trace(o, d) {
        None => ([0.0; 3], 0.0),
        Some(t) => {
            let p = o + d * t;
            let n = sdf_normal(&p);
            // Key light from above and a weaker fill from the opposite side, below: no face is
            // lit by ambient light alone, so the underside keeps its texture's contrast.
            let key = n.dot(&light()).max(0.0);
            let fill = (-n.dot(&light())).max(0.0);
            let a = albedo(&p);
            let s = 0.3 + 0.6 * key + 0.4 * fill;
            ([a[0] * s, a[1] * s, a[2] * s], 1.0)
        }
    }
}

/// The cameras: the first ring's, then each further ring's in order.
pub fn cameras(opts: &SdfSceneOptions) -> Vec<Camera> {
    let focal = 0.5 * opts.width as f64 / (0.5 * opts.fov_deg.to_radians()).tan();
    let k = Intrinsics::centered(focal, opts.width as u32, opts.height as u32);
    let ring = (0..opts.views).map(|i| {
        let az = i as f64 / opts.views as f64;
        let el = if i % 2 == 0 { 30f64 } else { 15f64 };
        (az, el)
    });
    let extra = opts.extra_rings.iter().flat_map(|r| {
        (0..r.views).map(move |j| ((j as f64 + r.offset) / r.views as f64, r.elevation_deg))
    });
    ring.chain(extra)
        .map(|(turns, el_deg)| {
            let az = turns * std::f64::consts::TAU;
            let el = el_deg.to_radians();
            let eye =
                Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()) * opts.distance;
            Camera::look_at(k, eye, Vector3::zeros(), Vector3::new(0.0, 0.0, 1.0))
        })
        .collect()
}

/// Renders one view: RGB image and mask (coverage ≥ 0.5).
pub fn render_view(camera: &Camera, supersample: usize) -> (Image, Image) {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let ss = supersample.max(1);
    let rows: Vec<(Vec<f32>, Vec<f32>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut rgb = vec![0.0f32; w * 3];
            let mut mask = vec![0.0f32; w];
            for x in 0..w {
                let mut acc = [0.0f64; 3];
                let mut cov = 0.0;
                for sy in 0..ss {
                    for sx in 0..ss {
                        let u = x as f64 + (sx as f64 + 0.5) / ss as f64;
                        let v = y as f64 + (sy as f64 + 0.5) / ss as f64;
                        let (o, d) = camera.ray(u, v);
                        let (c, a) = shade(&o, &d);
                        for k in 0..3 {
                            acc[k] += c[k];
                        }
                        cov += a;
                    }
                }
                let n = (ss * ss) as f64;
                for k in 0..3 {
                    rgb[x * 3 + k] = (acc[k] / n) as f32;
                }
                mask[x] = if cov / n >= 0.5 { 1.0 } else { 0.0 };
            }
            (rgb, mask)
        })
        .collect();
    let mut img = Vec::with_capacity(w * h * 3);
    let mut msk = Vec::with_capacity(w * h);
    for (r, m) in rows {
        img.extend(r);
        msk.extend(m);
    }
    (Image::from_vec(w, h, 3, img), Image::from_vec(w, h, 1, msk))
}

/// The scene as a dataset (exact poses; perturb them with [`crate::pose::perturb_poses`]).
pub fn sdf_dataset(opts: &SdfSceneOptions) -> Dataset {
    let cams = cameras(opts);
    let views = cams
        .par_iter()
        .enumerate()
        .map(|(i, c)| {
            let (image, mask) = render_view(c, opts.supersample);
            View {
                name: format!("sdf_{i:03}"),
                camera: c.clone(),
                image,
                mask: Some(mask),
                depth_bounds: None,
                mask_is_alpha: false,
                valid: None,
                source_index: i,
            }
        })
        .collect();
    let test = (0..opts.total_views())
        .filter(|i| !opts.train.contains(i))
        .collect();
    Dataset {
        name: "sdf-scene".into(),
        views,
        train: opts.train.clone(),
        test,
        points: None,
        background: [0.0; 3],
        to_source_world: None,
    }
}

/// Points on the true surface: a grid of `resolution³` cells, each sign-changing cell's centre
/// projected onto the zero set by Newton steps `p ← p − s(p) ∇s(p)`.
pub fn surface_points(resolution: usize) -> Points {
    let lo = -0.8;
    let step = 1.6 / resolution as f64;
    let pts: Vec<[f32; 3]> = (0..resolution)
        .into_par_iter()
        .flat_map_iter(|i| {
            let mut out = Vec::new();
            for j in 0..resolution {
                for k in 0..resolution {
                    let c = Vector3::new(
                        lo + (i as f64 + 0.5) * step,
                        lo + (j as f64 + 0.5) * step,
                        lo + (k as f64 + 0.5) * step,
                    );
                    if sdf(&c).abs() > step * 0.87 {
                        continue;
                    }
                    let mut p = c;
                    for _ in 0..8 {
                        p -= sdf_normal(&p) * sdf(&p);
                    }
                    if sdf(&p).abs() < 1e-6 && (p - c).norm() < step {
                        out.push([p.x as f32, p.y as f32, p.z as f32]);
                    }
                }
            }
            out
        })
        .collect();
    Points::from_positions(pts)
}

/// The true surface as a mesh: marching cubes of [`sdf`] on `resolution³` samples over
/// `[−0.8, 0.8]³` (vertex error O(voxel²) of the curvature, ~10⁻⁵ at 256).
pub fn surface_mesh(resolution: usize) -> fewview_geom::Result<fewview_geom::Mesh> {
    fewview_geom::mcubes::marching_cubes_chunked(
        |p: &[[f64; 3]]| {
            p.iter()
                .map(|q| sdf(&Vector3::new(q[0], q[1], q[2])) as f32)
                .collect()
        },
        ([-0.8; 3], [0.8; 3]),
        [resolution; 3],
        32,
        0.0,
    )
}

/// Whether `camera` sees the surface point `p`: it projects inside the image and a ray from
/// the camera centre towards it first meets the surface at `p` (within `1e-3`, much less than
/// the scene's features).
pub fn sees(camera: &Camera, p: &Vector3<f64>) -> bool {
    let Some((u, v, _)) = camera.project(p) else {
        return false;
    };
    if !(0.0..camera.width() as f64).contains(&u) || !(0.0..camera.height() as f64).contains(&v) {
        return false;
    }
    let o = camera.center();
    let to_p = p - o;
    let dist = to_p.norm();
    trace(&o, &(to_p / dist)).is_some_and(|t| t > dist - 1e-3)
}

/// For each face of `mesh` (a mesh of the true surface, e.g. [`surface_mesh`]): whether one of
/// `cameras` sees its centroid. Feeds [`fewview_geom::chamfer::surface_metrics_observed`], so
/// that the analytic scene is scored, like DTU, on the part of the surface the views show.
pub fn observed_faces(mesh: &fewview_geom::Mesh, cameras: &[Camera]) -> Vec<bool> {
    mesh.faces
        .par_iter()
        .map(|f| {
            let c = f
                .iter()
                .map(|&i| {
                    let v = mesh.vertices[i as usize];
                    Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)
                })
                .sum::<Vector3<f64>>()
                / 3.0;
            // Nudge the centroid (inside a convex patch) onto the zero set before testing.
            let on = c - sdf(&c) * sdf_normal(&c);
            cameras.iter().any(|cam| sees(cam, &on))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_tracing_lands_on_the_zero_set() {
        let opts = SdfSceneOptions::default();
        let cam = &cameras(&opts)[1];
        let mut hits = 0;
        for (u, v) in [(80.0, 60.0), (70.0, 50.0), (95.0, 66.0), (5.0, 5.0)] {
            let (o, d) = cam.ray(u, v);
            if let Some(t) = trace(&o, &d) {
                assert!(sdf(&(o + d * t)).abs() < 1e-6);
                hits += 1;
            }
        }
        assert_eq!(hits, 3, "the centre rays hit, the corner ray misses");
    }

    #[test]
    fn renders_have_texture_and_masks() {
        let opts = SdfSceneOptions {
            width: 64,
            height: 48,
            views: 2,
            train: vec![0],
            supersample: 1,
            ..Default::default()
        };
        let ds = sdf_dataset(&opts);
        let v = &ds.views[0];
        let m = v.mask.as_ref().unwrap();
        let fg = m.data.iter().filter(|x| **x > 0.5).count();
        assert!(fg > 300 && fg < 64 * 48 / 2, "{fg} foreground pixels");
        // Background pixels are black, foreground ones vary.
        let mut fg_values = Vec::new();
        for p in 0..64 * 48 {
            if m.data[p] < 0.5 {
                assert_eq!(&v.image.data[p * 3..p * 3 + 3], &[0.0, 0.0, 0.0]);
            } else {
                fg_values.push(v.image.data[p * 3]);
            }
        }
        let mean = fg_values.iter().sum::<f32>() / fg_values.len() as f32;
        let var =
            fg_values.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / fg_values.len() as f32;
        assert!(var > 0.005, "texture variance {var}");
        assert_eq!(ds.test, vec![1]);
    }

    #[test]
    fn surface_points_are_on_the_surface_and_cover_it() {
        let pts = surface_points(64);
        assert!(pts.len() > 3000, "{}", pts.len());
        for p in &pts.positions {
            let v = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            assert!(sdf(&v).abs() < 1e-5);
        }
        // Extent: the torus reaches |x| = 0.61, the ball z = 0.42.
        let max_x = pts.positions.iter().map(|p| p[0]).fold(f32::MIN, f32::max);
        let max_z = pts.positions.iter().map(|p| p[2]).fold(f32::MIN, f32::max);
        assert!((max_x - 0.61).abs() < 0.02, "{max_x}");
        assert!((max_z - 0.42).abs() < 0.03, "{max_z}");
    }

    /// The texture does not repeat under the half turn about the x axis, `(x, y, z) → (x, −y,
    /// −z)`, which maps the views from above onto views from below (the old one-XOR lattice
    /// hash nearly did: correlation 0.9–1.0 between such views), nor under the others.
    #[test]
    fn texture_has_no_half_turn_symmetry() {
        let mut rng_state = 7u64;
        let mut next = || {
            rng_state = rng_state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (rng_state >> 11) as f64 / (1u64 << 53) as f64 * 1.6 - 0.8
        };
        // Sign flips of the axes: the three half turns and the point reflection.
        let flips = [
            Vector3::new(1.0, -1.0, -1.0),
            Vector3::new(-1.0, 1.0, -1.0),
            Vector3::new(-1.0, -1.0, 1.0),
            Vector3::new(-1.0, -1.0, -1.0),
        ];
        for flip in flips {
            let (mut same, mut apart) = (0.0, 0.0);
            for _ in 0..2000 {
                let p = Vector3::new(next(), next(), next());
                let q = Vector3::new(next(), next(), next());
                same += (fbm(&p, 10.0, 1) - fbm(&p.component_mul(&flip), 10.0, 1)).abs();
                apart += (fbm(&p, 10.0, 1) - fbm(&q, 10.0, 1)).abs();
            }
            assert!(
                same > 0.8 * apart,
                "mirrored {same:.1} against random {apart:.1}"
            );
        }
    }

    /// The all-around layout's training views see every part of the true surface (the ring of
    /// eight alone misses the underside).
    #[test]
    fn all_around_views_see_the_whole_surface() {
        let mesh = surface_mesh(48).unwrap();
        let seen_fraction = |opts: &SdfSceneOptions| {
            let cams = cameras(opts);
            let train: Vec<Camera> = opts.train.iter().map(|&i| cams[i].clone()).collect();
            let flags = observed_faces(&mesh, &train);
            flags.iter().filter(|&&f| f).count() as f64 / flags.len() as f64
        };
        let around = SdfSceneOptions::ring_of_eight_all_around();
        assert_eq!(around.total_views(), 32);
        assert_eq!(around.train.len(), 24);
        let ring = seen_fraction(&SdfSceneOptions::ring_of_eight());
        let all = seen_fraction(&around);
        assert!(ring < 0.8, "ring of eight sees {ring:.3}");
        assert!(all > 0.99, "all around sees {all:.3}");
    }

    /// Seen from straight above, the top of the ball is visible and the bottom of the torus is
    /// not; a point behind the camera or outside the image is not; and the face flags of the
    /// true mesh follow: the top cap observed, the bottom cap not.
    #[test]
    fn visibility_from_above() {
        let k = Intrinsics::centered(200.0, 160, 120);
        let above = Camera::look_at(
            k,
            Vector3::new(0.0, 0.0, 3.0),
            Vector3::zeros(),
            Vector3::new(0.0, 1.0, 0.0),
        );
        let top = Vector3::new(0.0, 0.0, BALL_CENTER_Z + BALL_RADIUS);
        assert!(sdf(&top).abs() < 1e-9);
        assert!(sees(&above, &top));
        let underside = Vector3::new(TORUS_MAJOR, 0.0, -TORUS_MINOR);
        assert!(sdf(&underside).abs() < 1e-9);
        assert!(!sees(&above, &underside));
        let below = Camera::look_at(
            k,
            Vector3::new(0.0, 0.0, -3.0),
            Vector3::zeros(),
            Vector3::new(0.0, 1.0, 0.0),
        );
        assert!(sees(&below, &underside));
        assert!(!sees(&below, &top));
        let aside = Camera::look_at(
            k,
            Vector3::new(3.0, 0.0, 0.0),
            Vector3::new(3.0, 5.0, 0.0),
            Vector3::new(0.0, 0.0, 1.0),
        );
        assert!(!sees(&aside, &top));
        let mesh = surface_mesh(48).unwrap();
        let flags = observed_faces(&mesh, std::slice::from_ref(&above));
        let z_of =
            |f: &[u32; 3]| f.iter().map(|&i| mesh.vertices[i as usize][2]).sum::<f32>() / 3.0;
        let (mut top_seen, mut top_all, mut bottom_seen) = (0, 0, 0);
        for (f, &seen) in mesh.faces.iter().zip(&flags) {
            if z_of(f) > 0.35 {
                top_all += 1;
                top_seen += seen as usize;
            }
            if z_of(f) < -0.1 {
                bottom_seen += seen as usize;
            }
        }
        assert!(
            top_all > 0 && top_seen == top_all,
            "{top_seen} of {top_all}"
        );
        assert_eq!(bottom_seen, 0);
    }
}
