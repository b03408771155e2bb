//! Camera-axis conventions met at the border, converted to the crate's OpenCV axes.

use nalgebra::{Matrix3, Vector3};

use crate::camera::Se3;

/// OpenGL camera axes (right, up, back; NeRF, Blender, nerfstudio) → OpenCV (right, down,
/// forward) for a camera-to-world pose: negate the camera's y and z axes. The map is its own
/// inverse, so it also converts OpenCV back to OpenGL.
pub fn opengl_to_opencv(camera_to_world_gl: &Se3) -> Se3 {
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    Se3::new(
        camera_to_world_gl.rotation * flip,
        camera_to_world_gl.translation,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Camera, Intrinsics};

    #[test]
    fn opengl_camera_sees_its_minus_z_and_up_as_up() {
        // A point on an OpenGL camera's −z axis lands at the principal point; one along its +y
        // (up) axis lands above it: v decreases by f·0.3/3 = 10 px.
        let r_gl = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), 0.7).into_inner();
        let c2w_gl = Se3::new(r_gl, Vector3::new(0.3, -1.0, 2.0));
        let cam = Camera::from_camera_to_world(
            Intrinsics::centered(100.0, 64, 48),
            opengl_to_opencv(&c2w_gl),
        );
        let ahead = c2w_gl.transform_point(&Vector3::new(0.0, 0.0, -3.0));
        let (u, v, z) = cam.project(&ahead).unwrap();
        assert!((u - 32.0).abs() < 1e-12 && (v - 24.0).abs() < 1e-12 && (z - 3.0).abs() < 1e-12);
        let up = c2w_gl.transform_point(&Vector3::new(0.0, 0.3, -3.0));
        let (u, v, _) = cam.project(&up).unwrap();
        assert!((u - 32.0).abs() < 1e-12 && (v - (24.0 - 10.0)).abs() < 1e-12);
        let back = opengl_to_opencv(&opengl_to_opencv(&c2w_gl));
        assert_eq!(back, c2w_gl);
        assert!((cam.world_to_camera.rotation.determinant() - 1.0).abs() < 1e-12);
    }
}
