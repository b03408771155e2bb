use burn::tensor::{Device, Tensor};
use fewview_scene::load::{LoadOptions, load_dataset};
use fewview_splat::cputime::process_cpu_seconds as cpu;
use fewview_splat::init::{FrustumView, from_points, random_in_frustums};
use fewview_splat::loss::photometric_loss;
use fewview_splat::op::{RenderView, render};
use fewview_splat::raster::{RenderCamera, RenderSettings};
use fewview_splat::train::TrainView;
use std::time::Instant;

fn main() {
    let data = std::env::var("FEWVIEW_DATA").unwrap();
    let ds = load_dataset(
        &std::path::Path::new(&data).join("llff/fern"),
        &LoadOptions::default(),
    )
    .unwrap();
    let device = Device::flex().autodiff();
    let fv: Vec<FrustumView> = ds
        .train_views()
        .map(|v| FrustumView {
            camera: &v.camera,
            image: &v.image,
            near: v.depth_bounds.unwrap().0,
            far: v.depth_bounds.unwrap().1,
        })
        .collect();
    let model = from_points(&random_in_frustums(&fv, 20000, 0), 3);
    let views: Vec<TrainView> = ds
        .train_views()
        .map(|v| TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, &device))
        .collect();
    let n = model.len();
    {
        let settings = RenderSettings {
            background: [0.0; 3],
            sh_degree: 3,
            near_plane: 0.2,
        };
        for _ in 0..2 {
            let c0 = cpu();
            let (out, ctx) =
                fewview_splat::raster::forward(&model.refs(), &views[0].camera, &settings);
            let c1 = cpu();
            let go = vec![1e-3f32; out.data.len()];
            let gr = fewview_splat::raster::backward(&model.refs(), &ctx, &go);
            let c2 = cpu();
            println!(
                "host: fwd {:.0} ms cpu, {} pairs ({:.0} M/s/core); bwd {:.0} ms cpu, {} pairs ({:.0} M/s/core); entries {}",
                (c1 - c0) * 1e3,
                out.pairs,
                out.pairs as f64 / (c1 - c0) / 1e6,
                (c2 - c1) * 1e3,
                gr.pairs,
                gr.pairs as f64 / (c2 - c1) / 1e6,
                ctx.bins.entries.len()
            );
        }
    }
    for _ in 0..3 {
        let (w0, c0) = (Instant::now(), cpu());
        let g = model.to_tensors(&device, true);
        let probe = Tensor::<2>::zeros([n, 2], &device).require_grad();
        let (w1, c1) = (Instant::now(), cpu());
        let out = render(
            &g,
            probe.clone(),
            &RenderView {
                camera: views[0].camera.clone(),
                settings: RenderSettings {
                    background: [0.0; 3],
                    sh_degree: 3,
                    near_plane: 0.2,
                },
            },
        );
        let [h, w, _] = out.image.dims();
        let (w2, c2) = (Instant::now(), cpu());
        let rgb = out.image.clone().slice([0..h, 0..w, 0..3]);
        let loss = photometric_loss(rgb, views[0].target.clone(), 0.2);
        let lv = loss.clone().into_data();
        let (w3, c3) = (Instant::now(), cpu());
        let grads = loss.backward();
        let (w4, c4) = (Instant::now(), cpu());
        let a = g.means.grad(&grads).unwrap().into_data();
        let b = g.sh.grad(&grads).unwrap().into_data();
        let (w5, c5) = (Instant::now(), cpu());
        println!(
            "wall/cpu ms: tensors {:.0}/{:.0} render {:.0}/{:.0} loss {:.0}/{:.0} backward {:.0}/{:.0} grads {:.0}/{:.0}  {:?}{}{}",
            (w1 - w0).as_secs_f64() * 1e3,
            (c1 - c0) * 1e3,
            (w2 - w1).as_secs_f64() * 1e3,
            (c2 - c1) * 1e3,
            (w3 - w2).as_secs_f64() * 1e3,
            (c3 - c2) * 1e3,
            (w4 - w3).as_secs_f64() * 1e3,
            (c4 - c3) * 1e3,
            (w5 - w4).as_secs_f64() * 1e3,
            (c5 - c4) * 1e3,
            lv.num_elements(),
            a.num_elements(),
            b.num_elements()
        );
    }
}
