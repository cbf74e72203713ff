//! `rank3._rank3`: the Rust side of the Python package. The Python layer (`rank3/__init__.py`)
//! turns keyword arguments into settings overrides and tables into `(F, N, 2)` arrays; this
//! module runs the library with the GIL released and converts results to NumPy.
//!
//! Interruption: the observer passed to the library checks Python's signals (Ctrl-C) at most
//! every 50 ms and calls the `progress` callback; an exception from either unwinds out of the
//! library (`resume_unwind`, no panic message) and is raised in Python.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use rank3::{Config, Event, Id, Observer, TrackTable};

create_exception!(_rank3, Rank3Error, PyException, "Any error rank3 reports.");
create_exception!(
    _rank3,
    InputError,
    Rank3Error,
    "A file or an input value that cannot be used (attributes: path, line, field)."
);
create_exception!(
    _rank3,
    ConfigError,
    Rank3Error,
    "A setting outside its valid range."
);
create_exception!(
    _rank3,
    DataError,
    Rank3Error,
    "Data that do not determine a reconstruction (too few, disconnected, degenerate, no rigid majority)."
);
create_exception!(
    _rank3,
    NumericalError,
    Rank3Error,
    "A numerical routine failed."
);

/// The Python exception of a library error, with its fields as attributes (`kind`, and
/// `path`, `line`, `field`, ... where the error has them).
fn to_py(e: rank3::Error) -> PyErr {
    use rank3::Error as E;
    let message = e.to_string();
    let (err, kind, attrs): (PyErr, &str, Vec<(&str, String)>) = match &e {
        E::Io { path, .. } => (
            InputError::new_err(message),
            "io",
            vec![("path", path.display().to_string())],
        ),
        E::Parse {
            path,
            line,
            field,
            message: m,
        } => (
            InputError::new_err(message),
            "parse",
            vec![
                ("path", path.display().to_string()),
                ("line", line.to_string()),
                ("field", field.clone()),
                ("detail", m.clone()),
            ],
        ),
        E::UnknownFormat { path } => (
            InputError::new_err(message),
            "unknown-format",
            vec![("path", path.display().to_string())],
        ),
        E::EmptyTable { path, reason } => (
            InputError::new_err(message),
            "empty-table",
            [("reason", reason.clone())]
                .into_iter()
                .chain(path.iter().map(|p| ("path", p.display().to_string())))
                .collect(),
        ),
        E::Image { path, .. } | E::Video { path, .. } => (
            InputError::new_err(message),
            if matches!(e, E::Image { .. }) {
                "image"
            } else {
                "video"
            },
            vec![("path", path.display().to_string())],
        ),
        E::OutputIsInput { output, input, .. } => (
            InputError::new_err(message),
            "output-is-input",
            vec![
                ("path", output.display().to_string()),
                ("input", input.display().to_string()),
            ],
        ),
        E::Dimension { context, .. } => (
            InputError::new_err(message),
            "dimension",
            vec![("field", context.to_string())],
        ),
        E::InvalidConfig { field, message: m } => (
            ConfigError::new_err(message),
            "invalid-config",
            vec![("field", field.to_string()), ("detail", m.clone())],
        ),
        E::Numerical { stage, .. } => (
            NumericalError::new_err(message),
            "numerical",
            vec![("field", stage.to_string())],
        ),
        E::TooFew { what, .. } => (
            DataError::new_err(message),
            "too-few",
            vec![("field", what.to_string())],
        ),
        E::MissingData { .. } => (DataError::new_err(message), "missing-data", vec![]),
        E::Disconnected { .. } => (DataError::new_err(message), "disconnected", vec![]),
        E::NoRigidMajority { .. } => (DataError::new_err(message), "no-rigid-majority", vec![]),
        E::Degenerate(_) => (DataError::new_err(message), "degenerate", vec![]),
        E::InvalidModel(_) => (DataError::new_err(message), "invalid-model", vec![]),
        E::TooLarge { .. } => (InputError::new_err(message), "too-large", vec![]),
        _ => (Rank3Error::new_err(message), "other", vec![]),
    };
    Python::attach(|py| {
        let v = err.value(py);
        let _ = v.setattr("kind", kind);
        for key in ["path", "line", "field", "detail", "input", "reason"] {
            let value = attrs
                .iter()
                .find(|(k, _)| *k == key)
                .map(|(_, v)| v.clone());
            let _ = match (key, value) {
                ("line", Some(l)) => v.setattr(key, l.parse::<usize>().unwrap_or(0)),
                (_, Some(s)) => v.setattr(key, s),
                (_, None) => v.setattr(key, py.None()),
            };
        }
    });
    err
}

