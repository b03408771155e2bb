//! Flags parsed in unit tests without the whole command line.

/// `argv` (the command's name first) parsed as the flags `A`; panics on an error.
pub(crate) fn parse<A: clap::Args>(argv: &[&str]) -> A {
    let command = A::augment_args(clap::Command::new("test"));
    let matches = command
        .try_get_matches_from(argv)
        .unwrap_or_else(|e| panic!("{argv:?}: {e}"));
    A::from_arg_matches(&matches).unwrap_or_else(|e| panic!("{argv:?}: {e}"))
}
