//! Standard sparse-view train/test splits, and validation of user-given splits.
//!
//! Each function returns indices into the loader's list of views (or frames, for Blender data);
//! the protocols are the ones the sparse-view literature uses, documented per function and in
//! the data README.

use std::path::Path;

use crate::error::{Result, SceneError};

/// The seed-0 NumPy permutation of 0..100: `np.random.seed(0); np.random.permutation(100)`.
///
/// DietNeRF's sparse-view NeRF-synthetic protocol (reused by FreeNeRF and later work) trains on
/// the first n entries (8 views: 26, 86, 2, 55, 75, 93, 16, 73). Produced by
/// `tools/blender_sparse_permutation.py`, which holds the command to rerun it.
pub const BLENDER_SPARSE_PERMUTATION: [usize; 100] = [
    26, 86, 2, 55, 75, 93, 16, 73, 54, 95, //
    53, 92, 78, 13, 7, 30, 22, 24, 33, 8, //
    43, 62, 3, 71, 45, 48, 6, 99, 82, 76, //
    60, 80, 90, 68, 51, 27, 18, 56, 63, 74, //
    1, 61, 42, 41, 4, 15, 17, 40, 38, 5, //
    91, 59, 0, 34, 28, 50, 11, 35, 23, 52, //
    10, 31, 66, 57, 79, 85, 32, 84, 14, 89, //
    19, 29, 49, 97, 98, 69, 20, 94, 72, 77, //
    25, 37, 81, 46, 39, 65, 58, 12, 88, 70, //
    87, 36, 21, 83, 9, 96, 67, 64, 47, 44, //
];

/// Default number of training views of the sparse-view Blender protocol.
pub const BLENDER_DEFAULT_TRAIN: usize = 8;

/// DTU training views in the order of the pixelNeRF / RegNeRF / SPARF protocol; n views take the
/// first n (3 views: 25, 22, 28).
pub const DTU_TRAIN_ORDER: [usize; 9] = [25, 22, 28, 40, 44, 48, 0, 8, 13];

/// The 25 DTU test views of the pixelNeRF / RegNeRF / SPARF protocol (views 3–7, 16–21 and
/// 36–39 are excluded from both sides).
pub const DTU_TEST_VIEWS: [usize; 25] = [
    1, 2, 9, 10, 11, 12, 14, 15, 23, 24, 26, 27, 29, 30, 31, 32, 33, 34, 35, 41, 42, 43, 45, 46, 47,
];

/// Default number of DTU training views.
pub const DTU_DEFAULT_TRAIN: usize = 3;

/// Default number of LLFF training views (RegNeRF / SPARF 3-view setting).
pub const LLFF_DEFAULT_TRAIN: usize = 3;

/// The LLFF hold-out: every `every`-th view is a test view (NeRF's `llffhold = 8`).
pub fn holdout_test_views(n_views: usize, every: usize) -> Vec<usize> {
    (0..n_views).filter(|i| i % every.max(1) == 0).collect()
}

/// NumPy's `linspace(start, stop, num)`: `start + i·step` with `step = (stop − start)/(num − 1)`
/// and the last sample set to `stop` exactly, computed in the same order so that the rounding
/// below sees the same values.
fn linspace(start: f64, stop: f64, num: usize) -> Vec<f64> {
    match num {
        0 => Vec::new(),
        1 => vec![start],
        _ => {
            let step = (stop - start) / (num - 1) as f64;
            let mut v: Vec<f64> = (0..num).map(|i| i as f64 * step + start).collect();
            v[num - 1] = stop;
            v
        }
    }
}

