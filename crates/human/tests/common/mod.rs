//! A tiny capture in the synthetic dataset's layout, written by the tests themselves: a ring of
//! cameras looking at two joints, so that loaders, error paths and the split can be checked
//! without the shared data.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use fewview_scene::{Camera, Intrinsics};
use nalgebra::Vector3;
use npyz::WriterBuilder;

pub const SIZE: u32 = 16;
pub const JOINTS: [[f64; 3]; 2] = [[0.0, 0.0, 0.0], [0.05, -0.02, 0.1]];

/// The data folder named by `FEWVIEW_DATA` (the dataset tests are `#[ignore]`d without it and
/// fail, not skip, when run without it).
pub fn data_root() -> PathBuf {
    let root = std::env::var("FEWVIEW_DATA")
        .expect("set FEWVIEW_DATA to the data folder (e.g. /work/shared/data)");
    PathBuf::from(root)
}

/// Camera `i` of `n` on a ring of radius 2 around the origin, looking at it.
pub fn ring_camera(i: usize, n: usize) -> Camera {
    let a = i as f64 / n as f64 * std::f64::consts::TAU;
    let eye = Vector3::new(2.0 * a.sin(), -2.0 * a.cos(), 0.3);
    let k = Intrinsics::centered(20.0, SIZE, SIZE);
    Camera::look_at(k, eye, Vector3::zeros(), Vector3::z())
}

pub fn write_npy(path: &Path, shape: &[u64], data: &[f32]) {
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(std::fs::File::create(path).unwrap())
        .begin_nd()
        .unwrap();
    w.extend(data.iter().copied()).unwrap();
    w.finish().unwrap();
}

/// Writes a capture of `cameras` cameras and `frames` frames into `root/seq` with
/// `cameras.json` in OpenCV's convention (pixel centres at integers, so `cx = 7.5`).
pub fn write_capture(root: &Path, cameras: usize, frames: usize) {
    let mut entries = Vec::new();
    let seq = root.join("seq");
    for c in 0..cameras {
        let cam = ring_camera(c, cameras);
        let (r, t) = (
            cam.world_to_camera.rotation,
            cam.world_to_camera.translation,
        );
        let name = format!("cam_{c:02}");
        entries.push(serde_json::json!({
            "name": name, "width": SIZE, "height": SIZE,
            "K": [[20.0, 0.0, 7.5], [0.0, 20.0, 7.5], [0.0, 0.0, 1.0]],
            "R": [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]],
            "t": [t.x, t.y, t.z], "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
        }));
        let mut joints2d = Vec::new();
        for f in 0..frames {
            write_frame(&seq, &name, f);
            for j in JOINTS {
                let (u, v, _) = cam.project(&Vector3::from(j)).unwrap();
                joints2d.extend([(u - 0.5) as f32, (v - 0.5) as f32]);
            }
        }
        std::fs::create_dir_all(seq.join("joints2d")).unwrap();
        let path = seq.join("joints2d").join(format!("{name}.npy"));
        write_npy(&path, &[frames as u64, 2, 2], &joints2d);
    }
    let cams = serde_json::json!({ "cameras": entries });
    std::fs::write(root.join("cameras.json"), cams.to_string()).unwrap();
    let joints = serde_json::json!({ "names": ["pelvis", "head"], "parents": [-1, 0] });
    std::fs::write(root.join("joints.json"), joints.to_string()).unwrap();
    let j3: Vec<f32> = (0..frames)
        .flat_map(|_| JOINTS.iter().flatten().map(|&v| v as f32))
        .collect();
    write_npy(&seq.join("joints3d.npy"), &[frames as u64, 2, 3], &j3);
}

/// One camera's image (JPEG), mask and 16-bit depth for frame `f`.
fn write_frame(seq: &Path, name: &str, f: usize) {
    for kind in ["images", "masks", "depth"] {
        std::fs::create_dir_all(seq.join(kind).join(name)).unwrap();
    }
    let n = (SIZE * SIZE) as usize;
    let file = |kind: &str, ext: &str| {
        seq.join(kind)
            .join(name)
            .join(format!("frame_{f:04}.{ext}"))
    };
    let rgb: Vec<u8> = (0..n * 3).map(|i| (i * 5 % 256) as u8).collect();
    image::save_buffer(
        file("images", "jpg"),
        &rgb,
        SIZE,
        SIZE,
        image::ColorType::Rgb8,
    )
    .unwrap();
    let mask: Vec<u8> = (0..n).map(|i| if i % 3 == 0 { 255 } else { 0 }).collect();
    image::save_buffer(
        file("masks", "png"),
        &mask,
        SIZE,
        SIZE,
        image::ColorType::L8,
    )
    .unwrap();
    let depth: Vec<u16> = (0..n).map(|i| (2000 + i) as u16).collect();
    let depth = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(SIZE, SIZE, depth).unwrap();
    depth.save(file("depth", "png")).unwrap();
}
