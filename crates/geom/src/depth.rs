//! Depth maps to meshes and point clouds (the fusion paper §1–2).
//!
//! Every pixel `(i, j)` is back-projected through its centre `(i + 0.5, j + 0.5)` at its z-depth
//! (distance along the optical axis, as rasterizers render it). Pixels at *depth edges* are
//! dropped with the test of Eq. (1), and the mesh connects each pixel with its right and lower
//! neighbours (two triangles per 2×2 block) when all three corners survive.
//!
//! **Our reading of Eq. (1).** The paper writes
//! `(D − ∇ₓD) × (D − ∇ᵧD) / ‖D‖² < τ_depth` with `∇ₓD`, `∇ᵧD` "the depth values of the
//! neighbouring pixel one step along x and y", and calls it "the area of the meshed triangle".
//! Taken as a product of two scalars, the test cannot see an edge that runs along a pixel axis
//! (one of the two factors is zero there), so it would leave exactly the bridging triangles the
//! paper wants gone. We therefore read `×` as the cross product of the two triangle edges in
//! 3D: with `X`, `Xₓ`, `Xᵧ` the back-projected points of the pixel and its two neighbours,
//! `A = ‖(X − Xₓ) × (X − Xᵧ)‖ / D²` — twice the triangle's area over the squared depth, which is
//! scale-free — and keep pixels with `A < τ` ([`EdgeTest::TriangleArea`], the default). On a
//! surface facing the camera `A ≈ 1/(fₓ f_y)`, growing as `1/cos θ` with the slant, and a
//! jump of relative size `δ = ΔD/D` gives `A ≈ δ/f`; so τ = 1e-4 drops jumps above about
//! `f·10⁻⁴` (5 % at f = 500 px). τ must exceed `1/(fₓ f_y)`, i.e. `fₓ f_y > 10⁴` for the
//! default τ. The literal scalar product is available as [`EdgeTest::DepthProduct`].
//!
//! **τ ≤ 0 turns the test off** (every pixel with a positive depth is kept), so τ = 0 gives the
//! unfiltered mesh with its bridging triangles.
//!
//! At the last column/row the backward neighbour stands in for the missing forward one; a
//! neighbour without depth is replaced by a point at the pixel's own depth (flat in that
//! direction). Depth `≤ 0` means "no depth" and is skipped; NaN or infinite depth is an error.

use fewview_scene::{Camera, Image};
use nalgebra::Vector3;

use crate::error::{GeomError, Result};
use crate::mesh::{Mesh, Points};

/// The paper's τ_depth (the fusion paper §1).
pub const TAU_DEPTH: f32 = 1e-4;

/// Which quantity Eq. (1) thresholds (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum EdgeTest {
    /// `‖(X − Xₓ) × (X − Xᵧ)‖ / D²` with back-projected 3D points (default).
    #[default]
    #[cfg_attr(feature = "cli", value(name = "area"))]
    TriangleArea,
    /// The literal scalar reading `(D − Dₓ)(D − Dᵧ) / D²` (misses axis-aligned edges).
    #[cfg_attr(feature = "cli", value(name = "product"))]
    DepthProduct,
}

/// Options of the depth-edge filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthOptions {
    /// τ_depth of Eq. (1); `≤ 0` disables the filter.
    pub tau: f32,
    pub test: EdgeTest,
}

impl Default for DepthOptions {
    fn default() -> Self {
        Self {
            tau: TAU_DEPTH,
            test: EdgeTest::TriangleArea,
        }
    }
}

fn check_inputs(depth: &[f32], camera: &Camera, colors: Option<&Image>) -> Result<(usize, usize)> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    if !camera.is_finite() {
        return Err(GeomError::invalid(
            "camera",
            "non-finite or non-positive intrinsics/pose",
        ));
    }
    if depth.len() != w * h {
        return Err(GeomError::invalid(
            "depth",
            format!("{} values for a {w}×{h} camera", depth.len()),
        ));
    }
    if let Some(i) = depth.iter().position(|d| !d.is_finite()) {
        return Err(GeomError::invalid(
            "depth",
            format!(
                "pixel ({}, {}) is {} (NaN/inf depth)",
                i % w,
                i / w,
                depth[i]
            ),
        ));
    }
    if let Some(img) = colors {
        if img.width != w || img.height != h {
            return Err(GeomError::invalid(
                "colors",
                format!(
                    "image is {}×{} but the depth map is {w}×{h}",
                    img.width, img.height
                ),
            ));
        }
        if !matches!(img.channels, 1 | 3 | 4) {
            return Err(GeomError::invalid(
                "colors",
                format!("{} channels (expected 1, 3 or 4)", img.channels),
            ));
        }
    }
    Ok((w, h))
}

