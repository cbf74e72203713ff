use rerun::{RecordingStream, RecordingStreamError, Scalars, TextLog, TextLogLevel, TimeColumn};

use crate::{Config, Event, Observer, Reconstruction, TrackTable};

use super::input::log_input_with;
use super::reconstruction::{log_error, log_measurement_matrix, log_result, log_visibility};
use super::robust::log_robust;
use super::{
    RecordingOptions, RecordingResult, STAGES, TIMELINE_FRAME, TIMELINE_ITERATION, TIMELINE_STAGE,
    paths, stage_index,
};

/// Runs [`Reconstruction::from_tracks_observed`] with everything logged to `rec` when given:
/// the input ([`log_input`](super::log_input)), stage events, solver iterations and warnings
/// ([`RecordingObserver`]), then the result ([`log_reconstruction`](super::log_reconstruction)) or the error
/// ([`log_error`]). Without `rec` it is [`Reconstruction::from_tracks`]. Failed log calls
/// inside the pipeline are reported as a warning in the result.
///
/// The input, the visibility mask and W ([`log_measurement_matrix`], as soon as the
/// pipeline announces the frames and tracks of its fit with [`Event::FitSelection`]) are
/// logged on a second thread while the pipeline runs, so that their cost overlaps the
/// pipeline's instead of adding to it.
pub fn reconstruct_recorded(
    rec: Option<&RecordingStream>,
    table: &TrackTable,
    config: &Config,
) -> RecordingResult<Reconstruction> {
    reconstruct_recorded_with(rec, table, config, &mut crate::NoopObserver)
}

/// Forwards the first [`Event::FitSelection`] to the thread that logs W.
pub(super) struct SelectionForward(Option<std::sync::mpsc::Sender<(Vec<usize>, Vec<usize>)>>);

impl Observer for SelectionForward {
    fn on_event(&mut self, event: &Event<'_>) {
        if let Event::FitSelection { frames, tracks } = event
            && let Some(tx) = self.0.take()
        {
            // The receiver only goes away if its thread failed; that error is reported
            // when the thread is joined.
            tx.send((frames.to_vec(), tracks.to_vec())).ok();
        }
    }
}

/// [`reconstruct_recorded`] with every pipeline event also sent to `extra` (a progress
/// bar, say).
pub fn reconstruct_recorded_with(
    rec: Option<&RecordingStream>,
    table: &TrackTable,
    config: &Config,
    extra: &mut dyn Observer,
) -> RecordingResult<Reconstruction> {
    let Some(rec) = rec else {
        return Ok(Reconstruction::from_tracks_observed(table, config, extra)?);
    };
    let options = RecordingOptions::default();
    let (result, matrix_logged, observer) = std::thread::scope(|scope| {
        let (tx, rx) = std::sync::mpsc::channel::<(Vec<usize>, Vec<usize>)>();
        let opts = &options;
        let background = scope.spawn(move || -> RecordingResult<bool> {
            log_input_with(rec, table, opts)?;
            log_visibility(rec, table, opts)?;
            // Blocks until the pipeline has chosen its fit, or has ended without one.
            match rx.recv() {
                Ok((frames, tracks)) => {
                    log_measurement_matrix(rec, table, &frames, &tracks, opts)?;
                    Ok(true)
                }
                Err(_) => Ok(false),
            }
        });
        let mut observer = RecordingObserver::new(rec);
        let mut forward = SelectionForward(Some(tx));
        let result = Reconstruction::from_tracks_observed(
            table,
            config,
            &mut crate::Both(&mut observer, crate::Both(&mut forward, extra)),
        );
        // Closes the channel if the pipeline ended before choosing its fit.
        drop(forward);
        observer.flush();
        let logged = background
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (result, logged, observer)
    });
    let matrix_logged = matrix_logged?;
    match result {
        Ok(mut result) => {
            if let (n @ 1.., Some(first)) = observer.errors() {
                result
                    .warnings
                    .push(format!("recording: {n} log call(s) failed, first: {first}"));
            }
            log_result(rec, table, &result, &options, !matrix_logged)?;
            if let Some(r) = &result.robust {
                let mut inliers = vec![false; table.n_tracks()];
                for &p in &result.kept_tracks {
                    inliers[p] = true;
                }
                log_robust(
                    rec,
                    table,
                    &inliers,
                    &r.flagged_indices,
                    &r.inliers_per_iteration,
                )?;
            }
            Ok(result)
        }
        Err(e) => {
            log_error(rec, &e)?;
            Err(e.into())
        }
    }
}

/// Turns [`Event`]s into Rerun log calls: iterations become `Scalars` on the `iteration`
/// timeline (`solver/{cost,log10_cost,rms,lambda,log10_lambda}/<name>/run<k>`; λ and the
/// logarithms only when finite), stage events `TextLog`s on
/// `log/stages` at the stage's `stage`-timeline index, warnings `TextLog`s (level WARN)
/// on `log/warnings`. Logging errors cannot be returned from an observer; they are counted
/// and the first is kept ([`RecordingObserver::first_error`]).
///
/// Iteration scalars are buffered per series and sent as one chunk each (`send_columns`)
/// at the next stage or warning event, when a series reaches 4096 values, on
/// [`RecordingObserver::flush`] or on drop: a solver's hundreds of iterations cost a few
/// log calls, not three each.
///
/// Cost: O(1) amortised per event.
pub struct RecordingObserver {
    rec: RecordingStream,
    unknown_stages: Vec<String>,
    stage: i64,
    errors: usize,
    first_error: Option<String>,
    /// Solver scalars not yet sent, one series per entity path and stage.
    pending: Vec<PendingSeries>,
}

