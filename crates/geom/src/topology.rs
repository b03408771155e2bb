//! Mesh topology: edge use counts (watertightness, manifoldness, consistent orientation) and
//! connected components.

use std::collections::HashMap;

use crate::error::{GeomError, Result};
use crate::mesh::Mesh;

/// How the faces of a mesh meet along their edges.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EdgeReport {
    /// Undirected edges in all.
    pub edges: usize,
    /// Edges used by exactly one face (holes).
    pub boundary_edges: usize,
    /// Edges used by more than two faces.
    pub non_manifold_edges: usize,
    /// Edges shared by two faces that traverse them in the same direction (the two faces
    /// disagree on orientation).
    pub inconsistent_edges: usize,
    /// Faces with a repeated vertex index.
    pub degenerate_faces: usize,
}

impl EdgeReport {
    /// Every edge is shared by exactly two faces.
    pub fn is_watertight(&self) -> bool {
        self.boundary_edges == 0 && self.non_manifold_edges == 0
    }
    /// Watertight and every shared edge is traversed once in each direction.
    pub fn is_closed_oriented_manifold(&self) -> bool {
        self.is_watertight() && self.inconsistent_edges == 0 && self.degenerate_faces == 0
    }
}

/// Counts edge uses over all faces.
pub fn edge_report(mesh: &Mesh) -> EdgeReport {
    // Key: (min, max); value: (uses, uses in the min→max direction).
    let mut uses: HashMap<(u32, u32), (u32, u32)> = HashMap::with_capacity(mesh.faces.len() * 2);
    let mut degenerate = 0;
    for f in &mesh.faces {
        if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
            degenerate += 1;
            continue;
        }
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            let e = uses.entry((a.min(b), a.max(b))).or_insert((0, 0));
            e.0 += 1;
            if a < b {
                e.1 += 1;
            }
        }
    }
    let mut r = EdgeReport {
        edges: uses.len(),
        boundary_edges: 0,
        non_manifold_edges: 0,
        inconsistent_edges: 0,
        degenerate_faces: degenerate,
    };
    for &(n, forward) in uses.values() {
        match n {
            1 => r.boundary_edges += 1,
            2 => {
                if forward != 1 {
                    r.inconsistent_edges += 1;
                }
            }
            _ => r.non_manifold_edges += 1,
        }
    }
    r
}

/// Fails with a clear message when the mesh has edges shared by more than two faces; algorithms
/// that walk the surface (component labelling works on any mesh, but sampling normals or
/// orientation checks assume a manifold) call this first.
pub fn require_edge_manifold(mesh: &Mesh, what: &str) -> Result<()> {
    let r = edge_report(mesh);
    if r.non_manifold_edges > 0 {
        return Err(GeomError::invalid(
            what,
            format!(
                "mesh is not manifold: {} edges are shared by more than two faces",
                r.non_manifold_edges
            ),
        ));
    }
    Ok(())
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

/// Component label of every face (faces are connected through shared vertices), labels
/// `0..count` ordered by first appearance; returns `(labels, count)`.
pub fn face_components(mesh: &Mesh) -> (Vec<u32>, usize) {
    let n = mesh.vertices.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for f in &mesh.faces {
        let a = find(&mut parent, f[0]);
        for &v in &f[1..] {
            let b = find(&mut parent, v);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    let mut label_of_root: HashMap<u32, u32> = HashMap::new();
    let labels: Vec<u32> = mesh
        .faces
        .iter()
        .map(|f| {
            let r = find(&mut parent, f[0]);
            let next = label_of_root.len() as u32;
            *label_of_root.entry(r).or_insert(next)
        })
        .collect();
    (labels, label_of_root.len())
}

/// The connected component with the most faces (ties: the first), unused vertices dropped.
pub fn largest_component(mesh: &Mesh) -> Mesh {
    let (labels, count) = face_components(mesh);
    if count <= 1 {
        let keep = vec![true; mesh.faces.len()];
        return mesh.retain_faces(&keep);
    }
    let mut sizes = vec![0usize; count];
    for &l in &labels {
        sizes[l as usize] += 1;
    }
    let best = (0..count)
        .max_by_key(|&l| (sizes[l], usize::MAX - l))
        .unwrap_or(0) as u32;
    let keep: Vec<bool> = labels.iter().map(|&l| l == best).collect();
    mesh.retain_faces(&keep)
}

/// Removes components with fewer than `min_faces` faces.
pub fn remove_small_components(mesh: &Mesh, min_faces: usize) -> Mesh {
    let (labels, count) = face_components(mesh);
    let mut sizes = vec![0usize; count];
    for &l in &labels {
        sizes[l as usize] += 1;
    }
    let keep: Vec<bool> = labels
        .iter()
        .map(|&l| sizes[l as usize] >= min_faces)
        .collect();
    mesh.retain_faces(&keep)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_cube;

    #[test]
    fn cube_is_closed_and_oriented() {
        let r = edge_report(&test_cube());
        assert_eq!(r.edges, 18);
        assert!(r.is_closed_oriented_manifold(), "{r:?}");
    }

    #[test]
    fn flipped_face_and_hole_are_seen() {
        let mut m = test_cube();
        m.faces[0] = [m.faces[0][0], m.faces[0][2], m.faces[0][1]];
        let r = edge_report(&m);
        assert!(r.is_watertight());
        assert_eq!(r.inconsistent_edges, 3);
        m.faces.pop();
        assert_eq!(edge_report(&m).boundary_edges, 3);
    }

    #[test]
    fn non_manifold_is_an_error() {
        let mut m = test_cube();
        m.vertices.push([0.5, 0.5, -1.0]);
        m.faces.push([0, 1, 8]); // edge 0-1 now has three faces
        let err = require_edge_manifold(&m, "fin.obj")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("fin.obj") && err.contains("not manifold"),
            "{err}"
        );
    }

    #[test]
    fn largest_component_keeps_the_bigger_piece() {
        let mut m = test_cube();
        let base = m.vertices.len() as u32;
        m.vertices
            .extend([[5., 5., 5.], [6., 5., 5.], [5., 6., 5.]]);
        m.faces.push([base, base + 1, base + 2]);
        let (_, count) = face_components(&m);
        assert_eq!(count, 2);
        let l = largest_component(&m);
        assert_eq!(l.faces.len(), 12);
        assert_eq!(l.vertices.len(), 8);
        assert_eq!(remove_small_components(&m, 2).faces.len(), 12);
    }
}
