//! Voxel down-sampling with Open3D's semantics: voxels of edge `voxel` anchored at
//! `min_bound − voxel/2`; every occupied voxel becomes the mean of its points (normals and
//! colours averaged too, normals re-normalised). Output is ordered by voxel index.

use std::collections::BTreeMap;

use crate::error::{GeomError, Result};
use crate::mesh::{Points, bounds};

pub fn voxel_down_sample(points: &Points, voxel: f64) -> Result<Points> {
    if !(voxel > 0.0 && voxel.is_finite()) {
        return Err(GeomError::invalid(
            "voxel size",
            format!("{voxel} must be positive"),
        ));
    }
    points.validate("points")?;
    let Some((lo, _)) = bounds(&points.positions) else {
        return Ok(Points::default());
    };
    let origin = lo.map(|v| v as f64 - voxel / 2.0);
    // Sum of position, normal, colour and the count, per voxel.
    let mut cells: BTreeMap<[i64; 3], ([f64; 9], usize)> = BTreeMap::new();
    for (i, p) in points.positions.iter().enumerate() {
        let key: [i64; 3] =
            std::array::from_fn(|k| ((p[k] as f64 - origin[k]) / voxel).floor() as i64);
        let e = cells.entry(key).or_insert(([0.0; 9], 0));
        for k in 0..3 {
            e.0[k] += p[k] as f64;
            if let Some(n) = &points.normals {
                e.0[3 + k] += n[i][k] as f64;
            }
            if let Some(c) = &points.colors {
                e.0[6 + k] += c[i][k] as f64;
            }
        }
        e.1 += 1;
    }
    let mut out = Points {
        positions: Vec::with_capacity(cells.len()),
        colors: points
            .colors
            .as_ref()
            .map(|_| Vec::with_capacity(cells.len())),
        normals: points
            .normals
            .as_ref()
            .map(|_| Vec::with_capacity(cells.len())),
    };
    for (s, n) in cells.values() {
        let m = |k: usize| (s[k] / *n as f64) as f32;
        out.positions.push([m(0), m(1), m(2)]);
        if let Some(ns) = out.normals.as_mut() {
            let v = [m(3), m(4), m(5)];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            ns.push(if l > 0.0 { v.map(|x| x / l) } else { v });
        }
        if let Some(cs) = out.colors.as_mut() {
            cs.push([m(6), m(7), m(8)]);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averages_points_per_voxel() {
        let pts = Points::from_positions(vec![
            [0.0, 0.0, 0.0],
            [0.2, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.1, 0.0, 0.0],
        ]);
        // Anchored at −0.25: voxels [−0.25, 0.25) and [0.75, 1.25).
        let d = voxel_down_sample(&pts, 0.5).unwrap();
        assert_eq!(d.positions, vec![[0.1, 0.0, 0.0], [1.05, 0.0, 0.0]]);
        assert!(voxel_down_sample(&pts, 0.0).is_err());
    }
}
