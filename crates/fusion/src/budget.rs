//! What a run will need in memory, known before it is spent: the peak of each stage grows with
//! the pixels of one photo (the stereo start's cost volumes, the transition's 160 frames with
//! their flows and popping maps) and with the photos' pixels together (training), so a size the
//! machine cannot hold is refused before anything runs, with the downscale that fits.
//!
//! The bytes per pixel are the peaks `metrics.json` records (`memory`), rounded up, of a
//! 3-photo street at 1024×768 (docs/experiments.md, 2026-12-06).

/// Peak bytes per pixel of one photo: the stereo start (two cost volumes of up to 256
/// hypotheses at a time, and the cloud).
pub const STEREO_BYTES_PER_PIXEL: u64 = 2 * 1024;
/// Peak bytes per pixel of one render while training (the rasterizer's buffers, the loss).
pub const TRAINING_BYTES_PER_PIXEL: u64 = 1600;
/// Peak bytes per pixel of each training photo (the photo and its copies on the device).
pub const TRAINING_BYTES_PER_VIEW_PIXEL: u64 = 64;
/// Peak bytes per pixel of a frame while the transition is scored.
pub const TRANSITION_BYTES_PER_PIXEL: u64 = 9 * 1024;
/// What any run holds besides (the model, the program).
pub const BASE_BYTES: u64 = 512 << 20;

/// The peak a run on `views` photos of `width × height` pixels will reach (the transition
/// only when `transition`).
pub fn run_peak_bytes(width: usize, height: usize, views: usize, transition: bool) -> u64 {
    let pixels = (width * height) as u64;
    let stereo = STEREO_BYTES_PER_PIXEL * pixels;
    let training =
        (TRAINING_BYTES_PER_PIXEL + TRAINING_BYTES_PER_VIEW_PIXEL * views as u64) * pixels;
    let transition = if transition {
        TRANSITION_BYTES_PER_PIXEL * pixels
    } else {
        0
    };
    BASE_BYTES + stereo.max(training).max(transition)
}

/// Refuses a run that would need more than `available` bytes, naming the size, the need and
/// the smallest extra downscale (on top of `downscale`) that fits.
pub fn check_fits(
    (width, height): (usize, usize),
    views: usize,
    transition: bool,
    downscale: u32,
    available: u64,
) -> Result<(), String> {
    let need = run_peak_bytes(width, height, views, transition);
    if need <= available {
        return Ok(());
    }
    let fits = (2..=16u32).find(|k| {
        let (w, h) = (width / *k as usize, height / *k as usize);
        run_peak_bytes(w, h, views, transition) <= available
    });
    let gb = |b: u64| b as f64 / (1u64 << 30) as f64;
    Err(format!(
        "at {width}×{height} with {views} photos the run would need about {:.1} GB of memory and \
         {:.1} GB are available{}",
        gb(need),
        gb(available),
        match fits {
            Some(k) => format!("; pass --downscale {} to fit", downscale * k),
            None => String::new(),
        }
    ))
}

/// [`check_fits`] for the training views of `ds` (its largest photo) against the memory the
/// machine has available now; `Ok` where the system does not say.
pub fn check_dataset_fits(
    ds: &fewview_scene::Dataset,
    transition: bool,
    downscale: u32,
) -> Result<(), String> {
    let Some(available) = fewview_scene::memory::available_bytes() else {
        return Ok(());
    };
    let largest = ds
        .train_views()
        .map(|v| (v.image.width, v.image.height))
        .max_by_key(|(w, h)| w * h)
        .unwrap_or((0, 0));
    check_fits(largest, ds.train.len(), transition, downscale, available)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The street the constants were measured on fits in 8 GB; twice its side does not, and
    /// the message names the downscale that fits.
    #[test]
    fn a_size_that_does_not_fit_is_refused_with_the_downscale_that_does() {
        let eight = 8u64 << 30;
        assert!(run_peak_bytes(1024, 768, 3, true) < eight);
        assert!(check_fits((1024, 768), 3, true, 1, eight).is_ok());
        let e = check_fits((2048, 1536), 3, true, 1, eight).unwrap_err();
        assert!(
            e.contains("2048×1536") && e.contains("--downscale 2"),
            "{e}"
        );
        // Forty photos at the working size train within 8 GB.
        assert!(run_peak_bytes(1000, 750, 40, true) < eight);
    }
}
