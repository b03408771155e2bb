//! Triangle rasterisation into a pinhole camera with a z-buffer (the fusion paper, supplement §1, §4).
//!
//! Reprojects meshes built from rendered depth maps ([`crate::depth::depth_to_mesh`]) into a
//! virtual camera, carrying per-vertex attributes (colours, source pixel positions, ...).
//!
//! **Sampling.** Pixel `(x, y)` is sampled at its centre `(x + 0.5, y + 0.5)`, the convention of
//! [`crate::depth`], so a depth mesh rasterised into its own camera has every vertex exactly on
//! its pixel centre. Depth is z-depth (camera z, along the optical axis).
//!
//! **Coverage.** Projected vertices are snapped to 1/256 px (8 sub-pixel bits, as GPUs do) and
//! the edge functions are evaluated exactly in integers. A pixel centre exactly on an edge
//! belongs to the triangle for which that edge is a top or left edge (the top-left rule of
//! Direct3D), so on a mesh every pixel centre is drawn exactly once: no cracks along shared
//! edges and no double draws, also where a centre falls on a shared vertex. Both windings are
//! drawn (no back-face culling).
//!
//! **Interpolation.** Barycentrics come from the same exact edge values, so they are never
//! negative and interpolated values stay within the triangle's; they are those of the snapped
//! triangle, off by at most the snapping (1/512 px per coordinate). Depth and attributes are
//! perspective-correct: 1/z and a/z are interpolated linearly in screen space.
//!
//! **Visibility.** The nearest surface wins (largest 1/z); equal depths go to the smaller
//! triangle index, so the result does not depend on the order of processing.
//!
//! **Limits.** There is no clipping: a triangle with a vertex at camera z ≤ `near`, or with a
//! vertex projecting further than [`GUARD_BAND`] pixels from the image origin (only possible
//! just in front of the camera plane), is skipped whole. Triangles of zero area after snapping
//! are skipped.
//!
//! **Parallelism.** Triangles are binned by bands of [`BAND_ROWS`] image rows and the bands are
//! drawn in parallel (rayon), each owning its rows of the z-buffer, so the result is the same for
//! any number of threads.

use std::ops::Range;

use fewview_scene::Camera;
use rayon::prelude::*;

use crate::error::{GeomError, Result};
use crate::mesh::{Mesh, v3};

/// Sub-pixel precision of the snapped vertex positions: 1/256 px.
const SUBPIXEL_BITS: u32 = 8;
const ONE: i64 = 1 << SUBPIXEL_BITS;
const HALF: i64 = ONE / 2;

/// Vertices projecting further than this many pixels from the image origin skip their
/// triangles: it keeps the exact integer edge functions within `i64` (coordinates below 2²⁹
/// sub-pixel units, products below 2⁶¹).
pub const GUARD_BAND: f64 = (1u64 << 21) as f64;

/// Image rows per band, the unit of parallel work; small enough that a 300-row image gives
/// dozens of bands to balance over the threads.
pub const BAND_ROWS: usize = 8;

/// "No triangle" in [`Rasterized::triangle`].
const NONE: u32 = u32::MAX;

/// What a rasterisation produced, per pixel of the camera (row-major, width × height).
#[derive(Clone, Debug, PartialEq)]
pub struct Rasterized {
    pub width: usize,
    pub height: usize,
    /// z-depth (camera z) of the nearest surface through the pixel centre; 0 where none.
    pub depth: Vec<f32>,
    /// Perspective-correct interpolated vertex attributes, `channels` per pixel; 0 where none.
    pub attributes: Vec<f32>,
    pub channels: usize,
    /// Index of the visible triangle, `u32::MAX` where none.
    pub triangle: Vec<u32>,
}

impl Rasterized {
    /// Whether a triangle covers pixel `pixel` (row-major index; false beyond the image).
    pub fn covered(&self, pixel: usize) -> bool {
        self.triangle.get(pixel).is_some_and(|&t| t != NONE)
    }

    /// [`Rasterized::covered`] for every pixel, row-major.
    pub fn coverage(&self) -> Vec<bool> {
        self.triangle.iter().map(|&t| t != NONE).collect()
    }
}

/// Rasterises `triangles` (indices into `vertices`, world coordinates) into `camera` (world to
/// camera pose, +z forward, pinhole intrinsics, image y down), sampling at pixel centres
/// `(x + 0.5, y + 0.5)`; the nearest surface wins (z-buffer, ties to the smaller triangle
/// index). `attributes` holds `channels` values per vertex (`vertices.len() * channels`), and
/// they are interpolated perspective-correctly.
///
/// No clipping: triangles with a vertex at camera z ≤ `near` are skipped whole (as are those
/// reaching beyond [`GUARD_BAND`] and zero-area ones). Both windings are drawn. Pixel centres on
/// shared edges are drawn once (top-left rule; see the module docs).
///
/// Errors, naming the argument: a non-finite camera, `near` not finite or negative, an
/// attribute buffer of the wrong length, a vertex index out of range, a NaN or infinite vertex
/// coordinate or attribute.
pub fn rasterize(
    vertices: &[[f32; 3]],
    triangles: &[[u32; 3]],
    attributes: &[f32],
    channels: usize,
    camera: &Camera,
    near: f32,
) -> Result<Rasterized> {
    check_inputs(vertices, triangles, attributes, channels, camera, near)?;
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let projected = project(vertices, camera, near as f64);
    let setups: Vec<Option<Setup>> = triangles
        .par_iter()
        .map(|t| Setup::new(t, &projected, w, h))
        .collect();
    let mut out = Rasterized {
        width: w,
        height: h,
        depth: vec![0.0; w * h],
        attributes: vec![0.0; w * h * channels],
        channels,
        triangle: vec![NONE; w * h],
    };
    if w * h == 0 {
        return Ok(out);
    }
    let bins = bin(&setups, h.div_ceil(BAND_ROWS));
    let mesh = MeshRef {
        setups: &setups,
        attributes,
        channels,
    };
    bands(&mut out)
        .into_par_iter()
        .zip(bins)
        .for_each(|(band, bin)| draw_band(&mesh, &bin, band));
    Ok(out)
}