/// The unwinding payload that carries a Python exception out of the library.
struct Interrupted(PyErr);

/// Checks signals and calls `progress` (with the GIL) at most every 50 ms, and on every
/// stage event and on the first solver iteration of each stage (so that a fast stage's
/// iterations are seen at least once, whatever the machine's speed).
struct PyObserver {
    progress: Option<Py<PyAny>>,
    last: Instant,
    /// A stage has started and none of its iterations has been delivered yet.
    fresh: bool,
}

impl PyObserver {
    fn new(progress: Option<Py<PyAny>>) -> Self {
        PyObserver {
            progress,
            last: Instant::now() - Duration::from_secs(1),
            fresh: false,
        }
    }

    fn poll(&mut self, force: bool, event: impl FnOnce(Python<'_>) -> PyResult<Bound<'_, PyDict>>) {
        if !force && self.last.elapsed() < Duration::from_millis(50) {
            return;
        }
        self.last = Instant::now();
        let result = Python::attach(|py| -> PyResult<()> {
            py.check_signals()?;
            if let Some(cb) = &self.progress {
                cb.call1(py, (event(py)?,))?;
            }
            Ok(())
        });
        if let Err(e) = result {
            std::panic::resume_unwind(Box::new(Interrupted(e)));
        }
    }
}

impl Observer for PyObserver {
    fn on_event(&mut self, event: &Event<'_>) {
        let force = match event {
            Event::StageStarted { .. } => {
                self.fresh = true;
                true
            }
            Event::StageFinished { .. } | Event::Warning { .. } => true,
            Event::Iteration { .. } => std::mem::take(&mut self.fresh),
            _ => false,
        };
        self.poll(force, |py| {
            let d = PyDict::new(py);
            match event {
                Event::StageStarted { stage } => {
                    d.set_item("kind", "stage-started")?;
                    d.set_item("stage", *stage)?;
                }
                Event::StageFinished { stage, seconds } => {
                    d.set_item("kind", "stage-finished")?;
                    d.set_item("stage", *stage)?;
                    d.set_item("seconds", *seconds)?;
                }
                Event::Iteration {
                    solver,
                    run,
                    iteration,
                    cost,
                    rms,
                    lambda,
                } => {
                    d.set_item("kind", "iteration")?;
                    d.set_item("solver", *solver)?;
                    d.set_item("run", *run)?;
                    d.set_item("iteration", *iteration)?;
                    d.set_item("cost", *cost)?;
                    d.set_item("rms", *rms)?;
                    d.set_item("lambda", *lambda)?;
                }
                Event::Warning { message } => {
                    d.set_item("kind", "warning")?;
                    d.set_item("message", *message)?;
                }
                Event::FitSelection { frames, tracks } => {
                    d.set_item("kind", "fit-selection")?;
                    d.set_item("frames", frames.len())?;
                    d.set_item("tracks", tracks.len())?;
                }
                _ => {
                    d.set_item("kind", "other")?;
                }
            }
            Ok(d)
        });
    }
}

/// Runs `f` with the GIL released; a Python exception raised by the observer inside comes
/// back as that exception, a library error as its Python exception.
fn run_detached<T: Send>(
    py: Python<'_>,
    f: impl FnOnce() -> rank3::Result<T> + Send,
) -> PyResult<T> {
    let out = py.detach(|| std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    match out {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_py(e)),
        Err(payload) => match payload.downcast::<Interrupted>() {
            Ok(i) => Err(i.0),
            Err(other) => std::panic::resume_unwind(other),
        },
    }
}

fn apply_settings<T: serde::Serialize + serde::de::DeserializeOwned>(
    base: &T,
    json: &str,
) -> PyResult<T> {
    let value: serde_json::Value = serde_json::from_str(json)
        .map_err(|e| ConfigError::new_err(format!("settings are not valid JSON: {e}")))?;
    rank3::settings::apply(base, &value).map_err(to_py)
}

fn id_to_py(py: Python<'_>, id: &Id) -> Py<PyAny> {
    match id {
        Id::Int(i) => i
            .into_pyobject(py)
            .map(|v| v.into_any().unbind())
            .unwrap_or_else(|_| py.None()),
        Id::Str(s) => s
            .into_pyobject(py)
            .map(|v| v.into_any().unbind())
            .unwrap_or_else(|_| py.None()),
    }
}

fn id_from_py(v: &Bound<'_, PyAny>) -> PyResult<Id> {
    if let Ok(i) = v.extract::<i64>() {
        Ok(Id::Int(i))
    } else {
        Ok(Id::Str(v.str()?.to_string()))
    }
}

/// A track table as `(array (F, N, 2), frame ids, track ids)`; NaN where not observed.
fn table_to_py<'py>(py: Python<'py>, t: &TrackTable) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let (f, n) = (t.n_frames(), t.n_tracks());
    let mut a = Array3::<f64>::from_elem((f, n, 2), f64::NAN);
    for fi in 0..f {
        for p in 0..n {
            if let Some([x, y]) = t.get(fi, p) {
                a[(fi, p, 0)] = x;
                a[(fi, p, 1)] = y;
            }
        }
    }
    let frames = PyList::new(py, t.frame_ids().iter().map(|i| id_to_py(py, i)))?;
    let tracks = PyList::new(py, t.track_ids().iter().map(|i| id_to_py(py, i)))?;
    pyo3::types::PyTuple::new(
        py,
        [
            a.into_pyarray(py).into_any(),
            frames.into_any(),
            tracks.into_any(),
        ],
    )
}