/// RegNeRF / SPARF LLFF split: test views are every `every`-th view; the `n_train` training
/// views are `round(linspace(0, m − 1, n_train))` taken as positions in the list of the `m`
/// remaining views (Python's `round`, ties to even). `n_train = None` trains on all remaining
/// views. Fern (20 views, every 8): test 0, 8, 16; 3 views 1, 10, 19.
pub fn llff_split(
    n_views: usize,
    every: usize,
    n_train: Option<usize>,
    source: &Path,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let test = holdout_test_views(n_views, every);
    let remaining: Vec<usize> = (0..n_views).filter(|i| !test.contains(i)).collect();
    let train = match n_train {
        None => remaining,
        Some(n) => {
            if n > remaining.len() {
                return Err(SceneError::invalid(
                    source,
                    format!(
                        "asked for {n} training views but only {} views remain after holding out every {every}th view",
                        remaining.len()
                    ),
                ));
            }
            linspace(0.0, remaining.len().saturating_sub(1) as f64, n)
                .into_iter()
                .map(|x| remaining[x.round_ties_even() as usize])
                .collect()
        }
    };
    Ok((train, test))
}

/// Captures of at most this many photos train on every photo by default, and are scored by
/// leave-one-out instead of a held-out split.
pub const FEW_PHOTOS: usize = 8;

/// The default split of a capture (nerfstudio, COLMAP) of `n_views` photos, given the views the
/// user named: with no views named, at most [`FEW_PHOTOS`] photos all train and none is held
/// out (score them by leave-one-out), more follow [`llff_split`]; held-out views named alone
/// leave every other view (or `n_train` of them, spread evenly) to train; training views named
/// alone hold out the other photos of a few, or every `every`-th view of more.
pub fn capture_split(
    n_views: usize,
    (train_views, test_views): (Option<&[usize]>, Option<&[usize]>),
    n_train: Option<usize>,
    every: usize,
    source: &Path,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let (train, test) = match (train_views, test_views) {
        (Some(train), Some(test)) => (train.to_vec(), test.to_vec()),
        (Some(train), None) if n_views <= FEW_PHOTOS => {
            let rest = (0..n_views).filter(|i| !train.contains(i)).collect();
            (train.to_vec(), rest)
        }
        (Some(train), None) => (train.to_vec(), holdout_test_views(n_views, every)),
        (None, Some(test)) => {
            let rest: Vec<usize> = (0..n_views).filter(|i| !test.contains(i)).collect();
            (spread(&rest, n_train, source)?, test.to_vec())
        }
        (None, None) if n_views <= FEW_PHOTOS && n_train.is_none() => {
            ((0..n_views).collect(), Vec::new())
        }
        (None, None) => {
            let (train, test) = llff_split(n_views, every, n_train, source)?;
            (train, test)
        }
    };
    validate_split(&train, n_views, "train", source)?;
    // Few photos hold none out.
    if !test.is_empty() {
        validate_split(&test, n_views, "test", source)?;
    }
    Ok((train, test))
}

/// `n` of `views` spread evenly (all when `None`), as [`llff_split`] picks its training views.
fn spread(views: &[usize], n: Option<usize>, source: &Path) -> Result<Vec<usize>> {
    match n {
        None => Ok(views.to_vec()),
        Some(n) if n > views.len() => Err(SceneError::invalid(
            source,
            format!(
                "asked for {n} training views but only {} views remain",
                views.len()
            ),
        )),
        Some(n) => Ok(linspace(0.0, views.len().saturating_sub(1) as f64, n)
            .into_iter()
            .map(|x| views[x.round_ties_even() as usize])
            .collect()),
    }
}

/// The first `n` frames of the seed-0 permutation (DietNeRF protocol) among `n_frames` training
/// frames. The permutation is defined for exactly 100 frames; with another count only `n =
/// n_frames` (all frames, in file order) is accepted.
pub fn blender_train_views(n_frames: usize, n: usize, source: &Path) -> Result<Vec<usize>> {
    if n > n_frames {
        return Err(SceneError::invalid(
            source,
            format!("asked for {n} training views but the file has {n_frames} training frames"),
        ));
    }
    if n_frames == BLENDER_SPARSE_PERMUTATION.len() {
        return Ok(BLENDER_SPARSE_PERMUTATION[..n].to_vec());
    }
    if n == n_frames {
        return Ok((0..n_frames).collect());
    }
    Err(SceneError::invalid(
        source,
        format!(
            "the sparse-view permutation is defined for 100 training frames, the file has {n_frames}; pass explicit training views"
        ),
    ))
}

