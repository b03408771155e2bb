//! `fewview study`: run a pairwise 2AFC user study (the fusion paper §5, Fig. 3) and analyse it
//! (Tables 1–2 and the Bayesian Bradley–Terry ranking).

use std::net::SocketAddr;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Subcommand;
use fewview_study::analysis::bradley_terry::{MAX_DRAWS, MIN_DRAWS};
use fewview_study::analysis::{self as study, BtSettings};
use fewview_study::{StudyConfig, server, store};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: StudyCommand,
}

#[derive(Debug, Subcommand)]
enum StudyCommand {
    /// Serve the study page (two videos side by side, the configured questions).
    Serve {
        /// The study configuration (TOML).
        ///
        /// The study configuration (TOML: title, seed, methods, scenes, questions, one video
        /// per scene and method; crates/study/README.md).
        #[arg(long, value_name = "FILE")]
        config: PathBuf,
        /// Address to listen on (default: loopback).
        ///
        /// Address to listen on; loopback by default. Use 0.0.0.0:PORT to accept other machines.
        #[arg(long, default_value = "127.0.0.1:8080")]
        addr: SocketAddr,
    },
    /// Analyse the answers: win rates, exact binomial p-values, Bayesian Bradley–Terry ranking.
    Analyze {
        /// Read the answers from this study's database.
        #[arg(long, value_name = "FILE", conflicts_with = "responses")]
        config: Option<PathBuf>,
        /// Read the answers from CSV.
        ///
        /// Columns participant,question,scene,left,right,winner.
        #[arg(long, value_name = "FILE")]
        responses: Option<PathBuf>,
        /// Output folder of the report.
        ///
        /// Output folder (report.md, pairs.csv, skills.csv, analysis.json, ranking_*.png).
        #[arg(long)]
        out: PathBuf,
        /// Seed of the NUTS chains.
        #[arg(long, default_value_t = BtSettings::default().seed)]
        seed: u64,
        #[arg(long, value_name = "N", default_value_t = BtSettings::default().chains)]
        chains: usize,
        #[arg(long, value_name = "N", default_value_t = BtSettings::default().tune)]
        tune: u64,
        /// Post-tuning draws per chain.
        ///
        /// At least 10 (R̂ and the ESS split each chain in halves of at least 5 draws), at most
        /// 1,000,000 (every draw is kept in memory).
        #[arg(long, value_name = "N", default_value_t = BtSettings::default().draws,
              value_parser = clap::value_parser!(u64).range(MIN_DRAWS..=MAX_DRAWS))]
        draws: u64,
        #[arg(long, value_name = "P", default_value_t = BtSettings::default().target_accept)]
        target_accept: f64,
        /// Standard deviation of the Normal(0, σ) skill prior.
        #[arg(long, value_name = "SIGMA", default_value_t = BtSettings::default().prior_sigma)]
        prior_sigma: f64,
    },
    /// Export the stored answers as CSV.
    Export {
        #[arg(long, value_name = "FILE")]
        config: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        StudyCommand::Serve { config, addr } => {
            let config = StudyConfig::load(&config)?;
            let db = config.database.clone();
            let per = config.trials_per_participant();
            server::serve(config, addr, |bound| {
                println!(
                    "study: http://{bound}/  ({per} comparisons per participant; answers in {})",
                    db.display()
                );
            })?;
            Ok(())
        }
        StudyCommand::Analyze {
            config,
            responses,
            out,
            seed,
            chains,
            tune,
            draws,
            target_accept,
            prior_sigma,
        } => {
            let (answers, order) = match (config, responses) {
                (Some(path), None) => {
                    let cfg = StudyConfig::load(&path)?;
                    let store = store::Store::open(&cfg.database)?;
                    (
                        store.responses().with_context(|| {
                            format!("{}: reading answers", cfg.database.display())
                        })?,
                        Some(cfg.methods),
                    )
                }
                (None, Some(csv)) => (study::read_responses_csv(&csv)?, None),
                _ => bail!("give --config (the study's database) or --responses (a CSV file)"),
            };
            let settings = BtSettings {
                prior_sigma,
                chains,
                tune,
                draws,
                target_accept,
                seed,
                ..BtSettings::default()
            };
            let analysis = study::analyze(&answers, order.as_deref(), &settings)?;
            let written = analysis.write_report(&out)?;
            print!("{}", analysis.to_markdown());
            for p in written {
                println!("wrote {}", p.display());
            }
            Ok(())
        }
        StudyCommand::Export { config, out } => {
            let cfg = StudyConfig::load(&config)?;
            let store = store::Store::open(&cfg.database)?;
            let answers = store.responses()?;
            study::write_responses_csv(&out, &answers)?;
            println!("wrote {} answers to {}", answers.len(), out.display());
            Ok(())
        }
    }
}
