//! COLMAP's text model format (`cameras.txt`, `images.txt`, `points3D.txt`): one record per line
//! (two for images), fields separated by spaces, `#` comments.

use std::collections::BTreeMap;
use std::path::Path;
use std::str::FromStr;

use super::model::{
    ColmapCamera, ColmapImage, ColmapPoint, PoseFields, locate_poses, model_param_count,
};
use crate::error::{Result, SceneError};

fn read(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| SceneError::io(path, e))
}

/// Whether a line holds data (not blank, not a comment).
fn is_data(line: &str) -> bool {
    let t = line.trim();
    !t.is_empty() && !t.starts_with('#')
}

/// Parses field `i` of a line, naming the line and field in the error.
fn field<T: FromStr>(
    fields: &[&str],
    i: usize,
    what: &str,
    path: &Path,
    line_no: usize,
) -> Result<T> {
    let s = fields
        .get(i)
        .ok_or_else(|| SceneError::format(path, format!("line {line_no}: missing {what}")))?;
    s.parse().map_err(|_| {
        SceneError::format(
            path,
            format!("line {line_no}: {what} {s:?} is not a number"),
        )
    })
}

/// `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`.
pub fn read_cameras(path: &Path) -> Result<BTreeMap<u32, ColmapCamera>> {
    let text = read(path)?;
    let mut out = BTreeMap::new();
    for (i, line) in text.lines().enumerate().filter(|(_, l)| is_data(l)) {
        let n = i + 1;
        let f: Vec<&str> = line.split_whitespace().collect();
        let id: u32 = field(&f, 0, "camera id", path, n)?;
        let model = f
            .get(1)
            .ok_or_else(|| SceneError::format(path, format!("line {n}: missing camera model")))?
            .to_string();
        let count = model_param_count(&model).ok_or_else(|| {
            SceneError::format(path, format!("line {n}: unknown camera model {model}"))
        })?;
        if f.len() != 4 + count {
            return Err(SceneError::format(
                path,
                format!(
                    "line {n}: {model} needs {count} parameters, found {}",
                    f.len().saturating_sub(4)
                ),
            ));
        }
        let params = (0..count)
            .map(|k| field(&f, 4 + k, "parameter", path, n))
            .collect::<Result<Vec<f64>>>()?;
        let cam = ColmapCamera {
            id,
            model,
            width: field(&f, 2, "width", path, n)?,
            height: field(&f, 3, "height", path, n)?,
            params,
        };
        if out.insert(id, cam).is_some() {
            return Err(SceneError::format(
                path,
                format!("line {n}: camera {id} defined twice"),
            ));
        }
    }
    Ok(out)
}

/// Pairs of lines: `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`, then the 2D points (which may
/// be an empty line, so the second line is taken as is, as COLMAP's reader does).
pub fn read_images(path: &Path) -> Result<Vec<ColmapImage>> {
    let text = read(path)?;
    Ok(images_with_lines(&text, path)?
        .into_iter()
        .map(|(image, _)| image)
        .collect())
}

/// Parses `images.txt` held in memory: each image with the index of its line.
fn images_with_lines(text: &str, path: &Path) -> Result<Vec<(ColmapImage, usize)>> {
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate();
    while let Some((i, line)) = lines.next() {
        if !is_data(line) {
            continue;
        }
        let n = i + 1;
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 10 {
            return Err(SceneError::format(
                path,
                format!(
                    "line {n}: an image needs 10 fields (IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME), found {}",
                    f.len()
                ),
            ));
        }
        let num = |k: usize, what: &str| field::<f64>(&f, k, what, path, n);
        let image = ColmapImage {
            id: field(&f, 0, "image id", path, n)?,
            qvec: [num(1, "qw")?, num(2, "qx")?, num(3, "qy")?, num(4, "qz")?],
            tvec: [num(5, "tx")?, num(6, "ty")?, num(7, "tz")?],
            camera_id: field(&f, 8, "camera id", path, n)?,
            name: f[9].to_owned(),
        };
        let id = image.id;
        out.push((image, i));
        // The 2D points line (X Y POINT3D_ID triples, possibly none); its contents are not
        // needed. A file that ends here is fine. A line whose fields are not triples is the
        // next image's: a file without 2D points lines would otherwise lose every other image.
        if let Some((j, points)) = lines.next() {
            let fields = points.split_whitespace().count();
            if fields % 3 != 0 {
                return Err(SceneError::format(
                    path,
                    format!(
                        "line {}: expected the 2D points of image {} (X Y POINT3D_ID triples), found {fields} fields; each image takes two lines",
                        j + 1,
                        id
                    ),
                ));
            }
        }
    }
    Ok(out)
}

/// The first line of an image in `images.txt`: `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`
/// for the world-to-camera `pose` (no newline).
pub fn image_line(
    image_id: usize,
    pose: &crate::camera::Se3,
    camera_id: usize,
    name: &str,
) -> String {
    let q = nalgebra::UnitQuaternion::from_matrix(&pose.rotation);
    let t = pose.translation;
    format!(
        "{image_id} {:.17} {:.17} {:.17} {:.17} {:.17} {:.17} {:.17} {camera_id} {name}",
        q.w, q.i, q.j, q.k, t.x, t.y, t.z
    )
}

