//! Mesh, point-cloud, depth-map, grid and camera files.
//!
//! Meshes and points: PLY (ASCII/binary), OBJ and OFF, chosen by extension. Depth maps: `.npy`
//! float32/float64 H×W, or 16-bit (or 8-bit) PNG with a scale (metres per unit). Grids: `.npy`
//! D0×D1×D2. Cameras: JSON (see [`cameras`]).

pub mod cameras;
pub mod obj;
pub mod off;
pub mod ply;

use std::path::Path;

pub use ply::PlyEncoding;

use crate::error::{GeomError, Result};
use crate::mesh::{Mesh, Points};

/// A mesh file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    Ply(PlyEncoding),
    Obj,
    Off,
}

impl MeshFormat {
    /// The format of a path's extension (`.ply` → binary little-endian PLY).
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("ply") => Ok(Self::Ply(PlyEncoding::BinaryLittleEndian)),
            Some("obj") => Ok(Self::Obj),
            Some("off") => Ok(Self::Off),
            _ => Err(GeomError::format(
                path,
                "unknown mesh extension (expected .ply, .obj or .off)",
            )),
        }
    }
}

/// Reads a mesh (PLY, OBJ or OFF by extension).
pub fn read_mesh(path: &Path) -> Result<Mesh> {
    match MeshFormat::from_path(path)? {
        MeshFormat::Ply(_) => ply::read(path),
        MeshFormat::Obj => obj::read(path),
        MeshFormat::Off => off::read(path),
    }
}

/// Writes a mesh atomically in the format of its extension (PLY: binary little-endian).
pub fn write_mesh(path: &Path, mesh: &Mesh) -> Result<()> {
    write_mesh_as(path, mesh, MeshFormat::from_path(path)?)
}

/// Writes a mesh atomically in the given format.
pub fn write_mesh_as(path: &Path, mesh: &Mesh, format: MeshFormat) -> Result<()> {
    match format {
        MeshFormat::Ply(enc) => ply::write(path, mesh, enc),
        MeshFormat::Obj => obj::write(path, mesh),
        MeshFormat::Off => off::write(path, mesh),
    }
}

/// Reads the vertices of a mesh or point-cloud file as points.
pub fn read_points(path: &Path) -> Result<Points> {
    let m = read_mesh(path)?;
    if m.vertices.is_empty() {
        return Err(GeomError::invalid(
            path.display().to_string(),
            "file has no points",
        ));
    }
    Ok(m.to_points())
}

/// Writes points as a face-less mesh file.
pub fn write_points(path: &Path, points: &Points) -> Result<()> {
    let mesh = Mesh {
        vertices: points.positions.clone(),
        faces: Vec::new(),
        colors: points.colors.clone(),
        normals: points.normals.clone(),
    };
    write_mesh(path, &mesh)
}

/// A float array read from `.npy`, with its shape.
pub struct NpyArray {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// Reads a float32/float64 (or bool, uint8, uint16, int32) `.npy` array in C order. A value that
/// is NaN, infinite or (float64) beyond float32 range is an error naming the file and the index.
pub fn read_npy(path: &Path) -> Result<NpyArray> {
    let a = read_npy_unchecked(path)?;
    if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(GeomError::format(
            path,
            format!(
                "value at index {:?} is {} (NaN, infinite, or beyond float32 range); the array must hold finite numbers",
                unravel(i, &a.shape),
                a.data[i]
            ),
        ));
    }
    Ok(a)
}

/// [`read_npy`] without the check that the values are finite.
fn read_npy_unchecked(path: &Path) -> Result<NpyArray> {
    let bytes = std::fs::read(path).map_err(|e| GeomError::io(path, e))?;
    let npy = npyz::NpyFile::new(&bytes[..])
        .map_err(|e| GeomError::format(path, format!("not a .npy file: {e}")))?;
    if npy.order() != npyz::Order::C {
        return Err(GeomError::format(
            path,
            "Fortran-order arrays are not supported",
        ));
    }
    let shape: Vec<usize> = npy.shape().iter().map(|&s| s as usize).collect();
    let bad = |e: std::io::Error| GeomError::format(path, format!("cannot read data: {e}"));
    let data: Vec<f32> = match npy.dtype() {
        npyz::DType::Plain(t) => match (t.type_char(), t.size_field()) {
            (npyz::TypeChar::Float, 4) => npy.into_vec::<f32>().map_err(bad)?,
            (npyz::TypeChar::Float, 8) => npy
                .into_vec::<f64>()
                .map_err(bad)?
                .into_iter()
                .map(|v| v as f32)
                .collect(),
            (npyz::TypeChar::Bool, 1) => npy
                .into_vec::<bool>()
                .map_err(bad)?
                .into_iter()
                .map(|v| v as u8 as f32)
                .collect(),
            (npyz::TypeChar::Uint, 1) => npy
                .into_vec::<u8>()
                .map_err(bad)?
                .into_iter()
                .map(|v| v as f32)
                .collect(),
            (npyz::TypeChar::Uint, 2) => npy
                .into_vec::<u16>()
                .map_err(bad)?
                .into_iter()
                .map(|v| v as f32)
                .collect(),
            (npyz::TypeChar::Int, 4) => npy
                .into_vec::<i32>()
                .map_err(bad)?
                .into_iter()
                .map(|v| v as f32)
                .collect(),
            (c, s) => {
                return Err(GeomError::format(
                    path,
                    format!("unsupported dtype {c:?}{s} (use float32)"),
                ));
            }
        },
        other => {
            return Err(GeomError::format(
                path,
                format!("unsupported dtype {other:?} (use float32)"),
            ));
        }
    };
    Ok(NpyArray { shape, data })
}