/// Iteration scalars of one entity path, buffered so that a solver's hundreds of
/// iterations go out as one chunk (`send_columns`) instead of one log call each.
pub(super) struct PendingSeries {
    path: String,
    stage: i64,
    iterations: Vec<i64>,
    values: Vec<f64>,
}

/// A buffered series is sent once it holds this many values (bounded memory on long runs).
pub(super) const MAX_PENDING: usize = 4096;

impl RecordingObserver {
    /// An observer logging to `rec` (the stream is shared, not consumed).
    pub fn new(rec: &RecordingStream) -> Self {
        Self {
            rec: rec.clone(),
            unknown_stages: Vec::new(),
            stage: 0,
            errors: 0,
            first_error: None,
            pending: Vec::new(),
        }
    }

    /// Sends the buffered solver scalars (also done at every stage event and on drop).
    pub fn flush(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        for series in pending {
            let result = self.send_series(&series);
            self.note(result);
        }
    }

    fn send_series(&self, series: &PendingSeries) -> RecordingResult {
        let columns = Scalars::update_fields()
            .with_scalars(series.values.iter().copied())
            .columns_of_unit_batches()?;
        self.rec.send_columns(
            series.path.as_str(),
            [
                TimeColumn::new_sequence(TIMELINE_ITERATION, series.iterations.iter().copied()),
                TimeColumn::new_sequence(
                    TIMELINE_STAGE,
                    std::iter::repeat_n(series.stage, series.iterations.len()),
                ),
            ],
            columns,
        )?;
        Ok(())
    }

    fn note<E: std::fmt::Display>(&mut self, result: Result<(), E>) {
        if let Err(e) = result {
            self.errors += 1;
            if self.first_error.is_none() {
                self.first_error = Some(e.to_string());
            }
        }
    }

    /// Buffers one scalar of `path` at `iteration`.
    fn push(&mut self, path: String, iteration: usize, value: f64) {
        let stage = self.stage;
        let k = match self
            .pending
            .iter()
            .position(|s| s.stage == stage && s.path == path)
        {
            Some(k) => k,
            None => {
                self.pending.push(PendingSeries {
                    path,
                    stage,
                    iterations: Vec::new(),
                    values: Vec::new(),
                });
                self.pending.len() - 1
            }
        };
        let series = &mut self.pending[k];
        series.iterations.push(iteration as i64);
        series.values.push(value);
        if series.values.len() >= MAX_PENDING {
            let series = self.pending.swap_remove(k);
            let result = self.send_series(&series);
            self.note(result);
        }
    }

    /// Number of log calls that failed, and the first failure.
    pub fn errors(&self) -> (usize, Option<&str>) {
        (self.errors, self.first_error.as_deref())
    }

    /// The first logging failure, if any.
    pub fn first_error(&self) -> Option<&str> {
        self.first_error.as_deref()
    }

    fn stage_of(&mut self, stage: &str) -> i64 {
        if let Some(i) = stage_index(stage) {
            return i;
        }
        let k = match self.unknown_stages.iter().position(|s| s == stage) {
            Some(k) => k,
            None => {
                self.unknown_stages.push(stage.to_string());
                self.unknown_stages.len() - 1
            }
        };
        (STAGES.len() + k) as i64
    }

    fn handle(&mut self, event: &Event<'_>) -> Result<(), RecordingStreamError> {
        if !matches!(event, Event::Iteration { .. }) {
            self.flush();
        }
        let rec = &self.rec;
        match event {
            Event::StageStarted { stage } => {
                self.stage = self.stage_of(stage);
                let rec = &self.rec;
                rec.set_time_sequence(TIMELINE_STAGE, self.stage);
                rec.disable_timeline(TIMELINE_FRAME);
                rec.disable_timeline(TIMELINE_ITERATION);
                rec.log(
                    paths::LOG_STAGES,
                    &TextLog::new(format!("stage {stage} started")).with_level(TextLogLevel::INFO),
                )
            }
            Event::StageFinished { stage, seconds } => {
                rec.set_time_sequence(TIMELINE_STAGE, self.stage);
                rec.disable_timeline(TIMELINE_ITERATION);
                rec.log(
                    paths::LOG_STAGES,
                    &TextLog::new(format!("stage {stage} finished in {seconds:.4} s"))
                        .with_level(TextLogLevel::INFO),
                )
            }
            Event::Iteration {
                solver,
                run,
                iteration,
                cost,
                rms,
                lambda,
            } => {
                // One entity per quantity and run, so that the layout plots each quantity
                // on its own axis; the cost and λ also as log₁₀ (they span decades).
                let run = format!("{solver}/run{run}");
                self.push(format!("{}/{run}", paths::SOLVER_COST), *iteration, *cost);
                self.push(format!("{}/{run}", paths::SOLVER_RMS), *iteration, *rms);
                let optional = [
                    (paths::SOLVER_LOG10_COST, cost.log10()),
                    (paths::SOLVER_LAMBDA, *lambda),
                    (paths::SOLVER_LOG10_LAMBDA, lambda.log10()),
                ];
                for (quantity, value) in optional {
                    if value.is_finite() {
                        self.push(format!("{quantity}/{run}"), *iteration, value);
                    }
                }
                Ok(())
            }
            Event::Warning { message } => {
                rec.disable_timeline(TIMELINE_ITERATION);
                rec.log(
                    paths::LOG_WARNINGS,
                    &TextLog::new(*message).with_level(TextLogLevel::WARN),
                )
            }
            // Events added later are not recorded until this observer learns them.
            #[allow(unreachable_patterns)]
            _ => Ok(()),
        }
    }
}

impl Observer for RecordingObserver {
    fn on_event(&mut self, event: &Event<'_>) {
        let result = self.handle(event);
        self.note(result);
    }
}

impl Drop for RecordingObserver {
    fn drop(&mut self) {
        self.flush();
    }
}
