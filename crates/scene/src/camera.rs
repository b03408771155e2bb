//! Pinhole cameras and rigid poses in the one internal convention.
//!
//! World-to-camera `x_cam = R x_world + t`, OpenCV axes (x right, y down, z forward). Pixel
//! centres sit at half-integer coordinates (see the crate docs), so downscaling by an integer
//! factor `k` divides `fx, fy, cx, cy` by exactly `k`.

use nalgebra::{Matrix3, Matrix4, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics in pixels, with the image size they belong to.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: u32,
    pub height: u32,
}

impl Intrinsics {
    /// Intrinsics with the principal point at the image centre.
    pub fn centered(focal: f64, width: u32, height: u32) -> Self {
        Self {
            fx: focal,
            fy: focal,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            width,
            height,
        }
    }

    /// The intrinsics of the same camera imaged at `width × height` instead: focal lengths and
    /// principal point scale with the size (exact for pixel-centre-at-half-integer images).
    pub fn resized(&self, width: u32, height: u32) -> Self {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        Self {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            width,
            height,
        }
    }

    /// The 3×3 matrix `K`.
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Horizontal and vertical tangent of half the field of view, measured from the principal point
    /// to the farther image border.
    pub fn tan_half_fov(&self) -> (f64, f64) {
        let tx = self.cx.max(self.width as f64 - self.cx) / self.fx;
        let ty = self.cy.max(self.height as f64 - self.cy) / self.fy;
        (tx, ty)
    }

    /// The focal lengths and principal point with their names, for checks whose errors say
    /// which value is wrong.
    pub fn named_values(&self) -> [(&'static str, f64); 4] {
        [
            ("focal length fx", self.fx),
            ("focal length fy", self.fy),
            ("principal point cx", self.cx),
            ("principal point cy", self.cy),
        ]
    }

    pub fn is_finite(&self) -> bool {
        [self.fx, self.fy, self.cx, self.cy]
            .iter()
            .all(|v| v.is_finite())
            && self.fx > 0.0
            && self.fy > 0.0
    }
}

/// A rigid transform `x ↦ R x + t`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Se3 {
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
}

impl Default for Se3 {
    fn default() -> Self {
        Self::identity()
    }
}

impl Se3 {
    pub fn identity() -> Self {
        Self {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    pub fn new(rotation: Matrix3<f64>, translation: Vector3<f64>) -> Self {
        Self {
            rotation,
            translation,
        }
    }

    /// The transform of a homogeneous 4×4 matrix (the last row is ignored).
    pub fn from_matrix4(m: &Matrix4<f64>) -> Self {
        Self {
            rotation: m.fixed_view::<3, 3>(0, 0).into_owned(),
            translation: m.fixed_view::<3, 1>(0, 3).into_owned(),
        }
    }

    pub fn to_matrix4(&self) -> Matrix4<f64> {
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rotation);
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.translation);
        m
    }

    pub fn inverse(&self) -> Self {
        let rt = self.rotation.transpose();
        Self {
            rotation: rt,
            translation: -(rt * self.translation),
        }
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Se3) -> Self {
        Self {
            rotation: self.rotation * other.rotation,
            translation: self.rotation * other.translation + self.translation,
        }
    }

    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p + self.translation
    }

    pub fn transform_vector(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * v
    }

    /// The rotation as a unit quaternion (re-orthonormalised first, so slightly non-orthogonal
    /// input from files is tolerated).
    pub fn quaternion(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&self.rotation))
    }

    pub fn is_finite(&self) -> bool {
        self.rotation.iter().all(|v| v.is_finite())
            && self.translation.iter().all(|v| v.is_finite())
    }
}

/// A pinhole camera: intrinsics and world-to-camera pose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    /// `x_cam = R x_world + t`.
    pub world_to_camera: Se3,
}

impl Camera {
    pub fn new(intrinsics: Intrinsics, world_to_camera: Se3) -> Self {
        Self {
            intrinsics,
            world_to_camera,
        }
    }

    /// A camera from a camera-to-world pose (OpenCV axes).
    pub fn from_camera_to_world(intrinsics: Intrinsics, camera_to_world: Se3) -> Self {
        Self::new(intrinsics, camera_to_world.inverse())
    }

