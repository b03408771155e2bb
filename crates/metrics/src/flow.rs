//! Exact optical flow between rendered frames of a static scene, from cameras and depth maps.
//!
//! A renderer knows the depth of every pixel, so the flow between two of its frames needs no
//! estimation: each pixel's 3D point, projected into the other camera, is where it was. This
//! gives the backward [`Flow`] that the warping error ([`crate::temporal::warping_error`])
//! takes, together with a validity mask that removes the pixels whose point the previous frame
//! does not show (occluded there, off its image, or sky).
//!
//! Coordinates follow `fewview_scene`: pixel `(i, j)` is centred at `(i + 0.5, j + 0.5)` in the
//! camera's pixel coordinates, while a [`Flow`] displaces pixel indices (centres at integers),
//! so a flow vector is the difference of the two pixel-coordinate positions either way.
//!
//! **Occlusions** are found with the forward–backward consistency check of Sundaram, Brox and
//! Keutzer ("Dense point trajectories by GPU-accelerated large displacement optical flow", ECCV
//! 2010, Eq. 5), applied to the exact flows: a pixel's backward flow `b` is trusted where the
//! previous frame's forward flow `f`, bilinearly sampled at the landing point, brings it back,
//! `|b + f(x + b)|² < 0.01 (|b|² + |f(x + b)|²) + 0.5`. A disoccluded pixel lands on the
//! occluder in the previous frame, whose forward flow is the occluder's, not its own.

use fewview_scene::Camera;
use rayon::prelude::*;

use crate::error::{MetricsError, Result};
use crate::temporal::Flow;

/// Backward flow of frame `t` (camera `current`, z-depth map `current_depth`, 0 = no surface) to
/// frame t−1 (camera `previous`, its depth `previous_depth`), exact for a static scene: each
/// pixel's 3D point projected into the previous camera. `valid` marks pixels where the flow is
/// trusted: a surface in both frames, landing inside the previous frame, and forward–backward
/// consistent (the previous frame's forward flow at the landing point, bilinearly sampled, brings it
/// back: |b + f(x + b)|² < 0.01 (|b|² + |f(x+b)|²) + 0.5, Sundaram et al. 2010), which masks occlusions.
///
/// Depths are z-depths along each camera's optical axis (as `fewview_scene::synthetic::demo_depth`
/// and the splat renderer give them), row-major at the camera's image size; a depth that is not
/// a positive finite number means "no surface". Pixels without a surface get a zero, invalid
/// flow; the others keep their exact flow even where it is not trusted. "Inside the previous
/// frame" is the range the warping error can sample bilinearly: pixel centres from the first to
/// the last (a landing point less than 1e-6 px outside it is moved onto it, so that rounding does
/// not drop the pixels whose point lies exactly on the border). The two cameras may have
/// different image sizes.
pub fn flow_between(
    current: &Camera,
    current_depth: &[f32],
    previous: &Camera,
    previous_depth: &[f32],
) -> Result<Flow> {
    check_depth("current", current, current_depth)?;
    check_depth("previous", previous, previous_depth)?;
    let (w, h) = (current.width() as usize, current.height() as usize);
    let (pw, ph) = (previous.width() as usize, previous.height() as usize);
    if w == 0 || h == 0 || pw == 0 || ph == 0 {
        return Err(MetricsError::invalid(format!(
            "empty frame: current camera is {w}x{h}, previous {pw}x{ph}"
        )));
    }
    let forward = displacements(previous, previous_depth, current);
    let backward = displacements(current, current_depth, previous);
    let (last_x, last_y) = ((pw - 1) as f64, (ph - 1) as f64);
    let (data, valid): (Vec<[f32; 2]>, Vec<bool>) = backward
        .par_iter()
        .enumerate()
        .map(|(i, b)| {
            let Some([bx, by]) = *b else {
                return ([0.0; 2], false);
            };
            let (x0, y0) = ((i % w) as f64, (i / w) as f64);
            let (x, y) = (snap(x0 + bx, last_x), snap(y0 + by, last_y));
            let (bx, by) = (x - x0, y - y0);
            let inside = (0.0..=last_x).contains(&x) && (0.0..=last_y).contains(&y);
            let consistent = inside
                && sample(&forward, pw, ph, x, y).is_some_and(|[fx, fy]| {
                    let back = (bx + fx).powi(2) + (by + fy).powi(2);
                    let scale = bx * bx + by * by + fx * fx + fy * fy;
                    back < 0.01 * scale + 0.5
                });
            ([bx as f32, by as f32], consistent)
        })
        .unzip();
    Ok(Flow {
        width: w,
        height: h,
        data,
        valid: Some(valid),
        source: None,
    })
}

