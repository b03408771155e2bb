use super::*;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// A smooth random texture (`channels` channels), 8-bit.
fn texture(w: usize, h: usize, channels: usize, seed: u64) -> Vec<u8> {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise: Vec<f32> = (0..w * h * channels).map(|_| rng.random::<f32>()).collect();
    let mut out = vec![0u8; noise.len()];
    for y in 0..h {
        for x in 0..w {
            for c in 0..channels {
                let mut acc = 0.0;
                for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    let (xx, yy) = ((x + dx).min(w - 1), (y + dy).min(h - 1));
                    acc += noise[(yy * w + xx) * channels + c];
                }
                out[(y * w + x) * channels + c] = (20.0 + 215.0 * acc / 4.0) as u8;
            }
        }
    }
    out
}

/// `img` shifted left by `d` pixels (the right view of a plane at disparity `d`).
fn shifted(img: &[u8], w: usize, h: usize, channels: usize, d: usize) -> Vec<u8> {
    let mut out = vec![0u8; img.len()];
    for y in 0..h {
        for x in 0..w {
            let src = (x + d).min(w - 1);
            for c in 0..channels {
                out[(y * w + x) * channels + c] = img[(y * w + src) * channels + c];
            }
        }
    }
    out
}

#[test]
fn a_shifted_texture_gives_its_shift_everywhere_matched() {
    let (w, h) = (120, 60);
    for (channels, paths, border) in [
        (1, Paths::Five, Border::OpenCv),
        (3, Paths::Eight, Border::OpenCv),
        (3, Paths::Five, Border::Partial),
    ] {
        let left = texture(w, h, channels, 4);
        let right = shifted(&left, w, h, channels, 7);
        let l = GrayOrRgb::new(w, h, channels, &left).unwrap();
        let r = GrayOrRgb::new(w, h, channels, &right).unwrap();
        let params = SgmParams {
            num_disparities: 32,
            paths,
            border,
            ..Default::default()
        };
        // OpenCV's border leaves the 32 first columns out; the partial border only the columns
        // whose match lies outside the right image (and the blocks that straddle it).
        let first = if border == Border::OpenCv { 32 } else { 7 + 3 };
        let disp = match_left(&l, &r, &params).unwrap();
        for y in 0..h {
            for x in 0..w {
                // The rightmost columns see the replicated border in the right view.
                let matchable = x >= first && x + 7 < w - 2;
                let right_border = x + 7 >= w - 2;
                match disp.get(x, y) {
                    Some(d) if !right_border => assert!((d - 7.0).abs() < 0.25, "({x}, {y}): {d}"),
                    Some(_) => {}
                    None => assert!(!matchable, "({x}, {y}) lost"),
                }
            }
        }
        // Right-to-left matching finds the same shift for the right image's pixels.
        let back = match_right(&l, &r, &params).unwrap();
        let good = (0..h)
            .flat_map(|y| (0..w - 40).map(move |x| (x, y)))
            .filter(|&(x, y)| back.get(x, y).is_some_and(|d| (d - 7.0).abs() < 0.25))
            .count();
        assert!(good as f64 > 0.9 * ((w - 40) * h) as f64, "{good}");
    }
}