/// `images.txt` (read from `path`) with the poses of the images in `poses` (by id:
/// `cam_from_world` quaternion `(qw, qx, qy, qz)` and translation) replaced; every other line,
/// the 2D points included, as stored, and the image line's camera id and name as they were.
/// An id the file lacks is an error.
pub fn replace_image_poses(path: &Path, poses: &BTreeMap<u32, PoseFields>) -> Result<String> {
    let text = read(path)?;
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let found = images_with_lines(&text, path)?;
    for (line, id, (qvec, tvec)) in locate_poses(found, poses, path)? {
        // Fields from CAMERA_ID on (the name may hold spaces) stay as written.
        let rest = after_fields(&lines[line], 8);
        let pose: Vec<String> = qvec.iter().chain(tvec).map(f64::to_string).collect();
        lines[line] = format!("{id} {} {rest}", pose.join(" "));
    }
    // The file's own line endings are kept (COLMAP on Windows writes CRLF).
    let newline = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let mut out = lines.join(newline);
    if text.ends_with('\n') {
        out.push_str(newline);
    }
    Ok(out)
}

/// The part of `line` after its first `n` whitespace-separated fields, leading space removed.
fn after_fields(line: &str, n: usize) -> &str {
    let mut rest = line.trim_start();
    for _ in 0..n {
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        rest = rest[end..].trim_start();
    }
    rest
}

/// `POINT3D_ID X Y Z R G B ERROR TRACK[]`.
pub fn read_points(path: &Path) -> Result<Vec<ColmapPoint>> {
    let text = read(path)?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().filter(|(_, l)| is_data(l)) {
        let n = i + 1;
        let f: Vec<&str> = line.split_whitespace().collect();
        let num = |k: usize, what: &str| field::<f64>(&f, k, what, path, n);
        let byte = |k: usize, what: &str| field::<u8>(&f, k, what, path, n);
        let point = ColmapPoint {
            id: field(&f, 0, "point id", path, n)?,
            xyz: [num(1, "x")?, num(2, "y")?, num(3, "z")?],
            rgb: [byte(4, "red")?, byte(5, "green")?, byte(6, "blue")?],
            error: num(7, "error")?,
        };
        if let Some(problem) = point.problem() {
            return Err(SceneError::invalid(path, format!("line {n}: {problem}")));
        }
        out.push(point);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Windows-written `images.txt` comes back with CRLF endings, only the pose replaced.
    #[test]
    fn replacing_poses_keeps_crlf_line_endings() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("images.txt");
        let lf = "# Image list\n1 1 0 0 0 0.5 0 0 1 my image.png\n10 20 -1 30 40 7\n";
        for newline in ["\n", "\r\n"] {
            std::fs::write(&path, lf.replace('\n', newline)).unwrap();
            let poses = BTreeMap::from([(1, ([0.0, 1.0, 0.0, 0.0], [1.0, 2.0, 3.0]))]);
            let out = replace_image_poses(&path, &poses).unwrap();
            let expected = "# Image list\n1 0 1 0 0 1 2 3 1 my image.png\n10 20 -1 30 40 7\n";
            assert_eq!(out, expected.replace('\n', newline));
        }
    }

    /// An images file without its 2D points lines is refused (it lost every other image), and
    /// an image with no 2D points (an empty line) is read.
    #[test]
    fn images_need_their_points_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("images.txt");
        let image = |id: u32| format!("{id} 1 0 0 0 0 0 0 1 view{id}.png");
        std::fs::write(&path, format!("{}\n{}\n{}\n", image(1), image(2), image(3))).unwrap();
        let err = read_images(&path).unwrap_err().to_string();
        assert!(
            err.contains("line 2: expected the 2D points of image 1"),
            "{err}"
        );
        std::fs::write(&path, format!("{}\n\n{}\n1 2 -1\n", image(1), image(2))).unwrap();
        let ids: Vec<u32> = read_images(&path).unwrap().iter().map(|i| i.id).collect();
        assert_eq!(ids, [1, 2]);
    }

    /// A NaN or 1e300 coordinate is refused when reading, naming the file, line and point id.
    #[test]
    fn points_with_non_finite_or_huge_coordinates_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("points3D.txt");
        let ok = "# points\n3 1 2 3 10 20 30 0.5 1 0\n";
        std::fs::write(&path, ok).unwrap();
        assert_eq!(read_points(&path).unwrap()[0].xyz, [1.0, 2.0, 3.0]);
        for (line, axis) in [("5 nan 0 0 1 2 3 0.1", "x"), ("5 0 1e300 0 1 2 3 0.1", "y")] {
            std::fs::write(&path, format!("{ok}{line}\n")).unwrap();
            let err = read_points(&path).unwrap_err().to_string();
            assert!(
                err.contains("points3D.txt: line 3: point 5: coordinate"),
                "{err}"
            );
            assert!(err.contains(&format!("{axis} = ")), "{err}");
        }
        // A colour beyond a byte is refused too.
        std::fs::write(&path, "5 0 0 0 256 0 0 0.1\n").unwrap();
        let err = read_points(&path).unwrap_err().to_string();
        assert!(err.contains("points3D.txt: line 1: red"), "{err}");
    }
}
