//! `rank3 run`: frames → tracks → reconstruction.

use std::path::{Path, PathBuf};

use super::args::CameraArg;
use super::output::{refuse_overwriting_inputs, write_outputs};
use super::reconstruct::{ReconstructOpts, reconstruct_objects};
use super::track::{TrackOpts, track_recorded};
use super::verbosity::{self, info};

#[derive(clap::Args)]
pub struct RunArgs {
    /// A folder of PNG/JPEG frames (natural name order) or a video file (needs ffmpeg).
    pub input: PathBuf,
    /// Output directory (tracks.csv, reconstruction.json, completed.txt, points.ply).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub opts: TrackOpts,
    /// Camera model.
    #[arg(long, value_enum, default_value = "auto")]
    pub camera: CameraArg,
    /// Reconstruct from the tracks seen in every frame only (by default the partial
    /// tracks are used, through the missing-data solver).
    #[arg(long)]
    pub complete_tracks: bool,
    #[command(flatten)]
    pub recon: ReconstructOpts,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    pub record: rank3::recording::RecordingArgs,
}

/// Ticks a spinner on every pipeline event.
pub struct SpinnerObserver(indicatif::ProgressBar);

impl rank3::Observer for SpinnerObserver {
    fn on_event(&mut self, event: &rank3::Event<'_>) {
        match event {
            rank3::Event::StageStarted { stage } => self.0.set_message(stage.to_string()),
            rank3::Event::Iteration {
                solver,
                iteration,
                rms,
                ..
            } => self
                .0
                .set_message(format!("{solver} iteration {iteration}, RMS {rms:.4} px")),
            _ => {}
        }
        self.0.tick();
    }
}

pub fn run(a: &RunArgs) -> Result<(), rank3::Error> {
    let mut inputs: Vec<&Path> = vec![&a.input];
    inputs.extend(a.opts.init_points.as_deref());
    refuse_overwriting_inputs(
        &inputs,
        Some(&a.out),
        None,
        #[cfg(feature = "rerun")]
        &a.record,
    )?;
    std::fs::create_dir_all(&a.out).map_err(|e| rank3::Error::io(&a.out, e))?;
    // The table goes in with the reconstruction (reconstruct_recorded logs it).
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))]
    let (tracked, recording) = track_recorded(
        &a.input,
        &a.opts,
        #[cfg(feature = "rerun")]
        &a.record,
        false,
        matches!(a.camera, CameraArg::Perspective),
    )?;
    let mut table = tracked.table;
    let tracked_size = tracked.image_size;
    let tracks = a.out.join("tracks.csv");
    table.write(&tracks)?;
    info!(
        "wrote {} ({} frames × {} tracks, {:.1} % filled)",
        tracks.display(),
        table.n_frames(),
        table.n_tracks(),
        100.0 * table.fill()
    );
    if a.complete_tracks {
        let full: Vec<usize> = (0..table.n_tracks())
            .filter(|&p| table.track_len(p) == table.n_frames())
            .collect();
        let frames: Vec<usize> = (0..table.n_frames()).collect();
        info!(
            "--complete-tracks: reconstructing from the {} tracks seen in all {} frames",
            full.len(),
            table.n_frames()
        );
        table = table.select(&frames, &full);
    }
    let config = a.recon.config(a.camera, tracked_size, tracked.pixel_aspect);
    a.recon.print_settings(a.camera, &config);
    if let Some(objects) = a.recon.objects {
        #[cfg(feature = "rerun")]
        if let Some(r) = recording.as_ref() {
            rank3::recording::send_layout(
                r,
                rank3::recording::LayoutParts {
                    tracking: true,
                    objects: true,
                    ..Default::default()
                },
            )?;
        }
        return reconstruct_objects(
            #[cfg(feature = "rerun")]
            recording.as_ref(),
            &table,
            &config,
            objects,
            a.recon.assign_all,
            &a.out,
        );
    }
    let spinner = verbosity::spinner("reconstructing {spinner} {elapsed} {msg}");
    let mut obs = SpinnerObserver(spinner.clone());
    #[cfg(feature = "rerun")]
    let rec =
        rank3::recording::reconstruct_recorded_with(recording.as_ref(), &table, &config, &mut obs)
            .map_err(rank3::Error::from);
    #[cfg(not(feature = "rerun"))]
    let rec = rank3::Reconstruction::from_tracks_observed(&table, &config, &mut obs);
    spinner.finish_and_clear();
    let rec = rec?;
    #[cfg(feature = "rerun")]
    super::output::show_perspective_layout(
        recording.as_ref(),
        &rec,
        a.camera,
        rank3::recording::LayoutParts {
            tracking: true,
            reconstruction: true,
            ..Default::default()
        },
    )?;
    write_outputs(
        rec,
        &table,
        Some((&a.input, a.recon.image_size.or(tracked_size))),
        &a.recon,
        &a.out,
        #[cfg(feature = "rerun")]
        recording.as_ref(),
    )
}