    /// A camera at `eye` looking at `target`, with image "up" towards `up` (OpenCV axes: the
    /// camera's y axis points away from `up`).
    pub fn look_at(
        intrinsics: Intrinsics,
        eye: Vector3<f64>,
        target: Vector3<f64>,
        up: Vector3<f64>,
    ) -> Self {
        let z = (target - eye).normalize();
        let x = z.cross(&up).normalize();
        let y = z.cross(&x);
        let r_c2w = Matrix3::from_columns(&[x, y, z]);
        Self::from_camera_to_world(intrinsics, Se3::new(r_c2w, eye))
    }

    pub fn width(&self) -> u32 {
        self.intrinsics.width
    }

    pub fn height(&self) -> u32 {
        self.intrinsics.height
    }

    pub fn camera_to_world(&self) -> Se3 {
        self.world_to_camera.inverse()
    }

    /// The camera centre in world coordinates, `-Rᵀ t`.
    pub fn center(&self) -> Vector3<f64> {
        -(self.world_to_camera.rotation.transpose() * self.world_to_camera.translation)
    }

    /// The viewing direction (camera +z) in world coordinates.
    pub fn forward(&self) -> Vector3<f64> {
        self.world_to_camera.rotation.row(2).transpose()
    }

    /// Projects a world point to `(u, v, depth)` in pixels; `None` behind the camera.
    pub fn project(&self, p_world: &Vector3<f64>) -> Option<(f64, f64, f64)> {
        let p = self.world_to_camera.transform_point(p_world);
        if p.z <= 0.0 {
            return None;
        }
        let k = &self.intrinsics;
        Some((k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy, p.z))
    }

    /// The pixel (row-major index) a world point projects into and its depth there; `None`
    /// behind the camera or outside the image.
    pub fn pixel_of(&self, p_world: &Vector3<f64>) -> Option<(usize, f64)> {
        let (u, v, z) = self.project(p_world)?;
        let (w, h) = (self.width() as f64, self.height() as f64);
        (u >= 0.0 && v >= 0.0 && u < w && v < h)
            .then(|| ((v as usize) * self.width() as usize + u as usize, z))
    }

    /// The world-space point at pixel coordinates `(u, v)` and depth `z` along the optical axis.
    pub fn unproject(&self, u: f64, v: f64, z: f64) -> Vector3<f64> {
        let k = &self.intrinsics;
        let p_cam = Vector3::new((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z);
        self.camera_to_world().transform_point(&p_cam)
    }

    /// Ray through pixel coordinates `(u, v)`: origin and unit direction in world space.
    pub fn ray(&self, u: f64, v: f64) -> (Vector3<f64>, Vector3<f64>) {
        let k = &self.intrinsics;
        let d_cam = Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
        let d = self.world_to_camera.rotation.transpose() * d_cam;
        (self.center(), d.normalize())
    }

    /// The same camera imaged at another resolution.
    pub fn resized(&self, width: u32, height: u32) -> Self {
        Self::new(self.intrinsics.resized(width, height), self.world_to_camera)
    }

    /// The camera a fraction `s ∈ [0, 1]` of the way from `self` to `other`: rotations by SLERP,
    /// centres by linear interpolation, intrinsics linearly (size from `self`).
    pub fn interpolate(&self, other: &Camera, s: f64) -> Camera {
        let qa = self.world_to_camera.quaternion();
        let qb = other.world_to_camera.quaternion();
        let q = qa.slerp(&qb, s);
        let c = self.center() * (1.0 - s) + other.center() * s;
        let r = q.to_rotation_matrix().into_inner();
        let (ka, kb) = (&self.intrinsics, &other.intrinsics);
        let lerp = |a: f64, b: f64| a * (1.0 - s) + b * s;
        let intrinsics = Intrinsics {
            fx: lerp(ka.fx, kb.fx),
            fy: lerp(ka.fy, kb.fy),
            cx: lerp(ka.cx, kb.cx),
            cy: lerp(ka.cy, kb.cy),
            width: ka.width,
            height: ka.height,
        };
        Camera::new(intrinsics, Se3::new(r, -(r * c)))
    }

    pub fn is_finite(&self) -> bool {
        self.intrinsics.is_finite() && self.world_to_camera.is_finite()
    }
}

/// The point closest, in least squares, to the optical axes of world-to-camera `poses`: where
/// the cameras look. Falls back to the mean camera centre when the axes are all parallel.
pub fn axes_meeting_point(poses: &[Se3]) -> Vector3<f64> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for p in poses {
        let d: Vector3<f64> = p.rotation.row(2).transpose();
        let c = -(p.rotation.transpose() * p.translation);
        let proj = Matrix3::identity() - d * d.transpose();
        a += proj;
        b += proj * c;
    }
    a.try_inverse().map(|inv| inv * b).unwrap_or_else(|| {
        poses
            .iter()
            .map(|p| -(p.rotation.transpose() * p.translation))
            .sum::<Vector3<f64>>()
            / poses.len().max(1) as f64
    })
}

