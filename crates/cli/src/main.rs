//! `fewview`: the one binary. Each subcommand parses its flags, calls a library function and
//! prints; the work itself lives in the library crates.

// The binary is where the project prints.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod commands;

/// mimalloc instead of the system allocator: the rasterizer and trainer allocate and free
/// megabyte-sized buffers every iteration, which glibc's allocator returns to the kernel and
/// page-faults back in each time (about 12 % of a render's CPU time went to the kernel).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use clap::Parser;

/// Reconstruct 3D scenes from a few photos and render new views of them.
#[derive(Debug, Parser)]
#[command(name = "fewview", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: commands::Command,
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("FEWVIEW_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    match commands::run(cli.command) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        // The context and every cause, joined by `: ` on one line.
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    /// The libraries' errors carry their cause in their message and not also as `source()`,
    /// so the chain as printed says it once.
    #[test]
    fn a_file_error_prints_its_cause_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such dataset folder");
        let err = anyhow::Error::new(fewview_scene::SceneError::io("/nope", io))
            .context("cannot load dataset /nope");
        assert_eq!(
            format!("{err:#}"),
            "cannot load dataset /nope: /nope: no such dataset folder"
        );
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let err = anyhow::Error::new(fewview_geom::GeomError::from(
            fewview_scene::SceneError::io("/a.ply", io),
        ))
        .context("reading the reference surface /a.ply");
        assert_eq!(
            format!("{err:#}"),
            "reading the reference surface /a.ply: /a.ply: gone"
        );
    }
}
