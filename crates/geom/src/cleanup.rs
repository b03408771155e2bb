//! Mesh cleanup after marching cubes: keep the largest connected component, drop small pieces,
//! and cull what falls outside the object masks of the input views.

use std::path::Path;

use fewview_scene::{Camera, Image};

use crate::error::{GeomError, Result};
use crate::mesh::{Mesh, v3};

pub use crate::topology::{largest_component, remove_small_components};

/// Options of [`cull_by_masks`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CullOptions {
    /// A mask pixel counts as foreground above this value (channel 0).
    pub threshold: f32,
    /// A vertex goes when at least this many views see it (in front of the camera, inside the
    /// image) on background. 1 is the usual DTU culling ("outside any mask").
    pub min_background_views: usize,
}

impl Default for CullOptions {
    fn default() -> Self {
        Self {
            threshold: 0.5,
            min_background_views: 1,
        }
    }
}

/// Removes the vertices (and their faces) that project onto the background of the masks: for
/// each vertex and camera, the pixel containing its projection (`⌊u⌋, ⌊v⌋`, pixel centres at
/// half-integers) is looked up when the vertex is in front of the camera and inside the image.
/// Errors name a mask by its index ("mask 0"); [`cull_by_mask_files`] names the files.
pub fn cull_by_masks(
    mesh: &Mesh,
    cameras: &[Camera],
    masks: &[Image],
    options: &CullOptions,
) -> Result<Mesh> {
    cull(mesh, cameras, masks, options, |i| format!("mask {i}"))
}

/// [`cull_by_masks`] with the masks read from `paths` (one per camera, in order): an unreadable
/// mask, one whose size differs from its camera's, or one without a foreground pixel is an error
/// naming the mask file.
pub fn cull_by_mask_files<P: AsRef<Path>>(
    mesh: &Mesh,
    cameras: &[Camera],
    paths: &[P],
    options: &CullOptions,
) -> Result<Mesh> {
    let masks = paths
        .iter()
        .map(|p| Image::load(p.as_ref()).map_err(GeomError::from))
        .collect::<Result<Vec<_>>>()?;
    cull(mesh, cameras, &masks, options, |i| {
        format!("{}: mask {i}", paths[i].as_ref().display())
    })
}

/// [`cull_by_masks`], naming mask `i` by `name(i)` in errors.
fn cull(
    mesh: &Mesh,
    cameras: &[Camera],
    masks: &[Image],
    options: &CullOptions,
    name: impl Fn(usize) -> String,
) -> Result<Mesh> {
    mesh.validate("mesh")?;
    if cameras.len() != masks.len() {
        return Err(GeomError::invalid(
            "masks",
            format!("{} masks for {} cameras", masks.len(), cameras.len()),
        ));
    }
    for (i, (c, m)) in cameras.iter().zip(masks).enumerate() {
        if (m.width, m.height) != (c.width() as usize, c.height() as usize) {
            return Err(GeomError::invalid(
                name(i),
                format!(
                    "is {}×{} but camera {i} is {}×{}",
                    m.width,
                    m.height,
                    c.width(),
                    c.height()
                ),
            ));
        }
        if !m
            .data
            .iter()
            .step_by(m.channels)
            .any(|&v| v > options.threshold)
        {
            return Err(GeomError::invalid(
                name(i),
                format!("is empty (no foreground pixel above {})", options.threshold),
            ));
        }
    }
    let keep: Vec<bool> = mesh
        .vertices
        .iter()
        .map(|p| {
            let x = v3(p);
            let background = cameras
                .iter()
                .zip(masks)
                .filter(|(c, m)| match c.project(&x) {
                    Some((u, v, _)) if u >= 0.0 && v >= 0.0 => {
                        let (i, j) = (u.floor() as usize, v.floor() as usize);
                        i < m.width && j < m.height && m.get(i, j, 0) <= options.threshold
                    }
                    _ => false,
                })
                .count();
            background < options.min_background_views.max(1)
        })
        .collect();
    Ok(mesh.retain_vertices(&keep))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::depth::tests::test_camera;
    use crate::mesh::test_cube;

    #[test]
    fn culls_vertices_seen_on_background() {
        // A cube seen by one camera; the mask keeps only the left half of the image.
        let cam = test_camera(64, 48, 60.0);
        let mut cube = test_cube();
        for v in &mut cube.vertices {
            for k in 0..3 {
                v[k] = (v[k] - 0.5) * 0.4;
            }
            v[2] += 2.0;
        }
        let mut mask = Image::new(64, 48, 1);
        for j in 0..48 {
            for i in 0..32 {
                mask.set(i, j, 0, 1.0);
            }
        }
        let out = cull_by_masks(
            &cube,
            std::slice::from_ref(&cam),
            &[mask.clone()],
            &CullOptions::default(),
        )
        .unwrap();
        assert!(!out.vertices.is_empty() && out.vertices.len() < 8);
        for p in &out.vertices {
            let (u, _, _) = cam.project(&v3(p)).unwrap();
            assert!(u < 32.0);
        }
        // Needing two background views with one camera culls nothing.
        let opts = CullOptions {
            min_background_views: 2,
            ..Default::default()
        };
        assert_eq!(
            cull_by_masks(&cube, std::slice::from_ref(&cam), &[mask], &opts)
                .unwrap()
                .vertices
                .len(),
            8
        );
        let empty = Image::new(64, 48, 1);
        let e = cull_by_masks(
            &cube,
            std::slice::from_ref(&cam),
            &[empty],
            &CullOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("mask 0") && e.to_string().contains("empty"));
        let small = Image::new(10, 10, 1);
        assert!(cull_by_masks(&cube, &[cam], &[small], &CullOptions::default()).is_err());
    }

    /// Masks read from files name the file when empty, of the wrong size or unreadable.
    #[test]
    fn mask_file_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let cam = test_camera(32, 24, 30.0);
        let mut cube = test_cube();
        for v in &mut cube.vertices {
            v[2] += 2.0;
        }
        let cull = |p: &Path| {
            cull_by_mask_files(
                &cube,
                std::slice::from_ref(&cam),
                &[p],
                &CullOptions::default(),
            )
        };
        let empty = dir.path().join("empty_mask.png");
        Image::new(32, 24, 1).save_png(&empty).unwrap();
        let e = cull(&empty).unwrap_err().to_string();
        assert!(e.contains("empty_mask.png: mask 0: is empty"), "{e}");
        let small = dir.path().join("small_mask.png");
        Image::filled(10, 10, &[1.0]).save_png(&small).unwrap();
        let e = cull(&small).unwrap_err().to_string();
        assert!(
            e.contains("small_mask.png: mask 0: is 10×10 but camera 0 is 32×24"),
            "{e}"
        );
        let missing = dir.path().join("missing_mask.png");
        let e = cull(&missing).unwrap_err().to_string();
        assert!(e.contains("missing_mask.png"), "{e}");
        let full = dir.path().join("full_mask.png");
        Image::filled(32, 24, &[1.0]).save_png(&full).unwrap();
        assert!(cull(&full).is_ok());
    }
}
