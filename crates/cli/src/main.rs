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

/// `mi_option_purge_delay` of mimalloc's `mi_option_e` (the same index in its v2 and v3
/// headers; the Rust bindings do not name it).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Keeps freed pages committed instead of handing them back to the kernel a second later: the
/// training loops free and reallocate the same buffers every step, and each purged page came
/// back through a page fault and the kernel's zeroing (transparent huge pages, 2 MiB at a
/// time). The process's memory then stays at its peak until it exits.
fn keep_freed_pages() {
    // SAFETY: sets a process-wide option; mimalloc reads it when it next purges.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
}

use clap::Parser;

/// Reconstruct 3D scenes from a few photos and render new views of them.
#[derive(Debug, Parser)]
#[command(name = "fewview", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: commands::Command,
}

fn main() -> std::process::ExitCode {
    keep_freed_pages();
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
    /// The option index is mimalloc's purge delay: its default in the bundled v3 (1000 ms)
    /// before, and never purging after.
    #[test]
    fn freed_pages_stay_committed() {
        use super::{MI_OPTION_PURGE_DELAY, keep_freed_pages};
        // SAFETY: reads a process-wide option.
        let get = || unsafe { libmimalloc_sys::mi_option_get(MI_OPTION_PURGE_DELAY) };
        if std::env::var_os("MIMALLOC_PURGE_DELAY").is_none() {
            assert_eq!(get(), 1000);
        }
        keep_freed_pages();
        assert_eq!(get(), -1);
    }

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
