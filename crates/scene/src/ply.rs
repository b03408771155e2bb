//! PLY (Stanford polygon format, Turk 1994): ASCII, binary little- and big-endian, the one
//! reader and writer of vertex-and-face files in the workspace (meshes and point clouds in
//! `fewview-geom`, the sparse points a nerfstudio `ply_file_path` names in [`crate::transforms`]).
//!
//! Reads any element layout and keeps what meshes and point clouds need: `vertex` with
//! `x y z`, optional `nx ny nz` and `red green blue` (integer colours are divided by the type's
//! maximum, float colours taken as they are), and `face` with a `vertex_indices` (or
//! `vertex_index`) list, polygons fan-triangulated. Other elements and properties are skipped.
//! Writes `float` coordinates/normals, `uchar` colours and `uchar int` face lists.

use std::io::Write;
use std::path::Path;

use crate::error::{Result, SceneError};
use crate::ply_scalar::PlyScalar;

/// The vertices (with their colours and normals when the file has them) and triangles of a PLY
/// file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyGeometry {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// RGB in `[0, 1]`, one per vertex.
    pub colors: Option<Vec<[f32; 3]>>,
    pub normals: Option<Vec<[f32; 3]>>,
}

/// Reads a PLY mesh or point cloud (a file without faces gives no faces). A file that is not
/// PLY, or whose body does not match its header, is an error naming it.
pub fn read(path: &Path) -> Result<PlyGeometry> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    parse(&bytes).map_err(|m| SceneError::format(path, m))
}

/// PLY body encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyEncoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// The value that means "full intensity" for a colour stored as `t`.
fn colour_scale(t: PlyScalar) -> f64 {
    match t {
        PlyScalar::U8 | PlyScalar::I8 => 255.0,
        PlyScalar::U16 | PlyScalar::I16 => 65535.0,
        _ => 1.0,
    }
}

/// The type of a PLY property: one value, or a list of values after a count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyPropertyKind {
    Scalar(PlyScalar),
    List { count: PlyScalar, item: PlyScalar },
}

/// A property of an element, as its header line declares it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlyProperty {
    pub name: String,
    pub kind: PlyPropertyKind,
}

/// An element of a PLY file (`vertex`, `face`, …): its row count and properties, in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlyElement {
    pub name: String,
    pub count: usize,
    pub properties: Vec<PlyProperty>,
}

/// A PLY header: the body's encoding, the elements in file order, and its length in bytes (the
/// `end_header` line included), where the body starts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlyHeader {
    pub encoding: PlyEncoding,
    pub elements: Vec<PlyElement>,
    pub bytes: usize,
}

impl PlyHeader {
    /// The row count and scalar properties of a `vertex` element that comes first and once, as
    /// readers that take the body row by row from its start need (Gaussian splat files); a
    /// list property, another element first, or a second `vertex` is an error.
    pub fn leading_vertex(&self) -> std::result::Result<(usize, Vec<(String, PlyScalar)>), String> {
        let vertex = match self.elements.as_slice() {
            [] => return Err("no `vertex` element".into()),
            [first, ..] if first.name != "vertex" => {
                return Err(format!(
                    "element `{}` comes before `vertex`; the vertices must come first",
                    first.name
                ));
            }
            [vertex, rest @ ..] if rest.iter().any(|e| e.name == "vertex") => {
                return Err(format!("two `vertex` elements ({} and more)", vertex.count));
            }
            [vertex, ..] => vertex,
        };
        let properties = vertex
            .properties
            .iter()
            .map(|p| match p.kind {
                PlyPropertyKind::Scalar(t) => Ok((p.name.clone(), t)),
                PlyPropertyKind::List { .. } => Err(format!(
                    "list property {} in `vertex` is not supported",
                    p.name
                )),
            })
            .collect::<std::result::Result<_, _>>()?;
        Ok((vertex.count, properties))
    }
}

/// The most header lines [`read_header`] reads before giving up (a Gaussian PLY has about 70).
pub const MAX_HEADER_LINES: usize = 10_000;

