//! The Inria 3DGS PLY layout (what every common splat viewer opens): one `vertex` element with
//! `x y z nx ny nz f_dc_0..2 f_rest_0..M opacity scale_0..2 rot_0..3` as `float`, binary
//! little-endian. `f_rest` is channel-major (`f_rest_{c·(K−1) + k−1}` is coefficient `k` of
//! channel `c`), as the reference code's `transpose(1, 2).flatten()`.
//!
//! Reading accepts any property order, extra properties (ignored), `float`/`double` and the
//! other scalar types, binary little/big-endian or ASCII.

use std::io::{BufReader, Read, Write};
use std::path::Path;

use fewview_scene::SceneError;
use fewview_scene::ply::{PlyEncoding, read_header};

use crate::model::GaussianModel;

/// Writes `model` as an Inria-layout binary PLY, atomically.
pub fn write_ply(path: &Path, model: &GaussianModel) -> Result<(), SceneError> {
    model
        .validate()
        .map_err(|m| SceneError::invalid(path, format!("cannot write Gaussians: {m}")))?;
    let n = model.len();
    let k = model.sh_coeffs;
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    header += &format!("element vertex {n}\n");
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"]
        .iter()
        .map(std::string::ToString::to_string)
        .collect();
    names.extend((0..3).map(|c| format!("f_dc_{c}")));
    names.extend((0..3 * (k - 1)).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    for name in &names {
        header += &format!("property float {name}\n");
    }
    header += "end_header\n";
    let mut body = Vec::with_capacity(n * names.len() * 4);
    let mut row = Vec::with_capacity(names.len());
    for i in 0..n {
        row.clear();
        row.extend_from_slice(&model.means[3 * i..3 * i + 3]);
        row.extend_from_slice(&[0.0; 3]);
        let sh = &model.sh[i * k * 3..(i + 1) * k * 3];
        row.extend_from_slice(&sh[0..3]);
        for c in 0..3 {
            for kk in 1..k {
                row.push(sh[kk * 3 + c]);
            }
        }
        row.push(model.opacity_logits[i]);
        row.extend_from_slice(&model.log_scales[3 * i..3 * i + 3]);
        row.extend_from_slice(&model.quats[4 * i..4 * i + 4]);
        for v in &row {
            body.extend_from_slice(&v.to_le_bytes());
        }
    }
    fewview_scene::atomic::write_with(path, |w| {
        w.write_all(header.as_bytes())?;
        w.write_all(&body)
    })
}

/// Reads a Gaussian PLY (Inria layout; see the module docs for what is accepted).
pub fn read_ply(path: &Path) -> Result<GaussianModel, SceneError> {
    let file = std::fs::File::open(path).map_err(|e| SceneError::io(path, e))?;
    let mut r = BufReader::new(file);
    let bad = |m: String| SceneError::format(path, m);
    let header = read_header(&mut r).map_err(bad)?;
    let (n, props) = header.leading_vertex().map_err(bad)?;
    if n == 0 {
        return Err(SceneError::invalid(
            path,
            "the model has no Gaussians (element vertex 0); was it written by a run that pruned every Gaussian?",
        ));
    }
    let col = |name: &str| props.iter().position(|(p, _)| p == name);
    let need = |name: &str| col(name).ok_or_else(|| bad(format!("missing property `{name}`")));
    let xyz = [need("x")?, need("y")?, need("z")?];
    let dc = [need("f_dc_0")?, need("f_dc_1")?, need("f_dc_2")?];
    let n_rest = (0..)
        .take_while(|i| col(&format!("f_rest_{i}")).is_some())
        .count();
    if n_rest % 3 != 0 || !matches!(n_rest / 3 + 1, 1 | 4 | 9 | 16) {
        return Err(bad(format!(
            "{n_rest} f_rest properties is not 3·((d+1)² − 1) for d ≤ 3"
        )));
    }
    let rest: Vec<usize> = (0..n_rest)
        .map(|i| col(&format!("f_rest_{i}")).expect("counted"))
        .collect();
    let opacity = need("opacity")?;
    let scale = [need("scale_0")?, need("scale_1")?, need("scale_2")?];
    let rot = [
        need("rot_0")?,
        need("rot_1")?,
        need("rot_2")?,
        need("rot_3")?,
    ];
    let k = n_rest / 3 + 1;

    let mut model = GaussianModel {
        sh_coeffs: k,
        ..Default::default()
    };
    model.means.reserve(n * 3);
    let mut values = vec![0.0f64; props.len()];
    let fill = |values: &[f64], model: &mut GaussianModel| {
        let f = |i: usize| values[i] as f32;
        model.means.extend(xyz.map(f));
        for &i in &dc {
            model.sh.push(f(i));
        }
        let base = model.sh.len() - 3;
        model.sh.resize(base + k * 3, 0.0);
        for c in 0..3 {
            for kk in 1..k {
                model.sh[base + kk * 3 + c] = f(rest[c * (k - 1) + kk - 1]);
            }
        }
        model.opacity_logits.push(f(opacity));
        model.log_scales.extend(scale.map(f));
        model.quats.extend(rot.map(f));
    };
    match header.encoding {
        PlyEncoding::BinaryLittleEndian | PlyEncoding::BinaryBigEndian => {
            let little = header.encoding == PlyEncoding::BinaryLittleEndian;
            let stride: usize = props.iter().map(|(_, s)| s.size()).sum();
            let mut buf = vec![0u8; stride];
            for v in 0..n {
                r.read_exact(&mut buf)
                    .map_err(|_| bad(format!("file ends at vertex {v} of {n}")))?;
                let mut o = 0;
                for (i, (_, s)) in props.iter().enumerate() {
                    values[i] = s.decode(&buf[o..], little);
                    o += s.size();
                }
                fill(&values, &mut model);
            }
        }
        PlyEncoding::Ascii => {
            let mut text = String::new();
            r.read_to_string(&mut text)
                .map_err(|e| SceneError::io(path, e))?;
            let mut tokens = text.split_whitespace();
            for v in 0..n {
                for value in &mut values {
                    let t = tokens
                        .next()
                        .ok_or_else(|| bad(format!("file ends at vertex {v} of {n}")))?;
                    *value = t
                        .parse()
                        .map_err(|_| bad(format!("vertex {v}: `{t}` is not a number")))?;
                }
                fill(&values, &mut model);
            }
        }
    }
    model
        .validate()
        .map_err(|m| SceneError::invalid(path, format!("Gaussian parameters: {m}")))?;
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::tests::Scene;

    fn model(seed: u64, k: usize) -> GaussianModel {
        let s = Scene::random(seed, 50, k);
        let [means, log_scales, quats, opacity_logits, sh] = s.to_f32();
        GaussianModel {
            means,
            log_scales,
            quats,
            opacity_logits,
            sh,
            sh_coeffs: k,
        }
    }

    #[test]
    fn roundtrip_is_bit_exact_for_every_degree() {
        let dir = tempfile::tempdir().unwrap();
        for k in [1, 4, 9, 16] {
            let m = model(k as u64, k);
            let p = dir.path().join(format!("m{k}.ply"));
            write_ply(&p, &m).unwrap();
            let back = read_ply(&p).unwrap();
            assert_eq!(back, m);
            let size = std::fs::metadata(&p).unwrap().len() as usize;
            let props = 3 + 3 + 3 + 3 * (k - 1) + 1 + 3 + 4;
            let header = std::fs::read(&p)
                .unwrap()
                .windows(11)
                .position(|w| w == b"end_header\n")
                .unwrap()
                + 11;
            assert_eq!(size - header, 50 * props * 4);
        }
    }

    #[test]
    fn f_rest_is_channel_major() {
        let mut m = GaussianModel::new(1);
        let mut sh = vec![0.0; 12];
        // coefficient k, channel c = 10k + c
        for kk in 0..4 {
            for c in 0..3 {
                sh[kk * 3 + c] = (10 * kk + c) as f32;
            }
        }
        m.push(&crate::model::Gaussian {
            mean: [0.0; 3],
            log_scale: [0.0; 3],
            quat: [1.0, 0.0, 0.0, 0.0],
            opacity_logit: 0.0,
            sh,
        });
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.ply");
        write_ply(&p, &m).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let start = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        let vals: Vec<f32> = bytes[start..]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        // x y z nx ny nz | f_dc 0 1 2 | f_rest: R(k=1..3), G(k=1..3), B(k=1..3)
        assert_eq!(&vals[6..9], &[0.0, 1.0, 2.0]);
        assert_eq!(
            &vals[9..18],
            &[10.0, 20.0, 30.0, 11.0, 21.0, 31.0, 12.0, 22.0, 32.0]
        );
    }

    #[test]
    fn ascii_and_extra_properties_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.ply");
        let text = "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 1\nproperty double x\nproperty float y\nproperty float z\nproperty uchar red\nproperty float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\nproperty float scale_0\nproperty float scale_1\nproperty float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n1 2 3 255 0.1 0.2 0.3 -1 -2 -3 -4 1 0 0 0\n";
        std::fs::write(&p, text).unwrap();
        let m = read_ply(&p).unwrap();
        assert_eq!(m.sh_coeffs, 1);
        assert_eq!(m.means, vec![1.0, 2.0, 3.0]);
        assert_eq!(m.sh, vec![0.1, 0.2, 0.3]);
        assert_eq!(m.log_scales, vec![-2.0, -3.0, -4.0]);
    }

    #[test]
    fn bad_files_give_one_line_errors() {
        let dir = tempfile::tempdir().unwrap();
        let cases: [(&str, &[u8], &str); 4] = [
            ("notply.ply", b"hello\n", "not a PLY"),
            ("noscale.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n", "missing property `f_dc_0`"),
            ("short.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\nproperty float scale_0\nproperty float scale_1\nproperty float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n\0\0\0\0", "file ends at vertex 0"),
            ("nan.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\nproperty float scale_0\nproperty float scale_1\nproperty float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\nnan 0 0 0 0 0 0 0 0 0 1 0 0 0\n", "not finite"),
        ];
        for (name, bytes, want) in cases {
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            let e = read_ply(&p).unwrap_err().to_string();
            assert!(
                e.contains(name) && e.contains(want) && !e.contains('\n'),
                "{name}: {e}"
            );
        }
        // A model with no Gaussians, as written by `write_ply` or by hand, is refused.
        let empty = dir.path().join("empty.ply");
        let none = GaussianModel {
            sh_coeffs: 1,
            ..Default::default()
        };
        write_ply(&empty, &none).unwrap();
        let e = read_ply(&empty).unwrap_err().to_string();
        assert!(e.contains("empty.ply: the model has no Gaussians"), "{e}");
        std::fs::write(
            &empty,
            "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n",
        )
        .unwrap();
        let e = read_ply(&empty).unwrap_err().to_string();
        assert!(e.contains("empty.ply: the model has no Gaussians"), "{e}");
        let e = read_ply(&dir.path().join("missing.ply"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.ply"), "{e}");
    }
}
