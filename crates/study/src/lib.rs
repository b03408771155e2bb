//! Pairwise two-alternative forced-choice (2AFC) user studies, as in the fusion paper (supplementary
//! §5–6): the configuration (`study.toml`, [`config`]), the web server participants answer in
//! ([`server`]), the SQLite store that keeps every answer ([`store`]) and the analysis of the
//! answers ([`analysis`]: win rates, exact binomial p-values, Bayesian Bradley–Terry ranking by
//! NUTS, ranking plots).
//!
//! The `fewview study` command is a thin layer over [`server::serve`], [`analysis::analyze`]
//! and [`store::Store::responses`].

pub mod analysis;
pub mod config;
pub mod error;
pub mod server;
pub mod store;

pub use analysis::{
    BtSettings, Response, StudyAnalysis, analyze, read_responses_csv, write_responses_csv,
};
pub use config::StudyConfig;
pub use error::StudyError;
