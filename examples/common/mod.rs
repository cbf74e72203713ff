//! Helpers shared by the example programs that print measured figures.

/// The environment variable `name` parsed as `T`; `None` when unset or not parsable (the
/// experiment knobs of the example programs).
#[allow(dead_code)]
pub fn env<T: std::str::FromStr>(name: &str) -> Option<T> {
    std::env::var(name).ok()?.parse().ok()
}

/// The projective adjustment's experiment knobs, read from the environment into `c`:
/// `NOISE_TOL=τ` the noise-level stop (0: off), `REL_TOL=τ` the relative tail stop (0: off),
/// `GEO=α` the geodesic acceleration, `EXT=n` the step extension trials and `LDEC=f` the
/// damping's decrease after a good step. Unset or unparsable variables leave `c` as it is.
#[allow(dead_code)]
pub fn adjustment_knobs(c: &mut rank3::projective::bundle::LmConfig) {
    if let Some(t) = env("NOISE_TOL") {
        c.noise_tolerance = t;
    }
    if let Some(t) = env("REL_TOL") {
        c.window_relative_tolerance = t;
    }
    if let Some(a) = env("GEO") {
        c.geodesic_acceleration = a;
    }
    if let Some(n) = env("EXT") {
        c.extension_trials = n;
    }
    if let Some(f) = env("LDEC") {
        c.lambda_decrease = f;
    }
}

/// A solver trace on stderr — every iteration (solver, index, RMS, damping), warning and
/// finished stage — printed only when `on`.
#[allow(dead_code)]
pub struct Trace {
    pub on: bool,
}

#[allow(dead_code)]
impl Trace {
    /// On when the environment variable `name` is set.
    pub fn from_env(name: &str) -> Self {
        Self {
            on: std::env::var_os(name).is_some(),
        }
    }
}

impl rank3::Observer for Trace {
    fn on_event(&mut self, e: &rank3::Event<'_>) {
        if !self.on {
            return;
        }
        match e {
            rank3::Event::Iteration {
                solver,
                iteration,
                rms,
                lambda,
                ..
            } => eprintln!("{solver} {iteration} rms {rms:.9} lambda {lambda:.3e}"),
            rank3::Event::Warning { message } => eprintln!("warning: {message}"),
            rank3::Event::StageFinished { stage, seconds } => {
                eprintln!("stage {stage} {seconds:.1} s")
            }
            _ => {}
        }
    }
}

/// Peak resident memory of this process (`VmHWM` of `/proc/self/status`), MB; NaN where
/// `/proc` is not available.
#[allow(dead_code)]
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// Errors of a metric perspective model against a synthetic scene's exact cameras
/// ([`perspective_errors`]).
#[allow(dead_code)]
pub struct PerspectiveErrors {
    /// Per fitted frame, `|f_est − f_true| / f_true` against that frame's true focal length.
    pub focal: Vec<f64>,
    /// Largest rotation error over the fitted frames, degrees, after the points' alignment.
    pub rot_max_deg: f64,
    /// RMS point distance after the best proper similarity, over the truth's RMS spread.
    pub structure: f64,
}

/// Angle of `a bᵀ`, degrees.
#[allow(dead_code)]
pub fn rot_err_deg(a: &nalgebra::Matrix3<f64>, b: &nalgebra::Matrix3<f64>) -> f64 {
    let d = a * b.transpose();
    ((d.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// [`PerspectiveErrors`] of `model` (frames `kept_frames` × tracks `kept_tracks` of the
/// scene, in that order) against the truth of the perspective scene `s`: the points are
/// aligned by a proper similarity (a Euclidean reconstruction has no mirror ambiguity),
/// rotations are compared through that alignment, focal lengths frame by frame. The
/// accuracy measure of `perspective_benchmark` and `perspective_models`.
#[allow(dead_code)]
pub fn perspective_errors(
    model: &rank3::perspective::PerspectiveModel,
    kept_frames: &[usize],
    kept_tracks: &[usize],
    s: &rank3::synth::SynthScene,
) -> PerspectiveErrors {
    let truth = s.perspective.as_ref().expect("a perspective scene");
    let tp: Vec<nalgebra::Vector3<f64>> = kept_tracks.iter().map(|&p| s.truth.points[p]).collect();
    let al = rank3::eval::align_similarity(&model.points, &tp, false).expect("alignment");
    let mut rot_max_deg: f64 = 0.0;
    let mut focal = Vec::with_capacity(kept_frames.len());
    for (k, &f) in kept_frames.iter().enumerate() {
        rot_max_deg = rot_max_deg.max(rot_err_deg(
            &(model.rotations[k] * al.rotation.transpose()),
            truth.rotations[f].matrix(),
        ));
        let f_true = truth.intrinsics[f][(0, 0)];
        focal.push((model.focal_px[k] - f_true).abs() / f_true);
    }
    PerspectiveErrors {
        focal,
        rot_max_deg,
        structure: al.relative_rms,
    }
}

/// The exact cameras and points of the perspective scene `s` as a start model for
/// [`rank3::perspective::adjust`] (the accuracy floor: the adjustment started at the
/// truth): per-frame focal lengths, principal point and `k₁` as generated.
#[allow(dead_code)]
pub fn truth_model(s: &rank3::synth::SynthScene) -> rank3::perspective::PerspectiveModel {
    let t = s.perspective.as_ref().expect("a perspective scene");
    rank3::perspective::PerspectiveModel {
        focal_px: t.intrinsics.iter().map(|k| k[(0, 0)]).collect(),
        principal_point: [t.intrinsics[0][(0, 2)], t.intrinsics[0][(1, 2)]],
        k1: t.k1,
        aspect: 1.0,
        rotations: t.rotations.iter().map(|r| *r.matrix()).collect(),
        translations: t.translations.clone(),
        points: s.truth.points.clone(),
    }
}
