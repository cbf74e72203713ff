//! `rank3 eval`: scores a reconstruction against a reference.

use std::path::PathBuf;

use super::verbosity::data;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// The reconstruction: a reconstruction.json, or the output folder holding it.
    reconstruction: PathBuf,
    /// The reference: the truth.json written by `rank3 synth`, another reconstruction.json,
    /// or a folder holding either.
    #[arg(long, short = 'r', value_name = "FILE|DIR")]
    reference: PathBuf,
    /// Print the scores as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// The table (or JSON) on stdout, whatever the verbosity (it is the command's output).
pub fn eval(a: &EvalArgs) -> Result<(), rank3::compare::EvalError> {
    let c = rank3::compare::evaluate(&a.reconstruction, &a.reference)?;
    if a.json {
        data(format_args!(
            "{}",
            serde_json::to_string_pretty(&c).unwrap_or_default()
        ));
    } else {
        data(format_args!("{}", c.to_string().trim_end()));
    }
    Ok(())
}
