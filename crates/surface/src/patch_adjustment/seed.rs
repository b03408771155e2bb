//! Seeding the patches: one per match whose window lies inside the masks, at the depth its two
//! ends triangulate to, with the normal of the plane fitted to its neighbours; and joining each
//! patch to the further views that see it.

use fewview_scene::{Image, Se3};
use nalgebra::{Matrix3, SymmetricEigen, Vector2, Vector3};
use rayon::prelude::*;

use crate::matching::Match;

use super::options::PatchAdjustmentOptions;
use super::residual::{Patch, PatchState, Views};

/// Patches from the matches whose windows lie inside the reference view (and its mask), whose
/// two ends triangulate in front of both cameras, and whose second view correlates.
pub(super) fn seed_patches(
    views: &Views,
    masks: &[Option<&Image>],
    poses: &[Se3],
    matches: &[Match],
    options: &PatchAdjustmentOptions,
) -> (Vec<Patch>, Vec<PatchState>) {
    let points: Vec<Option<Vector3<f64>>> = matches
        .par_iter()
        .map(|m| triangulate(views, poses, m))
        .collect();
    let half = options.half_window as f64;
    let seeded: Vec<Option<(Patch, PatchState)>> = matches
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            let (r, b) = (m.view_a, m.view_b);
            let centre = Vector2::new(m.a[0] as f64, m.a[1] as f64);
            let plane = &views.planes[r];
            if !plane.inside(centre.x - half - 1.0, centre.y - half - 1.0)
                || !plane.inside(centre.x + half + 1.0, centre.y + half + 1.0)
                || !window_in_mask(masks.get(r).copied().flatten(), centre, options.half_window)
            {
                return None;
            }
            let world = points[i]?;
            let in_reference = poses[r].transform_point(&world);
            let normal = fitted_normal(matches, &points, i, options.neighbours)?;
            let mut normal = poses[r].rotation * normal;
            if normal.dot(&in_reference) > 0.0 {
                normal = -normal;
            }
            let samples: Vec<f64> = views
                .window
                .offsets
                .iter()
                .map(|d| plane.sample(&plane.value, centre.x + d.x, centre.y + d.y))
                .collect();
            let template = views.centred(&samples);
            let template_energy = views.weighted_dot(&template, &template);
            if template_energy < 1e-8 * views.weight_sum {
                return None;
            }
            let patch = Patch {
                reference: r,
                centre,
                ray: views.k_inv[r] * Vector3::new(centre.x, centre.y, 1.0),
                template,
                template_energy,
                views: vec![b],
                paired: 1,
            };
            let state = PatchState {
                log_depth: in_reference.z.ln(),
                normal,
            };
            let h = views.homography(&patch, &state, poses, b);
            let mut values = Vec::new();
            let inside = views.warped_window(&patch, &h, b, &mut values);
            (inside && views.ncc(&patch, &values) >= options.min_ncc).then_some((patch, state))
        })
        .collect();
    seeded.into_iter().flatten().unzip()
}

/// Whether every pixel of the `(2h + 1)²` window around `centre` is inside `mask` (true without
/// a mask).
pub(super) fn window_in_mask(mask: Option<&Image>, centre: Vector2<f64>, half: usize) -> bool {
    let Some(mask) = mask else {
        return true;
    };
    let h = half as isize;
    let (cx, cy) = (centre.x.floor() as isize, centre.y.floor() as isize);
    (-h..=h).all(|dy| {
        (-h..=h).all(|dx| {
            let (x, y) = (cx + dx, cy + dy);
            x >= 0
                && y >= 0
                && (x as usize) < mask.width
                && (y as usize) < mask.height
                && mask.pixel(x as usize, y as usize)[0] > 0.5
        })
    })
}

/// The midpoint of the closest approach of the match's two rays, when it lies in front of both
/// cameras.
pub(super) fn triangulate(views: &Views, poses: &[Se3], m: &Match) -> Option<Vector3<f64>> {
    let ray = |v: usize, p: [f32; 2]| {
        let to_world = poses[v].inverse();
        let direction =
            to_world.rotation * (views.k_inv[v] * Vector3::new(p[0] as f64, p[1] as f64, 1.0));
        (to_world.translation, direction)
    };
    let (oa, da) = ray(m.view_a, m.a);
    let (ob, db) = ray(m.view_b, m.b);
    // Minimise |oa + s·da − ob − u·db|².
    let w = oa - ob;
    let (a, b, c) = (da.dot(&da), da.dot(&db), db.dot(&db));
    let (d, e) = (da.dot(&w), db.dot(&w));
    let denominator = a * c - b * b;
    if denominator.abs() < 1e-12 * a * c {
        return None;
    }
    let s = (b * e - c * d) / denominator;
    let u = (a * e - b * d) / denominator;
    (s > 0.0 && u > 0.0).then(|| 0.5 * (oa + s * da + ob + u * db))
}

/// The normal (world frame) of the plane fitted to the triangulated points of the
/// `neighbours` matches of the same pair nearest match `i` in its first view.
pub(super) fn fitted_normal(
    matches: &[Match],
    points: &[Option<Vector3<f64>>],
    i: usize,
    neighbours: usize,
) -> Option<Vector3<f64>> {
    let m = &matches[i];
    let mut near: Vec<(f32, Vector3<f64>)> = matches
        .iter()
        .zip(points)
        .filter(|(o, _)| o.view_a == m.view_a && o.view_b == m.view_b)
        .filter_map(|(o, p)| {
            let d = (o.a[0] - m.a[0]).powi(2) + (o.a[1] - m.a[1]).powi(2);
            p.map(|p| (d, p))
        })
        .collect();
    if near.len() < 3 {
        return None;
    }
    let k = neighbours.max(3).min(near.len());
    near.select_nth_unstable_by(k - 1, |x, y| x.0.total_cmp(&y.0));
    let near = &near[..k];
    let mean = near.iter().map(|(_, p)| p).sum::<Vector3<f64>>() / k as f64;
    let scatter = near
        .iter()
        .map(|(_, p)| (p - mean) * (p - mean).transpose())
        .sum::<Matrix3<f64>>();
    let eigen = SymmetricEigen::new(scatter);
    let smallest = eigen.eigenvalues.imin();
    let normal = eigen.eigenvectors.column(smallest).into_owned();
    (normal.norm() > 0.5).then_some(normal)
}

/// Adds to each patch the further views its plane faces and whose warped window correlates.
pub(super) fn join_further_views(
    views: &Views,
    patches: &mut [Patch],
    states: &[PatchState],
    poses: &[Se3],
    options: &PatchAdjustmentOptions,
) {
    patches
        .par_iter_mut()
        .zip(states)
        .for_each(|(patch, state)| {
            let point = state.log_depth.exp() * patch.ray;
            let mut values = Vec::new();
            for v in 0..poses.len() {
                if v == patch.reference || patch.views.contains(&v) {
                    continue;
                }
                let to_v = poses[v].compose(&poses[patch.reference].inverse());
                let facing =
                    (to_v.rotation * state.normal).dot(&to_v.transform_point(&point)) < 0.0;
                let h = views.homography(patch, state, poses, v);
                if facing
                    && views.warped_window(patch, &h, v, &mut values)
                    && views.ncc(patch, &values) >= options.join_ncc
                {
                    patch.views.push(v);
                }
            }
        });
}
