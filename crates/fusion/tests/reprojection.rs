//! Reprojection through meshes of depth on the demo scene's exact depth (an independent ray
//! tracer): into the photo's own camera it gives the photo back; into a virtual camera between
//! two views, the two references agree with each other where both are valid.

use fewview_fusion::guidance::guidance_field;
use fewview_fusion::reproject::{ReprojectOptions, reference_mesh, reproject};
use fewview_fusion::virtual_view::virtual_camera;
use fewview_scene::synthetic::{DemoOptions, DemoShading, demo_dataset, demo_depth};

fn lambertian() -> fewview_scene::Dataset {
    demo_dataset(&DemoOptions {
        width: 160,
        height: 120,
        shading: DemoShading::Lambertian,
        ..DemoOptions::default()
    })
}

#[test]
fn a_reprojection_into_the_photos_own_camera_is_the_photo_inside_its_mask() {
    let ds = lambertian();
    let v = &ds.views[ds.train[0]];
    let depth = demo_depth(&v.camera);
    let mesh = reference_mesh(&depth, &v.camera, &v.image).unwrap();
    let r = reproject(&mesh, &v.camera, Some(&depth), &ReprojectOptions::default()).unwrap();
    let valid = r.valid.iter().filter(|&&b| b).count();
    assert!(
        valid > r.valid.len() / 2,
        "only {valid} of {} pixels valid",
        r.valid.len()
    );
    let mut worst = 0f32;
    for p in (0..r.valid.len()).filter(|&p| r.valid[p]) {
        for c in 0..3 {
            worst = worst.max((r.image[p * 3 + c] - v.image.data[p * 3 + c]).abs());
        }
    }
    assert!(worst < 1e-4, "largest colour difference {worst}");
}

#[test]
fn both_neighbours_reprojected_into_a_virtual_view_agree_where_both_are_valid() {
    // Lambertian shading: a surface point has one colour from every camera, so the two
    // reprojections differ only by resampling; their gradients (the guidance field's inputs)
    // agree too.
    let ds = lambertian();
    let (a, b) = (&ds.views[ds.train[0]], &ds.views[ds.train[1]]);
    let cam = virtual_camera(&a.camera, &b.camera, 0.4);
    let own = demo_depth(&cam);
    let options = ReprojectOptions::default();
    let f = reproject(
        &reference_mesh(&demo_depth(&a.camera), &a.camera, &a.image).unwrap(),
        &cam,
        Some(&own),
        &options,
    )
    .unwrap();
    let g = reproject(
        &reference_mesh(&demo_depth(&b.camera), &b.camera, &b.image).unwrap(),
        &cam,
        Some(&own),
        &options,
    )
    .unwrap();
    let both: Vec<usize> = (0..f.valid.len())
        .filter(|&p| f.valid[p] && g.valid[p])
        .collect();
    assert!(
        both.len() > f.valid.len() / 4,
        "{} common pixels",
        both.len()
    );
    let (fi, gi) = (&f.image, &g.image);
    let mean_difference = both
        .iter()
        .flat_map(|&p| (0..3).map(move |c| (fi[p * 3 + c] - gi[p * 3 + c]).abs()))
        .sum::<f32>()
        / (3 * both.len()) as f32;
    assert!(mean_difference < 0.03, "mean |f* − g*| = {mean_difference}");
    let field = guidance_field(&f, &g, 0.4);
    assert!(field.defined() > both.len());
}
