//! Which pairs of photos to match when there are too many to match them all: a global
//! descriptor per photo (VLAD, "Aggregating local descriptors into a compact image
//! representation", Jégou et al., CVPR 2010) and, for each photo, the photos most like it.
//!
//! COLMAP's answer for large collections is a vocabulary tree over the photos' SIFT
//! descriptors; for the tens of photos a few-view capture has, one small vocabulary learned
//! from the photos themselves does the same job. Each photo's descriptor is the sum, per
//! visual word, of its local descriptors' residuals to that word, normalised per word
//! ("intra-normalisation", Arandjelović and Zisserman, "All about VLAD", CVPR 2013), then
//! signed-square-rooted and scaled to unit length, so that two photos' similarity is one dot
//! product. The pairs are every photo with its [`RetrievalOptions::neighbours`] most similar
//! photos, plus the maximum spanning tree of the similarities, so that the chosen pairs never
//! split the photos into groups that are not matched with each other at all.

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Options of [`retrieval_pairs`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RetrievalOptions {
    /// Visual words of the vocabulary (VLAD's `k`; Jégou et al. use 16–256).
    pub words: usize,
    /// Each photo is matched with this many of the photos most similar to it.
    pub neighbours: usize,
    /// Most local descriptors the vocabulary is learned from (an even sample of all photos').
    pub training_sample: usize,
    /// Lloyd iterations of the vocabulary's k-means.
    pub iterations: usize,
    pub seed: u64,
}

impl Default for RetrievalOptions {
    fn default() -> Self {
        Self {
            words: 64,
            neighbours: 10,
            training_sample: 20_000,
            iterations: 10,
            seed: 0,
        }
    }
}

/// Visual words: the centres of a k-means clustering of local descriptors.
#[derive(Clone, Debug, PartialEq)]
pub struct Vocabulary<const D: usize> {
    pub words: Vec<[f32; D]>,
}

fn squared_distance<const D: usize>(a: &[f32; D], b: &[f32; D]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

impl<const D: usize> Vocabulary<D> {
    /// k-means (k-means++ seeding, then Lloyd iterations) on an even sample of the
    /// descriptors of all `photos`. Fewer distinct descriptors than words give fewer words.
    pub fn learn(photos: &[&[[f32; D]]], options: &RetrievalOptions) -> Self {
        let all: Vec<&[f32; D]> = photos.iter().flat_map(|p| p.iter()).collect();
        let step = all.len().div_ceil(options.training_sample.max(1)).max(1);
        let sample: Vec<[f32; D]> = all.iter().step_by(step).map(|d| **d).collect();
        let mut rng = StdRng::seed_from_u64(options.seed);
        let mut words = plus_plus_seeds(&sample, options.words, &mut rng);
        for _ in 0..options.iterations {
            let nearest: Vec<usize> = sample.par_iter().map(|d| nearest(&words, d)).collect();
            let mut sums = vec![[0.0f64; D]; words.len()];
            let mut counts = vec![0usize; words.len()];
            for (d, &w) in sample.iter().zip(&nearest) {
                counts[w] += 1;
                for (s, v) in sums[w].iter_mut().zip(d) {
                    *s += f64::from(*v);
                }
            }
            for ((word, sum), &count) in words.iter_mut().zip(&sums).zip(&counts) {
                // A word that lost all its descriptors keeps its place.
                if count > 0 {
                    *word = std::array::from_fn(|k| (sum[k] / count as f64) as f32);
                }
            }
        }
        Self { words }
    }

    /// The VLAD descriptor of one photo's local descriptors (module docs); all zeros for a
    /// photo without any.
    pub fn vlad(&self, descriptors: &[[f32; D]]) -> Vec<f32> {
        let mut v = vec![0.0f32; self.words.len() * D];
        for d in descriptors {
            let w = nearest(&self.words, d);
            for (k, slot) in v[w * D..(w + 1) * D].iter_mut().enumerate() {
                *slot += d[k] - self.words[w][k];
            }
        }
        for block in v.chunks_mut(D) {
            scale_to_unit(block);
        }
        for x in &mut v {
            *x = x.signum() * x.abs().sqrt();
        }
        scale_to_unit(&mut v);
        v
    }
}

fn scale_to_unit(v: &mut [f32]) {
    let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    if norm > 0.0 {
        v.iter_mut().for_each(|x| *x /= norm);
    }
}

fn nearest<const D: usize>(words: &[[f32; D]], d: &[f32; D]) -> usize {
    let mut best = (0, f32::INFINITY);
    for (i, w) in words.iter().enumerate() {
        let e = squared_distance(w, d);
        if e < best.1 {
            best = (i, e);
        }
    }
    best.0
}

/// k-means++ (Arthur and Vassilvitskii 2007): each next centre drawn with probability
/// proportional to its squared distance from the centres so far.
fn plus_plus_seeds<const D: usize>(
    sample: &[[f32; D]],
    k: usize,
    rng: &mut StdRng,
) -> Vec<[f32; D]> {
    let mut words: Vec<[f32; D]> = Vec::with_capacity(k);
    if sample.is_empty() {
        return words;
    }
    words.push(sample[rng.random_range(0..sample.len())]);
    let mut distance: Vec<f32> = sample
        .iter()
        .map(|d| squared_distance(&words[0], d))
        .collect();
    while words.len() < k {
        let total: f64 = distance.iter().map(|&e| f64::from(e)).sum();
        if total <= 0.0 {
            break; // every descriptor already sits on a centre
        }
        let mut target = rng.random::<f64>() * total;
        let mut pick = sample.len() - 1;
        for (i, &e) in distance.iter().enumerate() {
            target -= f64::from(e);
            if target <= 0.0 && e > 0.0 {
                pick = i;
                break;
            }
        }
        let word = sample[pick];
        for (e, d) in distance.iter_mut().zip(sample) {
            *e = e.min(squared_distance(&word, d));
        }
        words.push(word);
    }
    words
}

/// Cosine similarities of unit-length global descriptors (`n × n`, row-major).
pub fn similarities(global: &[Vec<f32>]) -> Vec<f32> {
    let n = global.len();
    (0..n * n)
        .into_par_iter()
        .map(|ij| {
            let (a, b) = (&global[ij / n], &global[ij % n]);
            a.iter().zip(b).map(|(x, y)| x * y).sum()
        })
        .collect()
}

/// The pairs `(a, b)`, `a < b`, to match among `photos` (module docs), sorted.
pub fn retrieval_pairs<const D: usize>(
    photos: &[&[[f32; D]]],
    options: &RetrievalOptions,
) -> Vec<(usize, usize)> {
    let vocabulary = Vocabulary::learn(photos, options);
    let global: Vec<Vec<f32>> = photos.par_iter().map(|p| vocabulary.vlad(p)).collect();
    pairs_from_similarities(&similarities(&global), photos.len(), options.neighbours)
}

/// Each of `n` photos with its `neighbours` most similar others, plus the maximum spanning
/// tree of `similarity` (`n × n`); sorted pairs `(a, b)` with `a < b`.
pub fn pairs_from_similarities(
    similarity: &[f32],
    n: usize,
    neighbours: usize,
) -> Vec<(usize, usize)> {
    let ordered = |a: usize, b: usize| (a.min(b), a.max(b));
    let mut pairs = std::collections::BTreeSet::new();
    for a in 0..n {
        let mut others: Vec<usize> = (0..n).filter(|&b| b != a).collect();
        others.sort_by(|&b, &c| {
            similarity[a * n + c]
                .total_cmp(&similarity[a * n + b])
                .then(b.cmp(&c))
        });
        pairs.extend(others.iter().take(neighbours).map(|&b| ordered(a, b)));
    }
    pairs.extend(
        maximum_spanning_tree(similarity, n)
            .into_iter()
            .map(|(a, b)| ordered(a, b)),
    );
    pairs.into_iter().collect()
}

/// Prim's algorithm on the complete graph weighted by `similarity`.
fn maximum_spanning_tree(similarity: &[f32], n: usize) -> Vec<(usize, usize)> {
    if n == 0 {
        return Vec::new();
    }
    let mut in_tree = vec![false; n];
    // For each photo outside the tree: its most similar photo inside, and that similarity.
    let mut best: Vec<(usize, f32)> = (0..n).map(|b| (0, similarity[b])).collect();
    in_tree[0] = true;
    let mut edges = Vec::with_capacity(n - 1);
    for _ in 1..n {
        let next = (0..n)
            .filter(|&b| !in_tree[b])
            .max_by(|&b, &c| best[b].1.total_cmp(&best[c].1).then(c.cmp(&b)))
            .expect("a photo outside the tree");
        in_tree[next] = true;
        edges.push((best[next].0, next));
        for b in 0..n {
            let s = similarity[next * n + b];
            if !in_tree[b] && s > best[b].1 {
                best[b] = (next, s);
            }
        }
    }
    edges
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Descriptors scattered around a few centres of a small space.
    fn cloud(centres: &[[f32; 4]], per: usize, seed: u64) -> Vec<[f32; 4]> {
        let mut rng = StdRng::seed_from_u64(seed);
        centres
            .iter()
            .flat_map(|c| {
                (0..per)
                    .map(|_| std::array::from_fn(|k| c[k] + 0.05 * (rng.random::<f32>() - 0.5)))
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    #[test]
    fn kmeans_finds_separated_clusters() {
        let centres = [
            [0.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 1.0],
        ];
        let descriptors = cloud(&centres, 50, 1);
        let options = RetrievalOptions {
            words: 3,
            ..RetrievalOptions::default()
        };
        let vocabulary = Vocabulary::learn(&[&descriptors], &options);
        for c in &centres {
            let w = &vocabulary.words[nearest(&vocabulary.words, c)];
            assert!(squared_distance(w, c).sqrt() < 0.02, "{c:?} ↔ {w:?}");
        }
    }

    #[test]
    fn vlad_of_a_photo_is_unit_length_and_matches_a_hand_computation() {
        let vocabulary = Vocabulary {
            words: vec![[0.0; 2], [1.0, 1.0]],
        };
        // Residuals: word 0 gets (0.1, 0) + (0, 0.3); word 1 gets (−0.2, 0).
        let v = vocabulary.vlad(&[[0.1, 0.0], [0.0, 0.3], [0.8, 1.0]]);
        let word0 = [0.1f32 / 0.1f32.hypot(0.3), 0.3 / 0.1f32.hypot(0.3)];
        let expect = [word0[0].sqrt(), word0[1].sqrt(), -1.0, 0.0];
        let norm = expect.iter().map(|x| x * x).sum::<f32>().sqrt();
        for (got, want) in v.iter().zip(expect) {
            assert!((got - want / norm).abs() < 1e-6, "{v:?}");
        }
    }

    #[test]
    fn photos_of_one_scene_pair_before_photos_of_another() {
        // Two scenes of 12 landmarks each (random 8-dimensional descriptors); photos 0–3 see 8
        // of scene A's landmarks, photos 4–7 8 of scene B's, each landmark three times with
        // noise. Four words are coarser than the landmarks, as a vocabulary is in practice.
        let mut rng = StdRng::seed_from_u64(7);
        let scenes: Vec<Vec<[f32; 8]>> = (0..2)
            .map(|_| {
                (0..12)
                    .map(|_| std::array::from_fn(|_| rng.random::<f32>()))
                    .collect()
            })
            .collect();
        let photos: Vec<Vec<[f32; 8]>> = (0..8)
            .map(|i| {
                let landmarks = &scenes[i / 4];
                let mut seen: Vec<usize> = (0..12).collect();
                for k in (1..12).rev() {
                    seen.swap(k, rng.random_range(0..=k));
                }
                seen[..8]
                    .iter()
                    .flat_map(|&l| [landmarks[l]; 3])
                    .map(|d| std::array::from_fn(|k| d[k] + 0.02 * (rng.random::<f32>() - 0.5)))
                    .collect()
            })
            .collect();
        let views: Vec<&[[f32; 8]]> = photos.iter().map(Vec::as_slice).collect();
        let options = RetrievalOptions {
            words: 4,
            neighbours: 3,
            ..RetrievalOptions::default()
        };
        let pairs = retrieval_pairs(&views, &options);
        let within = pairs.iter().filter(|(x, y)| (*x < 4) == (*y < 4)).count();
        // All 12 pairs within a scene, and the one tree edge that joins the two scenes.
        assert_eq!((pairs.len(), within), (13, 12), "{pairs:?}");
    }

    #[test]
    fn the_spanning_tree_joins_photos_no_neighbour_list_joins() {
        // Two groups, each photo most similar to its own group: neighbours alone split them.
        let n = 4;
        let s = [
            1.0, 0.9, 0.1, 0.2, //
            0.9, 1.0, 0.3, 0.1, //
            0.1, 0.3, 1.0, 0.8, //
            0.2, 0.1, 0.8, 1.0,
        ];
        assert_eq!(
            pairs_from_similarities(&s, n, 1),
            vec![(0, 1), (1, 2), (2, 3)]
        );
    }
}