/// Reads the header at the start of `reader`, which is left at the first byte of the body.
/// Every PLY reader of the workspace (meshes and point clouds here, Gaussian models in
/// `fewview-splat`, the viewer's check in `fewview-view`) parses its header with this. Errors
/// are one line, for the caller to put after the file's name.
pub fn read_header(reader: &mut impl std::io::BufRead) -> std::result::Result<PlyHeader, String> {
    let mut bytes = 0;
    let mut line = Vec::new();
    let mut encoding = None;
    let mut elements: Vec<PlyElement> = Vec::new();
    for k in 0..=MAX_HEADER_LINES {
        line.clear();
        let n = reader
            .read_until(b'\n', &mut line)
            .map_err(|e| format!("reading the header: {e}"))?;
        if n == 0 {
            return Err(if k == 0 {
                "empty file, not a PLY".into()
            } else {
                "PLY header ends before `end_header`".into()
            });
        }
        bytes += n;
        let text = std::str::from_utf8(&line).map_err(|_| "the PLY header is not text")?;
        if k == 0 {
            if text.trim_end() != "ply" {
                return Err("not a PLY file (missing `ply` magic)".into());
            }
            continue;
        }
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        match words.as_slice() {
            ["format", fmt, _version] => {
                encoding = Some(match *fmt {
                    "ascii" => PlyEncoding::Ascii,
                    "binary_little_endian" => PlyEncoding::BinaryLittleEndian,
                    "binary_big_endian" => PlyEncoding::BinaryBigEndian,
                    other => return Err(format!("unknown PLY format `{other}`")),
                });
            }
            ["element", name, count] => elements.push(PlyElement {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| format!("bad {name} count `{count}`"))?,
                properties: Vec::new(),
            }),
            ["property", "list", c, i, name] => {
                let count = scalar_type(c, name)?;
                let item = scalar_type(i, name)?;
                property_of(&mut elements, name, PlyPropertyKind::List { count, item })?;
            }
            ["property", t, name] => {
                let kind = PlyPropertyKind::Scalar(scalar_type(t, name)?);
                property_of(&mut elements, name, kind)?;
            }
            ["end_header"] => {
                let encoding = encoding.ok_or("missing `format` line")?;
                return Ok(PlyHeader {
                    encoding,
                    elements,
                    bytes,
                });
            }
            ["comment" | "obj_info", ..] | [] => {}
            _ => return Err(format!("unexpected header line `{}`", text.trim_end())),
        }
    }
    Err(format!(
        "no `end_header` in the first {MAX_HEADER_LINES} lines"
    ))
}

fn scalar_type(t: &str, property: &str) -> std::result::Result<PlyScalar, String> {
    PlyScalar::parse(t).ok_or_else(|| format!("property {property} has unknown type `{t}`"))
}

fn property_of(
    elements: &mut [PlyElement],
    name: &str,
    kind: PlyPropertyKind,
) -> std::result::Result<(), String> {
    let element = elements
        .last_mut()
        .ok_or_else(|| format!("property {name} comes before any element"))?;
    element.properties.push(PlyProperty {
        name: name.to_string(),
        kind,
    });
    Ok(())
}

/// Reads numbers from the body in the file's encoding.
enum Body<'a> {
    Ascii(std::str::SplitAsciiWhitespace<'a>),
    Binary {
        bytes: &'a [u8],
        pos: usize,
        big: bool,
    },
}

impl Body<'_> {
    fn read(&mut self, t: PlyScalar) -> std::result::Result<f64, String> {
        match self {
            Body::Ascii(tokens) => {
                let tok = tokens.next().ok_or("file ends early")?;
                tok.parse::<f64>()
                    .map_err(|_| format!("'{tok}' is not a number"))
            }
            Body::Binary { bytes, pos, big } => {
                let n = t.size();
                let b = bytes.get(*pos..*pos + n).ok_or("file ends early")?;
                *pos += n;
                Ok(t.decode(b, !*big))
            }
        }
    }
}

