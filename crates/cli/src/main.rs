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
            eprintln!("error: {}", one_line(&err));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The outermost context and every cause, joined by `: `, leaving out a cause whose text the
/// message before it already ends with (the project's I/O errors print their source in their
/// own message and also return it from `source()`, so anyhow's `{:#}` said it twice).
fn one_line(err: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if parts.last().is_some_and(|prev| prev.ends_with(&text)) {
            continue;
        }
        parts.push(text);
    }
    parts.join(": ")
}

#[cfg(test)]
mod tests {
    use super::one_line;

    #[test]
    fn a_cause_already_in_the_message_is_not_repeated() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such dataset folder");
        let err = anyhow::Error::new(fewview_scene::SceneError::io("/nope", io))
            .context("cannot load dataset /nope");
        assert_eq!(
            one_line(&err),
            "cannot load dataset /nope: /nope: no such dataset folder"
        );
    }

    #[test]
    fn distinct_causes_are_all_kept() {
        let err = anyhow::anyhow!("inner problem").context("outer step");
        assert_eq!(one_line(&err), "outer step: inner problem");
    }
}
