//! Wavefront OBJ: `v x y z [r g b]` and `f` lines (polygons fan-triangulated, `i/t/n` forms and
//! negative indices accepted); everything else is skipped.

use std::io::Write;
use std::path::Path;

use crate::error::{GeomError, Result};
use crate::mesh::Mesh;

pub fn read(path: &Path) -> Result<Mesh> {
    let text = std::fs::read_to_string(path).map_err(|e| GeomError::io(path, e))?;
    parse(&text).map_err(|m| GeomError::format(path, m))
}

fn parse(text: &str) -> std::result::Result<Mesh, String> {
    let mut mesh = Mesh::default();
    let mut colors: Vec<[f32; 3]> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let mut words = line.split_ascii_whitespace();
        let num = |w: Option<&str>| -> std::result::Result<f32, String> {
            let w = w.ok_or(format!("line {}: too few numbers", ln + 1))?;
            w.parse()
                .map_err(|_| format!("line {}: '{w}' is not a number", ln + 1))
        };
        match words.next() {
            Some("v") => {
                let p = [num(words.next())?, num(words.next())?, num(words.next())?];
                mesh.vertices.push(p);
                let rest: Vec<&str> = words.collect();
                if rest.len() >= 3 {
                    colors.push([
                        num(Some(rest[0]))?,
                        num(Some(rest[1]))?,
                        num(Some(rest[2]))?,
                    ]);
                }
            }
            Some("f") => {
                let n = mesh.vertices.len() as i64;
                let idx: Vec<u32> = words
                    .map(|w| {
                        let first = w.split('/').next().unwrap_or("");
                        let i: i64 = first
                            .parse()
                            .map_err(|_| format!("line {}: bad face index '{w}'", ln + 1))?;
                        let i = if i < 0 { n + i } else { i - 1 };
                        if i < 0 || i >= n {
                            return Err(format!(
                                "line {}: face index {w} outside the {n} vertices so far",
                                ln + 1
                            ));
                        }
                        Ok(i as u32)
                    })
                    .collect::<std::result::Result<_, _>>()?;
                if idx.len() < 3 {
                    return Err(format!("line {}: face with fewer than 3 vertices", ln + 1));
                }
                for k in 1..idx.len() - 1 {
                    mesh.faces.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if !colors.is_empty() {
        if colors.len() != mesh.vertices.len() {
            return Err("only some vertices have colours".into());
        }
        mesh.colors = Some(colors);
    }
    mesh.validate("OBJ").map_err(|e| e.to_string())?;
    Ok(mesh)
}

/// Writes `v` lines (with colours when present) and 1-based `f` lines, atomically.
pub fn write(path: &Path, mesh: &Mesh) -> Result<()> {
    mesh.validate(&path.display().to_string())?;
    fewview_scene::atomic::write_with(path, |w| {
        writeln!(w, "# written by fewview-geom")?;
        for (i, p) in mesh.vertices.iter().enumerate() {
            match &mesh.colors {
                Some(c) => writeln!(
                    w,
                    "v {} {} {} {} {} {}",
                    p[0], p[1], p[2], c[i][0], c[i][1], c[i][2]
                )?,
                None => writeln!(w, "v {} {} {}", p[0], p[1], p[2])?,
            }
        }
        for f in &mesh.faces {
            writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
        }
        Ok(())
    })?;
    Ok(())
}
