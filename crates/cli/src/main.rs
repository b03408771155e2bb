//! `fewview`: the one binary. Each subcommand parses its flags, calls a library function and
//! prints; the work itself lives in the library crates.

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
        Err(err) => {
            // One line: the outermost context and every cause, joined.
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