fn table_from_py(
    tracks: &PyReadonlyArray3<'_, f64>,
    frame_ids: &Bound<'_, PyList>,
    track_ids: &Bound<'_, PyList>,
) -> PyResult<TrackTable> {
    let shape = tracks.shape();
    if shape[2] != 2 {
        return Err(InputError::new_err(format!(
            "tracks must have shape (F, N, 2), got {shape:?}"
        )));
    }
    let (f, n) = (shape[0], shape[1]);
    if frame_ids.len() != f || track_ids.len() != n {
        return Err(InputError::new_err(format!(
            "{} frame ids and {} track ids for a ({f}, {n}, 2) array",
            frame_ids.len(),
            track_ids.len()
        )));
    }
    let fids = frame_ids
        .iter()
        .map(|v| id_from_py(&v))
        .collect::<PyResult<Vec<_>>>()?;
    let tids = track_ids
        .iter()
        .map(|v| id_from_py(&v))
        .collect::<PyResult<Vec<_>>>()?;
    let a = tracks.as_array();
    let mut t = TrackTable::new(fids, tids);
    for fi in 0..f {
        for p in 0..n {
            let (x, y) = (a[(fi, p, 0)], a[(fi, p, 1)]);
            match (x.is_nan(), y.is_nan()) {
                (true, true) => {}
                (false, false) if x.is_finite() && y.is_finite() => t.set(fi, p, x, y),
                _ => {
                    return Err(InputError::new_err(format!(
                        "tracks[{fi}, {p}] = ({x}, {y}): an entry is either two finite \
                         coordinates or two NaNs (missing)"
                    )));
                }
            }
        }
    }
    Ok(t)
}

/// The default settings of `"reconstruct"` (the library's `Config`) or `"track"`
/// (`TrackerConfig`), as JSON.
#[pyfunction]
fn default_settings(kind: &str) -> PyResult<String> {
    let v = match kind {
        "reconstruct" => rank3::settings::to_value(&Config::default()),
        "track" => rank3::settings::to_value(&rank3::tracking::TrackerConfig::default()),
        _ => return Err(ConfigError::new_err(format!("no settings named {kind:?}"))),
    }
    .map_err(to_py)?;
    Ok(v.to_string())
}