/// A mesh's z-depth through every pixel centre of `camera`, 0 where it shows no surface
/// ([`rasterize`] without attributes).
pub fn mesh_depth(mesh: &Mesh, camera: &Camera, near: f32) -> Result<Vec<f32>> {
    Ok(rasterize(&mesh.vertices, &mesh.faces, &[], 0, camera, near)?.depth)
}

/// [`rasterize`] with a mesh's vertex colours as the 3 attributes (an error if it has none).
pub fn rasterize_mesh_colors(mesh: &Mesh, camera: &Camera, near: f32) -> Result<Rasterized> {
    let colors = mesh
        .colors
        .as_ref()
        .ok_or_else(|| GeomError::invalid("mesh", "has no vertex colours to rasterise"))?;
    if colors.len() != mesh.vertices.len() {
        return Err(GeomError::invalid(
            "mesh colors",
            format!(
                "{} colours for {} vertices",
                colors.len(),
                mesh.vertices.len()
            ),
        ));
    }
    rasterize(
        &mesh.vertices,
        &mesh.faces,
        colors.as_flattened(),
        3,
        camera,
        near,
    )
}

/// Refuses input that would make the result meaningless or the indexing panic.
fn check_inputs(
    vertices: &[[f32; 3]],
    triangles: &[[u32; 3]],
    attributes: &[f32],
    channels: usize,
    camera: &Camera,
    near: f32,
) -> Result<()> {
    if !camera.is_finite() {
        return Err(GeomError::invalid(
            "camera",
            "non-finite or non-positive intrinsics/pose",
        ));
    }
    if !(near >= 0.0 && near.is_finite()) {
        return Err(GeomError::invalid(
            "near",
            format!("{near} (must be finite and ≥ 0)"),
        ));
    }
    check_attributes(vertices.len(), attributes, channels)?;
    if triangles.len() >= NONE as usize {
        return Err(GeomError::invalid(
            "triangles",
            format!("{} triangles (at most {})", triangles.len(), NONE - 1),
        ));
    }
    if let Some(i) = vertices
        .iter()
        .position(|v| !v.iter().all(|c| c.is_finite()))
    {
        return Err(GeomError::invalid(
            "vertices",
            format!("vertex {i} is {:?} (NaN/inf)", vertices[i]),
        ));
    }
    let n = vertices.len();
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(&v) = tri.iter().find(|&&v| v as usize >= n) {
            return Err(GeomError::invalid(
                "triangles",
                format!("triangle {t} refers to vertex {v}, but there are {n} vertices"),
            ));
        }
    }
    Ok(())
}

/// The attribute buffer must hold `channels` finite values per vertex.
fn check_attributes(vertices: usize, attributes: &[f32], channels: usize) -> Result<()> {
    if vertices.checked_mul(channels) != Some(attributes.len()) {
        return Err(GeomError::invalid(
            "attributes",
            format!(
                "{} values for {vertices} vertices × {channels} channels (expected {})",
                attributes.len(),
                vertices.saturating_mul(channels)
            ),
        ));
    }
    if let Some(k) = attributes.iter().position(|a| !a.is_finite()) {
        return Err(GeomError::invalid(
            "attributes",
            format!(
                "vertex {} channel {} is {} (NaN/inf)",
                k / channels,
                k % channels,
                attributes[k]
            ),
        ));
    }
    Ok(())
}

/// A vertex in screen space: snapped position in 1/256 px and 1/z.
#[derive(Clone, Copy, Debug)]
struct Projected {
    x: i64,
    y: i64,
    inv_z: f64,
}

/// Projects every vertex once (f64); `None` at camera z ≤ `near` or beyond the guard band.
fn project(vertices: &[[f32; 3]], camera: &Camera, near: f64) -> Vec<Option<Projected>> {
    let k = camera.intrinsics;
    let pose = camera.world_to_camera;
    vertices
        .par_iter()
        .map(|v| {
            let p = pose.transform_point(&v3(v));
            if !(p.z > near) {
                return None;
            }
            let (u, w) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
            let inv_z = 1.0 / p.z;
            let inside = u.abs() < GUARD_BAND && w.abs() < GUARD_BAND && inv_z.is_finite();
            inside.then(|| Projected {
                x: (u * ONE as f64).round() as i64,
                y: (w * ONE as f64).round() as i64,
                inv_z,
            })
        })
        .collect()
}