/// Back-projection in camera coordinates of pixel `(i, j)`'s centre at z-depth `z`.
#[inline]
fn cam_point(camera: &Camera, i: usize, j: usize, z: f64) -> Vector3<f64> {
    let k = &camera.intrinsics;
    Vector3::new(
        (i as f64 + 0.5 - k.cx) / k.fx * z,
        (j as f64 + 0.5 - k.cy) / k.fy * z,
        z,
    )
}

/// The Eq. (1) quantity at every pixel (`+∞` where the depth is missing).
pub fn edge_measure(depth: &[f32], camera: &Camera, test: EdgeTest) -> Result<Vec<f32>> {
    let (w, h) = check_inputs(depth, camera, None)?;
    let at = |i: usize, j: usize| depth[j * w + i];
    let mut out = vec![f32::INFINITY; w * h];
    for j in 0..h {
        for i in 0..w {
            let d = at(i, j);
            if d <= 0.0 {
                continue;
            }
            // Forward neighbour, else backward; a neighbour without depth counts as flat.
            let pick = |fwd: Option<(usize, usize)>, bwd: Option<(usize, usize)>| {
                let (ni, nj) = fwd.or(bwd).unwrap_or((i, j));
                let dn = at(ni, nj);
                ((ni, nj), if dn > 0.0 { dn } else { d })
            };
            let fx = (i + 1 < w).then(|| (i + 1, j));
            let bx = (i > 0).then(|| (i - 1, j));
            let fy = (j + 1 < h).then(|| (i, j + 1));
            let by = (j > 0).then(|| (i, j - 1));
            let ((xi, xj), dx) = pick(fx, bx);
            let ((yi, yj), dy) = pick(fy, by);
            let d64 = d as f64;
            out[j * w + i] = match test {
                EdgeTest::DepthProduct => {
                    (((d - dx) as f64 * (d - dy) as f64) / (d64 * d64)) as f32
                }
                EdgeTest::TriangleArea => {
                    let p = cam_point(camera, i, j, d64);
                    let px = cam_point(camera, xi, xj, dx as f64);
                    let py = cam_point(camera, yi, yj, dy as f64);
                    ((p - px).cross(&(p - py)).norm() / (d64 * d64)) as f32
                }
            };
        }
    }
    Ok(out)
}

/// Which pixels survive: positive depth and (when `tau > 0`) Eq. (1) below τ.
pub fn valid_pixels(depth: &[f32], camera: &Camera, options: &DepthOptions) -> Result<Vec<bool>> {
    if options.tau <= 0.0 {
        check_inputs(depth, camera, None)?;
        return Ok(depth.iter().map(|&d| d > 0.0).collect());
    }
    Ok(edge_measure(depth, camera, options.test)?
        .iter()
        .map(|&a| a < options.tau)
        .collect())
}

fn pixel_color(img: &Image, i: usize, j: usize) -> [f32; 3] {
    let p = img.pixel(i, j);
    if img.channels == 1 {
        [p[0]; 3]
    } else {
        [p[0], p[1], p[2]]
    }
}

/// World points, their pixel indices and (optional) colours.
type BackProjected = (Vec<[f32; 3]>, Vec<usize>, Option<Vec<[f32; 3]>>);

/// Back-projected world points of the valid pixels (row-major order), their pixel indices and
/// colours.
fn back_project(
    depth: &[f32],
    camera: &Camera,
    colors: Option<&Image>,
    valid: &[bool],
) -> BackProjected {
    let w = camera.width() as usize;
    let c2w = camera.camera_to_world();
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    let mut col = colors.map(|_| Vec::new());
    for (p, &ok) in valid.iter().enumerate() {
        if !ok {
            continue;
        }
        let (i, j) = (p % w, p / w);
        let x = c2w.transform_point(&cam_point(camera, i, j, depth[p] as f64));
        pos.push([x.x as f32, x.y as f32, x.z as f32]);
        idx.push(p);
        if let (Some(c), Some(img)) = (col.as_mut(), colors) {
            c.push(pixel_color(img, i, j));
        }
    }
    (pos, idx, col)
}

/// Mesh of a depth map (the fusion paper §1): one vertex per valid pixel, two triangles per 2×2 block
/// of valid pixels, faces towards the camera; `colors` (same size, 1/3/4 channels) become
/// vertex colours. `tau` is τ_depth of Eq. (1) (≤ 0: no filter).
pub fn depth_to_mesh(
    depth: &[f32],
    camera: &Camera,
    colors: Option<&Image>,
    tau: f32,
) -> Result<Mesh> {
    depth_to_mesh_with(
        depth,
        camera,
        colors,
        &DepthOptions {
            tau,
            ..Default::default()
        },
    )
}