/// Reads a track table file (.csv, .txt, .json): `(array (F, N, 2), frame ids, track ids)`.
#[pyfunction]
fn read_tracks<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let t = run_detached(py, || TrackTable::read(&path))?;
    table_to_py(py, &t)
}

/// Writes a track table file (format from the extension).
#[pyfunction]
fn write_tracks(
    path: PathBuf,
    tracks: PyReadonlyArray3<'_, f64>,
    frame_ids: &Bound<'_, PyList>,
    track_ids: &Bound<'_, PyList>,
) -> PyResult<()> {
    let t = table_from_py(&tracks, frame_ids, track_ids)?;
    t.write(&path).map_err(to_py)
}

/// The progress event of one tracked frame.
fn frame_event<'py>(
    py: Python<'py>,
    s: &rank3::tracking::FrameStats,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("kind", "frame")?;
    d.set_item("frame", s.frame)?;
    d.set_item("alive", s.alive)?;
    d.set_item("tracked", s.tracked)?;
    Ok(d)
}

/// Tracks a folder of images or a video: `(array, frame ids, track ids)`.
#[pyfunction]
#[pyo3(signature = (path, settings, progress=None))]
fn track_path<'py>(
    py: Python<'py>,
    path: PathBuf,
    settings: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let cfg = apply_settings(&rank3::tracking::TrackerConfig::default(), settings)?;
    let mut obs = PyObserver::new(progress);
    let (t, _) = run_detached(py, || {
        let mut src = rank3::tracking::FrameSource::open(&path)?;
        rank3::tracking::track_source(&mut src, &cfg, None, &mut |s, _| {
            obs.poll(true, |py| frame_event(py, s))
        })
    })?;
    table_to_py(py, &t)
}

/// Tracks an iterable of frames (2-D gray or 3-D RGB arrays, uint8 or float in [0, 1]).
#[pyfunction]
#[pyo3(signature = (frames, settings, progress=None))]
fn track_frames<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    settings: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let cfg = apply_settings(&rank3::tracking::TrackerConfig::default(), settings)?;
    let mut tracker = rank3::tracking::Tracker::new(cfg).map_err(to_py)?;
    let np = py.import("numpy")?;
    for (k, frame) in frames.try_iter()?.enumerate() {
        let frame = frame?;
        let arr = np.call_method1("asarray", (frame,))?;
        let dtype: String = arr.getattr("dtype")?.str()?.to_string();
        let scale = if dtype == "uint8" { 1.0 / 255.0 } else { 1.0 };
        let arr = arr.call_method1("astype", ("float32",))?;
        let ndim: usize = arr.getattr("ndim")?.extract()?;
        let gray = match ndim {
            2 => arr,
            3 => {
                let w = np.call_method1("array", (vec![0.299f32, 0.587, 0.114],))?;
                let rgb = arr.call_method1(
                    "__getitem__",
                    ((
                        pyo3::types::PySlice::full(py),
                        pyo3::types::PySlice::full(py),
                        pyo3::types::PySlice::new(py, 0, 3, 1),
                    ),),
                )?;
                rgb.call_method1("__matmul__", (w,))?
            }
            _ => {
                return Err(InputError::new_err(format!(
                    "frame {k}: expected a 2-D (gray) or 3-D (RGB) array, got {ndim} dimensions"
                )));
            }
        };
        let shape: Vec<usize> = gray.getattr("shape")?.extract()?;
        let data: Vec<f32> = gray
            .call_method0("ravel")?
            .extract::<Vec<f32>>()?
            .into_iter()
            .map(|v| v * scale)
            .collect();
        let img = rank3::tracking::GrayImage::new(shape[1], shape[0], data).map_err(to_py)?;
        py.check_signals()?;
        let stats = py
            .detach(|| tracker.push(Id::from(k), &img))
            .map_err(to_py)?;
        if let Some(cb) = &progress {
            cb.call1(py, (frame_event(py, &stats)?,))?;
        }
    }
    let (t, _) = tracker.finish();
    table_to_py(py, &t)
}