/// The backward flows of a camera path with its depth maps, one per transition `t = 1..T−1`
/// (`flow_between(cameras[t], depths[t], cameras[t − 1], depths[t − 1])`), as
/// [`crate::temporal::warping_errors`] takes them. Fewer than two frames give no flow.
pub fn path_flows(cameras: &[Camera], depths: &[Vec<f32>]) -> Result<Vec<Flow>> {
    if cameras.len() != depths.len() {
        return Err(MetricsError::ShapeMismatch(format!(
            "{} cameras but {} depth maps",
            cameras.len(),
            depths.len()
        )));
    }
    (1..cameras.len())
        .map(|t| {
            flow_between(&cameras[t], &depths[t], &cameras[t - 1], &depths[t - 1])
                .map_err(|e| MetricsError::invalid(format!("transition {t}: {e}")))
        })
        .collect()
}

/// A landing coordinate within [`BORDER_SNAP`] outside `[0, last]` moved onto the border: a point
/// exactly on the border (the first row under a purely horizontal motion) comes out of the
/// projection a rounding error away from it, and would otherwise be dropped.
fn snap(x: f64, last: f64) -> f64 {
    if (-BORDER_SNAP..0.0).contains(&x) {
        0.0
    } else if x > last && x <= last + BORDER_SNAP {
        last
    } else {
        x
    }
}

/// How far (pixels) outside the frame a landing point still counts as on its border.
const BORDER_SNAP: f64 = 1e-6;

fn check_depth(which: &str, camera: &Camera, depth: &[f32]) -> Result<()> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    if depth.len() != w * h {
        return Err(MetricsError::ShapeMismatch(format!(
            "the {which} depth map has {} values, its camera is {w}x{h} ({} pixels)",
            depth.len(),
            w * h
        )));
    }
    if !camera.is_finite() {
        return Err(MetricsError::invalid(format!(
            "the {which} camera is not finite (NaN or infinite pose or intrinsics)"
        )));
    }
    Ok(())
}

/// Another camera a frame's pixels may be seen from, with its z-depth map (0 = no surface) when
/// occlusion is to be tested.
#[derive(Clone, Copy)]
pub struct Onlooker<'a> {
    pub camera: &'a Camera,
    pub depth: Option<&'a [f32]>,
}

/// Relative depth margin within which a point counts as the surface another view shows.
pub const VISIBILITY_TOLERANCE: f64 = 0.05;

