//! The command line's parts: the arguments (`Cli`), one module per subcommand, and the
//! helpers they share. `main` parses, checks, dispatches and sets the exit code.
//!
//! * [`args`]: value enums and parsers of structured values;
//! * [`checks`]: options that would do nothing in the combination given (a usage error);
//! * [`verbosity`]: `-q`/`-v`, the printing macros and the progress bars;
//! * [`reconstruct`], [`run`], [`track`], [`synth`], [`eval`]: the subcommands;
//! * [`output`]: the files of a reconstruction; [`summary`]: what it prints.

pub mod args;
pub mod checks;
pub mod eval;
pub mod output;
pub mod reconstruct;
pub mod run;
pub mod summary;
pub mod synth;
pub mod track;
pub mod verbosity;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "rank3",
    version,
    about = "Structure and motion from 2D point tracks by Tomasi–Kanade factorization",
    after_help = "Output: summaries and progress go to stderr, each command's result line to \
                  stdout; -q keeps only warnings and errors (rank3 eval still prints its \
                  scores), -v adds detail.\n\n\
                  Exit status: 0 success; 1 an error (bad input, naming its file, line and \
                  field; an output or recording that could not be written; a solver's setup \
                  that failed); 2 a usage error (an unknown or missing argument, or options \
                  that would do nothing together)."
)]
pub struct Cli {
    #[command(flatten)]
    pub output: OutputArgs,
    #[command(subcommand)]
    pub command: Command,
}

/// How much is printed; valid before or after the subcommand.
#[derive(clap::Args)]
pub struct OutputArgs {
    /// Quiet: print only warnings and errors (stderr) — no progress bars, no summaries, no
    /// result lines. The output files are written as usual, and `rank3 eval` still prints
    /// its scores.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    pub quiet: bool,
    /// Verbose: print more — the settings in force, each stage's details and time, every
    /// track and frame set aside, the files written, the tracker's counts per frame.
    #[arg(short, long, global = true)]
    pub verbose: bool,
}

impl OutputArgs {
    pub fn level(&self) -> verbosity::Level {
        match (self.quiet, self.verbose) {
            (true, _) => verbosity::Level::Quiet,
            (false, true) => verbosity::Level::Verbose,
            (false, false) => verbosity::Level::Normal,
        }
    }
}

#[derive(Subcommand)]
pub enum Command {
    /// Reconstruct metric structure and cameras from a track table (.csv, .txt, .json, .npy,
    /// .npz, a COLMAP text model folder, or --x/--y matrices).
    Reconstruct(reconstruct::ReconstructArgs),
    /// Write a synthetic scene with ground truth: DIR/tracks.csv and DIR/truth.json.
    Synth(synth::SynthArgs),
    /// Track corners through a folder of images or a video (KLT) into a track table.
    Track(track::TrackArgs),
    /// Video or images → tracks → reconstruction, in one command.
    Run(run::RunArgs),
    /// Score a reconstruction against a reference (synth's truth.json, another
    /// reconstruction.json, or a COLMAP text model): structure, rotation, camera centre and
    /// focal length errors.
    Eval(eval::EvalArgs),
}

impl Command {
    /// Runs the subcommand; the error's message.
    pub fn run(&self) -> Result<(), String> {
        match self {
            Command::Reconstruct(a) => reconstruct::reconstruct(a).map_err(|e| e.to_string()),
            Command::Synth(a) => synth::synth(a).map_err(|e| e.to_string()),
            Command::Track(a) => track::track(a).map_err(|e| e.to_string()),
            Command::Run(a) => run::run(a).map_err(|e| e.to_string()),
            Command::Eval(a) => eval::eval(a).map_err(|e| e.to_string()),
        }
    }
}
