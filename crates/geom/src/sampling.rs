//! Point sampling on meshes and point-set thinning: uniform area-weighted samples (synthetic
//! metrics), the DTU evaluation's triangle-grid sampling and its greedy radius down-sampling.

use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};

use crate::error::{GeomError, Result};
use crate::knn::PointTree;
use crate::mesh::{Mesh, f3, v3};

/// The most points one mesh sampling may produce (about 0.6 GB of points; the kd-tree and
/// distances that follow need a few times more). Checked before anything is allocated, so that a
/// huge `--samples`, a tiny DTU density or a mesh in the wrong units is a clear error rather than
/// an allocation abort or a run that never ends. At the DTU density 0.2 mm this is about
/// 2·10⁶ mm² of surface, four times a sphere of radius 200 mm.
pub const MAX_SAMPLES: usize = 50_000_000;

/// `n` points uniformly distributed over the surface (area-weighted faces, uniform barycentric
/// coordinates), with the face each lies on. `n` is at most [`MAX_SAMPLES`].
pub fn sample_surface_with_faces(
    mesh: &Mesh,
    n: usize,
    seed: u64,
) -> Result<(Vec<[f32; 3]>, Vec<u32>)> {
    check_sample_count(n)?;
    mesh.validate("mesh")?;
    let mut cdf = Vec::with_capacity(mesh.faces.len());
    let mut total = 0.0;
    for f in 0..mesh.faces.len() {
        total += 0.5 * mesh.face_cross(f).norm();
        cdf.push(total);
    }
    if !(total > 0.0) {
        return Err(GeomError::invalid("mesh", "has no surface area to sample"));
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let mut pts = Vec::with_capacity(n);
    let mut faces = Vec::with_capacity(n);
    for _ in 0..n {
        let x = rng.random::<f64>() * total;
        let f = cdf.partition_point(|&c| c < x).min(cdf.len() - 1);
        let [a, b, c] = mesh.faces[f].map(|i| v3(&mesh.vertices[i as usize]));
        let (r1, r2) = (rng.random::<f64>().sqrt(), rng.random::<f64>());
        let p = a * (1.0 - r1) + b * (r1 * (1.0 - r2)) + c * (r1 * r2);
        pts.push(f3(&p));
        faces.push(f as u32);
    }
    Ok((pts, faces))
}

/// Refuses more than [`MAX_SAMPLES`] samples per mesh.
pub fn check_sample_count(n: usize) -> Result<()> {
    if n > MAX_SAMPLES {
        return Err(GeomError::invalid(
            "samples",
            format!("{n} points per mesh is more than the {MAX_SAMPLES} allowed; use fewer"),
        ));
    }
    Ok(())
}

/// `n` uniform surface samples (see [`sample_surface_with_faces`]).
pub fn sample_surface(mesh: &Mesh, n: usize, seed: u64) -> Result<Vec<[f32; 3]>> {
    Ok(sample_surface_with_faces(mesh, n, seed)?.0)
}

/// The DTU evaluation's mesh sampling (`eval.py` of DTUeval-python): the vertices, plus for each
/// triangle `(v0, v1, v2)` with edges `e1 = v1 − v0`, `e2 = v2 − v0` the points
/// `v0 + (i + ½)/n₁·e1 + (j + ½)/n₂·e2` with `i ≤ n₁`, `j ≤ n₂`, `(i + ½)/n₁ + (j + ½)/n₂ < 1`,
/// where `n_k = ⌊|e_k| / t⌋` and `t = density·√(|e1||e2| / |e1 × e2|)`. Degenerate faces add
/// nothing. At most [`MAX_SAMPLES`] points (about surface area / density²).
pub fn dtu_sample(mesh: &Mesh, density: f64) -> Result<Vec<[f32; 3]>> {
    mesh.validate("mesh")?;
    if !(density > 0.0) {
        return Err(GeomError::invalid(
            "density",
            format!("{density} must be positive"),
        ));
    }
    let grid = |a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>| {
        let (e1, e2) = (b - a, c - a);
        let (l1, l2) = (e1.norm(), e2.norm());
        let area2 = e1.cross(&e2).norm();
        if !(area2 > 0.0) {
            return None;
        }
        let t = density * (l1 * l2 / area2).sqrt();
        let (n1, n2) = ((l1 / t).floor(), (l2 / t).floor());
        // (i + ½)/1e-7 ≥ 1 for every i in the reference: no samples
        (n1 >= 1.0 && n2 >= 1.0).then_some((e1, e2, n1, n2))
    };
    let too_many = |count: f64| {
        GeomError::invalid(
            "density",
            format!(
                "{density} samples about {count:.3e} points on this mesh, more than the \
                 {MAX_SAMPLES} allowed; use a larger density (or check the mesh's units)"
            ),
        )
    };
    // The half grid of a face holds about n₁n₂/2 points: estimate before allocating anything.
    let estimate = mesh.vertices.len() as f64
        + mesh
            .faces
            .iter()
            .filter_map(|f| {
                let [a, b, c] = f.map(|i| v3(&mesh.vertices[i as usize]));
                grid(&a, &b, &c).map(|(_, _, n1, n2)| n1 * n2 / 2.0)
            })
            .sum::<f64>();
    if estimate > MAX_SAMPLES as f64 {
        return Err(too_many(estimate));
    }
    let mut out = Vec::with_capacity(estimate as usize);
    out.extend_from_slice(&mesh.vertices);
    for f in &mesh.faces {
        let [a, b, c] = f.map(|i| v3(&mesh.vertices[i as usize]));
        let Some((e1, e2, n1, n2)) = grid(&a, &b, &c) else {
            continue;
        };
        for i in 0..=n1 as usize {
            let u = (i as f64 + 0.5) / n1;
            for j in 0..=n2 as usize {
                let v = (j as f64 + 0.5) / n2;
                if u + v < 1.0 {
                    out.push(f3(&(a + e1 * u + e2 * v)));
                }
            }
            // The estimate is not exact (the diagonal's rows): keep the bound a hard one.
            if out.len() > MAX_SAMPLES {
                return Err(too_many(out.len() as f64));
            }
        }
    }
    Ok(out)
}

/// The DTU evaluation's down-sampling: shuffle (seeded), then walk the points in order, keeping
/// each point not yet removed and removing every other point within `radius` of it.
pub fn radius_downsample(points: &[[f32; 3]], radius: f64, seed: u64) -> Vec<[f32; 3]> {
    let mut pts = points.to_vec();
    pts.shuffle(&mut StdRng::seed_from_u64(seed));
    let tree = PointTree::new(&pts);
    let mut keep = vec![true; pts.len()];
    for cur in 0..pts.len() {
        if !keep[cur] {
            continue;
        }
        let p = pts[cur].map(|x| x as f64);
        for (j, _) in tree.within(&p, radius) {
            keep[j] = false;
        }
        keep[cur] = true;
    }
    pts.into_iter()
        .zip(keep)
        .filter(|(_, k)| *k)
        .map(|(p, _)| p)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_cube;

    #[test]
    fn uniform_samples_cover_faces_by_area() {
        let m = test_cube();
        let (pts, faces) = sample_surface_with_faces(&m, 60_000, 1).unwrap();
        let mut per_side = [0usize; 6];
        for (p, &f) in pts.iter().zip(&faces) {
            per_side[f as usize / 2] += 1;
            assert!(p.iter().all(|&x| (-1e-6..=1.0 + 1e-6).contains(&x)));
        }
        for c in per_side {
            assert!((c as f64 / 10_000.0 - 1.0).abs() < 0.05, "{per_side:?}");
        }
    }

    #[test]
    fn dtu_sampling_matches_the_reference_rule() {
        // Right triangle with legs 1: t = 0.2·√(1·1/1) = 0.2, n1 = n2 = 5; points with
        // (i+½)/5 + (j+½)/5 < 1 ⇔ i + j < 4: 10 points (i + j ∈ 0..=3), plus 3 vertices.
        let m = Mesh::new(
            vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]],
            vec![[0, 1, 2]],
        );
        let s = dtu_sample(&m, 0.2).unwrap();
        assert_eq!(s.len(), 13);
        assert!(s[3..].iter().all(|p| p[0] + p[1] < 1.0 && p[2] == 0.0));
        assert!((s[3][0] - 0.1).abs() < 1e-7 && (s[3][1] - 0.1).abs() < 1e-7);
    }

    /// A 10⁴-unit triangle at density 0.5 (≈ 2·10⁸ points), a tiny density, or 10¹¹ uniform
    /// samples used to abort on allocation or run for hours.
    #[test]
    fn sample_counts_beyond_the_cap_are_errors_before_allocating() {
        let big = Mesh::new(
            vec![[0., 0., 0.], [10_000., 0., 0.], [0., 10_000., 0.]],
            vec![[0, 1, 2]],
        );
        let e = dtu_sample(&big, 0.5).unwrap_err().to_string();
        assert!(e.contains("density") && e.contains("50000000"), "{e}");
        let unit = Mesh::new(
            vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]],
            vec![[0, 1, 2]],
        );
        assert!(dtu_sample(&unit, 1e-6).is_err());
        assert!(dtu_sample(&unit, f64::MIN_POSITIVE).is_err());
        let e = sample_surface(&unit, 100_000_000_000, 0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("samples") && e.contains("use fewer"), "{e}");
        // Just below the cap's order of magnitude still works.
        assert!(dtu_sample(&big, 20.0).unwrap().len() > 100_000);
    }

    #[test]
    fn radius_downsample_leaves_no_close_pairs() {
        let pts: Vec<[f32; 3]> = (0..40)
            .flat_map(|i| (0..40).map(move |j| [i as f32 * 0.05, j as f32 * 0.05, 0.0]))
            .collect();
        let d = radius_downsample(&pts, 0.12, 4);
        assert!(d.len() < pts.len() / 4 && d.len() > 40);
        let tree = PointTree::new(&d);
        for p in &d {
            let near = tree.within(&p.map(|x| x as f64), 0.12);
            assert_eq!(
                near.len(),
                1,
                "a kept point has a kept neighbour within the radius"
            );
        }
        // Every input point is within the radius of a kept one.
        for p in &pts {
            assert!(tree.nearest(p).1 <= 0.12 + 1e-9);
        }
    }
}
