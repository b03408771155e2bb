//! Nearest-neighbour queries over 3D points (a `kiddo` k-d tree in `f64`).

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// A static k-d tree over 3D points. Distances returned are Euclidean (not squared).
pub struct PointTree {
    tree: Option<ImmutableKdTree<f64, 3>>,
    len: usize,
}

#[inline]
fn p64(p: &[f32; 3]) -> [f64; 3] {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

impl PointTree {
    /// Builds the tree (an empty input gives a tree that finds nothing).
    pub fn new(points: &[[f32; 3]]) -> Self {
        let pts: Vec<[f64; 3]> = points.iter().map(p64).collect();
        Self::from_f64(&pts)
    }

    pub fn from_f64(points: &[[f64; 3]]) -> Self {
        let tree = if points.is_empty() {
            None
        } else {
            ImmutableKdTree::new_from_slice(points).ok()
        };
        Self {
            tree,
            len: points.len(),
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Index of and distance to the nearest point (`(usize::MAX, ∞)` for an empty tree).
    pub fn nearest(&self, p: &[f32; 3]) -> (usize, f64) {
        self.nearest64(&p64(p))
    }

    pub fn nearest64(&self, p: &[f64; 3]) -> (usize, f64) {
        match &self.tree {
            None => (usize::MAX, f64::INFINITY),
            Some(t) => {
                let r = t.query(p).nearest_one::<SquaredEuclidean<f64>>().execute();
                (r.item as usize, r.distance.sqrt())
            }
        }
    }

    /// [`nearest`](Self::nearest) for many queries, in parallel.
    pub fn nearest_many(&self, queries: &[[f32; 3]]) -> Vec<(usize, f64)> {
        queries.par_iter().map(|q| self.nearest(q)).collect()
    }

    /// The `k` nearest points, closest first.
    pub fn knn(&self, p: &[f64; 3], k: usize) -> Vec<(usize, f64)> {
        let (Some(t), Some(k)) = (&self.tree, NonZeroUsize::new(k)) else {
            return Vec::new();
        };
        t.query(p)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .into_iter()
            .map(|r| (r.item as usize, r.distance.sqrt()))
            .collect()
    }

    /// All points within `radius` (inclusive), closest first.
    pub fn within(&self, p: &[f64; 3], radius: f64) -> Vec<(usize, f64)> {
        let Some(t) = &self.tree else {
            return Vec::new();
        };
        t.query(p)
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .execute()
            .into_iter()
            .map(|r| (r.item as usize, r.distance.sqrt()))
            .collect()
    }

    /// Open3D's hybrid search: at most `max_nn` nearest points within `radius`, closest first.
    pub fn hybrid(&self, p: &[f64; 3], radius: f64, max_nn: usize) -> Vec<(usize, f64)> {
        let (Some(t), Some(k)) = (&self.tree, NonZeroUsize::new(max_nn)) else {
            return Vec::new();
        };
        t.query(p)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .within(radius * radius)
            .execute()
            .into_iter()
            .map(|r| (r.item as usize, r.distance.sqrt()))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn matches_brute_force() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let pts: Vec<[f32; 3]> = (0..500)
            .map(|_| [rng.random(), rng.random(), rng.random()])
            .collect();
        let tree = PointTree::new(&pts);
        let d = |a: &[f32; 3], b: &[f32; 3]| {
            (0..3)
                .map(|k| (a[k] as f64 - b[k] as f64).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        for _ in 0..50 {
            let q: [f32; 3] = [rng.random(), rng.random(), rng.random()];
            let mut all: Vec<(usize, f64)> =
                pts.iter().enumerate().map(|(i, p)| (i, d(&q, p))).collect();
            all.sort_by(|a, b| a.1.total_cmp(&b.1));
            let (i, dist) = tree.nearest(&q);
            assert_eq!(i, all[0].0);
            assert!((dist - all[0].1).abs() < 1e-9);
            let q64 = p64(&q);
            let k = tree.knn(&q64, 7);
            assert_eq!(
                k.iter().map(|x| x.0).collect::<Vec<_>>(),
                all[..7].iter().map(|x| x.0).collect::<Vec<_>>()
            );
            let w = tree.within(&q64, 0.2);
            assert_eq!(w.len(), all.iter().filter(|x| x.1 <= 0.2).count());
            let h = tree.hybrid(&q64, 0.2, 3);
            assert_eq!(h.len(), w.len().min(3));
        }
        assert_eq!(PointTree::new(&[]).nearest(&[0.0; 3]).0, usize::MAX);
    }
}
