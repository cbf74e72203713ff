//! `rank3 eval`: scores a reconstruction against a reference.

use std::path::PathBuf;

use super::verbosity::data;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// The reconstruction: a reconstruction.json, or the output folder holding it.
    reconstruction: PathBuf,
    /// The reference: the truth.json written by `rank3 synth`, another reconstruction.json,
    /// a folder holding either, or a COLMAP text model (a folder holding cameras.txt,
    /// images.txt and points3D.txt, or one of those files). A COLMAP model's images are
    /// matched to frames by name, its 3D points to tracks by shared observations
    /// (docs/formats.md).
    #[arg(long, short = 'r', value_name = "FILE|DIR")]
    reference: PathBuf,
    /// With a COLMAP reference: the track table the reconstruction was made from, as its
    /// observations (needed when the reconstruction has no colmap/ export, i.e. is not
    /// perspective).
    #[arg(long, value_name = "FILE|DIR")]
    tracks: Option<PathBuf>,
    /// With a COLMAP reference: how far, in pixels, an observation may lie from a keypoint
    /// to vote for its 3D point.
    #[arg(long, value_name = "PX", default_value_t = rank3::compare::MATCH_TOLERANCE_PX)]
    match_px: f64,
    /// Print the scores as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// The table (or JSON) on stdout, whatever the verbosity (it is the command's output).
pub fn eval(a: &EvalArgs) -> Result<(), rank3::compare::EvalError> {
    let opts = rank3::compare::EvalOptions {
        tracks: a.tracks.clone(),
        match_tolerance_px: a.match_px,
    };
    let c = rank3::compare::evaluate_with(&a.reconstruction, &a.reference, &opts)?;
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