/// [`depth_to_mesh`] with every option.
pub fn depth_to_mesh_with(
    depth: &[f32],
    camera: &Camera,
    colors: Option<&Image>,
    options: &DepthOptions,
) -> Result<Mesh> {
    let (w, h) = check_inputs(depth, camera, colors)?;
    let valid = valid_pixels(depth, camera, options)?;
    let (vertices, pixels, cols) = back_project(depth, camera, colors, &valid);
    let mut vid = vec![u32::MAX; w * h];
    for (v, &p) in pixels.iter().enumerate() {
        vid[p] = v as u32;
    }
    let mut faces = Vec::new();
    for j in 0..h.saturating_sub(1) {
        for i in 0..w.saturating_sub(1) {
            let p00 = vid[j * w + i];
            let p10 = vid[j * w + i + 1];
            let p01 = vid[(j + 1) * w + i];
            let p11 = vid[(j + 1) * w + i + 1];
            // Image y points down, so (p00, p01, p10) is counter-clockwise seen from the camera.
            for tri in [[p00, p01, p10], [p10, p01, p11]] {
                if tri.iter().all(|&v| v != u32::MAX) {
                    faces.push(tri);
                }
            }
        }
    }
    Ok(Mesh {
        vertices,
        faces,
        colors: cols,
        normals: None,
    })
}

/// Point cloud of a depth map (the fusion paper §2): the valid pixels of the same Eq. (1) filter,
/// back-projected to world space, with colours when given.
pub fn depth_to_points(
    depth: &[f32],
    camera: &Camera,
    colors: Option<&Image>,
    tau: f32,
) -> Result<Points> {
    depth_to_points_with(
        depth,
        camera,
        colors,
        &DepthOptions {
            tau,
            ..Default::default()
        },
    )
}

