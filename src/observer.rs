//! Progress reporting without a dependency on any particular front end.
//!
//! Solvers and pipeline stages call an [`Observer`]; a Rerun recording, a progress bar or a
//! test probe implements it. Every method has an empty default, so an observer overrides
//! only what it cares about.

/// Something that happened during a run.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub enum Event<'a> {
    /// A pipeline stage begins (`"load"`, `"factorize"`, `"complete"`, `"metric"`, `"refine"`, …).
    StageStarted { stage: &'a str },
    /// A pipeline stage ended after `seconds`.
    StageFinished { stage: &'a str, seconds: f64 },
    /// One iteration of an iterative solver.
    Iteration {
        /// Solver name, e.g. `"wiberg"`, `"als"`, `"lm-refine"`.
        solver: &'a str,
        /// Index of the run (random start) this iteration belongs to.
        run: usize,
        iteration: usize,
        /// Objective value (sum of squared residuals unless documented otherwise).
        cost: f64,
        /// RMS over observed scalars, pixels.
        rms: f64,
        /// Damping parameter, where the solver has one (NaN otherwise).
        lambda: f64,
    },
    /// A human-readable warning (also kept in the result).
    Warning { message: &'a str },
    /// The frames and tracks (indices into the input table) that the fit uses,
    /// once the set-aside and robust passes have chosen them. Sent once per run, before
    /// the `factorize` stage; a run that fails earlier never sends it.
    FitSelection {
        frames: &'a [usize],
        tracks: &'a [usize],
    },
}

/// Receives [`Event`]s. Implementations must be cheap: they run inside solver loops.
pub trait Observer {
    /// Called for every event.
    fn on_event(&mut self, _event: &Event<'_>) {}
}

/// An observer that ignores everything.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoopObserver;

impl Observer for NoopObserver {}

impl<T: Observer + ?Sized> Observer for &mut T {
    fn on_event(&mut self, event: &Event<'_>) {
        (**self).on_event(event)
    }
}

/// Forwards every event to two observers in turn (a recording and a progress bar, say).
#[derive(Debug, Default, Clone, Copy)]
pub struct Both<A, B>(pub A, pub B);

impl<A: Observer, B: Observer> Observer for Both<A, B> {
    fn on_event(&mut self, event: &Event<'_>) {
        self.0.on_event(event);
        self.1.on_event(event);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Default)]
    struct Count(usize);
    impl Observer for Count {
        fn on_event(&mut self, _: &Event<'_>) {
            self.0 += 1;
        }
    }

    #[test]
    fn both_forwards_to_each() {
        let (mut a, mut b) = (Count::default(), Count::default());
        let mut both = Both(&mut a, &mut b);
        both.on_event(&Event::Warning { message: "x" });
        both.on_event(&Event::StageStarted { stage: "input" });
        assert_eq!((a.0, b.0), (2, 2));
    }
}