/// A reconstruction: the library's result and the table it came from.
#[pyclass(module = "rank3._rank3", frozen)]
struct Reconstruction {
    rec: rank3::Reconstruction,
    table: TrackTable,
    /// Wall time inside the library call (the rest of `reconstruct` is conversion).
    library_seconds: f64,
}

/// Runs the pipeline on `tracks` (F, N, 2; NaN = missing).
#[pyfunction]
#[pyo3(signature = (tracks, frame_ids, track_ids, settings, rrd=None, progress=None))]
fn reconstruct(
    py: Python<'_>,
    tracks: PyReadonlyArray3<'_, f64>,
    frame_ids: &Bound<'_, PyList>,
    track_ids: &Bound<'_, PyList>,
    settings: &str,
    rrd: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Reconstruction> {
    let table = table_from_py(&tracks, frame_ids, track_ids)?;
    let config = apply_settings(&Config::default(), settings)?;
    let mut obs = PyObserver::new(progress);
    let mut library_seconds = 0.0;
    let rec = run_detached(py, || {
        let t0 = Instant::now();
        let stream = match &rrd {
            Some(path) => Some(
                rerun::RecordingStreamBuilder::new("rank3")
                    .save(path)
                    .map_err(|e| rank3::Error::Io {
                        path: path.clone(),
                        source: std::io::Error::other(e.to_string()),
                    })?,
            ),
            None => None,
        };
        let out =
            rank3::recording::reconstruct_recorded_with(stream.as_ref(), &table, &config, &mut obs)
                .map_err(rank3::Error::from);
        if let Some(s) = stream {
            s.flush_blocking().map_err(|e| rank3::Error::Io {
                path: rrd.clone().unwrap_or_default(),
                source: std::io::Error::other(e.to_string()),
            })?;
        }
        library_seconds = t0.elapsed().as_secs_f64();
        out
    })?;
    Ok(Reconstruction {
        rec,
        table,
        library_seconds,
    })
}

/// The streaming factorization of the complete tracks of a CSV file, never held whole
/// (`rank3 reconstruct --stream`; `rank3::stream`): `settings` overrides fields of
/// `rank3::stream::StreamConfig`.
#[pyfunction]
#[pyo3(signature = (path, settings, progress=None))]
fn reconstruct_stream(
    py: Python<'_>,
    path: PathBuf,
    settings: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<Reconstruction> {
    let cfg = apply_settings(&rank3::stream::StreamConfig::default(), settings)?;
    let mut obs = PyObserver::new(progress);
    let mut library_seconds = 0.0;
    let (rec, table) = run_detached(py, || {
        let t0 = Instant::now();
        let mut source = rank3::stream::CsvFile { path: path.clone() };
        let result = rank3::stream::factorize(&mut source, &cfg, &mut obs)?;
        // The ids only: the observations were never held.
        let table = TrackTable::new(result.frame_ids.clone(), result.track_ids.clone());
        let rec = result.into_reconstruction();
        library_seconds = t0.elapsed().as_secs_f64();
        Ok((rec, table))
    })?;
    Ok(Reconstruction {
        rec,
        table,
        library_seconds,
    })
}

#[pymethods]
impl Reconstruction {
    /// The reconstruction as `reconstruction.json` holds it.
    fn to_json(&self) -> String {
        self.rec.to_json()
    }

    /// Writes the CLI's files into `dir`: reconstruction.json, completed.txt, points.ply and,
    /// with a perspective result, colmap/.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        run_detached(py, || {
            rank3::output::write_all(&self.rec, &dir)?;
            rank3::output::write_colmap(&self.rec, &self.table, &dir.join("colmap"))?;
            Ok(())
        })
    }

    /// `"orthographic"`, `"scaled-orthographic"`, `"projective"` or `"perspective"`.
    #[getter]
    fn camera_model(&self) -> String {
        serde_json::to_value(self.rec.camera_model)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default()
    }

    /// Seconds spent inside the library (the call's other time is conversion).
    #[getter]
    fn library_seconds(&self) -> f64 {
        self.library_seconds
    }

    #[getter]
    fn rms_px(&self) -> f64 {
        self.rec.rms_px
    }

    #[getter]
    fn frame_ids(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        Ok(PyList::new(py, self.table.frame_ids().iter().map(|i| id_to_py(py, i)))?.unbind())
    }

    #[getter]
    fn track_ids(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        Ok(PyList::new(py, self.table.track_ids().iter().map(|i| id_to_py(py, i)))?.unbind())
    }

    /// `(F, 3, 3)` world-to-camera rotations (rows: camera axes), NaN for frames not used:
    /// the perspective cameras' when there are, else the affine-family model's.
    #[getter]
    fn rotations<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let f = self.table.n_frames();
        let index = self.frame_index();
        let mut a = Array3::<f64>::from_elem((f, 3, 3), f64::NAN);
        let mut put = |id: &Id, r: &[[f64; 3]; 3]| {
            if let Some(&i) = index.get(id) {
                for x in 0..3 {
                    for y in 0..3 {
                        a[(i, x, y)] = r[x][y];
                    }
                }
            }
        };
        match &self.rec.perspective {
            Some(p) => p.cameras.iter().for_each(|c| put(&c.frame, &c.rotation)),
            None => self
                .rec
                .frames
                .iter()
                .for_each(|c| put(&c.frame, &c.rotation)),
        }
        a.into_pyarray(py)
    }

    /// Translations, NaN for frames not used: `(F, 3)` of the perspective cameras
    /// (`x_cam = R X + t`), else `(F, 2)` of the affine-family model (pixels).
    #[getter]
    fn translations<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let index = self.frame_index();
        match &self.rec.perspective {
            Some(p) => {
                let mut a = Array2::<f64>::from_elem((self.table.n_frames(), 3), f64::NAN);
                for c in &p.cameras {
                    if let Some(&i) = index.get(&c.frame) {
                        for k in 0..3 {
                            a[(i, k)] = c.translation[k];
                        }
                    }
                }
                a.into_pyarray(py)
            }
            None => {
                let mut a = Array2::<f64>::from_elem((self.table.n_frames(), 2), f64::NAN);
                for c in &self.rec.frames {
                    if let Some(&i) = index.get(&c.frame) {
                        a[(i, 0)] = c.translation[0];
                        a[(i, 1)] = c.translation[1];
                    }
                }
                a.into_pyarray(py)
            }
        }
    }

    /// `(F,)` scales of the affine-family model (the perspective model's focal lengths with a
    /// perspective result: see `focal_px`), NaN for frames not used.
    #[getter]
    fn scales<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let index = self.frame_index();
        let mut a = Array1::<f64>::from_elem(self.table.n_frames(), f64::NAN);
        for c in &self.rec.frames {
            if let Some(&i) = index.get(&c.frame) {
                a[i] = c.scale;
            }
        }
        a.into_pyarray(py)
    }

    /// `(F,)` focal lengths of the perspective cameras, pixels (`None` without one).
    #[getter]
    fn focal_px<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        let p = self.rec.perspective.as_ref()?;
        let index = self.frame_index();
        let mut a = Array1::<f64>::from_elem(self.table.n_frames(), f64::NAN);
        for c in &p.cameras {
            if let Some(&i) = index.get(&c.frame) {
                a[i] = c.focal_px;
            }
        }
        Some(a.into_pyarray(py))
    }

    /// `(3, 3)` intrinsic matrix of the first perspective camera (`None` without one).
    #[getter]
    fn k<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        let p = self.rec.perspective.as_ref()?;
        let k = p.intrinsics.k;
        Some(Array2::from_shape_fn((3, 3), |(a, b)| k[a][b]).into_pyarray(py))
    }

    /// `(N, 3)` points in the input's track order (Euclidean with a perspective result),
    /// NaN for tracks set aside.
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let index = self.track_index();
        let mut a = Array2::<f64>::from_elem((self.table.n_tracks(), 3), f64::NAN);
        for q in self.point_list() {
            if let Some(&i) = index.get(&q.track) {
                for k in 0..3 {
                    a[(i, k)] = q.xyz[k];
                }
            }
        }
        a.into_pyarray(py)
    }

    /// `(N,)` true for the tracks the fit kept (false for outliers and tracks set aside).
    #[getter]
    fn inlier<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        let index = self.track_index();
        let mut a = Array1::<bool>::from_elem(self.table.n_tracks(), false);
        for q in self.point_list() {
            if let Some(&i) = index.get(&q.track) {
                a[i] = q.inlier;
            }
        }
        a.into_pyarray(py)
    }

    /// `(F, N)` true for the entries the robust pass flagged as gross errors.
    #[getter]
    fn flagged<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<bool>> {
        let mut a =
            Array2::<bool>::from_elem((self.table.n_frames(), self.table.n_tracks()), false);
        if let Some(r) = &self.rec.robust {
            for &(f, p) in &r.flagged_indices {
                if f < self.table.n_frames() && p < self.table.n_tracks() {
                    a[(f, p)] = true;
                }
            }
        }
        a.into_pyarray(py)
    }

    /// `(F, N, 2)` the fit's prediction of every track in every frame (as completed.txt),
    /// NaN for frames and tracks set aside.
    #[getter]
    fn completed<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let m = self.rec.completed_matrix();
        let (f, n) = (m.nrows() / 2, m.ncols());
        Array3::from_shape_fn((f, n, 2), |(fi, p, c)| m[(2 * fi + c, p)]).into_pyarray(py)
    }

    /// `(F, 3, 4)` projective cameras `P_f` (`None` without a projective result).
    #[getter]
    fn projective_cameras<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray3<f64>>> {
        let p = self.rec.projective.as_ref()?;
        let index = self.frame_index();
        let mut a = Array3::<f64>::from_elem((self.table.n_frames(), 3, 4), f64::NAN);
        for c in &p.cameras {
            if let Some(&i) = index.get(&c.frame) {
                for x in 0..3 {
                    for y in 0..4 {
                        a[(i, x, y)] = c.p[x][y];
                    }
                }
            }
        }
        Some(a.into_pyarray(py))
    }

    /// `(N, 4)` homogeneous points `X_p` of the projective model (`None` without one).
    #[getter]
    fn projective_points<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        let p = self.rec.projective.as_ref()?;
        let index = self.track_index();
        let mut a = Array2::<f64>::from_elem((self.table.n_tracks(), 4), f64::NAN);
        for q in &p.points {
            if let Some(&i) = index.get(&q.track) {
                for k in 0..4 {
                    a[(i, k)] = q.x[k];
                }
            }
        }
        Some(a.into_pyarray(py))
    }
}

