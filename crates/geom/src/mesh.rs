//! Triangle meshes and point sets with optional per-vertex colours and normals.

use nalgebra::Vector3;

use crate::error::{GeomError, Result};

/// An indexed triangle mesh. Faces are counter-clockwise seen from the side their normal points
/// to (right-hand rule), so `(v1 − v0) × (v2 − v0)` is the outward normal of a closed surface.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// RGB in `[0, 1]`, one per vertex, when known.
    pub colors: Option<Vec<[f32; 3]>>,
    /// Unit normals, one per vertex, when known.
    pub normals: Option<Vec<[f32; 3]>>,
}

/// A point set with optional colours and normals (one per point).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Points {
    pub positions: Vec<[f32; 3]>,
    pub colors: Option<Vec<[f32; 3]>>,
    pub normals: Option<Vec<[f32; 3]>>,
}

impl Points {
    pub fn from_positions(positions: Vec<[f32; 3]>) -> Self {
        Self {
            positions,
            colors: None,
            normals: None,
        }
    }
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    /// The subset at `indices`, in that order, with colours and normals.
    pub fn select(&self, indices: &[usize]) -> Points {
        Points {
            positions: indices.iter().map(|&i| self.positions[i]).collect(),
            colors: self
                .colors
                .as_ref()
                .map(|c| indices.iter().map(|&i| c[i]).collect()),
            normals: self
                .normals
                .as_ref()
                .map(|n| indices.iter().map(|&i| n[i]).collect()),
        }
    }
    /// Checks that colours/normals match the positions and every coordinate is finite.
    pub fn validate(&self, what: &str) -> Result<()> {
        check_attr_len(what, "colors", self.colors.as_ref(), self.positions.len())?;
        check_attr_len(what, "normals", self.normals.as_ref(), self.positions.len())?;
        check_finite(what, &self.positions)
    }
}

impl From<fewview_scene::PointCloud> for Points {
    fn from(pc: fewview_scene::PointCloud) -> Self {
        let colors = (pc.colors.len() == pc.positions.len()).then_some(pc.colors);
        Points {
            positions: pc.positions,
            colors,
            normals: None,
        }
    }
}

impl From<Points> for fewview_scene::PointCloud {
    fn from(p: Points) -> Self {
        let n = p.positions.len();
        fewview_scene::PointCloud {
            positions: p.positions,
            colors: p.colors.unwrap_or_else(|| vec![[0.5; 3]; n]),
            ..Default::default()
        }
    }
}

fn check_attr_len(what: &str, name: &str, attr: Option<&Vec<[f32; 3]>>, n: usize) -> Result<()> {
    if let Some(a) = attr
        && a.len() != n
    {
        return Err(GeomError::invalid(
            what,
            format!("{} {name} for {n} vertices", a.len()),
        ));
    }
    Ok(())
}

fn check_finite(what: &str, positions: &[[f32; 3]]) -> Result<()> {
    if let Some(i) = positions
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        return Err(GeomError::invalid(
            what,
            format!("vertex {i} is not finite ({:?})", positions[i]),
        ));
    }
    Ok(())
}

