//! The header of a Gaussian PLY as the page reads it. The page parses the vertex rows itself as
//! they stream in; the server checks the header first, so that a file the page cannot draw is
//! a one-line error before anything is served, and hands the page the row layout.
//!
//! Readable: the Inria 3DGS layout (`fewview_splat::ply` writes it) in binary little-endian,
//! one `vertex` element first, its properties in any order, extra scalar properties of any type
//! (skipped), and `float` for the ones drawn: `x y z f_dc_0..2 opacity scale_0..2 rot_0..3` and
//! 0, 9, 24 or 45 `f_rest_*` (SH degree 0–3, channel-major). ASCII and big-endian files, list
//! properties and `double` parameters are refused with the reason.

use std::collections::BTreeMap;
use std::io::BufReader;
use std::path::Path;

use fewview_scene::ply::{PlyEncoding, read_header};
use fewview_scene::ply_scalar::PlyScalar;
use serde::Serialize;

use crate::error::{Result, ViewError};

/// The layout of a Gaussian PLY's vertex rows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GaussianPly {
    /// Number of Gaussians.
    pub count: usize,
    /// SH degree, from the number of `f_rest_*` properties.
    pub sh_degree: usize,
    /// Bytes before the first row (the header, `end_header\n` included).
    pub header_bytes: usize,
    /// Bytes per row.
    pub stride: usize,
    /// Byte offset inside a row of each drawn property (all `float`).
    pub offsets: BTreeMap<String, usize>,
    /// Size of the whole file.
    pub file_bytes: u64,
}

/// The names of the properties the page draws, for SH degree `degree`.
fn drawn(degree: usize) -> Vec<String> {
    let mut names: Vec<String> = ["x", "y", "z"]
        .iter()
        .map(std::string::ToString::to_string)
        .collect();
    names.extend((0..3).map(|c| format!("f_dc_{c}")));
    let rest = 3 * ((degree + 1) * (degree + 1) - 1);
    names.extend((0..rest).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    names
}

/// Reads and checks the header of the Gaussian PLY at `path` (and that the file holds every
/// row it announces).
pub fn check_gaussian_ply(path: &Path) -> Result<GaussianPly> {
    let file = std::fs::File::open(path).map_err(|e| ViewError::io(path, e))?;
    let file_bytes = file.metadata().map_err(|e| ViewError::io(path, e))?.len();
    let mut r = BufReader::new(file);
    let bad = |m: String| ViewError::format(path, m);
    let header = read_header(&mut r).map_err(bad)?;
    if header.encoding != PlyEncoding::BinaryLittleEndian {
        return Err(bad(format!(
            "the viewer reads binary little-endian PLY, this one is {:?}",
            header.encoding
        )));
    }
    let header_bytes = header.bytes;
    let (count, props) = header.leading_vertex().map_err(bad)?;
    if count == 0 {
        return Err(bad("holds no Gaussians (vertex count 0)".into()));
    }
    let rest = props
        .iter()
        .filter(|(n, _)| n.starts_with("f_rest_"))
        .count();
    let sh_degree = match rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => {
            return Err(bad(format!(
                "{n} f_rest properties: not SH degree 0–3 (0, 9, 24 or 45)"
            )));
        }
    };
    let mut offset = 0;
    let mut all = BTreeMap::new();
    for (name, ty) in &props {
        all.insert(name.clone(), (offset, *ty));
        offset += ty.size();
    }
    let stride = offset;
    let mut offsets = BTreeMap::new();
    for name in drawn(sh_degree) {
        match all.get(&name) {
            None => {
                return Err(bad(format!(
                    "not a Gaussian splat PLY: no `{name}` property (the Inria 3DGS layout is \
                     x y z f_dc_* f_rest_* opacity scale_* rot_*)"
                )));
            }
            Some((_, ty)) if *ty != PlyScalar::F32 => {
                return Err(bad(format!(
                    "property {name} is {ty:?}; the viewer reads Gaussian parameters as `float`"
                )));
            }
            Some((o, _)) => {
                offsets.insert(name, *o);
            }
        }
    }
    let need = header_bytes as u64 + count as u64 * stride as u64;
    if file_bytes < need {
        return Err(bad(format!(
            "truncated: {count} Gaussians need {need} bytes, the file has {file_bytes}"
        )));
    }
    Ok(GaussianPly {
        count,
        sh_degree,
        header_bytes,
        stride,
        offsets,
        file_bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(props: &[&str], count: usize, format: &str) -> String {
        let mut h = format!("ply\nformat {format} 1.0\nelement vertex {count}\n");
        for p in props {
            h += &format!("property float {p}\n");
        }
        h + "end_header\n"
    }

    const PROPS: [&str; 17] = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0",
        "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ];

    #[test]
    fn reads_the_inria_layout_and_its_offsets() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.ply");
        let h = header(&PROPS, 2, "binary_little_endian");
        let mut bytes = h.clone().into_bytes();
        bytes.extend(vec![0u8; 2 * 17 * 4]);
        std::fs::write(&path, bytes).unwrap();
        let p = check_gaussian_ply(&path).unwrap();
        assert_eq!(
            (p.count, p.sh_degree, p.header_bytes, p.stride),
            (2, 0, h.len(), 68)
        );
        assert_eq!(p.offsets["f_dc_0"], 24);
        assert_eq!(p.offsets["rot_3"], 64);
        assert!(!p.offsets.contains_key("nx"));
    }

    #[test]
    fn refuses_what_the_page_cannot_draw_in_one_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.ply");
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"hello\n".to_vec(), "not a PLY"),
            (b"ply\nformat ascii 1.0\n".to_vec(), "before `end_header`"),
            (
                header(&PROPS, 1, "ascii").into_bytes(),
                "binary little-endian",
            ),
            (
                header(&PROPS[..9], 1, "binary_little_endian").into_bytes(),
                "no `opacity`",
            ),
            (
                header(&PROPS, 3, "binary_little_endian").into_bytes(),
                "truncated",
            ),
            (
                header(&PROPS, 0, "binary_little_endian").into_bytes(),
                "no Gaussians",
            ),
        ];
        for (bytes, needle) in cases {
            std::fs::write(&path, bytes).unwrap();
            let e = check_gaussian_ply(&path).unwrap_err().to_string();
            assert!(e.contains(needle) && !e.contains('\n'), "{e}");
            assert!(e.contains("a.ply"), "{e}");
        }
    }
}
