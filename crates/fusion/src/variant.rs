//! The method and its alternatives (the fusion paper, "Splat-based Gradient-domain Fusion for Seamless
//! View Transition", supplement §4), chosen by one setting, and the settings they share.

use serde::{Deserialize, Serialize};

use crate::reproject::{Occlusion, ReprojectOptions};

/// What regularises the views between the training views.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Variant {
    /// No regulariser: the stereo start and the photometric loss only.
    Plain,
    /// (a) 1 % of the hierarchical cloud as the initial Gaussians instead of 10 %.
    SparseInit,
    /// (b) Every 100 iterations the 50 nearest neighbours of each Gaussian; an L2 pull of its
    /// diffuse colour to their mean, weight 10, throughout training.
    KnnColor,
    /// (c) L1 total variation of the rendered virtual view, weight 1.
    Tv,
    /// (d) L1 of the rendered virtual view to the reprojected references (their `t`-weighted
    /// mean where both are valid), the fusion loss's weight.
    L1Virtual,
    /// (e) L1 to the occlusion-aware Poisson blend of the two reprojections (Eq. 3) as a pseudo
    /// ground truth, the fusion loss's weight.
    Poisson,
    /// (f) Gradient-domain fusion: L1 between the rendered virtual view's gradients and the
    /// guidance field of its two reprojected neighbours (ours).
    #[default]
    Gf,
}

impl Variant {
    /// Every variant, in the supplement's order.
    pub const ALL: [Variant; 7] = [
        Variant::Plain,
        Variant::SparseInit,
        Variant::KnnColor,
        Variant::Tv,
        Variant::L1Virtual,
        Variant::Poisson,
        Variant::Gf,
    ];

    /// The name flags and files use.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Plain => "plain",
            Variant::SparseInit => "sparse-init",
            Variant::KnnColor => "knn-color",
            Variant::Tv => "tv",
            Variant::L1Virtual => "l1-virtual",
            Variant::Poisson => "poisson",
            Variant::Gf => "gf",
        }
    }

    /// The supplement's letter ("" for plain).
    pub fn letter(self) -> &'static str {
        match self {
            Variant::Plain => "",
            Variant::SparseInit => "a",
            Variant::KnnColor => "b",
            Variant::Tv => "c",
            Variant::L1Virtual => "d",
            Variant::Poisson => "e",
            Variant::Gf => "f",
        }
    }

    /// Whether the variant renders virtual views while training.
    pub fn uses_virtual_views(self) -> bool {
        matches!(
            self,
            Variant::Tv | Variant::L1Virtual | Variant::Poisson | Variant::Gf
        )
    }

    /// Whether the variant reprojects the training photos into the virtual views.
    pub fn uses_references(self) -> bool {
        matches!(self, Variant::L1Virtual | Variant::Poisson | Variant::Gf)
    }

    /// Whether the variant combines with a per-photo appearance model
    /// ([`fewview_splat::train::appearance`]). (d) and (e) pull the virtual view's colours
    /// themselves towards a blend of the photos; under an appearance model each photo lives in
    /// its own colour space, brought into the model's only through transforms that keep moving
    /// between re-meshings, so their targets would chase stale colours. GF's target is the
    /// photos' gradients, which a transform scales without moving an edge, and the others have
    /// no photo-based target.
    pub fn takes_appearance(self) -> bool {
        !matches!(self, Variant::L1Virtual | Variant::Poisson)
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Variant {
    type Err = String;

    /// A variant by name or by the supplement's letter (`gf` or `f`).
    fn from_str(s: &str) -> Result<Self, String> {
        Variant::ALL
            .into_iter()
            .find(|v| v.name() == s || (!v.letter().is_empty() && v.letter() == s))
            .ok_or_else(|| {
                let names: Vec<&str> = Variant::ALL.iter().map(|v| v.name()).collect();
                format!(
                    "unknown variant `{s}`; expected one of {}",
                    names.join(", ")
                )
            })
    }
}

/// The largest dropout rate ([`fewview_splat::train::dropout`]) a fusion run trains with unless
/// asked: none. DropGaussian's dropout, `train`'s default, keeps the held-out views as good or
/// better but made the demo's transition worse against its ray-traced truth over two seeds
/// (`docs/experiments.md`, 2026-12-07), and the transition is this method's product.
pub const FUSION_DROPOUT: f32 = 0.0;

/// Settings of the fusion method and its alternatives.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FusionConfig {
    pub variant: Variant,
    /// λ of the virtual-view loss of (d), (e) and (f). The paper does not print it; 0.3 is
    /// the best of a sweep over 0.1–3 on the demo scene (`docs/guide/fusion.md`).
    pub weight: f32,
    /// Weight of the total variation of (c) (the supplement: 1).
    pub tv_weight: f32,
    /// The virtual-view losses start at this fraction of the run.
    pub start_fraction: f64,
    /// ... and are taken every this many iterations.
    pub every: usize,
    /// The training views' depth is re-rendered and re-meshed every this many iterations.
    pub refresh_interval: usize,
    /// Bring the two references of a virtual view to one exposure before they are used
    /// ([`crate::guidance::exposure_matched`]): for photos whose exposure or white balance
    /// differ. On by default for gf, off for the alternatives (see [`FusionConfig::for_variant`]).
    #[serde(default)]
    pub match_exposure: bool,
    pub reproject: ReprojectOptions,
    pub knn: KnnColorOptions,
}

