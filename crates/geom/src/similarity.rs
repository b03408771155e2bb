//! Similarity transforms `x ↦ s·R·x + t` and their least-squares estimate from point pairs
//! (Umeyama 1991).

use nalgebra::{Matrix3, Matrix4, Vector3};
use serde::Serialize;

use crate::error::{GeomError, Result};

/// `x ↦ scale · rotation · x + translation`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Similarity {
    pub scale: f64,
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
}

impl Default for Similarity {
    fn default() -> Self {
        Self::identity()
    }
}

impl Similarity {
    pub fn identity() -> Self {
        Self {
            scale: 1.0,
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    pub fn new(scale: f64, rotation: Matrix3<f64>, translation: Vector3<f64>) -> Self {
        Self {
            scale,
            rotation,
            translation,
        }
    }

    pub fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * x * self.scale + self.translation
    }

    /// A world-to-camera pose of the source world as a pose of the mapped world: the camera
    /// centre is mapped, its axes rotated (pinhole projection is unchanged by the scale).
    pub fn apply_to_pose(&self, world_to_camera: &fewview_scene::Se3) -> fewview_scene::Se3 {
        let c2w = world_to_camera.inverse();
        fewview_scene::Se3::new(self.rotation * c2w.rotation, self.apply(&c2w.translation))
            .inverse()
    }

    /// Applies to `f32` points.
    pub fn apply_points(&self, pts: &[[f32; 3]]) -> Vec<[f32; 3]> {
        pts.iter()
            .map(|p| crate::mesh::f3(&self.apply(&crate::mesh::v3(p))))
            .collect()
    }

    /// A copy of `mesh` in the mapped world: vertices mapped, normals rotated (a positive scale
    /// keeps the faces' orientation), faces and colours as they are.
    pub fn apply_to_mesh(&self, mesh: &crate::mesh::Mesh) -> crate::mesh::Mesh {
        let rotate = |n: &[f32; 3]| crate::mesh::f3(&(self.rotation * crate::mesh::v3(n)));
        crate::mesh::Mesh {
            vertices: self.apply_points(&mesh.vertices),
            normals: mesh
                .normals
                .as_ref()
                .map(|ns| ns.iter().map(rotate).collect()),
            ..mesh.clone()
        }
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Similarity) -> Similarity {
        Similarity {
            scale: self.scale * other.scale,
            rotation: self.rotation * other.rotation,
            translation: self.apply(&other.translation),
        }
    }

    pub fn inverse(&self) -> Similarity {
        let rt = self.rotation.transpose();
        Similarity {
            scale: 1.0 / self.scale,
            rotation: rt,
            translation: -(rt * self.translation) / self.scale,
        }
    }

    /// The 4×4 matrix `[sR | t; 0 0 0 1]`.
    pub fn to_matrix4(&self) -> Matrix4<f64> {
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(self.rotation * self.scale));
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.translation);
        m
    }

    /// Splits `[sR | t]` (scale from the cube root of the determinant, which must be positive).
    pub fn from_matrix4(m: &Matrix4<f64>) -> Result<Similarity> {
        let a: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
        let det = a.determinant();
        if !(det > 0.0) || !det.is_finite() {
            return Err(GeomError::invalid(
                "transform",
                format!("3×3 part has determinant {det} (not a similarity)"),
            ));
        }
        let s = det.cbrt();
        let rotation = a / s;
        // A shear or an uneven scale has a positive determinant too; it is no similarity. The
        // tolerance admits matrices printed with five or six significant digits.
        let off = (rotation.transpose() * rotation - Matrix3::identity())
            .abs()
            .max();
        if off > 1e-4 {
            return Err(GeomError::invalid(
                "transform",
                format!("3×3 part is not a scaled rotation (|RᵀR − I| = {off:.1e})"),
            ));
        }
        let bottom = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)] - 1.0];
        if bottom.iter().any(|v| v.abs() > 1e-9) {
            return Err(GeomError::invalid(
                "transform",
                "last row is not 0 0 0 1 (a projective map, not a similarity)",
            ));
        }
        Ok(Similarity {
            scale: s,
            rotation,
            translation: m.fixed_view::<3, 1>(0, 3).into_owned(),
        })
    }

    /// From the rows of `[sR | t; 0 0 0 1]` (see [`from_matrix4`](Self::from_matrix4)).
    pub fn from_rows(rows: &[[f64; 4]; 4]) -> Result<Similarity> {
        Self::from_matrix4(&Matrix4::from_fn(|r, c| rows[r][c]))
    }

    /// The rows of [`to_matrix4`](Self::to_matrix4), for JSON output.
    pub fn matrix_rows(&self) -> [[f64; 4]; 4] {
        let m = self.to_matrix4();
        std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
    }
}

