//! How much the command line prints: `-q` (warnings and errors only), the default, `-v`
//! (more detail). Set once in `main` from the global flags; read by the printing macros.
//!
//! Where each kind of line goes:
//! * errors (`error: …`, by `main`) and warnings ([`warning!`]): stderr, always;
//! * progress and summaries ([`info!`]): stderr, not with `-q`;
//! * details ([`detail!`]): stderr, with `-v` only;
//! * a command's closing result line ([`say!`]: `wrote …`, the reconstruction's one-line
//!   result): stdout, not with `-q`;
//! * a command's data (`rank3 eval`'s scores, [`data`]): stdout, always.

use std::io::IsTerminal as _;
use std::sync::atomic::{AtomicU8, Ordering};

/// The level of output chosen on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// `-q`: warnings and errors only.
    Quiet = 0,
    /// The default.
    Normal = 1,
    /// `-v`: the default plus details.
    Verbose = 2,
}

static LEVEL: AtomicU8 = AtomicU8::new(Level::Normal as u8);

/// Sets the level (once, in `main`).
pub fn set(level: Level) {
    LEVEL.store(level as u8, Ordering::Relaxed);
}

/// The level in force.
pub fn level() -> Level {
    match LEVEL.load(Ordering::Relaxed) {
        0 => Level::Quiet,
        1 => Level::Normal,
        _ => Level::Verbose,
    }
}

/// Whether summaries and progress are printed (not with `-q`).
pub fn normal() -> bool {
    level() >= Level::Normal
}

/// Whether details are printed (`-v`).
pub fn verbose() -> bool {
    level() >= Level::Verbose
}

/// A line on stdout; a closed stdout (`rank3 … | head`) is not an error worth a panic.
pub fn data(line: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stdout().lock(), "{line}");
}

/// A summary line on stderr (not with `-q`).
macro_rules! info {
    ($($arg:tt)*) => {
        if $crate::cli::verbosity::normal() {
            eprintln!($($arg)*);
        }
    };
}

/// A detail line on stderr (with `-v` only).
macro_rules! detail {
    ($($arg:tt)*) => {
        if $crate::cli::verbosity::verbose() {
            eprintln!($($arg)*);
        }
    };
}

/// `warning: …` on stderr, at every level.
macro_rules! warning {
    ($($arg:tt)*) => {
        eprintln!("warning: {}", format_args!($($arg)*))
    };
}

/// A command's result line on stdout (not with `-q`).
macro_rules! say {
    ($($arg:tt)*) => {
        if $crate::cli::verbosity::normal() {
            $crate::cli::verbosity::data(format_args!($($arg)*));
        }
    };
}

pub(crate) use {detail, info, say, warning};

fn style(template: &str) -> indicatif::ProgressStyle {
    indicatif::ProgressStyle::with_template(template)
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
}

/// Whether progress bars are drawn: on a terminal (stderr), and not with `-q`.
fn progress_shown() -> bool {
    normal() && std::io::stderr().is_terminal()
}

/// A progress bar of `len` steps, or a spinner when the length is unknown; hidden with `-q`
/// or when stderr is not a terminal.
pub fn progress(
    len: Option<u64>,
    bar_template: &str,
    spinner_template: &str,
) -> indicatif::ProgressBar {
    if !progress_shown() {
        return indicatif::ProgressBar::hidden();
    }
    match len {
        Some(n) => indicatif::ProgressBar::new(n).with_style(style(bar_template)),
        None => indicatif::ProgressBar::new_spinner().with_style(style(spinner_template)),
    }
}

/// A spinner; hidden with `-q` or when stderr is not a terminal.
pub fn spinner(template: &str) -> indicatif::ProgressBar {
    if !progress_shown() {
        return indicatif::ProgressBar::hidden();
    }
    indicatif::ProgressBar::new_spinner().with_style(style(template))
}