/// Gf's configuration: [`FusionConfig::for_variant`] of [`Variant::Gf`].
impl Default for FusionConfig {
    fn default() -> Self {
        Self::for_variant(Variant::Gf)
    }
}

impl FusionConfig {
    /// The defaults of `variant`. Gf brings the two references of a virtual view to one
    /// exposure and tests them against each other's meshes ([`Occlusion::Meshes`]): on the
    /// demo, with and without photo jitter, that form leads the supplement's literal reading
    /// (references as they are, hidden by the virtual view's own depth) in popping in excess of
    /// the ray-traced truth's and in path PSNR against it (the table is in
    /// `docs/guide/fusion.md`); `--match-exposure false --occlusion own-depth` gives the
    /// literal reading. The alternatives (a)–(e) keep the literal reading, as the supplement
    /// describes them.
    pub fn for_variant(variant: Variant) -> Self {
        let gf = variant == Variant::Gf;
        Self {
            variant,
            weight: 0.3,
            tv_weight: 1.0,
            start_fraction: 0.2,
            every: 3,
            refresh_interval: 500,
            match_exposure: gf,
            reproject: ReprojectOptions {
                occlusion: if gf {
                    Occlusion::Meshes
                } else {
                    Occlusion::OwnDepth
                },
                ..ReprojectOptions::default()
            },
            knn: KnnColorOptions::default(),
        }
    }
}

impl FusionConfig {
    /// Checks the values make sense; the message names the setting.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(format!("weight {} must be finite and ≥ 0", self.weight));
        }
        if !(0.0..=1.0).contains(&self.start_fraction) {
            return Err(format!(
                "start fraction {} is not in [0, 1]",
                self.start_fraction
            ));
        }
        if self.every == 0 || self.refresh_interval == 0 || self.knn.interval == 0 {
            return Err("intervals must be at least 1".into());
        }
        if self.knn.neighbours == 0 {
            return Err("the colour regulariser needs at least 1 neighbour".into());
        }
        Ok(())
    }
}

/// Alternative (b)'s settings (supplement §4: 50 neighbours, every 100 iterations, weight 10).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct KnnColorOptions {
    pub neighbours: usize,
    pub interval: usize,
    pub weight: f32,
}

impl Default for KnnColorOptions {
    fn default() -> Self {
        Self {
            neighbours: 50,
            interval: 100,
            weight: 10.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_parse_by_name_and_letter_and_unknown_names_list_the_choices() {
        for v in Variant::ALL {
            assert_eq!(v.name().parse::<Variant>(), Ok(v));
            if !v.letter().is_empty() {
                assert_eq!(v.letter().parse::<Variant>(), Ok(v));
            }
        }
        let e = "gradient".parse::<Variant>().unwrap_err();
        assert!(e.contains("gradient") && e.contains("knn-color"), "{e}");
    }
}