/// Twice the signed area of `(a, b, c)` in sub-pixel units²: `(b − a) × (c − a)`, positive
/// when the triangle is clockwise on screen (image y points down).
fn cross(a: &Projected, b: &Projected, c: &Projected) -> i64 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

/// The edge function of the directed edge `a → b`, `E(p) = (b − a) × (p − a)`, positive on the
/// inner side of a clockwise triangle.
#[derive(Clone, Copy, Debug)]
struct Edge {
    ax: i64,
    ay: i64,
    dx: i64,
    dy: i64,
    /// 0 when the edge owns the centres on it (top or left edge), −1 when it does not, so
    /// that `E + bias ≥ 0` is the inside test with the tie rule built in.
    bias: i64,
}

impl Edge {
    fn new(a: &Projected, b: &Projected) -> Self {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        // Clockwise on screen, a left edge runs up (dy < 0) and a top edge runs right.
        let top_left = dy < 0 || (dy == 0 && dx > 0);
        Self {
            ax: a.x,
            ay: a.y,
            dx,
            dy,
            bias: if top_left { 0 } else { -1 },
        }
    }

    fn at(&self, px: i64, py: i64) -> i64 {
        self.dx * (py - self.ay) - self.dy * (px - self.ax)
    }
}

/// A triangle ready to draw: clockwise corners and the pixels its bounding box covers.
#[derive(Clone, Debug)]
struct Setup {
    /// Vertex indices, reordered to be clockwise on screen.
    corners: [u32; 3],
    points: [Projected; 3],
    /// Twice the snapped area (> 0).
    area: i64,
    /// Inclusive pixel ranges of the bounding box, clamped to the image.
    x: (usize, usize),
    y: (usize, usize),
}

impl Setup {
    /// `None` for triangles that are skipped (a vertex not projected, zero area, off-image).
    fn new(tri: &[u32; 3], projected: &[Option<Projected>], w: usize, h: usize) -> Option<Self> {
        let mut corners = *tri;
        let [a, b, c] = corners.map(|c| projected[c as usize]);
        let mut points = [a?, b?, c?];
        let mut area = cross(&points[0], &points[1], &points[2]);
        if area == 0 {
            return None;
        }
        if area < 0 {
            corners.swap(1, 2);
            points.swap(1, 2);
            area = -area;
        }
        let x = pixel_range(points.map(|p| p.x), w)?;
        let y = pixel_range(points.map(|p| p.y), h)?;
        Some(Self {
            corners,
            points,
            area,
            x,
            y,
        })
    }

    /// Edge `i` is the one opposite corner `i`, so its function is corner `i`'s weight.
    fn edges(&self) -> [Edge; 3] {
        let p = &self.points;
        [
            Edge::new(&p[1], &p[2]),
            Edge::new(&p[2], &p[0]),
            Edge::new(&p[0], &p[1]),
        ]
    }

    /// Perspective weights `λᵢ / zᵢ` from the edge values `e` (λ = e / area) and their sum 1/z.
    fn weights(&self, e: [i64; 3]) -> ([f64; 3], f64) {
        let a = self.area as f64;
        let w: [f64; 3] = std::array::from_fn(|i| e[i] as f64 / a * self.points[i].inv_z);
        (w, w[0] + w[1] + w[2])
    }
}

/// The pixels whose centres `n + 0.5` lie within the sub-pixel coordinates `c`, clamped to
/// `0..size`; `None` when empty.
fn pixel_range(c: [i64; 3], size: usize) -> Option<(usize, usize)> {
    let (lo, hi) = (c.iter().min()?, c.iter().max()?);
    let first = (lo - HALF + ONE - 1).div_euclid(ONE).max(0);
    let last = (hi - HALF).div_euclid(ONE).min(size as i64 - 1);
    (first <= last).then_some((first as usize, last as usize))
}

/// Calls `f(x, y, e)` for every pixel of `rows` whose centre the triangle covers (tie rule
/// included), with `e` the three exact edge values there.
fn for_each_fragment(s: &Setup, rows: Range<usize>, mut f: impl FnMut(usize, usize, [i64; 3])) {
    let edges = s.edges();
    let step = edges.map(|g| -g.dy * ONE);
    let px0 = ONE * s.x.0 as i64 + HALF;
    for y in s.y.0.max(rows.start)..(s.y.1 + 1).min(rows.end) {
        let py = ONE * y as i64 + HALF;
        let mut e = edges.map(|g| g.at(px0, py) + g.bias);
        for x in s.x.0..=s.x.1 {
            if (e[0] | e[1] | e[2]) >= 0 {
                f(x, y, std::array::from_fn(|i| e[i] - edges[i].bias));
            }
            for i in 0..3 {
                e[i] += step[i];
            }
        }
    }
}

/// The triangles with what their pixels need: setups (`None`: skipped) and attributes.
struct MeshRef<'a> {
    setups: &'a [Option<Setup>],
    attributes: &'a [f32],
    channels: usize,
}

/// The rows `row0..` of the output that one parallel task owns.
struct Band<'a> {
    row0: usize,
    width: usize,
    depth: &'a mut [f32],
    /// Holds the winning triangle index.
    triangle: &'a mut [u32],
    attributes: &'a mut [f32],
}

