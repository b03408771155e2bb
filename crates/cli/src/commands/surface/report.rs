//! What the `surface` command prints: pipeline events above the progress bar, the warm-up's
//! pose errors and the final report.

use fewview_metrics::pose_error::PoseError;
use fewview_surface::warmup::WarmupReport;
use fewview_surface::{Event, RunReport};

use crate::commands::progress::Bar;

/// Prints a pipeline event above the progress bar (or moves the bar).
pub(super) fn print_event(bar: &Bar, e: Event) {
    match e {
        Event::Matched {
            matches,
            matcher,
            fallback,
            precision,
            densified_because,
        } => {
            let p = precision
                .map(|p| {
                    format!(
                        " ({:.0} % within 2 px of the true epipolar lines)",
                        100.0 * p.precision_2px
                    )
                })
                .unwrap_or_default();
            let by = matcher.map(|m| format!(" by {m}")).unwrap_or_default();
            bar.suspend(|| {
                if let Some(why) = fallback {
                    eprintln!("{why}");
                }
                if let Some(why) = densified_because {
                    eprintln!(
                        "sparse matches cannot tie the views together ({why}): growing dense ones"
                    );
                }
                eprintln!("{matches} correspondences{by}{p}");
            });
        }
        Event::Step(s) => {
            bar.set_position(s.iteration as u64 + 1);
            if s.iteration % 10 == 0 {
                bar.set_message(format!("psnr {:.2}  inv_s {:.0}", s.psnr, s.inv_s));
            }
        }
        Event::Checkpoint {
            iteration,
            pose_error,
        } => bar.suspend(|| {
            eprintln!(
                "iteration {iteration}: rotation error {:.3}°, translation error (×100) {:.3}",
                pose_error.rotation_deg,
                100.0 * pose_error.translation
            );
        }),
        Event::WarmedUp {
            report,
            pose_error,
            pair_errors_deg,
        } => bar.suspend(|| print_warmup(report, pose_error, pair_errors_deg)),
        Event::BundleAdjusted { report, pose_error } => bar.suspend(|| match &report.skipped {
            Some(why) => eprintln!("bundle adjustment skipped: {why}"),
            None => eprintln!(
                "bundle adjustment ({} tracks, {} in three views or more; {} iterations, median \
                 reprojection error {:.3} → {:.3} px): rotation error {:.3}°, translation error \
                 (×100) {:.3}",
                report.tracks,
                report.multi_view_tracks,
                report.iterations,
                report.median_px_before,
                report.median_px_after,
                pose_error.rotation_deg,
                100.0 * pose_error.translation
            ),
        }),
        Event::PatchesAdjusted { report, pose_error } => bar.suspend(|| match &report.skipped {
            Some(why) => eprintln!("patch adjustment skipped: {why}"),
            None => eprintln!(
                "patch adjustment ({} patches in {} views beyond their own, {} of them joined; \
                     {} iterations): rotation error {:.3}°, translation error (×100) {:.3}",
                report.patches,
                report.observations,
                report.joined,
                report.iterations,
                pose_error.rotation_deg,
                100.0 * pose_error.translation
            ),
        }),
        Event::PoseTimingFallback(timing) => bar.suspend(|| {
            let from = if timing.start > 0.0 {
                format!("{:.0} % into the run", 100.0 * timing.start)
            } else {
                "the first iteration".into()
            };
            eprintln!(
                "so the poses are refined from {from} at {:e} → {:e} instead (views that share \
                 few matches may need a larger --max-pair-angle: 180 matches every pair)",
                timing.lr.start, timing.lr.end
            );
        }),
        Event::Stage(st) => bar.set_message(st.to_string()),
        Event::Notice(text) => bar.suspend(|| eprintln!("note: {text}")),
    }
}