/// A point as an `f64` vector.
#[inline]
pub fn v3(p: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// An `f64` vector as an `f32` point.
#[inline]
pub fn f3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

impl Mesh {
    pub fn new(vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>) -> Self {
        Self {
            vertices,
            faces,
            colors: None,
            normals: None,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.faces.is_empty()
    }

    /// Checks indices, attribute lengths and finiteness; `what` names the mesh in the error.
    pub fn validate(&self, what: &str) -> Result<()> {
        let n = self.vertices.len();
        check_attr_len(what, "colors", self.colors.as_ref(), n)?;
        check_attr_len(what, "normals", self.normals.as_ref(), n)?;
        check_finite(what, &self.vertices)?;
        if let Some((fi, f)) = self
            .faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&i| i as usize >= n))
        {
            return Err(GeomError::invalid(
                what,
                format!("face {fi} {f:?} indexes past the {n} vertices"),
            ));
        }
        Ok(())
    }

    /// `(v1 − v0) × (v2 − v0)` of face `f`: twice its area times its unit normal.
    pub fn face_cross(&self, f: usize) -> Vector3<f64> {
        let [a, b, c] = self.faces[f].map(|i| v3(&self.vertices[i as usize]));
        (b - a).cross(&(c - a))
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        (0..self.faces.len())
            .map(|f| 0.5 * self.face_cross(f).norm())
            .sum()
    }

    /// Area-weighted vertex normals (unit length; zero for vertices of degenerate faces only).
    pub fn vertex_normals(&self) -> Vec<[f32; 3]> {
        let mut acc = vec![Vector3::<f64>::zeros(); self.vertices.len()];
        for (f, face) in self.faces.iter().enumerate() {
            let n = self.face_cross(f);
            for &i in face {
                acc[i as usize] += n;
            }
        }
        acc.iter()
            .map(|n| {
                let l = n.norm();
                if l > 0.0 { f3(&(n / l)) } else { [0.0; 3] }
            })
            .collect()
    }

    /// Signed volume enclosed (divergence theorem); positive for a closed, outward-oriented mesh.
    pub fn signed_volume(&self) -> f64 {
        self.faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| v3(&self.vertices[i as usize]));
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Axis-aligned bounding box `(min, max)`; `None` for a mesh without vertices.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        bounds(&self.vertices)
    }

    /// Keeps the vertices with `keep[i]`, the faces whose three vertices are all kept, and
    /// re-indexes.
    pub fn retain_vertices(&self, keep: &[bool]) -> Mesh {
        let mut remap = vec![u32::MAX; self.vertices.len()];
        let mut next = 0u32;
        for (i, &k) in keep.iter().enumerate() {
            if k {
                remap[i] = next;
                next += 1;
            }
        }
        let pick = |attr: &Vec<[f32; 3]>| -> Vec<[f32; 3]> {
            attr.iter()
                .zip(keep)
                .filter(|(_, k)| **k)
                .map(|(a, _)| *a)
                .collect()
        };
        let faces = self
            .faces
            .iter()
            .filter_map(|f| {
                let g = f.map(|i| remap[i as usize]);
                g.iter().all(|&i| i != u32::MAX).then_some(g)
            })
            .collect();
        Mesh {
            vertices: pick(&self.vertices),
            faces,
            colors: self.colors.as_ref().map(pick),
            normals: self.normals.as_ref().map(pick),
        }
    }

    /// Keeps the faces with `keep[f]` and drops vertices no kept face uses.
    pub fn retain_faces(&self, keep: &[bool]) -> Mesh {
        let faces: Vec<[u32; 3]> = self
            .faces
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(f, _)| *f)
            .collect();
        let mut used = vec![false; self.vertices.len()];
        for f in &faces {
            for &i in f {
                used[i as usize] = true;
            }
        }
        Mesh {
            faces,
            ..self.clone()
        }
        .retain_vertices(&used)
    }

    /// The vertices (with their colours and normals) as a point set.
    pub fn to_points(&self) -> Points {
        Points {
            positions: self.vertices.clone(),
            colors: self.colors.clone(),
            normals: self.normals.clone(),
        }
    }
}

/// Axis-aligned bounding box of points; `None` when empty.
pub fn bounds(points: &[[f32; 3]]) -> Option<([f32; 3], [f32; 3])> {
    let first = *points.first()?;
    let mut lo = first;
    let mut hi = first;
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    Some((lo, hi))
}

/// Length of the bounding-box diagonal (0 when empty).
pub fn bbox_diagonal(points: &[[f32; 3]]) -> f64 {
    bounds(points)
        .map(|(lo, hi)| (v3(&hi) - v3(&lo)).norm())
        .unwrap_or(0.0)
}

#[cfg(test)]
pub(crate) use tests::cube as test_cube;

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube, outward-oriented.
    pub(crate) fn cube() -> Mesh {
        let v = vec![
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [0., 0., 1.],
            [1., 0., 1.],
            [1., 1., 1.],
            [0., 1., 1.],
        ];
        let f = vec![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [2, 3, 7],
            [2, 7, 6],
            [1, 2, 6],
            [1, 6, 5],
            [0, 4, 7],
            [0, 7, 3],
        ];
        Mesh::new(v, f)
    }

    #[test]
    fn cube_area_volume_normals() {
        let m = cube();
        assert!((m.area() - 6.0).abs() < 1e-12);
        assert!((m.signed_volume() - 1.0).abs() < 1e-12);
        let n = m.vertex_normals();
        // Vertex 0 = (0,0,0) has two faces on each of its three sides: its normal points along
        // −(1,1,1)/√3.
        let s = -1.0 / 3f32.sqrt();
        for k in 0..3 {
            assert!((n[0][k] - s).abs() < 1e-6, "{:?}", n[0]);
        }
    }

    #[test]
    fn retain_reindexes() {
        let m = cube();
        let mut keep = vec![true; 8];
        keep[6] = false;
        let r = m.retain_vertices(&keep);
        assert_eq!(r.vertices.len(), 7);
        // 12 faces, of which those touching vertex 6 (5 of them) go.
        assert_eq!(r.faces.len(), 7);
        r.validate("retained").unwrap();
    }

    #[test]
    fn validate_catches_bad_index_and_nan() {
        let mut m = cube();
        m.faces.push([0, 1, 99]);
        assert!(m.validate("m").unwrap_err().to_string().contains("face 12"));
        let mut m = cube();
        m.vertices[3][1] = f32::NAN;
        assert!(
            m.validate("m")
                .unwrap_err()
                .to_string()
                .contains("vertex 3")
        );
    }
}