/// Splits the output into bands of [`BAND_ROWS`] rows.
fn bands(out: &mut Rasterized) -> Vec<Band<'_>> {
    let (w, ch) = (out.width, out.channels);
    let (mut depth, mut triangle) = (&mut out.depth[..], &mut out.triangle[..]);
    let mut attributes = &mut out.attributes[..];
    let mut bands = Vec::new();
    for row0 in (0..out.height).step_by(BAND_ROWS) {
        let n = BAND_ROWS.min(out.height - row0) * w;
        let (d, rest_d) = std::mem::take(&mut depth).split_at_mut(n);
        let (t, rest_t) = std::mem::take(&mut triangle).split_at_mut(n);
        let (a, rest_a) = std::mem::take(&mut attributes).split_at_mut(n * ch);
        (depth, triangle, attributes) = (rest_d, rest_t, rest_a);
        bands.push(Band {
            row0,
            width: w,
            depth: d,
            triangle: t,
            attributes: a,
        });
    }
    bands
}

/// The triangles overlapping each band of [`BAND_ROWS`] rows, in increasing order.
fn bin(setups: &[Option<Setup>], bands: usize) -> Vec<Vec<u32>> {
    let mut bins = vec![Vec::new(); bands];
    for (i, s) in setups.iter().enumerate() {
        if let Some(t) = s {
            for b in &mut bins[t.y.0 / BAND_ROWS..=t.y.1 / BAND_ROWS] {
                b.push(i as u32);
            }
        }
    }
    bins
}

/// Draws the triangles of `bin` into `band` (z-buffer on 1/z), then fills in depth and
/// attributes of the winners. Nearer wins, then the smaller index: a total order, so the order
/// of drawing does not matter.
fn draw_band(mesh: &MeshRef, bin: &[u32], band: Band) {
    let w = band.width;
    let rows = band.row0..band.row0 + band.depth.len() / w;
    let mut inv_z = vec![0.0f64; band.depth.len()];
    let winner = band.triangle;
    for &i in bin {
        let Some(t) = &mesh.setups[i as usize] else {
            continue;
        };
        for_each_fragment(t, rows.clone(), |x, y, e| {
            let z = t.weights(e).1;
            let p = (y - band.row0) * w + x;
            if z > inv_z[p] || (z == inv_z[p] && i < winner[p]) {
                inv_z[p] = z;
                winner[p] = i;
            }
        });
    }
    for (p, &i) in winner.iter().enumerate() {
        if let Some(Some(t)) = mesh.setups.get(i as usize) {
            band.depth[p] = (1.0 / inv_z[p]) as f32;
            let ch = mesh.channels;
            let (x, y) = (p % w, band.row0 + p / w);
            interpolate(t, mesh, x, y, &mut band.attributes[p * ch..(p + 1) * ch]);
        }
    }
}

/// Perspective-correct attributes of triangle `t` at the centre of pixel `(x, y)`.
fn interpolate(t: &Setup, mesh: &MeshRef, x: usize, y: usize, out: &mut [f32]) {
    if out.is_empty() {
        return;
    }
    let (px, py) = (ONE * x as i64 + HALF, ONE * y as i64 + HALF);
    let (wt, sum) = t.weights(t.edges().map(|g| g.at(px, py)));
    let ch = mesh.channels;
    for (c, v) in out.iter_mut().enumerate() {
        let a: f64 = (0..3)
            .map(|i| wt[i] * mesh.attributes[t.corners[i] as usize * ch + c] as f64)
            .sum();
        *v = (a / sum) as f32;
    }
}

