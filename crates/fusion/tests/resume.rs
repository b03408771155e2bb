//! A fusion run interrupted on a refresh boundary and resumed from its state ends bit for bit
//! where the uninterrupted run ends: the terms are pure functions of the iteration and the model.
//! The interrupted and resumed halves keep their state on the device (the GPU's default, here
//! on the CPU backend), where the terms read the host model on demand; the straight run keeps
//! it on the host. With a per-photo appearance model, its colour transforms resume as well.

use burn::tensor::Device;
use fewview_fusion::run::{fusion_terms, training_pairs};
use fewview_fusion::{FusionConfig, Variant};
use fewview_scene::Dataset;
use fewview_scene::photometric::PhotoJitter;
use fewview_scene::synthetic::{DemoOptions, demo_dataset};
use fewview_splat::pipeline::{RunConfig, initial_model};
use fewview_splat::raster::RenderCamera;
use fewview_splat::train::appearance::IDENTITY;
use fewview_splat::train::{AppearanceModel, TrainConfig, TrainView, Trainer};

fn trainer(ds: &Dataset, cfg: &RunConfig, fusion: &FusionConfig) -> Trainer {
    let device = Device::flex().autodiff();
    let views = ds
        .train_views()
        .map(|v| TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, &device))
        .collect();
    let (_, extent) = ds.camera_extent();
    let model = initial_model(ds, cfg).unwrap();
    let mut t = Trainer::new(cfg.train.clone(), model, views, extent as f32, device).unwrap();
    let pairs = training_pairs(ds).unwrap();
    for term in fusion_terms(ds, cfg, fusion, &pairs).0 {
        t.add_term(term);
    }
    t
}

#[test]
fn a_resumed_fusion_run_equals_the_uninterrupted_one() {
    // Photos with per-photo exposure, so that the colour transforms have something to learn.
    let ds = demo_dataset(&DemoOptions {
        width: 64,
        height: 48,
        jitter: PhotoJitter {
            exposure_ev: 0.5,
            white_balance: 0.05,
            ..PhotoJitter::default()
        },
        ..DemoOptions::default()
    });
    let mut base = RunConfig::new(TrainConfig::sparse_view(45));
    base.train.background = ds.background;
    let cases = [
        (Variant::Gf, AppearanceModel::None),
        (Variant::KnnColor, AppearanceModel::None),
        (Variant::Gf, AppearanceModel::Affine),
    ];
    for (variant, appearance) in cases {
        let mut cfg = base.clone();
        cfg.train.appearance.model = appearance;
        let fusion = FusionConfig {
            variant,
            refresh_interval: 15,
            knn: fewview_fusion::variant::KnnColorOptions {
                interval: 15,
                ..Default::default()
            },
            ..FusionConfig::default()
        };
        let mut straight = trainer(&ds, &cfg, &fusion);
        while !straight.is_done() {
            straight.step().unwrap();
        }
        let mut first = trainer(&ds, &cfg, &fusion);
        first.keep_state_on_device(true).unwrap();
        for _ in 0..30 {
            first.step().unwrap();
        }
        let mut resumed = trainer(&ds, &cfg, &fusion);
        resumed.keep_state_on_device(true).unwrap();
        resumed.set_state(first.state().unwrap().clone());
        while !resumed.is_done() {
            resumed.step().unwrap();
        }
        assert_eq!(
            resumed.state().unwrap(),
            straight.state().unwrap(),
            "{variant} {appearance:?}"
        );
        if appearance == AppearanceModel::Affine {
            let transforms = &straight.state().unwrap().appearance.transforms;
            assert_eq!(transforms.len(), 3);
            assert!(transforms.iter().all(|m| *m != IDENTITY), "{transforms:?}");
        }
        // ... and the term changed the result (the comparison is not vacuous).
        let plain = FusionConfig {
            variant: Variant::Plain,
            ..fusion.clone()
        };
        let mut without = trainer(&ds, &cfg, &plain);
        while !without.is_done() {
            without.step().unwrap();
        }
        assert_ne!(
            without.state().unwrap().model,
            straight.state().unwrap().model,
            "{variant}"
        );
    }
}