/// The global start's pairs and the epipolar warm-up's outcome.
fn print_warmup(report: &WarmupReport, pose_error: &PoseError, pair_errors_deg: &[f64]) {
    if let Some(why) = &report.global_start_failed {
        eprintln!("global start: none ({why})");
    }
    for (p, err) in report.global_start.iter().zip(pair_errors_deg) {
        eprintln!(
            "global start: views {}–{} five-point pose from {} of {} matches \
             (median {:.3} px), relative rotation {err:.3}° from the truth",
            p.view_a, p.view_b, p.inliers, p.matches, p.median_px
        );
    }
    match &report.skipped {
        Some(why) => eprintln!("epipolar warm-up skipped: {why}"),
        None => eprintln!(
            "epipolar warm-up (from the {} start, {} iterations, median Sampson distance \
             {:.2} → {:.2} px): rotation error {:.3}°, translation error (×100) {:.3}",
            report.chosen_start,
            report.iterations,
            report.initial_median_px,
            report.final_median_px,
            pose_error.rotation_deg,
            100.0 * pose_error.translation
        ),
    }
}

pub(super) fn print_report(r: &RunReport, out: &std::path::Path) {
    println!(
        "poses            R {:.3}° → {:.3}°   t(×100) {:.2} → {:.2}",
        r.initial_pose_error.rotation_deg,
        r.final_pose_error.rotation_deg,
        100.0 * r.initial_pose_error.translation,
        100.0 * r.final_pose_error.translation
    );
    let warmed_up = r.warmup.as_ref().is_some_and(|w| w.skipped.is_none());
    if let Some(w) = r.warmup_pose_error.as_ref().filter(|_| warmed_up) {
        println!(
            "  after warm-up  R {:.3}°   t(×100) {:.2}",
            w.rotation_deg,
            100.0 * w.translation
        );
    }
    let bundled = r
        .bundle_adjustment
        .as_ref()
        .is_some_and(|b| b.skipped.is_none());
    if let Some(b) = r.bundle_adjustment_pose_error.as_ref().filter(|_| bundled) {
        println!(
            "  after bundle   R {:.3}°   t(×100) {:.2}",
            b.rotation_deg,
            100.0 * b.translation
        );
    }
    let adjusted = r
        .patch_adjustment
        .as_ref()
        .is_some_and(|p| p.skipped.is_none());
    if let Some(p) = r.patch_adjustment_pose_error.as_ref().filter(|_| adjusted) {
        println!(
            "  after patches  R {:.3}°   t(×100) {:.2}",
            p.rotation_deg,
            100.0 * p.translation
        );
    }
    let sparf = &r.rotation_at_sparf_eps;
    println!(
        "  at ε = {:.0e}     R {:.3}° → {}{:.3}° (SPARF's code; the surface paper Table 1's convention)",
        sparf.eps,
        sparf.initial_deg,
        [
            sparf.warmup_deg.filter(|_| warmed_up),
            sparf.bundle_adjustment_deg.filter(|_| bundled),
            sparf.patch_adjustment_deg.filter(|_| adjusted)
        ]
        .iter()
        .flatten()
        .map(|w| format!("{w:.3}° → "))
        .collect::<String>(),
        sparf.final_deg
    );
    println!(
        "training         {} iterations, {:.0} s ({:.2} it/s)",
        r.iterations, r.train_seconds_wall, r.iterations_per_second_wall
    );
    if r.pose_steps_skipped > 0 {
        println!(
            "  pose steps     {} skipped: the pose gradient was not finite (the field still stepped)",
            r.pose_steps_skipped
        );
    }
    if let (Some(p), Some(s)) = (r.mean_psnr_masked, r.mean_ssim_masked) {
        println!(
            "test views       masked PSNR {p:.2} dB, SSIM {s:.3} ({} views)",
            r.test_views.len()
        );
    }
    if let Some(c) = &r.chamfer {
        println!(
            "chamfer-L1       {:.5} ({:.2} % of the bounding-box diagonal)",
            c.chamfer_l1,
            100.0 * c.relative
        );
    }
    if let Some(c) = &r.chamfer_observed {
        println!(
            "  observed part  {:.5} ({:.2} % of the diagonal; the faces a training view sees)",
            c.chamfer_l1,
            100.0 * c.relative
        );
    }
    if let Some(why) = &r.chamfer_error {
        println!("chamfer-L1       not scored: {why}");
    }
    println!(
        "mesh             {} vertices, {} faces (mesh.ply; mesh_input_frame.ply in the input's world)",
        r.mesh_vertices, r.mesh_faces
    );
    if !r.refined_pose_files.is_empty() {
        println!("refined poses    {}", r.refined_pose_files.join(", "));
    }
    println!("written to       {}", out.display());
}
