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

use clap::{Arg, ArgAction, CommandFactory, FromArgMatches, Parser};

/// Reconstruct 3D scenes from a few photos and render new views of them.
#[derive(Debug, Parser)]
#[command(name = "fewview", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: commands::Command,
}

/// The command line with its two levels of help: `-h`/`--help` list every flag with the first
/// paragraph of its doc comment, a one-line summary (so that a command's help fits two
/// screens); `--help-all` (or `fewview help COMMAND`) prints every comment in full.
fn command_line() -> clap::Command {
    Cli::command()
        .disable_help_flag(true)
        .arg(
            Arg::new("help")
                .short('h')
                .long("help")
                .global(true)
                .action(ArgAction::HelpShort)
                .display_order(usize::MAX - 1)
                .help("Print a summary of the flags (`--help-all`: in full)"),
        )
        .arg(
            Arg::new("help-all")
                .long("help-all")
                .global(true)
                .action(ArgAction::HelpLong)
                .display_order(usize::MAX)
                .help("Print every flag's full description"),
        )
}

fn main() -> std::process::ExitCode {
    keep_freed_pages();
    let cli = Cli::from_arg_matches(&command_line().get_matches()).unwrap_or_else(|e| e.exit());
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

    /// Columns and rows of the screen the help is measured on.
    const SCREEN: (usize, usize) = (100, 50);

    /// Every command's help at `SCREEN`'s width, by its path (`fewview surface`, ...).
    fn helps(long: bool) -> Vec<(String, String)> {
        fn walk(cmd: &mut clap::Command, path: &str, long: bool, out: &mut Vec<(String, String)>) {
            let path = format!("{path} {}", cmd.get_name()).trim().to_string();
            let mut sized = cmd.clone().term_width(SCREEN.0);
            let help = if long {
                sized.render_long_help()
            } else {
                sized.render_help()
            };
            out.push((path.clone(), help.to_string()));
            for sub in cmd.get_subcommands_mut() {
                walk(sub, &path, long, out);
            }
        }
        let mut cmd = super::command_line();
        cmd.build();
        let mut out = Vec::new();
        walk(&mut cmd, "", long, &mut out);
        out
    }

    /// `-h`/`--help` of the binary and of every command fit two screens; `--help-all` still
    /// has each flag's full description (here, one from a second paragraph).
    #[test]
    fn every_help_fits_two_screens() {
        let short = helps(false);
        assert!(short.len() > 25, "{} commands", short.len());
        for (path, help) in &short {
            let rows = help.lines().count();
            assert!(rows <= 2 * SCREEN.1, "`{path} --help`: {rows} lines");
            let wide = help.lines().map(|l| l.chars().count()).max().unwrap_or(0);
            assert!(
                wide <= SCREEN.0,
                "`{path} --help`: a line of {wide} columns"
            );
        }
        let detail = "100k on a GPU";
        let find = |helps: &[(String, String)]| {
            helps
                .iter()
                .find(|(p, _)| p == "fewview surface")
                .map(|(_, h)| h.contains(detail))
        };
        assert_eq!(find(&short), Some(false));
        assert_eq!(find(&helps(true)), Some(true));
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