/// [`depth_to_points`] with every option.
pub fn depth_to_points_with(
    depth: &[f32],
    camera: &Camera,
    colors: Option<&Image>,
    options: &DepthOptions,
) -> Result<Points> {
    check_inputs(depth, camera, colors)?;
    let valid = valid_pixels(depth, camera, options)?;
    let (positions, _, colors) = back_project(depth, camera, colors, &valid);
    Ok(Points {
        positions,
        colors,
        normals: None,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::mesh::v3;
    use fewview_scene::{Intrinsics, Se3};
    use nalgebra::Matrix3;

    /// A camera 1 unit behind the origin, looking along world +z, slightly rotated so that world
    /// and camera axes differ.
    pub(crate) fn test_camera(w: u32, h: u32, f: f64) -> Camera {
        let r = nalgebra::Rotation3::from_euler_angles(0.05, -0.03, 0.02).into_inner();
        let c = Vector3::new(0.1, -0.2, -1.0);
        Camera::new(Intrinsics::centered(f, w, h), Se3::new(r, -(r * c)))
    }

    /// Renders (ray-casts) the depth of two fronto-parallel planes: a near one at z = `z_near`
    /// (camera frame) covering camera-x < 0, over a far one at `z_far`.
    pub(crate) fn two_planes(cam: &Camera, z_near: f64, z_far: f64) -> Vec<f32> {
        let (w, h) = (cam.width() as usize, cam.height() as usize);
        let k = cam.intrinsics;
        let mut d = vec![0.0; w * h];
        for j in 0..h {
            for i in 0..w {
                let dir_x = (i as f64 + 0.5 - k.cx) / k.fx;
                d[j * w + i] = if dir_x * z_near < -0.013 {
                    z_near
                } else {
                    z_far
                } as f32;
            }
        }
        d
    }

    fn cam_depth_of(cam: &Camera, p: &[f32; 3]) -> f64 {
        cam.world_to_camera.transform_point(&v3(p)).z
    }

    #[test]
    fn no_triangle_spans_the_gap_but_tau_zero_bridges_it() {
        let cam = test_camera(80, 60, 400.0);
        let depth = two_planes(&cam, 2.0, 3.0);
        let spanning = |m: &Mesh| {
            m.faces
                .iter()
                .filter(|f| {
                    let z: Vec<f64> = f
                        .iter()
                        .map(|&v| cam_depth_of(&cam, &m.vertices[v as usize]))
                        .collect();
                    z.iter().cloned().fold(f64::MIN, f64::max)
                        - z.iter().cloned().fold(f64::MAX, f64::min)
                        > 0.5
                })
                .count()
        };
        let filtered = depth_to_mesh(&depth, &cam, None, TAU_DEPTH).unwrap();
        assert_eq!(spanning(&filtered), 0);
        // The filter drops only the pixels at the edge: one column of the 80.
        assert_eq!(filtered.vertices.len(), 80 * 60 - 60);
        let unfiltered = depth_to_mesh(&depth, &cam, None, 0.0).unwrap();
        assert_eq!(unfiltered.vertices.len(), 80 * 60);
        assert_eq!(unfiltered.faces.len(), 2 * 79 * 59);
        // One column of quads bridges the gap: 2 triangles per row.
        assert_eq!(spanning(&unfiltered), 2 * 59);
    }

    #[test]
    fn vertices_land_on_their_pixels_and_faces_face_the_camera() {
        let cam = test_camera(16, 12, 400.0);
        // A slanted plane: z = 2 + 0.5·x_cam, ray-cast exactly.
        let (w, h) = (16, 12);
        let k = cam.intrinsics;
        let mut depth = vec![0.0f32; w * h];
        for j in 0..h {
            for i in 0..w {
                let dx = (i as f64 + 0.5 - k.cx) / k.fx;
                depth[j * w + i] = (2.0 / (1.0 - 0.5 * dx)) as f32;
            }
        }
        let mut img = Image::new(w, h, 3);
        for (n, v) in img.data.iter_mut().enumerate() {
            *v = (n % 7) as f32 / 7.0;
        }
        let m = depth_to_mesh(&depth, &cam, Some(&img), TAU_DEPTH).unwrap();
        assert_eq!(
            m.vertices.len(),
            w * h,
            "a smooth slanted plane loses no pixel"
        );
        for (n, p) in m.vertices.iter().enumerate() {
            let (u, v, z) = cam.project(&v3(p)).unwrap();
            let (i, j) = (n % w, n / w);
            assert!((u - (i as f64 + 0.5)).abs() < 1e-3 && (v - (j as f64 + 0.5)).abs() < 1e-3);
            assert!((z - depth[n] as f64).abs() < 1e-5);
            assert_eq!(m.colors.as_ref().unwrap()[n], pixel_color(&img, i, j));
        }
        for f in 0..m.faces.len() {
            let n = m.face_cross(f);
            let to_cam = cam.center() - v3(&m.vertices[m.faces[f][0] as usize]);
            assert!(n.dot(&to_cam) > 0.0, "face {f} turns away from the camera");
        }
    }

    #[test]
    fn measures_match_hand_computation() {
        // 2×2 depth map, identity pose, f = 100, principal point at the centre.
        let cam = Camera::new(
            Intrinsics::centered(100.0, 2, 2),
            Se3::new(Matrix3::identity(), Vector3::zeros()),
        );
        let depth = [2.0f32, 3.0, 2.5, 2.0];
        let prod = edge_measure(&depth, &cam, EdgeTest::DepthProduct).unwrap();
        // Pixel (0,0): (2 − 3)(2 − 2.5)/4.
        assert!((prod[0] - 0.125).abs() < 1e-7);
        // Pixel (1,1) uses backward neighbours (0,1) = 2.5 and (1,0) = 3: (2 − 2.5)(2 − 3)/4.
        assert!((prod[3] - 0.125).abs() < 1e-7);
        let area = edge_measure(&depth, &cam, EdgeTest::TriangleArea).unwrap();
        let p = cam_point(&cam, 0, 0, 2.0);
        let px = cam_point(&cam, 1, 0, 3.0);
        let py = cam_point(&cam, 0, 1, 2.5);
        let want = (p - px).cross(&(p - py)).norm() / 4.0;
        assert!((area[0] as f64 - want).abs() < 1e-7);
    }

    #[test]
    fn points_follow_the_same_filter_and_bad_input_is_rejected() {
        let cam = test_camera(40, 30, 300.0);
        let mut depth = two_planes(&cam, 2.0, 3.0);
        depth[5] = 0.0; // missing depth
        let pts = depth_to_points(&depth, &cam, None, TAU_DEPTH).unwrap();
        let mesh = depth_to_mesh(&depth, &cam, None, TAU_DEPTH).unwrap();
        assert_eq!(pts.positions, mesh.vertices);
        assert_eq!(pts.len(), 40 * 30 - 30 - 1);
        depth[7] = f32::NAN;
        let e = depth_to_points(&depth, &cam, None, TAU_DEPTH)
            .unwrap_err()
            .to_string();
        assert!(e.contains("(7, 0)") && e.contains("NaN"), "{e}");
        let e = depth_to_mesh(&depth[..10], &cam, None, TAU_DEPTH)
            .unwrap_err()
            .to_string();
        assert!(e.contains("10 values for a 40×30"), "{e}");
        let img = Image::new(20, 30, 3);
        let depth = two_planes(&cam, 2.0, 3.0);
        let e = depth_to_mesh(&depth, &cam, Some(&img), TAU_DEPTH)
            .unwrap_err()
            .to_string();
        assert!(e.contains("20×30") && e.contains("40×30"), "{e}");
    }
}