impl Reconstruction {
    fn frame_index(&self) -> std::collections::HashMap<&Id, usize> {
        self.table
            .frame_ids()
            .iter()
            .enumerate()
            .map(|(i, id)| (id, i))
            .collect()
    }
    fn track_index(&self) -> std::collections::HashMap<&Id, usize> {
        self.table
            .track_ids()
            .iter()
            .enumerate()
            .map(|(i, id)| (id, i))
            .collect()
    }
    fn point_list(&self) -> &[rank3::reconstruction::PointResult] {
        self.rec
            .perspective
            .as_ref()
            .map_or(&self.rec.points, |p| &p.points)
    }
}

#[pymodule]
fn _rank3(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("Rank3Error", py.get_type::<Rank3Error>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("DataError", py.get_type::<DataError>())?;
    m.add("NumericalError", py.get_type::<NumericalError>())?;
    m.add_class::<Reconstruction>()?;
    m.add_function(wrap_pyfunction!(default_settings, m)?)?;
    m.add_function(wrap_pyfunction!(read_tracks, m)?)?;
    m.add_function(wrap_pyfunction!(write_tracks, m)?)?;
    m.add_function(wrap_pyfunction!(track_path, m)?)?;
    m.add_function(wrap_pyfunction!(track_frames, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct_stream, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
