//! The masked DTU scores as the sparse-view peers take them (CoR-GS's and DNGaussian's
//! `metrics_dtu.py`, which score RegNeRF's protocol):
//!
//! * **PSNR** over the object's interior only. The peers resize each object mask to the test
//!   size with a bicubic filter and keep the pixels where it is exactly 1, which drops the ring
//!   of pixels the object's outline crosses. Our masks reach the test size already binary, so
//!   the interior is the mask's pixels whose four neighbours are in the mask too.
//! * **SSIM** and **LPIPS** over the whole image, with render and photo both set to white
//!   outside the mask: the background then counts as a perfect match, as it does for the peers.
//!
//! `fewview train` keeps its own masked scores (`mean_masked_psnr`: every mask pixel, the
//! convention of the sparse-view surface papers); only `benchmark --protocol dtu` scores so.

use fewview_metrics::lpips::Lpips;
use fewview_metrics::psnr::psnr_masked;
use fewview_metrics::ssim::{SsimOptions, ssim_with};
use fewview_scene::{Dataset, Image};

use crate::eval::render_model;
use crate::model::GaussianModel;
use crate::raster::{RenderCamera, RenderSettings};

/// The mean masked scores of a model's renders of a dataset's held-out views.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskedScores {
    pub psnr: f64,
    pub ssim: f64,
    /// ST-LPIPS, when a network was given.
    pub lpips: Option<f64>,
}

/// Renders `model` at each of `ds`'s held-out views and scores it as [`score_view`] does; every
/// held-out view must have a mask.
pub fn held_out_masked_scores(
    ds: &Dataset,
    model: &GaussianModel,
    settings: &RenderSettings,
    lpips: Option<&Lpips>,
) -> Result<MaskedScores, String> {
    let (mut psnr, mut ssim, mut lp) = (0.0, 0.0, 0.0);
    for v in ds.test_views() {
        let mask = v
            .mask
            .as_ref()
            .ok_or_else(|| format!("held-out view `{}` has no object mask", v.name))?;
        let rendered = render_model(model, &RenderCamera::from(&v.camera), settings).rgb;
        let s = score_view(&rendered, &v.image, mask, lpips)
            .map_err(|e| format!("held-out view `{}`: {e}", v.name))?;
        psnr += s.psnr;
        ssim += s.ssim;
        lp += s.lpips.unwrap_or(0.0);
    }
    let n = ds.test.len().max(1) as f64;
    Ok(MaskedScores {
        psnr: psnr / n,
        ssim: ssim / n,
        lpips: lpips.map(|_| lp / n),
    })
}

/// One view's masked scores: PSNR inside the mask's [`interior`], SSIM (the evaluation's
/// default, [`SsimOptions::default`]) and ST-LPIPS of both images made white outside the mask.
pub fn score_view(
    rendered: &Image,
    truth: &Image,
    mask: &Image,
    lpips: Option<&Lpips>,
) -> Result<MaskedScores, fewview_metrics::MetricsError> {
    let psnr = psnr_masked(rendered, truth, &interior(mask))?;
    let (r, t) = (white_outside(rendered, mask), white_outside(truth, mask));
    let ssim = ssim_with(&r, &t, &SsimOptions::default())?;
    let lpips = match lpips {
        Some(net) => Some(net.distance(&r, &t)?),
        None => None,
    };
    Ok(MaskedScores { psnr, ssim, lpips })
}

/// The pixels of a 1-channel mask (`> 0.5`) whose four neighbours are in it too; pixels on the
/// image border count their missing neighbours as outside.
pub fn interior(mask: &Image) -> Image {
    let (w, h) = (mask.width, mask.height);
    let inside = |x: isize, y: isize| {
        x >= 0
            && y >= 0
            && x < w as isize
            && y < h as isize
            && mask.data[y as usize * w + x as usize] > 0.5
    };
    let data = (0..h as isize)
        .flat_map(|y| (0..w as isize).map(move |x| (x, y)))
        .map(|(x, y)| {
            let kept = [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .all(|&(dx, dy)| inside(x + dx, y + dy));
            if kept { 1.0 } else { 0.0 }
        })
        .collect();
    Image::from_vec(w, h, 1, data)
}

/// `image` with every pixel outside the 1-channel `mask` (`≤ 0.5`) set to white.
pub fn white_outside(image: &Image, mask: &Image) -> Image {
    let c = image.channels;
    let data = image
        .data
        .iter()
        .enumerate()
        .map(|(i, &v)| if mask.data[i / c] > 0.5 { v } else { 1.0 })
        .collect();
    Image::from_vec(image.width, image.height, c, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4×3 block of foreground in a 6×5 mask: its interior is the block's 2×1 centre.
    #[test]
    fn interior_drops_the_outline_ring() {
        let mut mask = Image::filled(6, 5, &[0.0]);
        for y in 1..4 {
            for x in 1..5 {
                mask.set(x, y, 0, 1.0);
            }
        }
        let inner = interior(&mask);
        let kept: Vec<(usize, usize)> = (0..5)
            .flat_map(|y| (0..6).map(move |x| (x, y)))
            .filter(|&(x, y)| inner.data[y * 6 + x] > 0.5)
            .collect();
        assert_eq!(kept, vec![(2, 2), (3, 2)]);
        // A full mask loses its border pixels, whose neighbours lie outside the image.
        let full = interior(&Image::filled(6, 5, &[1.0]));
        assert_eq!(full.data.iter().filter(|&&m| m > 0.5).count(), 4 * 3);
    }

    /// An error of 0.1 inside the interior gives exactly 20 dB whatever the ring and the
    /// background hold; a render equal to the photo inside the mask has SSIM 1.
    #[test]
    fn only_the_interior_counts_for_psnr_and_the_background_is_white() {
        let (w, h) = (24, 20);
        let mut mask = Image::filled(w, h, &[0.0]);
        for y in 4..16 {
            for x in 4..20 {
                mask.set(x, y, 0, 1.0);
            }
        }
        let inner = interior(&mask);
        let truth = Image::filled(w, h, &[0.5, 0.5, 0.5]);
        let mut rendered = Image::filled(w, h, &[0.9, 0.1, 0.3]);
        for y in 0..h {
            for x in 0..w {
                if inner.data[y * w + x] > 0.5 {
                    for c in 0..3 {
                        rendered.set(x, y, c, 0.6);
                    }
                }
            }
        }
        let s = score_view(&rendered, &truth, &mask, None).unwrap();
        assert!((s.psnr - 20.0).abs() < 1e-5, "{}", s.psnr);
        assert_eq!(s.lpips, None);
        let mut same_inside = white_outside(&truth, &mask);
        same_inside.set(0, 0, 1, 0.0); // outside the mask: painted over by the white fill
        let s = score_view(&same_inside, &truth, &mask, None).unwrap();
        assert!((s.ssim - 1.0).abs() < 1e-6, "{}", s.ssim); // SSIM runs in f32
        assert_eq!(s.psnr, f64::INFINITY);
    }
}