/// The C-order multi-index of flat index `i` in an array of `shape`.
fn unravel(mut i: usize, shape: &[usize]) -> Vec<usize> {
    let mut index = vec![0; shape.len()];
    for (slot, &n) in index.iter_mut().zip(shape).rev() {
        if n > 0 {
            *slot = i % n;
            i /= n;
        }
    }
    index
}

/// Writes a float32 `.npy` array in C order, atomically.
pub fn write_npy(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    use npyz::WriterBuilder;
    let shape64: Vec<u64> = shape.iter().map(|&s| s as u64).collect();
    fewview_scene::atomic::write_with(path, |w| {
        let mut writer = npyz::WriteOptions::new()
            .default_dtype()
            .shape(&shape64)
            .writer(w)
            .begin_nd()?;
        writer.extend(data.iter().copied())?;
        writer.finish()
    })?;
    Ok(())
}

/// A depth map: `width × height` z-depths (along the optical axis), row-major.
pub struct DepthMap {
    pub width: usize,
    pub height: usize,
    pub depth: Vec<f32>,
}

/// Reads a depth map: `.npy` float H×W (or H×W×1), taken as is; or a PNG (16- or 8-bit grey)
/// whose integer values are multiplied by `png_scale` (e.g. 0.001 for millimetre PNGs). A value
/// of 0 means "no depth" in either.
pub fn read_depth(path: &Path, png_scale: f32) -> Result<DepthMap> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("npy") => {
            let a = read_npy_unchecked(path)?;
            let (h, w) = match a.shape.as_slice() {
                [h, w] | [h, w, 1] => (*h, *w),
                s => {
                    return Err(GeomError::format(
                        path,
                        format!("depth must be H×W, found shape {s:?}"),
                    ));
                }
            };
            if let Some(i) = a.data.iter().position(|d| !d.is_finite()) {
                return Err(GeomError::format(
                    path,
                    format!(
                        "pixel ({}, {}) is {} (NaN/inf depth)",
                        i % w.max(1),
                        i / w.max(1),
                        a.data[i]
                    ),
                ));
            }
            Ok(DepthMap {
                width: w,
                height: h,
                depth: a.data,
            })
        }
        Some("png") => {
            let img = image::ImageReader::open(path)
                .map_err(|e| GeomError::io(path, e))?
                .decode()
                .map_err(|e| GeomError::format(path, format!("cannot decode PNG: {e}")))?;
            if img.color().channel_count() != 1 {
                return Err(GeomError::format(
                    path,
                    "depth PNG must be single-channel (16-bit grey)",
                ));
            }
            let (w, h) = (img.width() as usize, img.height() as usize);
            // Scale the stored integers: 8-bit files are read as 8-bit (not widened to 16).
            let raw: Vec<u16> = match img {
                image::DynamicImage::ImageLuma8(g) => {
                    g.into_raw().into_iter().map(u16::from).collect()
                }
                other => other.into_luma16().into_raw(),
            };
            let depth = raw.into_iter().map(|v| v as f32 * png_scale).collect();
            Ok(DepthMap {
                width: w,
                height: h,
                depth,
            })
        }
        _ => Err(GeomError::format(
            path,
            "unknown depth extension (expected .npy or .png)",
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_cube;

    fn coloured_cube() -> Mesh {
        let mut m = test_cube();
        m.colors = Some(
            (0..8)
                .map(|i| [i as f32 / 7.0, 1.0 - i as f32 / 7.0, 0.5])
                .collect(),
        );
        m.normals = Some(m.vertex_normals());
        m
    }

    fn close(a: &Mesh, b: &Mesh, colour_tol: f32) {
        assert_eq!(a.faces, b.faces);
        assert_eq!(a.vertices, b.vertices);
        if let (Some(ca), Some(cb)) = (&a.colors, &b.colors) {
            for (x, y) in ca.iter().flatten().zip(cb.iter().flatten()) {
                assert!((x - y).abs() <= colour_tol, "{x} vs {y}");
            }
        }
    }

    #[test]
    fn every_format_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let m = coloured_cube();
        for enc in [
            PlyEncoding::Ascii,
            PlyEncoding::BinaryLittleEndian,
            PlyEncoding::BinaryBigEndian,
        ] {
            let p = dir.path().join("a.ply");
            write_mesh_as(&p, &m, MeshFormat::Ply(enc)).unwrap();
            let r = read_mesh(&p).unwrap();
            close(&m, &r, 0.5 / 255.0 + 1e-6);
            assert_eq!(r.normals, m.normals, "{enc:?}");
        }
        for name in ["a.obj", "a.off"] {
            let p = dir.path().join(name);
            write_mesh(&p, &m).unwrap();
            close(&m, &read_mesh(&p).unwrap(), 0.5 / 255.0 + 1e-6);
        }
    }

    #[test]
    fn reads_hand_written_files_with_polygons_and_doubles() {
        let dir = tempfile::tempdir().unwrap();
        let ply = "ply\nformat ascii 1.0\ncomment x\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty float intensity\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n4 0 1 2 3\n";
        let p = dir.path().join("q.ply");
        std::fs::write(&p, ply).unwrap();
        let m = read_mesh(&p).unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
        let obj = "# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 -1//1\n";
        let p = dir.path().join("q.obj");
        std::fs::write(&p, obj).unwrap();
        assert_eq!(read_mesh(&p).unwrap().faces, vec![[0, 1, 2], [0, 2, 3]]);
        let off = "OFF\n# c\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        let p = dir.path().join("q.off");
        std::fs::write(&p, off).unwrap();
        assert_eq!(read_mesh(&p).unwrap().faces, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn bad_files_name_the_path_and_problem() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("trunc.ply");
        std::fs::write(
            &p,
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0",
        )
        .unwrap();
        let e = read_mesh(&p).unwrap_err().to_string();
        assert!(e.contains("trunc.ply") && e.contains("ends early"), "{e}");
        let p = dir.path().join("bad.obj");
        std::fs::write(&p, "v 0 0 0\nf 1 2 3\n").unwrap();
        let e = read_mesh(&p).unwrap_err().to_string();
        assert!(e.contains("bad.obj") && e.contains("outside"), "{e}");
        let p = dir.path().join("x.stl");
        assert!(read_mesh(&p).unwrap_err().to_string().contains("extension"));
        let p = dir.path().join("missing.ply");
        assert!(
            read_mesh(&p)
                .unwrap_err()
                .to_string()
                .contains("missing.ply")
        );
    }

    #[test]
    fn npy_and_png_depth() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.npy");
        let data: Vec<f32> = (0..6).map(|i| i as f32 * 0.5).collect();
        write_npy(&p, &[2, 3], &data).unwrap();
        let d = read_depth(&p, 1.0).unwrap();
        assert_eq!((d.width, d.height), (3, 2));
        assert_eq!(d.depth, data);
        let p = dir.path().join("d.png");
        let img =
            image::ImageBuffer::<image::Luma<u16>, _>::from_raw(2, 1, vec![1000u16, 2500]).unwrap();
        img.save(&p).unwrap();
        let d = read_depth(&p, 0.001).unwrap();
        assert_eq!(d.depth, vec![1.0, 2.5]);
    }

    /// A grid with ±inf (or a float64 beyond float32 range) is refused when reading, naming the
    /// file and the index; a depth map names the file and the pixel.
    #[test]
    fn non_finite_npy_values_name_the_file_and_index() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("grid.npy");
        for bad in [f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            let mut g = vec![0.5f32; 2 * 3 * 4];
            g[(3 + 2) * 4 + 1] = bad;
            write_npy(&p, &[2, 3, 4], &g).unwrap();
            let e = read_npy(&p).err().unwrap().to_string();
            assert!(e.contains("grid.npy: value at index [1, 2, 1] is "), "{e}");
        }
        let q = dir.path().join("f64.npy");
        npyz::to_file_1d(&q, vec![1.0f64, 1e300]).unwrap();
        let e = read_npy(&q).err().unwrap().to_string();
        assert!(e.contains("f64.npy: value at index [1] is inf"), "{e}");
        let d = dir.path().join("depth.npy");
        let mut data = vec![1.0f32; 6];
        data[4] = f32::NAN;
        write_npy(&d, &[2, 3], &data).unwrap();
        let e = read_depth(&d, 1.0).err().unwrap().to_string();
        assert!(e.contains("depth.npy: pixel (1, 1) is NaN"), "{e}");
    }
}
