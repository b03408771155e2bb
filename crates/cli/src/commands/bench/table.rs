//! The `bench` command's printed table.

use super::report::Report;

pub(super) fn print_table(r: &Report) {
    println!("{:<46} {:>14} {:>14}", "figure", "value", "reference");
    if let Some(m) = &r.matching {
        let pair = format!("{}x{} pair", m.width, m.height);
        let rows = [
            ("XFeat detect, one image s", m.detect_seconds, String::new()),
            (
                "XFeat + MNN, pair s",
                m.pair_mnn_seconds,
                format!("{} matches", m.mnn_matches),
            ),
            (
                "XFeat + LighterGlue, pair s",
                m.pair_lighterglue_seconds,
                format!("{} matches", m.lighterglue_matches),
            ),
            (
                "XFeat*, pair s",
                m.pair_star_seconds,
                format!("{} matches", m.star_matches),
            ),
        ];
        for (name, seconds, note) in rows {
            println!(
                "{:<46} {:>14.3} {:>14}",
                format!("{name} ({pair})"),
                seconds,
                note
            );
        }
    }
    for t in &r.human_training {
        println!(
            "{:<46} {:>14.3} {:>14}",
            format!(
                "PoseGaussian {} training s/step ({}x{}, {})",
                t.preset, t.size[0], t.size[1], t.device
            ),
            t.seconds_per_step,
            format!("fwd {:.3}", t.forward_seconds)
        );
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "  training GMAC/s vs 1024³ matmul", t.network_gmacs_per_s, t.matmul_gmacs_per_s
        );
    }
    for h in &r.human_inference {
        println!(
            "{:<46} {:>14.3} {:>14}",
            format!(
                "PoseGaussian {} s/frame ({}x{}, 2 sources)",
                h.preset, h.size[0], h.size[1]
            ),
            h.seconds_per_frame,
            ""
        );
        println!(
            "{:<46} {:>14}",
            "  image / pose / depth enc, decoder, TPS, render",
            format!(
                "{:.3} / {:.3} / {:.3} / {:.3} / {:.3} / {:.3}",
                h.image_encoder,
                h.pose_encoder,
                h.depth_encoder,
                h.decoder_and_heads,
                h.tps,
                h.rendering
            )
        );
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "  network GMAC/s vs 1024³ matmul", h.network_gmacs_per_s, h.matmul_gmacs_per_s
        );
    }
    if let Some(rb) = &r.raster {
        print_raster(rb);
    }
    print_training(r);
    if let Some(s) = &r.ssim {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "SSIM value+grad ms 504x378 (vs PSNR)", s.value_grad_ms, s.psnr_ms
        );
    }
    print_blend_and_stereo(r);
    if let Some(m) = r.peak_memory_mib {
        println!("{:<46} {:>14.0} {:>14}", "peak memory MiB", m, "");
    }
}

fn print_raster(rb: &fewview_splat::bench::RasterBench) {
    let g = |v: f64| format!("{v:.3e}");
    println!(
        "{:<46} {:>14} {:>14}",
        format!(
            "raster fwd pairs/s/core ({}k, {}x{}, 1 thread)",
            rb.gaussians / 1000,
            rb.width,
            rb.height
        ),
        g(rb.forward_pairs_per_sec_per_core),
        g(rb.reference_pairs_per_sec)
    );
    println!(
        "{:<46} {:>14} {:>14}",
        "raster bwd pairs/s/core (1 thread)",
        g(rb.backward_pairs_per_sec_per_core),
        ""
    );
    println!(
        "{:<46} {:>14} {:>14}",
        format!("  fwd / bwd per CPU-s, {} threads", rb.threads),
        g(rb.forward_pairs_per_cpu_sec_all_threads),
        g(rb.backward_pairs_per_cpu_sec_all_threads)
    );
    println!(
        "{:<46} {:>14.1} {:>14}",
        format!("raster fwd ms (wall, {} threads)", rb.threads),
        rb.forward_seconds * 1e3,
        ""
    );
    println!(
        "{:<46} {:>14.1} {:>14}",
        format!("raster bwd ms (wall, {} threads)", rb.threads),
        rb.backward_seconds * 1e3,
        ""
    );
    println!(
        "{:<46} {:>14.2} {:>14}",
        "raster fwd speed-up vs plain loop (per core)", rb.forward_vs_reference, "1"
    );
}