/// The first `n` views of the DTU training order [`DTU_TRAIN_ORDER`].
pub fn dtu_train_views(n: usize, source: &Path) -> Result<Vec<usize>> {
    if n > DTU_TRAIN_ORDER.len() {
        return Err(SceneError::invalid(
            source,
            format!(
                "the DTU protocol defines at most {} training views, asked for {n}; pass explicit training views",
                DTU_TRAIN_ORDER.len()
            ),
        ));
    }
    Ok(DTU_TRAIN_ORDER[..n].to_vec())
}

/// Parses a view list as given on a command line: comma- or space-separated indices
/// (`"22,23,24"`, `"25 22 28"`).
pub fn parse_view_list(s: &str) -> std::result::Result<Vec<usize>, String> {
    let views = s
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<usize>()
                .map_err(|_| format!("view index {t:?} is not a non-negative integer"))
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    if views.is_empty() {
        return Err("the view list is empty".to_owned());
    }
    Ok(views)
}

/// Checks a split against the number of views: non-empty, in range, no index twice. `what`
/// names the split ("train", "test") in the message.
pub fn validate_split(views: &[usize], n_views: usize, what: &str, source: &Path) -> Result<()> {
    if views.is_empty() {
        return Err(SceneError::invalid(
            source,
            format!("the {what} split is empty"),
        ));
    }
    for (k, &i) in views.iter().enumerate() {
        if i >= n_views {
            return Err(SceneError::invalid(
                source,
                format!("{what} view {i} is out of range: there are {n_views} views"),
            ));
        }
        if views[..k].contains(&i) {
            return Err(SceneError::invalid(
                source,
                format!("{what} view {i} is listed twice"),
            ));
        }
    }
    Ok(())
}