/// Angle of a rotation matrix in degrees (`acos((tr − 1)/2)`, argument clamped to [−1, 1]).
pub fn rotation_angle_deg(r: &Matrix3<f64>) -> f64 {
    ((r.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// The similarity (or, with `with_scale = false`, rigid transform) minimising
/// `Σ ‖dst_i − (s R src_i + t)‖²` (Umeyama 1991), with `det R = +1`. Needs three or more
/// non-collinear points.
pub fn umeyama(src: &[Vector3<f64>], dst: &[Vector3<f64>], with_scale: bool) -> Result<Similarity> {
    if src.len() != dst.len() {
        return Err(GeomError::invalid(
            "point pairs",
            format!("{} source vs {} target points", src.len(), dst.len()),
        ));
    }
    let n = src.len();
    if n < 3 {
        return Err(GeomError::invalid(
            "point pairs",
            format!("{n} pairs; need at least 3"),
        ));
    }
    let nf = n as f64;
    let mu_s = src.iter().sum::<Vector3<f64>>() / nf;
    let mu_d = dst.iter().sum::<Vector3<f64>>() / nf;
    let mut cov = Matrix3::zeros();
    let mut var_s = 0.0;
    for (s, d) in src.iter().zip(dst) {
        let (a, b) = (s - mu_s, d - mu_d);
        cov += b * a.transpose();
        var_s += a.norm_squared();
    }
    cov /= nf;
    var_s /= nf;
    if !cov.iter().all(|v| v.is_finite()) {
        return Err(GeomError::invalid("point pairs", "non-finite coordinates"));
    }
    let svd = cov.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(GeomError::numerical("SVD failed in Umeyama alignment"));
    };
    let sv = svd.singular_values;
    let scale_ref = sv[0].max(f64::MIN_POSITIVE);
    // Rank < 2 (all points on a line or at one spot): the rotation is not determined.
    let mut sorted = [sv[0], sv[1], sv[2]];
    sorted.sort_by(|a, b| b.total_cmp(a));
    if sorted[1] <= 1e-12 * scale_ref || var_s <= 0.0 {
        return Err(GeomError::numerical(
            "points are collinear or coincident: rotation is undetermined",
        ));
    }
    let mut s_diag = Vector3::new(1.0, 1.0, 1.0);
    if (u.determinant() * vt.determinant()) < 0.0 {
        // Flip the axis of the smallest singular value.
        let imin = (0..3).min_by(|&a, &b| sv[a].total_cmp(&sv[b])).unwrap_or(2);
        s_diag[imin] = -1.0;
    }
    let rotation = u * Matrix3::from_diagonal(&s_diag) * vt;
    let scale = if with_scale {
        (sv.component_mul(&s_diag)).sum() / var_s
    } else {
        1.0
    };
    let translation = mu_d - rotation * mu_s * scale;
    Ok(Similarity {
        scale,
        rotation,
        translation,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};
    use rand::{RngExt, SeedableRng};

    pub(crate) fn random_similarity(seed: u64) -> Similarity {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let axis = Unit::new_normalize(Vector3::new(
            rng.random::<f64>() - 0.5,
            rng.random::<f64>() - 0.5,
            rng.random::<f64>() - 0.5,
        ));
        let angle = rng.random::<f64>() * std::f64::consts::PI;
        Similarity::new(
            0.5 + rng.random::<f64>() * 1.5,
            Rotation3::from_axis_angle(&axis, angle).into_inner(),
            Vector3::new(rng.random(), rng.random(), rng.random()) * 4.0 - Vector3::repeat(2.0),
        )
    }

    #[test]
    fn umeyama_recovers_a_similarity() {
        let t = random_similarity(1);
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let src: Vec<Vector3<f64>> = (0..20)
            .map(|_| Vector3::new(rng.random(), rng.random(), rng.random()))
            .collect();
        let dst: Vec<Vector3<f64>> = src.iter().map(|p| t.apply(p)).collect();
        let e = umeyama(&src, &dst, true).unwrap();
        assert!((e.scale - t.scale).abs() < 1e-10);
        assert!((e.rotation - t.rotation).norm() < 1e-10);
        assert!((e.translation - t.translation).norm() < 1e-10);
        let rigid = umeyama(&src, &dst, false).unwrap();
        assert_eq!(rigid.scale, 1.0);
        assert!((rigid.rotation - t.rotation).norm() < 1e-10);
        // Inverse and composition.
        let id = t.compose(&t.inverse());
        assert!((id.apply(&src[3]) - src[3]).norm() < 1e-12);
        let back = Similarity::from_matrix4(&t.to_matrix4()).unwrap();
        assert!(
            (back.scale - t.scale).abs() < 1e-12 && (back.rotation - t.rotation).norm() < 1e-12
        );
        // A reflection-free answer even for mirrored data.
        let mirrored: Vec<Vector3<f64>> =
            src.iter().map(|p| Vector3::new(-p.x, p.y, p.z)).collect();
        assert!(
            umeyama(&src, &mirrored, true)
                .unwrap()
                .rotation
                .determinant()
                > 0.0
        );
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        let line: Vec<Vector3<f64>> = (0..5).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        assert!(umeyama(&line, &line, true).is_err());
        assert!(umeyama(&line[..2], &line[..2], true).is_err());
        assert!(umeyama(&line, &line[..4], true).is_err());
    }

    /// A mapped tetrahedron: its edges scale by `s`, each face's cross-product normal (from the
    /// mapped vertices) is the original one turned by `R` (orientation kept), and the stored
    /// vertex normals are turned alike.
    #[test]
    fn a_mapped_mesh_keeps_its_shape_and_orientation() {
        let mut mesh = crate::mesh::Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        );
        let third = 1.0 / 3f32.sqrt();
        mesh.normals = Some(vec![
            [-third; 3],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ]);
        mesh.colors = Some(vec![[0.1, 0.2, 0.3]; 4]);
        let sim = random_similarity(7);
        let mapped = sim.apply_to_mesh(&mesh);
        let v = |m: &crate::mesh::Mesh, i: u32| crate::mesh::v3(&m.vertices[i as usize]);
        for f in &mesh.faces {
            let normal =
                |m: &crate::mesh::Mesh| (v(m, f[1]) - v(m, f[0])).cross(&(v(m, f[2]) - v(m, f[0])));
            let expected = sim.rotation * normal(&mesh).normalize();
            assert!((normal(&mapped).normalize() - expected).norm() < 1e-6);
            let edge = |m: &crate::mesh::Mesh| (v(m, f[1]) - v(m, f[0])).norm();
            assert!((edge(&mapped) - sim.scale * edge(&mesh)).abs() < 1e-5 * sim.scale);
        }
        for (n, m) in mesh
            .normals
            .as_ref()
            .unwrap()
            .iter()
            .zip(mapped.normals.as_ref().unwrap())
        {
            let turned = sim.rotation * crate::mesh::v3(n);
            assert!((crate::mesh::v3(m) - turned).norm() < 1e-6);
        }
        assert_eq!((&mapped.faces, &mapped.colors), (&mesh.faces, &mesh.colors));
    }

    /// Only scaled rotations plus a translation are similarities: a shear, an uneven scale, a
    /// mirror or a projective last row are refused; a matrix printed to six digits is taken.
    #[test]
    fn only_similarities_are_read_from_matrices() {
        let t = random_similarity(3);
        let mut printed = t.to_matrix4();
        printed
            .iter_mut()
            .for_each(|v| *v = (*v * 1e5).round() / 1e5);
        let back = Similarity::from_matrix4(&printed).unwrap();
        assert!((back.scale - t.scale).abs() < 1e-4 * t.scale);
        let mut bad = [Matrix4::identity(); 4];
        bad[0][(0, 1)] = 0.1; // shear
        bad[1][(2, 2)] = 2.0; // uneven scale
        bad[2][(0, 0)] = -1.0; // mirror
        bad[3][(3, 0)] = 0.5; // projective
        for (k, m) in bad.iter().enumerate() {
            assert!(Similarity::from_matrix4(m).is_err(), "case {k} accepted");
        }
    }
}