fn print_training(r: &Report) {
    for t in [r.train_demo.as_ref(), r.train_fern.as_ref()]
        .into_iter()
        .flatten()
    {
        println!(
            "{:<46} {:>14.2} {:>14}",
            format!(
                "train it/s {} {}x{} ({} G)",
                t.dataset, t.width, t.height, t.gaussians
            ),
            t.iterations_per_second,
            ""
        );
        println!(
            "{:<46} {:>14.2} {:>14}",
            "  it per CPU-second", t.iterations_per_cpu_second, ""
        );
    }
    if let Some(f) = &r.fusion_demo {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "demo it/s with fusion term (vs without)",
            f.fusion.iterations_per_second,
            f.plain.iterations_per_second
        );
        println!(
            "{:<46} {:>14.2} {:>14}",
            "  fusion term's share of a step", f.term_share, ""
        );
    }
    if let Some(a) = &r.appearance_demo {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "demo it/CPU-s with colour transforms (vs without)",
            a.affine.iterations_per_cpu_second,
            a.plain.iterations_per_cpu_second
        );
        println!(
            "{:<46} {:>14.3} {:>14}",
            "  transforms' cost per step (fraction, CPU time)", a.overhead, ""
        );
    }
    if let Some(s) = &r.train_surface {
        println!(
            "{:<46} {:>14.3} {:>14.4}",
            format!(
                "surface it/s {} {}x{} (vs NeuS MLP)",
                s.dataset, s.width, s.height
            ),
            s.hash_grid.iterations_per_second,
            s.reference_neus_mlp.iterations_per_second
        );
        println!(
            "{:<46} {:>14.3} {:>14.4}",
            "  it per CPU-second",
            s.hash_grid.iterations_per_cpu_second,
            s.reference_neus_mlp.iterations_per_cpu_second
        );
        println!(
            "{:<46} {:>14.3} {:>14.3}",
            "  it per CPU-second, poses held (vs refined)",
            s.hash_grid_poses_held.iterations_per_cpu_second,
            s.hash_grid.iterations_per_cpu_second
        );
    }
}

fn print_blend_and_stereo(r: &Report) {
    let g = |v: f64| format!("{v:.3e}");
    if let Some(b) = &r.blend {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "Poisson blend 1024^2x3 s (vs direct, half size)", b.seconds, b.reference_seconds
        );
        if let Some(c) = b.cpu_seconds {
            println!("{:<46} {:>14.2} {:>14}", "  CPU seconds", c, "");
        }
    }
    if let Some(b) = &r.stereo {
        println!(
            "{:<46} {:>14} {:>14}",
            format!(
                "SGM pix·disp/CPU-s ({}x{}, {} d, vs 1 thread)",
                b.width, b.height, b.disparities
            ),
            g(b.pixel_disparities_per_cpu_second),
            g((b.width * b.height * b.disparities) as f64 / b.one_thread_seconds)
        );
        println!(
            "{:<46} {:>14.3} {:>14.3}",
            "  SGM s: 5 paths (vs 1 thread)", b.opencv_mode_seconds, b.one_thread_seconds
        );
        println!(
            "{:<46} {:>14.3} {:>14}",
            "  SGM s: 8 paths, partial border", b.default_seconds, ""
        );
        println!(
            "{:<46} {:>14.3} {:>14}",
            format!(
                "  stereo pair s ({}x{}, {} d, both ways, refined)",
                b.pair_width, b.pair_height, b.pair_disparities
            ),
            b.pair_seconds,
            ""
        );
    }
}
