//! Local popping of the demo scene's exact transition: the ray-traced truth along its path, with
//! the flow of its exact depth, changes nothing but the viewpoint, so what the measure reads is
//! its floor (texture finer than the pixels aliases differently in every frame). The low-pass of
//! `fewview_metrics::popping` is there to bring that floor down.

use fewview_fusion::transition::transition_path;
use fewview_metrics::flow::path_flows;
use fewview_metrics::popping::{local_popping, local_popping_with};
use fewview_scene::synthetic::{DemoOptions, DemoShading, demo_dataset, demo_depth, demo_render};

#[test]
fn the_exact_transition_pops_little_once_low_passed() {
    let opts = DemoOptions {
        shading: DemoShading::Lambertian,
        ..DemoOptions::default()
    };
    let ds = demo_dataset(&opts);
    let keys: Vec<_> = ds.train_views().map(|v| v.camera.clone()).collect();
    let path = transition_path(&keys, 160);
    let frames: Vec<_> = path.iter().map(|c| demo_render(c, &opts)).collect();
    let depths: Vec<_> = path.iter().map(demo_depth).collect();
    let flows = path_flows(&path, &depths).unwrap();
    let levels = |p: f64| p * 255.0;
    let raw = levels(local_popping_with(&frames, &flows, 0.0).unwrap().0.p99);
    let one = levels(local_popping_with(&frames, &flows, 1.0).unwrap().0.p99);
    let default = levels(local_popping(&frames, &flows).unwrap().0.p99);
    eprintln!(
        "exact transition's popping: {raw:.1} levels per pixel, {one:.1} at σ 1, {default:.1} at σ 2"
    );
    assert!(raw > 25.0, "{raw}");
    assert!(default < 6.0 && default < raw / 5.0, "{default} vs {raw}");
    assert!(one > default, "{one} vs {default}");
}