fn parse(bytes: &[u8]) -> std::result::Result<PlyGeometry, String> {
    let header = read_header(&mut std::io::Cursor::new(bytes))?;
    let (encoding, elements) = (header.encoding, header.elements);
    let body_bytes = &bytes[header.bytes..];
    let mut body = match encoding {
        PlyEncoding::Ascii => Body::Ascii(
            std::str::from_utf8(body_bytes)
                .map_err(|_| "ASCII body is not text")?
                .split_ascii_whitespace(),
        ),
        PlyEncoding::BinaryLittleEndian | PlyEncoding::BinaryBigEndian => Body::Binary {
            bytes: body_bytes,
            pos: 0,
            big: encoding == PlyEncoding::BinaryBigEndian,
        },
    };
    let mut mesh = PlyGeometry::default();
    for el in &elements {
        let slot = |name: &str| el.properties.iter().position(|p| p.name == name);
        let is_vertex = el.name == "vertex";
        let is_face = el.name == "face";
        let xyz = [slot("x"), slot("y"), slot("z")];
        let nrm = [slot("nx"), slot("ny"), slot("nz")];
        let rgb = [slot("red"), slot("green"), slot("blue")];
        let idx = slot("vertex_indices").or_else(|| slot("vertex_index"));
        if is_vertex && xyz.iter().any(Option::is_none) {
            return Err("vertex element lacks x, y or z".into());
        }
        let has_n = is_vertex && nrm.iter().all(Option::is_some);
        let has_c = is_vertex && rgb.iter().all(Option::is_some);
        if is_vertex {
            mesh.vertices.reserve(el.count);
        }
        let mut normals = Vec::new();
        let mut colors = Vec::new();
        let mut scalars = vec![0.0f64; el.properties.len()];
        let mut list = Vec::new();
        for row in 0..el.count {
            for (pi, p) in el.properties.iter().enumerate() {
                match p.kind {
                    PlyPropertyKind::Scalar(t) => scalars[pi] = body.read(t)?,
                    PlyPropertyKind::List { count, item } => {
                        let n = body.read(count)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(format!("{} {row}: bad list length {n}", el.name));
                        }
                        let keep = is_face && Some(pi) == idx;
                        if keep {
                            list.clear();
                        }
                        for _ in 0..n as usize {
                            let v = body.read(item)?;
                            if keep {
                                list.push(v);
                            }
                        }
                    }
                }
            }
            if is_vertex {
                let g = |s: [Option<usize>; 3]| s.map(|i| scalars[i.unwrap_or(0)] as f32);
                mesh.vertices.push(g(xyz));
                if has_n {
                    normals.push(g(nrm));
                }
                if has_c {
                    let PlyPropertyKind::Scalar(t) = el.properties[rgb[0].unwrap_or(0)].kind else {
                        return Err("colour is a list".into());
                    };
                    let s = colour_scale(t) as f32;
                    colors.push(g(rgb).map(|v| v / s));
                }
            } else if is_face && idx.is_some() {
                if list.len() < 3 {
                    continue;
                }
                for k in 1..list.len() - 1 {
                    let tri = [list[0], list[k], list[k + 1]];
                    if tri.iter().any(|&i| i < 0.0 || i.fract() != 0.0) {
                        return Err(format!("face {row}: bad vertex index in {list:?}"));
                    }
                    mesh.faces.push(tri.map(|i| i as u32));
                }
            }
        }
        if has_n {
            mesh.normals = Some(normals);
        }
        if has_c {
            mesh.colors = Some(colors);
        }
    }
    Ok(mesh)
}

/// Writes vertices and faces (faces may be empty: a point cloud) atomically; colours and
/// normals, when given, must hold one entry per vertex (the caller checks).
pub fn write(path: &Path, mesh: &PlyGeometry, encoding: PlyEncoding) -> Result<()> {
    let fmt = match encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::BinaryBigEndian => "binary_big_endian",
    };
    let mut header = format!(
        "ply\nformat {fmt} 1.0\ncomment written by fewview\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        mesh.vertices.len()
    );
    if mesh.normals.is_some() {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    if mesh.colors.is_some() {
        header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    }
    if !mesh.faces.is_empty() {
        header += &format!(
            "element face {}\nproperty list uchar int vertex_indices\n",
            mesh.faces.len()
        );
    }
    header += "end_header\n";
    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    crate::atomic::write_with(path, |w| {
        w.write_all(header.as_bytes())?;
        let big = encoding == PlyEncoding::BinaryBigEndian;
        let f32b = |v: f32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let i32b = |v: i32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        for (i, p) in mesh.vertices.iter().enumerate() {
            let n = mesh.normals.as_ref().map(|n| n[i]);
            let c = mesh.colors.as_ref().map(|c| c[i].map(to_u8));
            if encoding == PlyEncoding::Ascii {
                write!(w, "{} {} {}", p[0], p[1], p[2])?;
                if let Some(n) = n {
                    write!(w, " {} {} {}", n[0], n[1], n[2])?;
                }
                if let Some(c) = c {
                    write!(w, " {} {} {}", c[0], c[1], c[2])?;
                }
                writeln!(w)?;
            } else {
                for v in p {
                    w.write_all(&f32b(*v))?;
                }
                if let Some(n) = n {
                    for v in n {
                        w.write_all(&f32b(v))?;
                    }
                }
                if let Some(c) = c {
                    w.write_all(&c)?;
                }
            }
        }
        for f in &mesh.faces {
            if encoding == PlyEncoding::Ascii {
                writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
            } else {
                w.write_all(&[3u8])?;
                for &i in f {
                    w.write_all(&i32b(i as i32))?;
                }
            }
        }
        Ok(())
    })
}