#[test]
fn a_texture_shifted_right_gives_its_negative_shift_and_no_match_past_the_right_edge() {
    // A rectification with one principal point per image gives negative disparities: the
    // right view sees the texture moved to the right. Left pixels near the right edge then
    // have their true match outside the right image, and must stay unmatched rather than take
    // a wrong candidate.
    let (w, h, channels, shift) = (120, 60, 3, 7);
    let left = texture(w, h, channels, 5);
    let mut right = vec![0u8; left.len()];
    for y in 0..h {
        for x in 0..w {
            let src = x.saturating_sub(shift);
            for c in 0..channels {
                right[(y * w + x) * channels + c] = left[(y * w + src) * channels + c];
            }
        }
    }
    let l = GrayOrRgb::new(w, h, channels, &left).unwrap();
    let r = GrayOrRgb::new(w, h, channels, &right).unwrap();
    let params = SgmParams {
        min_disparity: -32,
        num_disparities: 32,
        ..Default::default()
    };
    let disp = match_left(&l, &r, &params).unwrap();
    let mut matched = 0;
    for y in 0..h {
        for x in 0..w {
            match disp.get(x, y) {
                Some(d) => {
                    assert!(
                        x + shift < w,
                        "({x}, {y}): matched past the right edge ({d})"
                    );
                    // The leftmost columns see the right view's replicated border.
                    let left_border = x < shift + 3;
                    assert!(
                        left_border || (d + shift as f32).abs() < 0.25,
                        "({x}, {y}): {d}"
                    );
                    matched += 1;
                }
                None => assert!(x < shift + 3 || x + shift + 3 >= w, "({x}, {y}) lost"),
            }
        }
    }
    assert!(matched as f64 > 0.8 * (w * h) as f64, "{matched}");
}

#[test]
fn median_matches_a_naive_sort_with_replicated_borders() {
    let (w, h) = (7, 5);
    let mut rng = StdRng::seed_from_u64(1);
    let src: Vec<i16> = (0..w * h).map(|_| rng.random_range(-20..20)).collect();
    let mut fast = src.clone();
    median3x3(&mut fast, w, h);
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let mut v = Vec::new();
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (xx, yy) = (
                        (x + dx).clamp(0, w as i64 - 1),
                        (y + dy).clamp(0, h as i64 - 1),
                    );
                    v.push(src[(yy * w as i64 + xx) as usize]);
                }
            }
            v.sort();
            assert_eq!(fast[(y * w as i64 + x) as usize], v[4]);
        }
    }
}

#[test]
fn speckles_up_to_the_window_size_are_dropped() {
    // A 6×4 map: a 3-pixel island of 100s, a 4-pixel region of 50s joined by steps ≤ 2, and
    // invalid (-16) elsewhere.
    let inv = -16;
    #[rustfmt::skip]
    let mut map: Vec<i16> = vec![
        100, 100, inv, 50, 51, inv,
        100, inv, inv, 52, inv, inv,
        inv, inv, inv, 53, inv, 10,
        inv, inv, inv, inv, inv, 90,
    ];
    let orig = map.clone();
    speckle_filter(&mut map, 6, 4, inv, 3, 2);
    for (i, (&a, &b)) in map.iter().zip(&orig).enumerate() {
        let kept = matches!(b, 50..=53);
        assert_eq!(a, if kept { b } else { inv }, "pixel {i}");
    }
}

#[test]
fn bad_parameters_and_mismatched_images_are_refused() {
    let img = vec![0u8; 20 * 10];
    let l = GrayOrRgb::new(20, 10, 1, &img).unwrap();
    let odd = SgmParams {
        block_size: 4,
        ..Default::default()
    };
    assert!(
        match_left(&l, &l, &odd)
            .unwrap_err()
            .to_string()
            .contains("block size 4")
    );
    let huge = SgmParams {
        block_size: 11,
        ..Default::default()
    };
    let rgb = vec![0u8; 20 * 10 * 3];
    let c = GrayOrRgb::new(20, 10, 3, &rgb).unwrap();
    assert!(
        match_left(&c, &c, &huge)
            .unwrap_err()
            .to_string()
            .contains("overflow")
    );
    let small = vec![0u8; 19 * 10];
    let s = GrayOrRgb::new(19, 10, 1, &small).unwrap();
    assert!(
        match_left(&l, &s, &SgmParams::default())
            .unwrap_err()
            .to_string()
            .contains("20×10×1")
    );
    assert!(GrayOrRgb::new(20, 10, 2, &img).is_err());
    assert!(GrayOrRgb::new(20, 11, 1, &img).is_err());
    // Narrower than the disparity range: nothing matched with OpenCV's border, no panic.
    let opencv = SgmParams {
        border: Border::OpenCv,
        ..Default::default()
    };
    let d = match_left(&l, &l, &opencv).unwrap();
    assert_eq!(d.valid_fraction(), 0.0);
}