/// Checks that no view is both a training and a held-out view (indices into the same list of
/// views, as in [`crate::Dataset::train`] and [`crate::Dataset::test`]); otherwise held-out
/// metrics would be measured on views the model was fitted to. The error names both lists.
///
/// Not applied by the loaders themselves: some protocols overlap on purpose (DTU's narrow
/// 22, 23, 24 surface setting keeps the standard 25 test views, which include 23 and 24; a
/// one-image file loads as train \[0\], test \[0\]). Commands that report held-out metrics of a
/// model they train (`fewview train`) call it.
pub fn check_disjoint(train: &[usize], test: &[usize], source: &Path) -> Result<()> {
    let shared: Vec<usize> = train.iter().copied().filter(|i| test.contains(i)).collect();
    if shared.is_empty() {
        return Ok(());
    }
    Err(SceneError::invalid(
        source,
        format!(
            "train views {train:?} and test views {test:?} share {shared:?}: held-out metrics \
             would be measured on training views"
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn few_photos_all_train_and_named_views_split_the_rest() {
        let src = Path::new("capture");
        let split = |n, train: Option<&[usize]>, test: Option<&[usize]>, k| {
            capture_split(n, (train, test), k, 8, src).unwrap()
        };
        assert_eq!(split(3, None, None, None), (vec![0, 1, 2], vec![]));
        assert_eq!(split(8, None, None, None).1, Vec::<usize>::new());
        // Nine photos: every 8th held out, as LLFF.
        assert_eq!(
            split(9, None, None, None),
            (vec![1, 2, 3, 4, 5, 6, 7], vec![0, 8])
        );
        // Held-out views named alone leave the others to train.
        assert_eq!(split(3, None, Some(&[1]), None), (vec![0, 2], vec![1]));
        assert_eq!(split(5, None, Some(&[2]), Some(2)), (vec![0, 4], vec![2]));
        assert_eq!(split(3, Some(&[0, 2]), None, None), (vec![0, 2], vec![1]));
        assert_eq!(split(10, Some(&[1, 2]), None, None).1, vec![0, 8]);
        assert!(capture_split(3, (None, Some(&[1])), Some(3), 8, src).is_err());
    }

    #[test]
    fn overlapping_splits_are_refused_naming_both_lists() {
        check_disjoint(&[1, 10, 19], &[0, 8, 16], p()).unwrap();
        let e = check_disjoint(&[0, 8, 16], &[0, 8, 16], p())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("train views [0, 8, 16] and test views [0, 8, 16] share [0, 8, 16]"),
            "{e}"
        );
        let e = check_disjoint(&[1, 2], &[1, 3], p())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("[1, 2]") && e.contains("[1, 3]") && e.contains("share [1]"),
            "{e}"
        );
    }

    fn p() -> &'static Path {
        Path::new("scene")
    }

    #[test]
    fn fern_splits_match_regnerf() {
        let (train, test) = llff_split(20, 8, Some(3), p()).unwrap();
        assert_eq!(test, vec![0, 8, 16]);
        assert_eq!(train, vec![1, 10, 19]);
        let (train, _) = llff_split(20, 8, Some(6), p()).unwrap();
        assert_eq!(train, vec![1, 4, 7, 12, 15, 19]);
        let (train, _) = llff_split(20, 8, Some(9), p()).unwrap();
        assert_eq!(train, vec![1, 3, 5, 7, 10, 12, 14, 17, 19]);
        let (train, _) = llff_split(20, 8, None, p()).unwrap();
        assert_eq!(train.len(), 17);
        assert!(llff_split(20, 8, Some(18), p()).is_err());
    }

    #[test]
    fn linspace_rounding_ties_to_even_like_python() {
        // linspace(0, 4, 9) = 0, 0.5, 1, ..., 4: Python's round sends 0.5 → 0, 1.5 → 2, 2.5 → 2.
        let v: Vec<usize> = linspace(0.0, 4.0, 9)
            .into_iter()
            .map(|x| x.round_ties_even() as usize)
            .collect();
        assert_eq!(v, vec![0, 0, 1, 2, 2, 2, 3, 4, 4]);
        assert_eq!(linspace(0.0, 16.0, 1), vec![0.0]);
    }

    #[test]
    fn blender_first_eight() {
        assert_eq!(
            blender_train_views(100, 8, p()).unwrap(),
            vec![26, 86, 2, 55, 75, 93, 16, 73]
        );
        let all = blender_train_views(100, 100, p()).unwrap();
        let mut sorted = all.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..100).collect::<Vec<_>>());
        assert!(blender_train_views(100, 101, p()).is_err());
        assert!(blender_train_views(50, 8, p()).is_err());
        assert_eq!(blender_train_views(50, 50, p()).unwrap().len(), 50);
    }

    #[test]
    fn dtu_protocol() {
        assert_eq!(dtu_train_views(3, p()).unwrap(), vec![25, 22, 28]);
        assert!(dtu_train_views(10, p()).is_err());
        for v in DTU_TRAIN_ORDER {
            assert!(!DTU_TEST_VIEWS.contains(&v));
        }
    }

    #[test]
    fn view_lists_parse() {
        assert_eq!(parse_view_list("22,23,24").unwrap(), vec![22, 23, 24]);
        assert_eq!(parse_view_list(" 25 22, 28 ").unwrap(), vec![25, 22, 28]);
        assert!(parse_view_list("1,-2").unwrap_err().contains("\"-2\""));
        assert!(parse_view_list(" , ").unwrap_err().contains("empty"));
    }

    #[test]
    fn split_validation_messages() {
        let e = validate_split(&[], 5, "train", p())
            .unwrap_err()
            .to_string();
        assert!(e.contains("train split is empty"), "{e}");
        let e = validate_split(&[1, 7], 5, "test", p())
            .unwrap_err()
            .to_string();
        assert!(e.contains("test view 7 is out of range"), "{e}");
        let e = validate_split(&[1, 1], 5, "train", p())
            .unwrap_err()
            .to_string();
        assert!(e.contains("listed twice"), "{e}");
        validate_split(&[0, 4], 5, "train", p()).unwrap();
    }
}
