//! Object File Format (OFF, and COFF with per-vertex RGB(A) colours): counts line, vertices,
//! polygon faces (fan-triangulated). `#` starts a comment.

use std::io::Write;
use std::path::Path;

use crate::error::{GeomError, Result};
use crate::mesh::Mesh;

pub fn read(path: &Path) -> Result<Mesh> {
    let text = std::fs::read_to_string(path).map_err(|e| GeomError::io(path, e))?;
    parse(&text).map_err(|m| GeomError::format(path, m))
}

fn parse(text: &str) -> std::result::Result<Mesh, String> {
    let mut lines = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty());
    let first = lines.next().ok_or("empty file")?;
    let (coloured, counts_inline) = match first.split_ascii_whitespace().next() {
        Some("OFF") => (false, first.len() > 3),
        Some("COFF") => (true, first.len() > 4),
        _ => return Err("not an OFF file (first word is not OFF/COFF)".into()),
    };
    let counts_line = if counts_inline {
        first
            .split_once(char::is_whitespace)
            .map(|x| x.1)
            .unwrap_or("")
    } else {
        lines.next().ok_or("no counts line")?
    };
    let counts: Vec<usize> = counts_line
        .split_ascii_whitespace()
        .map(|w| w.parse().map_err(|_| format!("bad count '{w}'")))
        .collect::<std::result::Result<_, String>>()?;
    let (nv, nf) = match counts.as_slice() {
        [nv, nf, ..] => (*nv, *nf),
        _ => return Err("counts line needs vertex and face counts".into()),
    };
    let mut mesh = Mesh::default();
    let mut colors = Vec::new();
    for i in 0..nv {
        let line = lines.next().ok_or(format!("file ends at vertex {i}"))?;
        let v: Vec<f32> = line
            .split_ascii_whitespace()
            .map(|w| {
                w.parse()
                    .map_err(|_| format!("vertex {i}: '{w}' is not a number"))
            })
            .collect::<std::result::Result<_, String>>()?;
        if v.len() < 3 {
            return Err(format!("vertex {i}: fewer than 3 coordinates"));
        }
        mesh.vertices.push([v[0], v[1], v[2]]);
        if coloured {
            if v.len() < 6 {
                return Err(format!("vertex {i}: COFF vertex without colour"));
            }
            let s = if v[3..6].iter().any(|&c| c > 1.0) {
                255.0
            } else {
                1.0
            };
            colors.push([v[3] / s, v[4] / s, v[5] / s]);
        }
    }
    for f in 0..nf {
        let line = lines.next().ok_or(format!("file ends at face {f}"))?;
        let w: Vec<i64> = line
            .split_ascii_whitespace()
            .map(|w| {
                w.parse()
                    .map_err(|_| format!("face {f}: '{w}' is not an integer"))
            })
            .collect::<std::result::Result<_, String>>()?;
        let n = *w.first().ok_or(format!("face {f}: empty"))? as usize;
        let idx = w
            .get(1..1 + n)
            .ok_or(format!("face {f}: fewer than {n} indices"))?;
        if n < 3 || idx.iter().any(|&i| i < 0 || i as usize >= nv) {
            return Err(format!("face {f}: bad polygon {idx:?}"));
        }
        for k in 1..n - 1 {
            mesh.faces
                .push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
        }
    }
    if coloured {
        mesh.colors = Some(colors);
    }
    Ok(mesh)
}

/// Writes OFF (COFF with 0–255 colours when the mesh has colours), atomically.
pub fn write(path: &Path, mesh: &Mesh) -> Result<()> {
    mesh.validate(&path.display().to_string())?;
    fewview_scene::atomic::write_with(path, |w| {
        writeln!(w, "{}", if mesh.colors.is_some() { "COFF" } else { "OFF" })?;
        writeln!(w, "{} {} 0", mesh.vertices.len(), mesh.faces.len())?;
        for (i, p) in mesh.vertices.iter().enumerate() {
            write!(w, "{} {} {}", p[0], p[1], p[2])?;
            if let Some(c) = &mesh.colors {
                let q = c[i].map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
                write!(w, " {} {} {} 255", q[0], q[1], q[2])?;
            }
            writeln!(w)?;
        }
        for f in &mesh.faces {
            writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
        }
        Ok(())
    })?;
    Ok(())
}
