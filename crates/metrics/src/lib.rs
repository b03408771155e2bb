//! Metrics the papers report: see the modules.
