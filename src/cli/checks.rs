//! Options that would do nothing in the combination given are refused (a usage error, exit
//! 2) with the reason, rather than silently ignored. The simple cases are declared on the
//! arguments (`requires`, `conflicts_with`); these are the ones that depend on a value or on
//! whether an option with a default was given.

use clap::parser::ValueSource;
use clap::{ArgMatches, CommandFactory as _};

use super::args::{CameraArg, LossArg};
use super::reconstruct::ReconstructOpts;
use super::track::TrackOpts;
use super::{Cli, Command};

/// Checks the parsed command line (`matches` is what `cli` was parsed from).
pub fn check(cli: &Cli, matches: &ArgMatches) -> Result<(), clap::Error> {
    let Some((name, m)) = matches.subcommand() else {
        return Ok(());
    };
    let problem = match &cli.command {
        Command::Reconstruct(a) => perspective_only(m, a.camera)
            .or_else(|| loss_scale(m, &a.opts))
            .or_else(|| {
                (a.opts.no_mesh && a.images.is_none()).then(|| {
                    "--no-mesh does nothing without --images: the mesh is only built from the \
                     frames"
                        .to_string()
                })
            }),
        Command::Run(a) => perspective_only(m, a.camera)
            .or_else(|| loss_scale(m, &a.recon))
            .or_else(|| detection_unused(m, &a.opts)),
        Command::Track(a) => detection_unused(m, &a.opts),
        Command::Synth(a) => {
            let perspective = matches!(a.camera, CameraArg::Perspective | CameraArg::Projective);
            if let Some(flag) = (!perspective)
                .then(|| {
                    given_of(
                        m,
                        &[
                            ("focal", "--focal"),
                            ("distance", "--distance"),
                            ("zoom", "--zoom"),
                            ("distortion", "--distortion"),
                        ],
                    )
                })
                .flatten()
            {
                Some(format!(
                    "{flag} sets up the perspective camera: it does nothing with --camera {} \
                     (add --camera perspective)",
                    a.camera.name()
                ))
            } else if given(m, "outlier_kind") && a.outliers == 0.0 {
                Some(
                    "--outlier-kind does nothing without outlier tracks: give --outliers \
                     FRACTION too"
                        .to_string(),
                )
            } else {
                None
            }
        }
        Command::Eval(_) => None,
    };
    match problem {
        Some(message) => {
            let mut cmd = Cli::command();
            cmd.build();
            let sub = cmd
                .find_subcommand_mut(name)
                .expect("the parsed subcommand exists");
            Err(clap::Error::raw(clap::error::ErrorKind::ArgumentConflict, message).format(sub))
        }
        None => Ok(()),
    }
}

/// Whether the option `id` was given on the command line (not just defaulted).
fn given(m: &ArgMatches, id: &str) -> bool {
    m.value_source(id) == Some(ValueSource::CommandLine)
}

/// The flag of the first of `ids` (id, flag) given on the command line.
fn given_of(m: &ArgMatches, ids: &[(&str, &'static str)]) -> Option<&'static str> {
    ids.iter()
        .find(|(id, _)| given(m, id))
        .map(|(_, flag)| *flag)
}

/// The perspective camera's options with a camera that is never perspective.
fn perspective_only(m: &ArgMatches, camera: CameraArg) -> Option<String> {
    if matches!(camera, CameraArg::Auto | CameraArg::Perspective) {
        return None;
    }
    let flag = given_of(
        m,
        &[
            ("focal", "--focal"),
            ("principal_point", "--principal-point"),
            ("per_frame_focal", "--per-frame-focal"),
            ("estimate_principal_point", "--estimate-principal-point"),
            ("distortion", "--distortion"),
            ("estimate_aspect_ratio", "--estimate-aspect-ratio"),
            ("loss", "--loss"),
            ("loss_scale", "--loss-scale"),
        ],
    )?;
    Some(format!(
        "{flag} is an option of the perspective camera: it does nothing with --camera {} \
         (use --camera perspective, or auto to let the data choose)",
        camera.name()
    ))
}

/// `--loss-scale` with `--loss none`.
fn loss_scale(m: &ArgMatches, opts: &ReconstructOpts) -> Option<String> {
    (opts.loss == LossArg::None && given(m, "loss_scale")).then(|| {
        "--loss-scale does nothing with --loss none (plain least squares has no scale)".to_string()
    })
}

/// The corner detector's options when nothing is detected: `--init-points` without
/// `--redetect`.
fn detection_unused(m: &ArgMatches, opts: &TrackOpts) -> Option<String> {
    if opts.init_points.is_none() || opts.redetect {
        return None;
    }
    let flag = given_of(
        m,
        &[
            ("max_features", "--max-features"),
            ("quality", "--quality"),
            ("min_distance", "--min-distance"),
            ("no_subpixel", "--no-subpixel"),
        ],
    )?;
    Some(format!(
        "{flag} is an option of the corner detector, which does not run when --init-points \
         gives the points: add --redetect to detect new corners as tracks die"
    ))
}
