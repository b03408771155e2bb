//! PLY meshes and point clouds, through the workspace's one PLY codec
//! ([`fewview_scene::ply`]): read into a [`Mesh`] and checked, written from one.

use std::path::Path;

pub use fewview_scene::ply::PlyEncoding;
use fewview_scene::ply::PlyGeometry;

use crate::error::Result;
use crate::mesh::Mesh;

/// Reads a PLY mesh or point cloud (a file without faces gives a mesh with no faces); a face
/// naming a missing vertex or a non-finite coordinate is an error naming the file.
pub fn read(path: &Path) -> Result<Mesh> {
    let g = fewview_scene::ply::read(path)?;
    let mesh = Mesh {
        vertices: g.vertices,
        faces: g.faces,
        colors: g.colors,
        normals: g.normals,
    };
    mesh.validate(&format!("{}: PLY body", path.display()))?;
    Ok(mesh)
}

/// Writes a mesh (faces may be empty: a point cloud) atomically.
pub fn write(path: &Path, mesh: &Mesh, encoding: PlyEncoding) -> Result<()> {
    mesh.validate(&path.display().to_string())?;
    let geometry = PlyGeometry {
        vertices: mesh.vertices.clone(),
        faces: mesh.faces.clone(),
        colors: mesh.colors.clone(),
        normals: mesh.normals.clone(),
    };
    Ok(fewview_scene::ply::write(path, &geometry, encoding)?)
}