/// How many of `others` see each pixel's 3D point of `camera` (z-depth map `depth`, as
/// [`flow_between`] takes it): in front of them and inside their image (`[0, w] × [0, h]` in
/// pixel coordinates) and, for an onlooker with a depth map, not behind the surface it shows
/// there (the point's depth at most [`VISIBILITY_TOLERANCE`] beyond the largest of the four
/// depths around where it lands). 0 where `camera` sees no surface.
pub fn views_seeing(camera: &Camera, depth: &[f32], others: &[Onlooker<'_>]) -> Result<Vec<u8>> {
    check_depth("frame", camera, depth)?;
    for o in others {
        if let Some(d) = o.depth {
            check_depth("onlooker", o.camera, d)?;
        }
    }
    let w = camera.width() as usize;
    Ok(depth
        .par_iter()
        .enumerate()
        .map(|(i, &z)| {
            if !(z.is_finite() && z > 0.0) {
                return 0;
            }
            let p = camera.unproject((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, z as f64);
            let sees = |o: &&Onlooker<'_>| {
                let c = o.camera;
                c.project(&p).is_some_and(|(u, v, zo)| {
                    (0.0..=c.width() as f64).contains(&u)
                        && (0.0..=c.height() as f64).contains(&v)
                        && o.depth.is_none_or(|d| in_front_of(d, c, u, v, zo))
                })
            };
            others.iter().filter(sees).count().min(u8::MAX as usize) as u8
        })
        .collect())
}

/// Whether depth `z` at pixel coordinates `(u, v)` of `camera` is not behind the surface of
/// its depth map `depth` (the largest of the four pixels around, with the tolerance).
fn in_front_of(depth: &[f32], camera: &Camera, u: f64, v: f64, z: f64) -> bool {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let (x0, y0) = ((u - 0.5).floor(), (v - 0.5).floor());
    let surface = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
        .iter()
        .map(|(dx, dy)| {
            let x = (x0 + dx).clamp(0.0, (w - 1) as f64) as usize;
            let y = (y0 + dy).clamp(0.0, (h - 1) as f64) as usize;
            depth[y * w + x]
        })
        .filter(|d| d.is_finite() && *d > 0.0)
        .fold(0.0f32, f32::max);
    surface > 0.0 && z <= surface as f64 * (1.0 + VISIBILITY_TOLERANCE)
}

/// Where each pixel of `from` (depth `depth`) lands in `to`, as a displacement in pixels; `None`
/// where `from` sees no surface or the point is behind `to`.
fn displacements(from: &Camera, depth: &[f32], to: &Camera) -> Vec<Option<[f64; 2]>> {
    let w = from.width() as usize;
    depth
        .par_iter()
        .enumerate()
        .map(|(i, &z)| {
            if !(z.is_finite() && z > 0.0) {
                return None;
            }
            let (u, v) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let p = from.unproject(u, v, z as f64);
            let (u2, v2, _) = to.project(&p)?;
            Some([u2 - u, v2 - v])
        })
        .collect()
}

/// Bilinear sample of a `w × h` displacement field at pixel-index coordinates `(x, y)` (inside
/// `[0, w−1] × [0, h−1]`); `None` if a sample with non-zero weight has no displacement.
fn sample(field: &[Option<[f64; 2]>], w: usize, h: usize, x: f64, y: f64) -> Option<[f64; 2]> {
    let (x0, y0) = (
        (x.floor() as usize).min(w - 1),
        (y.floor() as usize).min(h - 1),
    );
    let (ax, ay) = (x - x0 as f64, y - y0 as f64);
    let mut out = [0.0; 2];
    for (dy, wy) in [(0, 1.0 - ay), (1, ay)] {
        for (dx, wx) in [(0, 1.0 - ax), (1, ax)] {
            let weight = wx * wy;
            if weight == 0.0 {
                continue;
            }
            let [fx, fy] = field[(y0 + dy).min(h - 1) * w + (x0 + dx).min(w - 1)]?;
            out[0] += weight * fx;
            out[1] += weight * fy;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::temporal::warping_error;
    use fewview_scene::{Image, Intrinsics, Se3};
    use nalgebra::{Rotation3, Vector3};

    const W: usize = 64;
    const H: usize = 48;

    fn intrinsics() -> Intrinsics {
        Intrinsics {
            fx: 60.0,
            fy: 58.0,
            cx: 31.0,
            cy: 24.5,
            width: W as u32,
            height: H as u32,
        }
    }

    /// A camera with centre `c` and world-to-camera rotation `r`.
    fn camera(r: Rotation3<f64>, c: Vector3<f64>) -> Camera {
        let r = r.into_inner();
        Camera::new(intrinsics(), Se3::new(r, -(r * c)))
    }

    /// The z-depth map of `camera` looking at the world plane `n · x = d` (0 where the ray misses
    /// it or meets it behind the camera).
    fn plane_depth(camera: &Camera, n: Vector3<f64>, d: f64) -> Vec<f32> {
        let forward = camera.forward();
        (0..W * H)
            .map(|i| {
                let (o, dir) = camera.ray((i % W) as f64 + 0.5, (i / W) as f64 + 0.5);
                let t = (d - n.dot(&o)) / n.dot(&dir);
                if t > 0.0 {
                    (t * dir.dot(&forward)) as f32
                } else {
                    0.0
                }
            })
            .collect()
    }

    #[test]
    fn pure_rotation_gives_the_homography_flow() {
        let c = Vector3::new(0.3, -0.2, 1.0);
        let previous = camera(Rotation3::from_euler_angles(0.02, -0.01, 0.005), c);
        let current = camera(Rotation3::from_euler_angles(-0.03, 0.06, -0.02), c);
        // Depth does not matter under a rotation about the centre: any positive values.
        let depth: Vec<f32> = (0..W * H).map(|i| 2.0 + (i % 7) as f32).collect();
        let flow = flow_between(&current, &depth, &previous, &depth).unwrap();
        // x_prev ~ K R_prev R_curᵀ K⁻¹ x_cur.
        let k = intrinsics().matrix();
        let hom = k
            * previous.world_to_camera.rotation
            * current.world_to_camera.rotation.transpose()
            * k.try_inverse().unwrap();
        let valid = flow.valid.as_ref().unwrap();
        let (mut worst, mut trusted) = (0.0f64, 0);
        for (i, &ok) in valid.iter().enumerate() {
            let (u, v) = ((i % W) as f64 + 0.5, (i / W) as f64 + 0.5);
            let q = hom * Vector3::new(u, v, 1.0);
            let want = [q.x / q.z - u, q.y / q.z - v];
            let got = flow.data[i];
            worst = worst
                .max((got[0] as f64 - want[0]).abs())
                .max((got[1] as f64 - want[1]).abs());
            let (x, y) = ((i % W) as f64 + want[0], (i / W) as f64 + want[1]);
            let inside = x >= 0.0 && y >= 0.0 && x <= (W - 1) as f64 && y <= (H - 1) as f64;
            // Away from the border, every pixel is trusted; outside the frame none is.
            let margin = x > 0.5 && y > 0.5 && x < W as f64 - 1.5 && y < H as f64 - 1.5;
            if margin {
                assert!(ok, "pixel {i} should be valid");
            }
            if !inside {
                assert!(!ok, "pixel {i} lands outside");
            }
            trusted += ok as usize;
        }
        eprintln!("rotation: worst flow error {worst:.2e} px, {trusted} valid pixels");
        assert!(worst < 1e-3, "{worst}");
        assert!(trusted > W * H / 2, "{trusted}");
    }

    #[test]
    fn sideways_translation_over_a_plane_gives_constant_flow() {
        // Both cameras look down +z at the plane z = 5; the current one sits tx to the right.
        // A point seen at u in the current frame was at u + fx·tx/z in the previous one.
        let (tx, z) = (0.2, 5.0);
        let previous = camera(Rotation3::identity(), Vector3::zeros());
        let current = camera(Rotation3::identity(), Vector3::new(tx, 0.0, 0.0));
        let n = Vector3::z();
        let flow = flow_between(
            &current,
            &plane_depth(&current, n, z),
            &previous,
            &plane_depth(&previous, n, z),
        )
        .unwrap();
        let want = intrinsics().fx * tx / z; // 2.4 px
        let valid = flow.valid.as_ref().unwrap();
        for (i, [dx, dy]) in flow.data.iter().enumerate() {
            assert!(
                (*dx as f64 - want).abs() < 1e-4 && dy.abs() < 1e-4,
                "{i}: {dx} {dy}"
            );
            // Valid exactly where x + 2.4 stays inside the previous frame.
            assert_eq!(
                valid[i],
                (i % W) as f64 + want <= (W - 1) as f64,
                "pixel {i}"
            );
        }
    }

    /// A small square at z = 2 in front of a plane at z = 10; the camera moves sideways, so the
    /// plane shifts by 1.74 px and the square by 8.7 px. The pixels of the plane that the square hid
    /// in the previous frame are marked invalid; everything else is valid except a band of about
    /// a pixel around the square's outline in the previous frame (where bilinear sampling mixes
    /// the square's forward flow with the plane's) and the frame border.
    #[test]
    fn occluder_masks_the_disoccluded_pixels() {
        // (The square's half-size is chosen so that no pixel centre lies on its outline, the
        // translation so that neither flow is a whole number of pixels, which would land every
        // pixel on a pixel centre and never mix the two flows.)
        let (near, far, half, tx) = (2.0, 10.0, 0.2537, 0.29);
        let previous = camera(Rotation3::identity(), Vector3::zeros());
        let current = camera(Rotation3::identity(), Vector3::new(tx, 0.0, 0.0));
        // The scene's z-depth through a pixel of `cam`: the square if the ray meets it, else the plane.
        let depth = |cam: &Camera| -> Vec<f32> {
            (0..W * H)
                .map(|i| {
                    let p = cam.unproject((i % W) as f64 + 0.5, (i / W) as f64 + 0.5, near);
                    if p.x.abs() <= half && p.y.abs() <= half {
                        near as f32
                    } else {
                        far as f32
                    }
                })
                .collect()
        };
        let (dc, dp) = (depth(&current), depth(&previous));
        let flow = flow_between(&current, &dc, &previous, &dp).unwrap();
        let valid = flow.valid.as_ref().unwrap();
        let fx = intrinsics().fx;
        let (mut disoccluded, mut band, mut band_invalid) = (0, 0, 0);
        for i in 0..W * H {
            let (x, y) = (i % W, i / W);
            let (u, v) = (x as f64 + 0.5, y as f64 + 0.5);
            let p = current.unproject(u, v, dc[i] as f64);
            // Seen from the previous camera (at the origin), is the point behind the square?
            let s = p * (near / p.z);
            let hidden = dc[i] as f64 == far && s.x.abs() <= half && s.y.abs() <= half;
            let [bx, _] = flow.data[i];
            assert!((bx as f64 - fx * tx / dc[i] as f64).abs() < 1e-4);
            let landing = x as f64 + bx as f64;
            if hidden {
                disoccluded += 1;
                assert!(!valid[i], "disoccluded pixel ({x}, {y}) is marked valid");
                continue;
            }
            // Distance (pixels) of the landing point from the square's outline in the previous
            // frame, and from its border.
            let (su, sv) = (fx * half / near, intrinsics().fy * half / near);
            let (lu, lv) = (landing + 0.5 - intrinsics().cx, v - intrinsics().cy);
            let outline = ((lu.abs() - su).abs()).min((lv.abs() - sv).abs());
            let near_outline = outline < 1.5 && lu.abs() < su + 1.5 && lv.abs() < sv + 1.5;
            let inside = landing >= 0.0 && landing <= (W - 1) as f64;
            if near_outline {
                band += 1;
                band_invalid += !valid[i] as usize;
            } else {
                assert_eq!(valid[i], inside, "pixel ({x}, {y})");
            }
        }
        eprintln!(
            "occluder: {disoccluded} disoccluded pixels (all invalid); {band} pixels land within \
             1.5 px of the square's outline, {band_invalid} of them invalid"
        );
        // The disoccluded strip is about 7 px wide (8.7 − 1.74) and 15 rows high.
        assert!(disoccluded >= 6 * 14, "{disoccluded}");
        assert!(band < 200, "{band}");
    }

    /// Two frames of a textured tilted plane, rendered analytically (each pixel's colour is the
    /// texture at its ray's intersection): warping the first with the exact flow reproduces the
    /// second up to bilinear interpolation of a smooth texture.
    #[test]
    fn warping_error_with_the_exact_flow_is_near_zero() {
        let n = Vector3::new(0.1, -0.3, 1.0).normalize();
        let d = 6.0;
        let texture = |p: Vector3<f64>| -> [f32; 3] {
            let a = (0.9 * p.x + 0.4 * p.y).sin();
            let b = (0.7 * p.y - 0.5 * p.x).cos();
            [
                (0.5 + 0.3 * a) as f32,
                (0.5 + 0.3 * b) as f32,
                (0.5 + 0.2 * a * b) as f32,
            ]
        };
        let render = |cam: &Camera| -> (Image, Vec<f32>) {
            let depth = plane_depth(cam, n, d);
            let mut img = Image::new(W, H, 3);
            for (i, &z) in depth.iter().enumerate() {
                let (x, y) = (i % W, i / W);
                let p = cam.unproject(x as f64 + 0.5, y as f64 + 0.5, z as f64);
                for (c, value) in texture(p).into_iter().enumerate() {
                    img.set(x, y, c, value);
                }
            }
            (img, depth)
        };
        let previous = camera(
            Rotation3::from_euler_angles(0.01, 0.02, 0.0),
            Vector3::new(0.0, 0.0, 0.0),
        );
        let current = camera(
            Rotation3::from_euler_angles(-0.02, 0.05, 0.01),
            Vector3::new(0.3, 0.1, 0.2),
        );
        let (prev_img, prev_depth) = render(&previous);
        let (cur_img, cur_depth) = render(&current);
        let flow = flow_between(&current, &cur_depth, &previous, &prev_depth).unwrap();
        let valid = flow.valid.as_ref().unwrap().iter().filter(|&&v| v).count();
        let exact = warping_error(&prev_img, &cur_img, &flow).unwrap();
        let still = Flow {
            data: vec![[0.0; 2]; W * H],
            valid: None,
            ..flow.clone()
        };
        let unwarped = warping_error(&prev_img, &cur_img, &still).unwrap();
        eprintln!(
            "warping error {exact:.2e} with the exact flow, {unwarped:.2e} without; {valid} valid pixels"
        );
        assert!(valid > W * H / 2, "{valid}");
        assert!(exact < 1e-5, "{exact}");
        assert!(unwarped > 1000.0 * exact, "{unwarped}");
        // The flows of the path (previous, current) are this one.
        let flows = path_flows(&[previous, current], &[prev_depth, cur_depth]).unwrap();
        assert_eq!(flows, vec![flow]);
    }

    #[test]
    fn size_mismatches_are_named() {
        let cam = camera(Rotation3::identity(), Vector3::zeros());
        let good = vec![1.0f32; W * H];
        let e = flow_between(&cam, &good[1..], &cam, &good)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("current depth map has 3071 values, its camera is 64x48 (3072 pixels)"),
            "{e}"
        );
        let e = flow_between(&cam, &good, &cam, &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("previous depth map has 0 values"), "{e}");
        let e = path_flows(&[cam.clone(), cam.clone()], std::slice::from_ref(&good))
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 cameras but 1 depth maps"), "{e}");
        let e = path_flows(&[cam.clone(), cam.clone()], &[good.clone(), vec![0.0; 5]])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("transition 1: ") && e.contains("5 values"),
            "{e}"
        );
        assert!(
            path_flows(std::slice::from_ref(&cam), &[good])
                .unwrap()
                .is_empty()
        );
    }

    #[test]
    fn views_seeing_counts_the_frusta_a_point_lies_in() {
        // Three cameras facing the plane z = 4 from z = 0; the second is shifted right by a
        // third of the footprint, the third looks away. Pixel columns the shifted camera sees:
        // world x ≥ its left edge.
        let id = Rotation3::identity();
        let a = camera(id, Vector3::zeros());
        let b = camera(id, Vector3::new(1.55, 0.0, 0.0));
        let away = camera(
            Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI),
            Vector3::zeros(),
        );
        let depth = plane_depth(&a, Vector3::z(), 4.0);
        fn frusta<'a>(cams: &[&'a Camera]) -> Vec<Onlooker<'a>> {
            cams.iter()
                .map(|&camera| Onlooker {
                    camera,
                    depth: None,
                })
                .collect()
        }
        let counts = views_seeing(&a, &depth, &frusta(&[&a, &b, &away])).unwrap();
        let k = intrinsics();
        for (i, &count) in counts.iter().enumerate() {
            let u = (i % W) as f64 + 0.5;
            // World x of the pixel, and where that point lands in b.
            let x = (u - k.cx) / k.fx * 4.0;
            let ub = k.fx * (x - 1.55) / 4.0 + k.cx;
            let want = 1 + u8::from((0.0..=W as f64).contains(&ub));
            assert_eq!(count, want, "pixel {i}");
        }
        assert!(counts.contains(&1) && counts.contains(&2));
        let mut sky = depth.clone();
        sky[0] = 0.0;
        assert_eq!(views_seeing(&a, &sky, &frusta(&[&a, &b])).unwrap()[0], 0);
        assert!(views_seeing(&a, &depth[1..], &frusta(&[&b])).is_err());
    }

    #[test]
    fn views_seeing_leaves_out_a_view_that_shows_a_nearer_surface() {
        // Camera b, shifted right, sees the plane z = 4 except through a wall at z = 2 over its
        // left half: points of a's plane behind the wall count for a but not for b.
        let id = Rotation3::identity();
        let a = camera(id, Vector3::zeros());
        let b = camera(id, Vector3::new(1.55, 0.0, 0.0));
        let depth = plane_depth(&a, Vector3::z(), 4.0);
        let mut b_depth = plane_depth(&b, Vector3::z(), 4.0);
        for (i, d) in b_depth.iter_mut().enumerate() {
            if i % W < W / 2 {
                *d = 2.0;
            }
        }
        let onlookers = [
            Onlooker {
                camera: &a,
                depth: Some(&depth),
            },
            Onlooker {
                camera: &b,
                depth: Some(&b_depth),
            },
        ];
        let counts = views_seeing(&a, &depth, &onlookers).unwrap();
        let k = intrinsics();
        for (i, &count) in counts.iter().enumerate() {
            let u = (i % W) as f64 + 0.5;
            let ub = k.fx * ((u - k.cx) / k.fx * 4.0 - 1.55) / 4.0 + k.cx;
            // Clear of the wall's edge by a pixel, b sees the point where it lands right of it.
            if (ub - W as f64 / 2.0).abs() > 1.5 && ub < W as f64 - 1.0 {
                let want = 1 + u8::from(ub > W as f64 / 2.0);
                assert_eq!(count, want, "pixel {i}, lands at {ub:.1} in b");
            }
        }
        assert!(counts.contains(&1) && counts.contains(&2));
        let bad = [Onlooker {
            camera: &b,
            depth: Some(&b_depth[1..]),
        }];
        assert!(views_seeing(&a, &depth, &bad).is_err());
    }
}
