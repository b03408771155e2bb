use clap::Parser;
use fewview_surface::matching::refine::WarpModel;
use fewview_surface::schedule::PoseTiming;

use super::Args;

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: Args,
}

fn config(flags: &[&str]) -> fewview_surface::RunConfig {
    let argv = std::iter::once("surface")
        .chain(["--synthetic"])
        .chain(flags.iter().copied());
    Cli::try_parse_from(argv).unwrap().args.config().unwrap()
}

#[test]
fn default_schedule_is_the_cpu_one_with_the_papers_fallback() {
    let c = config(&[]);
    assert!(c.pose_warmup.is_some());
    assert_eq!(PoseTiming::of(&c.train), PoseTiming::LATE_RELEASE);
    assert_eq!(c.pose_timing_without_warmup, Some(PoseTiming::PAPER));
}

#[test]
fn paper_schedule_has_no_warm_up_and_refines_from_the_start() {
    let c = config(&["--schedule", "paper"]);
    assert!(c.pose_warmup.is_none());
    assert_eq!(PoseTiming::of(&c.train), PoseTiming::PAPER);
    assert_eq!(c.pose_timing_without_warmup, None);
    // A warm-up asked for explicitly keeps the paper's pose timing.
    let c = config(&["--schedule", "paper", "--pose-warmup", "on"]);
    assert!(c.pose_warmup.is_some());
    assert_eq!(PoseTiming::of(&c.train), PoseTiming::PAPER);
}

#[test]
fn explicit_flags_override_the_schedule_and_its_fallback() {
    let c = config(&["--pose-warmup", "off"]);
    assert!(c.pose_warmup.is_none());
    let c = config(&["--pose-start", "0.5"]);
    assert_eq!(c.train.pose_start, 0.5);
    assert_eq!(c.pose_timing_without_warmup, None);
    let c = config(&["--pose-lr", "1e-2,1e-3"]);
    assert_eq!((c.train.pose_lr.start, c.train.pose_lr.end), (1e-2, 1e-3));
    assert_eq!(c.train.pose_start, 0.75);
    assert_eq!(c.pose_timing_without_warmup, None);
    let c = config(&["--warmup-min-matches", "30"]);
    assert_eq!(c.pose_warmup.unwrap().min_matches_per_pair, 30);
}

#[test]
fn densify_is_automatic_explicit_or_off() {
    let c = config(&[]);
    assert_eq!(
        (c.densify.is_some(), c.densify_if_needed.is_some()),
        (false, true)
    );
    let c = config(&["--densify", "6"]);
    assert_eq!(c.densify.map(|d| d.spacing_px), Some(6));
    for off in ["off", "0"] {
        let c = config(&["--densify", off]);
        assert_eq!(
            (c.densify.is_some(), c.densify_if_needed.is_some()),
            (false, false)
        );
    }
    let c = config(&["--schedule", "paper"]);
    assert!(c.densify_if_needed.is_none());
    // A typo fails while parsing.
    let err = Cli::try_parse_from(["surface", "--densify", "dense"])
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("--densify") && err.contains("dense"), "{err}");
}

#[test]
fn match_refinement_warp_bend_limit_and_warm_up_scale_reach_the_config() {
    let c = config(&[]);
    let refine = c.match_refinement.unwrap();
    assert_eq!((refine.warp, refine.max_bend_px), (WarpModel::Affine, None));
    let c = config(&["--match-refine", "quadratic", "--match-max-bend", "4"]);
    let refine = c.match_refinement.unwrap();
    assert_eq!(
        (refine.warp, refine.max_bend_px),
        (WarpModel::Quadratic, Some(4.0))
    );
    assert!(
        config(&["--match-refine", "none"])
            .match_refinement
            .is_none()
    );
    let c = config(&["--warmup-cauchy", "0.3"]);
    assert_eq!(c.pose_warmup.unwrap().cauchy_px, 0.3);
    // The covariance polish: on with the CPU schedule, off with the paper's (whose
    // warm-up, when asked for, is the plain one), and either way by flag.
    assert!(c.pose_warmup.unwrap().covariance_polish);
    let c = config(&["--warmup-covariance", "off"]);
    assert!(!c.pose_warmup.unwrap().covariance_polish);
    let c = config(&["--schedule", "paper", "--pose-warmup", "on"]);
    assert!(!c.pose_warmup.unwrap().covariance_polish);
    let c = config(&[
        "--schedule",
        "paper",
        "--pose-warmup",
        "on",
        "--warmup-covariance",
        "on",
    ]);
    assert!(c.pose_warmup.unwrap().covariance_polish);
    let refused = |flags: &[&str]| {
        let argv = ["surface", "--synthetic"]
            .into_iter()
            .chain(flags.iter().copied());
        match Cli::try_parse_from(argv) {
            Err(e) => e.to_string(),
            Ok(cli) => cli.args.config().unwrap_err().to_string(),
        }
    };
    let err = refused(&["--match-max-bend", "4"]);
    assert!(err.contains("--match-refine quadratic"), "{err}");
    let err = refused(&["--match-refine", "cubic"]);
    assert!(
        err.contains("--match-refine") && err.contains("cubic"),
        "{err}"
    );
    assert!(refused(&["--warmup-cauchy", "0"]).contains("--warmup-cauchy"));
    assert!(refused(&["--match-max-bend", "NaN"]).contains("--match-max-bend"));
}

#[test]
fn loss_switches_and_weights_reach_the_overrides() {
    let argv = [
        "surface",
        "--no-loss",
        "ncc,gc",
        "--no-loss",
        "eikonal",
        "--lambda",
        "u=0.02,GC=0",
        "--lambda",
        "u=0.5",
    ];
    let args = Cli::try_parse_from(argv).unwrap().args;
    let on = args.loss_switches();
    assert_eq!(
        (on.matching, on.ncc, on.geometric_consistency),
        (true, false, false)
    );
    assert_eq!((on.uncertainty, on.psdf, on.eikonal), (true, true, false));
    let w = args.loss_weights();
    assert_eq!(
        (w.u, w.gc, w.mc, w.geo, w.psdf),
        (Some(0.5), Some(0.0), None, None, None)
    );
    for bad in ["u", "v=1", "u=-1", "u=NaN"] {
        let err = Cli::try_parse_from(["surface", "--lambda", bad])
            .err()
            .expect("refused")
            .to_string();
        assert!(err.contains("--lambda") && err.contains(bad), "{err}");
    }
    assert!(Cli::try_parse_from(["surface", "--no-loss", "colour"]).is_err());
}

#[test]
fn contradictory_or_bad_schedule_flags_are_refused() {
    let parse = |flags: &[&str]| {
        Cli::try_parse_from(std::iter::once("surface").chain(flags.iter().copied()))
    };
    assert!(parse(&["--pose-warmup", "on", "--pose-warmup", "off"]).is_err());
    assert!(parse(&["--pose-warmup", "yes"]).is_err());
    assert!(parse(&["--schedule", "fast"]).is_err());
    let args = parse(&["--pose-start", "1.5"]).unwrap().args;
    let err = args.config().unwrap_err().to_string();
    assert!(err.contains("--pose-start 1.5"), "{err}");
}

/// Every flag's default is the library's: an empty command line gives `Overrides::default()`.
#[test]
fn an_empty_command_line_gives_the_librarys_defaults() {
    let argv = ["surface", "--synthetic"];
    let args = Cli::try_parse_from(argv).unwrap().args;
    assert_eq!(args.overrides(), fewview_surface::Overrides::default());
}
