//! Flags that change the photos a run sees: per-photo exposure, white balance and vignetting
//! (`demo`, `fusion`), and the demo scene's highlights, mirror floor and baseline.

use clap::Args;
use fewview_scene::photometric::{MAX_EXPOSURE_EV, MAX_VIGNETTING, MAX_WHITE_BALANCE, PhotoJitter};
use fewview_scene::synthetic::{DemoGloss, DemoOptions};

use crate::commands::number_args::number_pair;

/// Per-photo exposure, white balance and vignetting of the training photos (held-out photos
/// keep theirs), as a phone's automatic exposure gives them.
#[derive(Debug, Clone, Args)]
pub struct JitterArgs {
    /// Exposure jitter of the training photos, EV (0–3).
    ///
    /// Exposure jitter: each training photo gets the gain 2^u, u drawn uniformly in [−EV, EV]
    /// (0 to 3).
    #[arg(long, value_name = "EV", default_value_t = 0.0, value_parser = exposure_ev)]
    pub exposure_jitter: f64,
    /// White-balance jitter of the photos (0–0.5).
    ///
    /// White-balance jitter: each channel of each training photo gets the factor 1 + F·v,
    /// v uniform in [−1, 1] (0 to 0.5).
    #[arg(long, value_name = "F", default_value_t = 0.0, value_parser = white_balance)]
    pub white_balance_jitter: f64,
    /// Vignetting strength of the photos (0–0.9).
    ///
    /// Vignetting of strength S per training photo: a radial falloff and a gradient across the
    /// frame, drawn per photo (0 to 0.9).
    #[arg(long, value_name = "S", default_value_t = 0.0, value_parser = vignetting)]
    pub vignetting: f64,
    /// Seed of the jitter's draws.
    ///
    /// Photo i's gains depend only on it and i.
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    pub jitter_seed: u64,
}

impl JitterArgs {
    pub fn jitter(&self) -> PhotoJitter {
        PhotoJitter {
            exposure_ev: self.exposure_jitter,
            white_balance: self.white_balance_jitter,
            vignetting: self.vignetting,
            seed: self.jitter_seed,
        }
    }
}

/// How glossy the demo scene is and how wide its arc of cameras.
#[derive(Debug, Clone, Args)]
pub struct DemoSceneArgs {
    /// The spheres' highlight `KS,EXP`.
    ///
    /// The spheres' Blinn–Phong highlight `KS,EXP` (default 0.1,60, weak enough for the stereo
    /// start; 0.4,40 is a highlight at full strength).
    #[arg(long, value_name = "KS,EXP", value_parser = highlight)]
    pub specular: Option<(f64, f64)>,
    /// Mirror reflectance of the floor, in [0, 1).
    ///
    /// Mirror reflectance of the floor in [0, 1): the spheres' reflections move over it with the
    /// camera.
    #[arg(long, value_name = "M", default_value_t = 0.0)]
    pub mirror_floor: f64,
    /// Widen the demo's arc of cameras K times.
    ///
    /// 1: 50° of azimuth; 2: 100°, views twice as far apart; 0.25 to 3.
    #[arg(long, value_name = "K", default_value_t = 1.0, value_parser = baseline_scale)]
    pub baseline_scale: f64,
}

impl DemoSceneArgs {
    /// `opts` with this scene: gloss and arc, checked (a one-line error names the flag).
    pub fn apply(&self, opts: DemoOptions) -> anyhow::Result<DemoOptions> {
        Ok(DemoOptions {
            gloss: self.gloss()?,
            baseline_scale: self.baseline_scale,
            ..opts
        })
    }

    /// The scene's gloss, checked: a one-line error names the flag.
    fn gloss(&self) -> anyhow::Result<DemoGloss> {
        let mut gloss = DemoGloss {
            mirror: self.mirror_floor,
            ..DemoGloss::default()
        };
        if let Some(highlight) = self.specular {
            gloss.sphere = highlight;
        }
        gloss
            .validate()
            .map_err(|m| anyhow::anyhow!("--specular/--mirror-floor: {m}"))?;
        Ok(gloss)
    }

    /// Whether a flag asks for something other than the default scene.
    pub fn is_set(&self) -> bool {
        self.specular.is_some() || self.mirror_floor != 0.0 || self.baseline_scale != 1.0
    }
}

fn in_range(s: &str, max: f64, what: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{s:?}: {e}"))?;
    if v.is_finite() && (0.0..=max).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{s}: the {what} must be between 0 and {max}"))
    }
}

/// `KS,EXP`: two numbers (their ranges are the scene's to check).
fn highlight(s: &str) -> Result<(f64, f64), String> {
    number_pair(s, "0.4,40")
}

fn baseline_scale(s: &str) -> Result<f64, String> {
    match in_range(s, 3.0, "baseline scale")? {
        v if v >= 0.25 => Ok(v),
        _ => Err(format!(
            "{s}: the baseline scale must be between 0.25 and 3"
        )),
    }
}

fn exposure_ev(s: &str) -> Result<f64, String> {
    in_range(s, MAX_EXPOSURE_EV, "exposure jitter (EV)")
}

fn white_balance(s: &str) -> Result<f64, String> {
    in_range(s, MAX_WHITE_BALANCE, "white-balance jitter")
}

fn vignetting(s: &str) -> Result<f64, String> {
    in_range(s, MAX_VIGNETTING, "vignetting strength")
}
