//! The `rank3` command line: `rank3 reconstruct`, `synth`, `track`, `run` and `eval`
//! (src/cli/ holds the subcommands and their shared parts).

mod cli;

use std::process::ExitCode;

use clap::{CommandFactory as _, FromArgMatches as _};

fn main() -> ExitCode {
    // Parse (a usage error exits with 2), refuse options that would do nothing together.
    let matches = cli::Cli::command().get_matches();
    let args = cli::Cli::from_arg_matches(&matches)
        .unwrap_or_else(|e| e.format(&mut cli::Cli::command()).exit());
    if let Err(e) = cli::checks::check(&args, &matches) {
        e.exit();
    }
    cli::verbosity::set(args.output.level());
    let result = args.command.run();
    // A recording that could not be written or streamed is an error too (after the
    // command's own outputs, which are written by then).
    #[cfg(feature = "rerun")]
    let recording_failures = rank3::recording::finish_opened(std::time::Duration::from_secs(20));
    #[cfg(not(feature = "rerun"))]
    let recording_failures: Vec<String> = Vec::new();
    for f in &recording_failures {
        eprintln!("error: {f}");
    }
    match result {
        Ok(()) if recording_failures.is_empty() => ExitCode::SUCCESS,
        Ok(()) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