/// A smooth path visiting `keys` in order, `frames_per_segment` frames from each key to the next
/// (SLERP rotations, linear centres). The last key is included once at the end.
pub fn camera_path(keys: &[Camera], frames_per_segment: usize) -> Vec<Camera> {
    let mut out = Vec::new();
    if keys.is_empty() {
        return out;
    }
    for pair in keys.windows(2) {
        for f in 0..frames_per_segment.max(1) {
            let s = f as f64 / frames_per_segment.max(1) as f64;
            out.push(pair[0].interpolate(&pair[1], s));
        }
    }
    out.push(keys[keys.len() - 1].clone());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::look_at(
            Intrinsics::centered(100.0, 64, 48),
            Vector3::new(1.0, -2.0, 3.0),
            Vector3::zeros(),
            Vector3::new(0.0, 0.0, 1.0),
        )
    }

    #[test]
    fn project_unproject_roundtrip() {
        let c = cam();
        let p = Vector3::new(0.1, 0.2, -0.3);
        let (u, v, z) = c.project(&p).unwrap();
        let q = c.unproject(u, v, z);
        assert!((p - q).norm() < 1e-12);
    }

    #[test]
    fn look_at_centers_target_with_up_on_top() {
        let c = cam();
        let (u, v, _) = c.project(&Vector3::zeros()).unwrap();
        assert!((u - 32.0).abs() < 1e-9 && (v - 24.0).abs() < 1e-9);
        // A point above the target (world +z) lands above the centre (smaller v).
        let (_, v_up, _) = c.project(&Vector3::new(0.0, 0.0, 0.1)).unwrap();
        assert!(v_up < v);
        assert!((c.center() - Vector3::new(1.0, -2.0, 3.0)).norm() < 1e-12);
    }

    #[test]
    fn interpolation_hits_ends_and_midpoint() {
        let a = cam();
        let b = Camera::look_at(
            Intrinsics::centered(100.0, 64, 48),
            Vector3::new(-3.0, 1.0, 2.0),
            Vector3::zeros(),
            Vector3::new(0.0, 0.0, 1.0),
        );
        let a0 = a.interpolate(&b, 0.0);
        let b1 = a.interpolate(&b, 1.0);
        assert!((a0.world_to_camera.rotation - a.world_to_camera.rotation).norm() < 1e-9);
        assert!((b1.world_to_camera.rotation - b.world_to_camera.rotation).norm() < 1e-9);
        assert!((b1.center() - b.center()).norm() < 1e-9);
        let m = a.interpolate(&b, 0.5);
        assert!((m.center() - (a.center() + b.center()) / 2.0).norm() < 1e-9);
        // The midpoint rotation is equally far (in angle) from both ends.
        let qa = a.world_to_camera.quaternion();
        let qb = b.world_to_camera.quaternion();
        let qm = m.world_to_camera.quaternion();
        assert!((qa.angle_to(&qm) - qm.angle_to(&qb)).abs() < 1e-9);
        let path = camera_path(&[a.clone(), b.clone()], 10);
        assert_eq!(path.len(), 11);
    }

    #[test]
    fn resize_halves_intrinsics() {
        let k = Intrinsics {
            fx: 800.0,
            fy: 790.0,
            cx: 400.0,
            cy: 300.5,
            width: 800,
            height: 600,
        };
        let h = k.resized(400, 300);
        assert_eq!((h.fx, h.fy, h.cx, h.cy), (400.0, 395.0, 200.0, 150.25));
    }
}