/// How often each pixel is drawn by any triangle (no depth test), to check the tie rule.
#[cfg(test)]
fn fragment_counts(
    vertices: &[[f32; 3]],
    triangles: &[[u32; 3]],
    camera: &Camera,
) -> Result<Vec<u32>> {
    check_inputs(vertices, triangles, &[], 0, camera, 0.0)?;
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let projected = project(vertices, camera, 0.0);
    let mut counts = vec![0; w * h];
    for tri in triangles {
        if let Some(s) = Setup::new(tri, &projected, w, h) {
            for_each_fragment(&s, 0..h, |x, y, _| counts[y * w + x] += 1);
        }
    }
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{raster_problem, turned_camera};
    use crate::depth::depth_to_mesh;
    use fewview_scene::{Image, Intrinsics, Se3};
    use nalgebra::{Matrix3, Vector3};

    /// A camera at the origin looking along +z with focal length `f`, centred principal point.
    fn straight_camera(w: u32, h: u32, f: f64) -> Camera {
        Camera::new(Intrinsics::centered(f, w, h), Se3::identity())
    }

    /// The world point that `straight_camera` sees at pixel coordinates `(u, v)` and depth `z`.
    fn at_pixel(cam: &Camera, u: f64, v: f64, z: f64) -> [f32; 3] {
        let k = cam.intrinsics;
        [
            ((u - k.cx) / k.fx * z) as f32,
            ((v - k.cy) / k.fy * z) as f32,
            z as f32,
        ]
    }

    /// Whether `p` lies inside triangle `t` (screen space, any winding) by more than `margin`.
    fn inside(t: [[f64; 2]; 3], p: [f64; 2], margin: f64) -> bool {
        let side = |a: [f64; 2], b: [f64; 2]| {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            (dx * (p[1] - a[1]) - dy * (p[0] - a[0])) / dx.hypot(dy)
        };
        let s = [side(t[0], t[1]), side(t[1], t[2]), side(t[2], t[0])];
        s.iter().all(|&d| d > margin) || s.iter().all(|&d| d < -margin)
    }

    #[test]
    fn raster_depth_mesh_into_its_own_camera_reproduces_depth_and_colour() {
        let (w, h) = (80, 60);
        let p = raster_problem(w, h).unwrap();
        let r = rasterize_mesh_colors(&p.mesh, &p.camera, 0.0).unwrap();
        let (mut max_depth, mut max_colour) = (0.0f64, 0.0f64);
        // With τ = 0 every pixel is a vertex, so every pixel off the border has its whole 3×3
        // neighbourhood in the mesh and its centre on a vertex.
        for j in 1..h - 1 {
            for i in 1..w - 1 {
                let n = j * w + i;
                assert!(r.covered(n), "pixel ({i}, {j}) not drawn");
                let d = p.depth[n] as f64;
                max_depth = max_depth.max((r.depth[n] as f64 - d).abs() / d);
                for c in 0..3 {
                    let e = r.attributes[n * 3 + c] - p.image.get(i, j, c);
                    max_colour = max_colour.max(e.abs() as f64);
                }
            }
        }
        println!("own camera: max relative depth error {max_depth:.2e}, colour {max_colour:.2e}");
        assert!(max_depth < 1e-4 && max_colour < 1e-4);
        assert!(p.depth.iter().any(|&d| d < 2.5), "the sphere is in view");
    }

    /// A plane `n · X = d` (world), its exact depth map in `cam`, and pixel coordinates as colour.
    fn plane_view(cam: &Camera, n: Vector3<f64>, d: f64) -> (Vec<f32>, Image) {
        let (w, h) = (cam.width() as usize, cam.height() as usize);
        let mut depth = vec![0.0; w * h];
        let mut image = Image::new(w, h, 3);
        for j in 0..h {
            for i in 0..w {
                let (u, v) = (i as f64 + 0.5, j as f64 + 0.5);
                let (o, dir) = cam.ray(u, v);
                let x = o + dir * ((d - n.dot(&o)) / n.dot(&dir));
                depth[j * w + i] = cam.world_to_camera.transform_point(&x).z as f32;
                image.set(i, j, 0, u as f32);
                image.set(i, j, 1, v as f32);
            }
        }
        (depth, image)
    }

    #[test]
    fn raster_plane_reprojection_matches_the_homography() {
        let ka = Intrinsics::centered(70.0, 96, 72);
        let kb = Intrinsics {
            fx: 80.0,
            fy: 78.0,
            cx: 45.0,
            cy: 37.0,
            width: 90,
            height: 70,
        };
        let a = turned_camera(ka, [0.05, -0.03, 0.02], Vector3::new(0.1, -0.2, -1.0));
        let b = turned_camera(kb, [-0.04, 0.14, 0.06], Vector3::new(0.45, -0.1, -0.8));
        let n = Vector3::new(0.2, -0.1, 1.0).normalize();
        let d = n.dot(&Vector3::new(0.0, 0.0, 2.0));
        let (depth, image) = plane_view(&a, n, d);
        let mesh = depth_to_mesh(&depth, &a, Some(&image), 0.0).unwrap();
        let r = rasterize_mesh_colors(&mesh, &b, 0.0).unwrap();
        // X_a = R X_b + t for camera-b points; on the plane n_b · X_b = d_b, so
        // X_a = (R + t n_bᵀ / d_b) X_b (the textbook R − t nᵀ/d with nᵀX + d = 0).
        let (pa, pb) = (a.world_to_camera, b.world_to_camera);
        let rot = pa.rotation * pb.rotation.transpose();
        let t = pa.translation - rot * pb.translation;
        let nb = pb.rotation * n;
        let db = d + nb.dot(&pb.translation);
        let kb_inv = kb.matrix().try_inverse().unwrap();
        let hom: Matrix3<f64> = ka.matrix() * (rot + t * nb.transpose() / db) * kb_inv;
        let (mut max_px, mut max_depth, mut covered) = (0.0f64, 0.0f64, 0);
        for y in 0..70 {
            for x in 0..90 {
                let p = Vector3::new(x as f64 + 0.5, y as f64 + 0.5, 1.0);
                let q = hom * p;
                let (u, v) = (q.x / q.z, q.y / q.z);
                let z = db / nb.dot(&(kb_inv * p));
                let i = y * 90 + x;
                let inner = |c: f64, size: f64, m: f64| c > 0.5 + m && c < size - 0.5 - m;
                if inner(u, 96.0, 0.02) && inner(v, 72.0, 0.02) {
                    assert!(r.covered(i), "hole at ({x}, {y})");
                } else if !inner(u, 96.0, -0.02) || !inner(v, 72.0, -0.02) {
                    assert!(!r.covered(i), "({x}, {y}) drawn outside the mesh");
                }
                if !r.covered(i) {
                    continue;
                }
                covered += 1;
                let at = &r.attributes[i * 3..i * 3 + 3];
                max_px = max_px.max((at[0] as f64 - u).hypot(at[1] as f64 - v));
                max_depth = max_depth.max((r.depth[i] as f64 - z).abs() / z);
                assert_eq!(at[2], 0.0);
            }
        }
        println!(
            "homography: {covered} pixels, max error {max_px:.2e} px, relative depth {max_depth:.2e}"
        );
        assert!(covered > 90 * 70 / 2);
        assert!(max_px < 0.5 && max_depth < 1e-4);
        assert!(
            max_px < 0.01,
            "expected about the 1/512 px snapping, got {max_px}"
        );
    }

    /// A triangle of `cam` at screen positions `uv`, each at its depth `z`.
    fn screen_triangle(cam: &Camera, uv: [[f64; 2]; 3], z: [f64; 3]) -> Vec<[f32; 3]> {
        (0..3)
            .map(|i| at_pixel(cam, uv[i][0], uv[i][1], z[i]))
            .collect()
    }

    #[test]
    fn raster_nearer_triangle_wins_in_either_order_and_ties_go_to_the_smaller_index() {
        let cam = straight_camera(32, 32, 50.0);
        let near_uv = [[2.0, 2.0], [30.0, 3.0], [5.0, 30.0]];
        let far_uv = [[1.0, 1.0], [31.0, 1.3], [16.0, 31.0]];
        let near = screen_triangle(&cam, near_uv, [2.0; 3]);
        let far = screen_triangle(&cam, far_uv, [3.0; 3]);
        for near_first in [true, false] {
            let (first, second) = if near_first {
                (&near, &far)
            } else {
                (&far, &near)
            };
            let vertices: Vec<[f32; 3]> = first.iter().chain(second).copied().collect();
            let attr: Vec<f32> = [1.0, 1.0, 1.0, 2.0, 2.0, 2.0].to_vec();
            let attr = if near_first {
                attr
            } else {
                attr.into_iter().rev().collect()
            };
            let r = rasterize(&vertices, &[[0, 1, 2], [3, 4, 5]], &attr, 1, &cam, 0.1).unwrap();
            let near_index = if near_first { 0 } else { 1 };
            let mut both = 0;
            for y in 0..32 {
                for x in 0..32 {
                    let (p, i) = ([x as f64 + 0.5, y as f64 + 0.5], y * 32 + x);
                    if inside(near_uv, p, 0.01) {
                        both += inside(far_uv, p, 0.01) as usize;
                        assert_eq!(r.triangle[i], near_index);
                        assert!((r.depth[i] - 2.0).abs() < 1e-6 && r.attributes[i] == 1.0);
                    } else if inside(far_uv, p, 0.01) {
                        assert_eq!(r.triangle[i], 1 - near_index);
                        assert!((r.depth[i] - 3.0).abs() < 1e-6 && r.attributes[i] == 2.0);
                    }
                }
            }
            // Centre (17.5, 16.5) lies exactly on the near triangle's lower right edge, which
            // does not own it: it shows the far triangle.
            assert_eq!(r.triangle[16 * 32 + 17], 1 - near_index);
            assert!(both > 200, "the triangles overlap on {both} pixels");
        }
        // The same triangle twice at the same depth: the smaller index wins, in either order.
        let tri = screen_triangle(&cam, near_uv, [2.0, 2.5, 3.0]);
        let r = rasterize(&tri, &[[0, 1, 2], [0, 2, 1]], &[], 0, &cam, 0.1).unwrap();
        assert!(r.triangle.iter().all(|&t| t == 0 || t == NONE));
        assert!(r.coverage().iter().filter(|&&c| c).count() > 200);
    }

    #[test]
    fn raster_interpolation_is_perspective_correct() {
        let cam = straight_camera(64, 64, 100.0);
        let uv = [[4.5, 4.5], [36.5, 4.5], [4.5, 36.5]];
        let z = [1.0, 4.0, 2.0];
        let vertices = screen_triangle(&cam, uv, z);
        // The attribute is corner 1's barycentric weight in 3D.
        let r = rasterize(&vertices, &[[0, 1, 2]], &[0.0, 1.0, 0.0], 1, &cam, 0.1).unwrap();
        // Pixel (20, 12) has centre 0.25·V0 + 0.5·V1 + 0.25·V2 on screen, so
        // 1/z = 0.25/1 + 0.5/4 + 0.25/2 = 0.5 and a = (0.5 · 1/4) · z = 0.25 (affine: z = 2.75,
        // a = 0.5).
        let i = 12 * 64 + 20;
        assert!((r.depth[i] - 2.0).abs() < 1e-5, "{}", r.depth[i]);
        assert!((r.attributes[i] - 0.25).abs() < 1e-5, "{}", r.attributes[i]);
        // Every covered pixel against the ray-plane intersection in 3D.
        let v: Vec<Vector3<f64>> = vertices.iter().map(v3).collect();
        let normal = (v[1] - v[0]).cross(&(v[2] - v[0]));
        let (mut max_err, mut max_affine) = (0.0f64, 0.0f64);
        for (p, &t) in r.triangle.iter().enumerate() {
            if t == NONE {
                continue;
            }
            let (u, w) = ((p % 64) as f64 + 0.5, (p / 64) as f64 + 0.5);
            let ray = Vector3::new((u - 32.0) / 100.0, (w - 32.0) / 100.0, 1.0);
            let x = ray * (normal.dot(&v[0]) / normal.dot(&ray));
            let weight1 = (v[2] - v[0]).cross(&(x - v[0])).norm() / normal.norm();
            max_err = max_err.max((r.attributes[p] as f64 - weight1).abs());
            max_err = max_err.max((r.depth[p] as f64 - x.z).abs() / x.z);
            let affine1 = (u - 4.5) / 32.0;
            max_affine = max_affine.max((affine1 - weight1).abs());
        }
        println!("perspective: max error {max_err:.2e}, affine would be off by {max_affine:.2}");
        assert!(max_err < 1e-5 && max_affine > 0.2);
    }

    #[test]
    fn raster_skips_triangles_reaching_the_near_plane() {
        let cam = straight_camera(16, 16, 20.0);
        let mut vertices = screen_triangle(&cam, [[1.0, 1.0], [15.0, 1.0], [1.0, 15.0]], [1.0; 3]);
        let r = rasterize(&vertices, &[[0, 1, 2]], &[], 0, &cam, 0.5).unwrap();
        assert!(r.coverage().iter().any(|&c| c));
        vertices[2][2] = 0.4;
        let r = rasterize(&vertices, &[[0, 1, 2]], &[], 0, &cam, 0.5).unwrap();
        assert!(r.coverage().iter().all(|&c| !c) && r.depth.iter().all(|&d| d == 0.0));
        vertices[2][2] = -1.0; // behind the camera
        let r = rasterize(&vertices, &[[0, 1, 2]], &[], 0, &cam, 0.0).unwrap();
        assert!(r.coverage().iter().all(|&c| !c));
        // An empty image is an empty result.
        for (w, h) in [(0, 16), (16, 0)] {
            let mut empty = cam.clone();
            (empty.intrinsics.width, empty.intrinsics.height) = (w, h);
            let r = rasterize(&vertices, &[[0, 1, 2]], &[0.0; 6], 2, &empty, 0.0);
            assert!(r.unwrap().depth.is_empty());
        }
    }

    /// A deterministic pseudo-random number in [0, 1).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A grid mesh over screen positions `xs × ys` (at depths varying with position), cells split
    /// along alternating diagonals, every third triangle with its winding reversed.
    fn grid_mesh(cam: &Camera, xs: &[f64], ys: &[f64]) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let mut vertices = Vec::new();
        for &y in ys {
            for &x in xs {
                vertices.push(at_pixel(cam, x, y, 1.0 + 0.01 * (x + 2.0 * y)));
            }
        }
        let nx = xs.len() as u32;
        let mut faces = Vec::new();
        for j in 0..ys.len() as u32 - 1 {
            for i in 0..nx - 1 {
                let (a, b, c, d) = (
                    j * nx + i,
                    j * nx + i + 1,
                    (j + 1) * nx + i,
                    (j + 1) * nx + i + 1,
                );
                let tris = if (i + j) % 2 == 0 {
                    [[a, c, b], [b, c, d]]
                } else {
                    [[a, c, d], [a, d, b]]
                };
                faces.extend(tris);
            }
        }
        for (n, f) in faces.iter_mut().enumerate() {
            if n % 3 == 0 {
                f.swap(1, 2);
            }
        }
        (vertices, faces)
    }

    #[test]
    fn raster_shared_edges_draw_every_pixel_centre_exactly_once() {
        let cam = straight_camera(48, 40, 40.0);
        // Every vertex on a pixel centre: edges and vertices lie on centres (all ties).
        let xs: Vec<f64> = (0..13).map(|i| 4.5 + 3.0 * i as f64).collect();
        let ys: Vec<f64> = (0..9).map(|j| 3.5 + 4.0 * j as f64).collect();
        let (vertices, faces) = grid_mesh(&cam, &xs, &ys);
        let counts = fragment_counts(&vertices, &faces, &cam).unwrap();
        for (p, &c) in counts.iter().enumerate() {
            let (x, y) = ((p % 48) as f64 + 0.5, (p / 48) as f64 + 0.5);
            let strictly_inside = x > 4.5 && x < 40.5 && y > 3.5 && y < 35.5;
            let outside = !(4.5..=40.5).contains(&x) || !(3.5..=35.5).contains(&y);
            assert!(c <= 1, "pixel ({x}, {y}) drawn {c} times");
            assert!(!strictly_inside || c == 1, "crack at ({x}, {y})");
            assert!(!outside || c == 0);
        }
        // Generic positions: a rectangle whose border misses every centre, jittered inside.
        let mut state = 7;
        let mut xs: Vec<f64> = (0..10).map(|i| 3.3 + 4.6 * i as f64).collect();
        let ys: Vec<f64> = (0..8).map(|j| 2.2 + 5.1 * j as f64).collect();
        xs[9] = 44.7;
        let (mut vertices, faces) = grid_mesh(&cam, &xs, &ys);
        for j in 1..7 {
            for i in 1..9 {
                let v = &mut vertices[j * 10 + i];
                let z = v[2] as f64;
                let (u, w) = (
                    xs[i] + 3.0 * (lcg(&mut state) - 0.5),
                    ys[j] + 3.0 * (lcg(&mut state) - 0.5),
                );
                *v = at_pixel(&cam, u, w, z);
            }
        }
        let counts = fragment_counts(&vertices, &faces, &cam).unwrap();
        let raster = rasterize(&vertices, &faces, &[], 0, &cam, 0.0).unwrap();
        for (p, &c) in counts.iter().enumerate() {
            let (x, y) = ((p % 48) as f64 + 0.5, (p / 48) as f64 + 0.5);
            let want = (x > 3.3 && x < 44.7 && y > 2.2 && y < 37.9) as u32;
            assert_eq!(c, want, "pixel ({x}, {y})");
            assert_eq!(raster.covered(p), want == 1);
        }
    }

    #[test]
    fn raster_quad_of_two_triangles_covers_its_area_without_cracks() {
        let cam = straight_camera(64, 64, 60.0);
        let quad = [[6.3, 20.1], [40.7, 3.9], [58.2, 41.6], [17.9, 60.4]];
        let vertices: Vec<[f32; 3]> = quad
            .iter()
            .map(|q| at_pixel(&cam, q[0], q[1], 2.0))
            .collect();
        let faces = [[0, 1, 2], [0, 3, 2]];
        let r = rasterize(&vertices, &faces, &[], 0, &cam, 0.0).unwrap();
        let counts = fragment_counts(&vertices, &faces, &cam).unwrap();
        let mut analytic = 0;
        for p in 0..64 * 64 {
            let c = [(p % 64) as f64 + 0.5, (p / 64) as f64 + 0.5];
            let want = inside([quad[0], quad[1], quad[2]], c, 0.0)
                || inside([quad[0], quad[2], quad[3]], c, 0.0)
                || diagonal_hit(quad[0], quad[2], c);
            analytic += want as usize;
            assert_eq!(r.covered(p), want, "pixel {c:?}");
            assert_eq!(counts[p], want as u32, "pixel {c:?}");
        }
        // Twice the shoelace area, for a sanity check on the count.
        let area = 0.5
            * (0..4)
                .map(|i| {
                    let (a, b) = (quad[i], quad[(i + 1) % 4]);
                    a[0] * b[1] - b[0] * a[1]
                })
                .sum::<f64>();
        println!("quad: {analytic} pixels, area {area:.1}");
        assert!((analytic as f64 - area).abs() < 0.1 * area);
    }

    /// Whether `p` lies on the segment `a–b` (within 1e-9 px).
    fn diagonal_hit(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let cross = dx * (p[1] - a[1]) - dy * (p[0] - a[0]);
        let t = (dx * (p[0] - a[0]) + dy * (p[1] - a[1])) / (dx * dx + dy * dy);
        cross.abs() < 1e-9 && (0.0..=1.0).contains(&t)
    }

    #[test]
    fn raster_result_is_independent_of_thread_count() {
        let p = raster_problem(96, 72).unwrap();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| rasterize_mesh_colors(&p.mesh, &p.virtual_camera, 0.0).unwrap())
        };
        let one = run(1);
        assert!(one.coverage().iter().filter(|&&c| c).count() > 96 * 72 / 2);
        for threads in [2, 3, 8] {
            assert_eq!(run(threads), one, "{threads} threads");
        }
        // Every face twice: exact depth ties everywhere, always won by the first copy.
        let mut doubled = p.mesh.clone();
        doubled.faces.extend(p.mesh.faces.clone());
        let twice = rasterize_mesh_colors(&doubled, &p.virtual_camera, 0.0).unwrap();
        assert_eq!(twice, one);
    }

    #[test]
    fn raster_rejects_bad_input_naming_the_problem() {
        let cam = straight_camera(8, 8, 10.0);
        let v = [[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0]];
        let err = |r: Result<Rasterized>| r.unwrap_err().to_string();
        let e = err(rasterize(&v, &[[0, 1, 2], [0, 7, 2]], &[], 0, &cam, 0.0));
        assert!(
            e.contains("triangle 1 refers to vertex 7") && e.contains("3 vertices"),
            "{e}"
        );
        let e = err(rasterize(&v, &[[0, 1, 2]], &[0.0; 5], 2, &cam, 0.0));
        assert!(
            e.contains("attributes: 5 values for 3 vertices × 2 channels (expected 6)"),
            "{e}"
        );
        let e = err(rasterize(
            &v,
            &[[0, 1, 2]],
            &[0.0, f32::NAN, 0.0],
            1,
            &cam,
            0.0,
        ));
        assert!(e.contains("vertex 1 channel 0 is NaN"), "{e}");
        let mut bad = v;
        bad[2][1] = f32::INFINITY;
        let e = err(rasterize(&bad, &[[0, 1, 2]], &[], 0, &cam, 0.0));
        assert!(e.contains("vertex 2") && e.contains("NaN/inf"), "{e}");
        let e = err(rasterize(&v, &[[0, 1, 2]], &[], 0, &cam, -1.0));
        assert!(e.starts_with("near: -1"), "{e}");
        let mesh = Mesh {
            vertices: v.to_vec(),
            faces: vec![[0, 1, 2]],
            ..Default::default()
        };
        let e = err(rasterize_mesh_colors(&mesh, &cam, 0.0));
        assert!(e.contains("no vertex colours"), "{e}");
    }
}
