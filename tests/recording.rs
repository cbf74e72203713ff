//! Records a small synthetic reconstruction to a temporary .rrd, reads it back with the Rerun
//! SDK's own decoder (`re_log_encoding`, the codec the viewer uses) and checks that every
//! entity is there with the expected number of rows and instances, on the expected
//! timelines, and that logged values match the reconstruction.

#![cfg(feature = "rerun")]

use std::collections::BTreeMap;
use std::io::BufReader;
use std::os::unix::process::CommandExt as _;
use std::path::Path;

use rank3::recording::{self, RecordingObserver, paths};
use rank3::synth::{Shape, SynthConfig, generate};
use rank3::table::Id;
use rank3::{Config, Event, Observer, Reconstruction, TrackTable};
use re_log_encoding::DecoderApp;
use rerun::components::Position3D;
use rerun::external::arrow::array::Array as _;
use rerun::log::{Chunk, LogMsg};

/// Everything logged to one (entity, component) pair.
#[derive(Default, Debug)]
struct Column {
    /// Instances per logged row.
    instances: Vec<usize>,
    /// Timeline name → values, one per row (static rows have none).
    times: BTreeMap<String, Vec<i64>>,
    is_static: bool,
}

impl Column {
    fn rows(&self) -> usize {
        self.instances.len()
    }
    fn total(&self) -> usize {
        self.instances.iter().sum()
    }
}

struct Contents {
    columns: BTreeMap<(String, String), Column>,
    chunks: Vec<Chunk>,
}

impl Contents {
    fn get(&self, entity: &str, component: &str) -> &Column {
        self.columns
            .get(&(entity.to_string(), component.to_string()))
            .unwrap_or_else(|| {
                panic!(
                    "{entity} / {component} missing; recorded: {:?}",
                    self.columns.keys().collect::<Vec<_>>()
                )
            })
    }

    /// Colours (RGB) logged to `entity` under `component` (all rows concatenated).
    fn colors(&self, entity: &str, component: rerun::ComponentIdentifier) -> Vec<[u8; 3]> {
        let mut out = Vec::new();
        for c in self
            .chunks
            .iter()
            .filter(|c| c.entity_path().to_string().trim_start_matches('/') == entity)
        {
            for row in c.iter_component::<rerun::components::Color>(component) {
                out.extend(row.iter().map(|c| {
                    let [r, g, b, _] = c.to_array();
                    [r, g, b]
                }));
            }
        }
        out
    }

    /// Scalars logged to `entity` (all rows concatenated).
    fn scalars(&self, entity: &str) -> Vec<f64> {
        let id = rerun::Scalars::descriptor_scalars().component;
        let mut out = Vec::new();
        for c in self.of(entity) {
            for row in c.iter_component::<rerun::components::Scalar>(id) {
                out.extend(row.iter().map(|s| s.0.0));
            }
        }
        out
    }

    /// The `show_labels` flags logged to `entity` under `component` (all rows).
    fn show_labels(&self, entity: &str, component: rerun::ComponentIdentifier) -> Vec<bool> {
        let mut out = Vec::new();
        for c in self.of(entity) {
            for row in c.iter_component::<rerun::components::ShowLabels>(component) {
                out.extend(row.iter().map(|s| s.0.0));
            }
        }
        out
    }

    /// The chunks of `entity`.
    fn of<'a>(&'a self, entity: &'a str) -> impl Iterator<Item = &'a Chunk> + 'a {
        self.chunks
            .iter()
            .filter(move |c| c.entity_path().to_string().trim_start_matches('/') == entity)
    }

    /// Positions logged to `entity` (all rows concatenated).
    fn positions3(&self, entity: &str) -> Vec<[f32; 3]> {
        let id = rerun::Points3D::descriptor_positions().component;
        let mut out = Vec::new();
        for c in self
            .chunks
            .iter()
            .filter(|c| c.entity_path().to_string().trim_start_matches('/') == entity)
        {
            for row in c.iter_component::<Position3D>(id) {
                out.extend(row.iter().map(|p| [p.x(), p.y(), p.z()]));
            }
        }
        out
    }
}

fn read_rrd(path: &Path) -> Contents {
    try_read_rrd(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// [`read_rrd`], with a message instead of a panic when the file cannot be read or decoded
/// (e.g. one still being written).
fn try_read_rrd(path: &Path) -> Result<Contents, String> {
    let file = std::fs::File::open(path).map_err(|e| format!("open: {e}"))?;
    let mut columns: BTreeMap<(String, String), Column> = BTreeMap::new();
    let mut chunks = Vec::new();
    for msg in DecoderApp::decode_lazy(BufReader::new(file)) {
        let msg = msg.map_err(|e| format!("decode: {e}"))?;
        let LogMsg::ArrowMsg(_, arrow) = msg else {
            continue;
        };
        let chunk = Chunk::from_arrow_msg(&arrow).map_err(|e| format!("chunk: {e}"))?;
        let entity = chunk
            .entity_path()
            .to_string()
            .trim_start_matches('/')
            .to_string();
        for col in chunk.components().0.values() {
            let key = (entity.clone(), col.descriptor.component.to_string());
            let e = columns.entry(key).or_default();
            e.is_static |= chunk.is_static();
            let list = &col.list_array;
            for i in 0..list.len() {
                e.instances.push(if list.is_null(i) {
                    0
                } else {
                    list.value_length(i) as usize
                });
                for (name, tc) in chunk.timelines() {
                    e.times
                        .entry(name.to_string())
                        .or_default()
                        .push(tc.times_raw()[i]);
                }
            }
        }
        chunks.push(chunk);
    }
    Ok(Contents { columns, chunks })
}

/// A fresh temporary directory `rank3-recording-{name}-PID` and a recording saved to its
/// `run.rrd`.
fn temp_recording(
    name: &str,
) -> (
    std::path::PathBuf,
    std::path::PathBuf,
    rerun::RecordingStream,
) {
    let dir = std::env::temp_dir().join(format!("rank3-recording-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.rrd");
    let rec = rerun::RecordingStreamBuilder::new("rank3-test")
        .save(&path)
        .unwrap();
    (dir, path, rec)
}

/// A complete synthetic scene plus two stray tracks seen in one frame (set aside).
fn table() -> (TrackTable, usize) {
    let scene = generate(&SynthConfig {
        shape: Shape::Cloud,
        frames: 9,
        points: 30,
        noise: 0.5,
        seed: 5,
        ..Default::default()
    })
    .unwrap();
    let t = &scene.table;
    let mut ids = t.track_ids().to_vec();
    ids.push(Id::Str("stray-a".into()));
    ids.push(Id::Str("stray-b".into()));
    let mut out = TrackTable::new(t.frame_ids().to_vec(), ids);
    for f in 0..t.n_frames() {
        for p in 0..t.n_tracks() {
            if let Some([x, y]) = t.get(f, p) {
                out.set(f, p, x, y);
            }
        }
    }
    out.set(3, t.n_tracks(), 10.0, 20.0);
    out.set(5, t.n_tracks() + 1, 30.0, 40.0);
    (out, t.n_tracks())
}

#[test]
fn recording_round_trips_through_the_rerun_decoder() {
    let (table, n_used) = table();
    let (nf, n_all) = (table.n_frames(), table.n_tracks());
    let (dir, path, rec) = temp_recording("test");
    recording::log_input(&rec, &table).unwrap();
    let mut observer = RecordingObserver::new(&rec);
    let result =
        Reconstruction::from_tracks_observed(&table, &Config::default(), &mut observer).unwrap();
    // A solver's iterations (the placeholder refinement emits none): two runs of 3 and 2.
    for (run, its) in [(0usize, 3usize), (1, 2)] {
        for iteration in 0..its {
            observer.on_event(&Event::Iteration {
                solver: "probe",
                run,
                iteration,
                cost: 10.0 / (1 + iteration) as f64,
                rms: 1.0,
                lambda: f64::NAN,
            });
        }
    }
    assert_eq!(observer.errors().0, 0, "{:?}", observer.first_error());
    recording::log_reconstruction(&rec, &table, &result).unwrap();
    let mut inliers = vec![true; n_all];
    inliers[n_all - 1] = false;
    inliers[0] = false;
    recording::log_robust(
        &rec,
        &table,
        &inliers,
        &[(1, 2), (1, 4), (7, 2)],
        &[20, 25, 28, 28],
    )
    .unwrap();
    // Mismatched robust data is a typed error, not a panic.
    assert!(recording::log_robust(&rec, &table, &inliers[1..], &[], &[]).is_err());
    assert!(recording::log_robust(&rec, &table, &inliers, &[(nf, 0)], &[]).is_err());
    drop(observer);
    drop(rec); // flushes and finalizes the file

    assert_eq!(
        result.kept_tracks.len(),
        n_used,
        "the stray tracks are set aside"
    );
    assert_eq!(result.kept_frames.len(), nf);
    let c = read_rrd(&path);

    // Input.
    let tracks = c.get(paths::TRACKS, "Points2D:positions");
    assert_eq!(tracks.rows(), nf);
    assert_eq!(tracks.total(), table.n_observed());
    assert_eq!(tracks.times["frame"], (0..nf as i64).collect::<Vec<_>>());
    assert_eq!(
        c.get(paths::TRACKS, "Points2D:class_ids").total(),
        table.n_observed()
    );
    let traj = c.get(paths::TRAJECTORIES, "LineStrips2D:strips");
    assert_eq!((traj.rows(), traj.total()), (1, n_all));
    assert_eq!(traj.times["stage"], vec![0]);
    let ctx = c.get("image", "AnnotationContext:context");
    assert!(ctx.is_static);
    assert_eq!(ctx.rows(), 1, "one context (a map of {n_all} class ids)");

    // Set-aside tracks: separate red entities.
    assert_eq!(
        c.get(paths::SET_ASIDE_TRAJECTORIES, "LineStrips2D:strips")
            .total(),
        2
    );
    let aside = c.get(paths::SET_ASIDE_POINTS, "Points2D:positions");
    assert_eq!((aside.rows(), aside.total()), (nf, 2));
    assert_eq!(c.get(paths::LOG_SET_ASIDE, "TextLog:text").rows(), 2);

    // Factorization.
    assert_eq!(c.get(paths::VISIBILITY, "Image:buffer").rows(), 1);
    assert_eq!(c.get(paths::W, "Tensor:data").rows(), 1);
    let sv = c.get(paths::SINGULAR_VALUES, "BarChart:values");
    assert_eq!(sv.rows(), 1);
    assert_eq!(sv.times["stage"], vec![3]);
    let ratio = c.get(paths::RANK_RATIO, "Scalars:scalars");
    assert_eq!((ratio.rows(), ratio.total()), (1, 1));

    // Structure before and after the metric upgrade.
    assert_eq!(
        c.get(paths::AFFINE_POINTS, "Points3D:positions").total(),
        n_used
    );
    let pts = c.get(paths::POINTS, "Points3D:positions");
    assert_eq!((pts.rows(), pts.total()), (1, n_used));
    assert_eq!(c.get(paths::POINTS, "Points3D:colors").total(), n_used);
    assert_eq!(pts.times["stage"], vec![4]);
    let logged = c.positions3(paths::POINTS);
    let scale = result
        .points
        .iter()
        .map(|p| p.xyz.iter().fold(0.0f64, |a, v| a.max(v.abs())))
        .fold(0.0, f64::max);
    for (got, want) in logged.iter().zip(&result.points) {
        for k in 0..3 {
            assert!(
                (got[k] as f64 - want.xyz[k]).abs() <= 1e-6 * scale,
                "point {:?} logged as {got:?}",
                want.xyz
            );
        }
    }
    assert_eq!(c.get(paths::EIGENVALUES_LS, "BarChart:values").rows(), 1);
    assert_eq!(c.get(paths::EIGENVALUES, "BarChart:values").rows(), 1);
    assert_eq!(c.get(paths::METRIC_METHOD, "TextDocument:text").rows(), 1);

    // Cameras: one pose per kept frame, on the frame timeline.
    let cam = c.get(paths::CAMERA, "Transform3D:mat3x3");
    assert_eq!(cam.rows(), nf);
    assert_eq!(
        cam.times["frame"],
        result
            .kept_frames
            .iter()
            .map(|&f| f as i64)
            .collect::<Vec<_>>()
    );
    assert_eq!(c.get(paths::CAMERA, "Transform3D:translation").rows(), nf);
    let axes = c.get(paths::CAMERA_AXES, "Arrows3D:vectors");
    assert!(axes.is_static);
    assert_eq!(axes.total(), 3);
    assert_eq!(
        c.get(paths::VIEW_DIRECTIONS, "Arrows3D:vectors").total(),
        nf
    );
    assert_eq!(
        c.get(paths::CAMERA_TRAJECTORY, "LineStrips3D:strips")
            .total(),
        1
    );

    // Residuals.
    let arrows = c.get(paths::RESIDUAL_ARROWS, "Arrows2D:vectors");
    assert_eq!((arrows.rows(), arrows.total()), (nf, nf * n_used));
    assert_eq!(
        c.get(paths::RESIDUAL_ARROWS, "Arrows2D:origins").total(),
        nf * n_used
    );
    assert_eq!(c.get(paths::POINT_RMS, "BarChart:values").rows(), 1);
    assert_eq!(c.get(paths::FRAME_RMS, "Scalars:scalars").rows(), nf);

    // Observer: stages, warnings, solver iterations.
    let stages = c.get(paths::LOG_STAGES, "TextLog:text");
    assert!(stages.rows() >= 2 * result.timings.len(), "{stages:?}");
    let warnings = c.get(paths::LOG_WARNINGS, "TextLog:level");
    assert_eq!(warnings.rows(), result.warnings.len());
    assert!(!result.warnings.is_empty(), "set-aside tracks warn");
    // One entity per quantity and run (`solver/<quantity>/<solver>/run<k>`), so that the
    // layout plots each quantity on its own axis; the cost also as log₁₀, λ (NaN here) not.
    let cost0 = c.get(
        &format!("{}/probe/run0", paths::SOLVER_COST),
        "Scalars:scalars",
    );
    assert_eq!(cost0.times["iteration"], vec![0, 1, 2]);
    assert_eq!(
        c.get(
            &format!("{}/probe/run1", paths::SOLVER_RMS),
            "Scalars:scalars"
        )
        .rows(),
        2
    );
    let log_cost = c.scalars(&format!("{}/probe/run0", paths::SOLVER_LOG10_COST));
    let want: Vec<f64> = (0..3).map(|i| (10.0 / (1 + i) as f64).log10()).collect();
    assert_eq!(log_cost.len(), 3);
    for (got, want) in log_cost.iter().zip(&want) {
        assert!((got - want).abs() < 1e-12, "log10 cost {got} vs {want}");
    }
    assert!(
        !c.columns
            .keys()
            .any(|(e, _)| e.contains("lambda") && e.contains("probe")),
        "a NaN λ is not logged"
    );
    // Track labels are not drawn on every point, strip and arrow (hover names them); the
    // two set-aside tracks' labels are.
    let no_labels = |entity: &str, component: rerun::ComponentIdentifier| {
        let flags = c.show_labels(entity, component);
        assert!(
            !flags.is_empty() && flags.iter().all(|&s| !s),
            "{entity}: {flags:?}"
        );
    };
    no_labels(
        paths::TRACKS,
        rerun::Points2D::descriptor_show_labels().component,
    );
    no_labels(
        paths::TRAJECTORIES,
        rerun::LineStrips2D::descriptor_show_labels().component,
    );
    no_labels(
        paths::RESIDUAL_ARROWS,
        rerun::Arrows2D::descriptor_show_labels().component,
    );
    no_labels(
        paths::POINTS,
        rerun::Points3D::descriptor_show_labels().component,
    );
    no_labels(
        paths::AFFINE_POINTS,
        rerun::Points3D::descriptor_show_labels().component,
    );
    assert_eq!(
        c.show_labels(
            paths::SET_ASIDE_TRAJECTORIES,
            rerun::LineStrips2D::descriptor_show_labels().component
        ),
        vec![true]
    );
    // The input trajectories are on the `frame` timeline too (at 0), where `rank3 track`'s
    // recording opens.
    assert_eq!(
        c.get(paths::TRAJECTORIES, "LineStrips2D:strips").times["frame"],
        vec![0]
    );
    assert_eq!(c.get(paths::SUMMARY, "TextDocument:text").rows(), 1);

    // Robust pass.
    // The input trajectories get one colour each at the robust stage: red for the two
    // outliers (tracks 0 and n − 1), green for the rest.
    let colours = c.get(paths::TRAJECTORIES, "LineStrips2D:colors");
    assert_eq!((colours.rows(), colours.total()), (1, n_all));
    assert_eq!(colours.times["stage"], vec![2]);
    let rgb = c.colors(
        paths::TRAJECTORIES,
        rerun::LineStrips2D::descriptor_colors().component,
    );
    let red: Vec<usize> = (0..n_all).filter(|&p| rgb[p][0] > rgb[p][1]).collect();
    assert_eq!(red, vec![0, n_all - 1]);
    assert_eq!(
        c.get(paths::ROBUST_OUTLIERS, "LineStrips2D:strips").total(),
        2
    );
    let flagged = c.get(paths::ROBUST_FLAGGED, "Points2D:positions");
    assert_eq!((flagged.rows(), flagged.total()), (2, 3));
    assert_eq!(
        c.get(paths::ROBUST_INLIER_COUNT, "Scalars:scalars").rows(),
        4
    );

    std::fs::remove_dir_all(&dir).ok();
}

/// `reconstruct_recorded` logs the input, the mask and W on a second thread while the
/// pipeline runs: each exactly once, W being the matrix of the frames and tracks the fit
/// used (the two stray tracks are set aside), with the values of the table.
#[test]
fn reconstruct_recorded_logs_w_of_the_fit_once() {
    let (table, n_used) = table();
    let nf = table.n_frames();
    let (dir, path, rec) = temp_recording("w");
    let result = recording::reconstruct_recorded(Some(&rec), &table, &Config::default()).unwrap();
    drop(rec);
    assert_eq!(result.kept_tracks.len(), n_used);
    let c = read_rrd(&path);

    let tracks = c.get(paths::TRACKS, "Points2D:positions");
    assert_eq!((tracks.rows(), tracks.total()), (nf, table.n_observed()));
    assert_eq!(c.get(paths::TRAJECTORIES, "LineStrips2D:strips").rows(), 1);
    let mask = c.get(paths::VISIBILITY, "Image:buffer");
    assert_eq!((mask.rows(), mask.times["stage"].clone()), (1, vec![3]));
    let w_col = c.get(paths::W, "Tensor:data");
    assert_eq!((w_col.rows(), w_col.times["stage"].clone()), (1, vec![3]));

    let id = rerun::Tensor::descriptor_data().component;
    let w: Vec<rerun::components::TensorData> = c
        .chunks
        .iter()
        .filter(|ch| ch.entity_path().to_string().trim_start_matches('/') == paths::W)
        .flat_map(|ch| ch.iter_component::<rerun::components::TensorData>(id))
        .flat_map(|row| row.to_vec())
        .collect();
    assert_eq!(w.len(), 1);
    let w = &w[0].0;
    assert_eq!(w.shape.to_vec(), vec![2 * nf as u64, n_used as u64]);
    let rerun::datatypes::TensorBuffer::F32(values) = &w.buffer else {
        panic!("W is not f32: {:?}", w.buffer.dtype());
    };
    for (kf, &f) in result.kept_frames.iter().enumerate() {
        for (kp, &p) in result.kept_tracks.iter().enumerate() {
            let [x, y] = table.get(f, p).unwrap();
            assert_eq!(values[2 * kf * n_used + kp], x as f32, "W x at ({f}, {p})");
            assert_eq!(
                values[(2 * kf + 1) * n_used + kp],
                y as f32,
                "W y at ({f}, {p})"
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A run whose robust pass rejects tracks records them: the result's points hold kept and
/// outlier tracks, and the recording puts the kept ones on `world/points`, the outliers on
/// `world/outliers` and in red on the trajectories.
#[test]
fn reconstruct_recorded_with_outlier_tracks() {
    let scene = generate(&SynthConfig {
        frames: 12,
        points: 60,
        noise: 0.5,
        outliers: 0.2,
        seed: 5,
        ..Default::default()
    })
    .unwrap();
    let table = &scene.table;
    let (dir, path, rec) = temp_recording("outl");
    let result = recording::reconstruct_recorded(Some(&rec), table, &Config::default()).unwrap();
    drop(rec);
    let (nk, no) = (result.kept_tracks.len(), result.outlier_tracks.len());
    assert!(no > 0, "no outlier track rejected");
    assert_eq!(result.points.len(), nk + no);
    let c = read_rrd(&path);
    assert_eq!(c.get(paths::POINTS, "Points3D:positions").total(), nk);
    assert_eq!(c.get(paths::POINTS, "Points3D:colors").total(), nk);
    assert_eq!(
        c.get(paths::OUTLIER_POINTS, "Points3D:positions").total(),
        no
    );
    // Outliers are not "set aside" (the scene sets nothing aside).
    assert!(result.set_aside.is_empty());
    assert!(
        !c.columns
            .keys()
            .any(|(entity, _)| entity.starts_with("image/set_aside")),
        "outlier tracks drawn as set aside"
    );
    assert_eq!(
        c.get(paths::ROBUST_OUTLIERS, "LineStrips2D:strips").total(),
        no
    );
    // The few flagged (outlier) tracks are labelled on the image plane; in 3D (where nearby
    // points' labels overlap) neither they nor the kept ones are: hover names them.
    assert!(no <= 24);
    assert_eq!(
        c.show_labels(
            paths::ROBUST_OUTLIERS,
            rerun::LineStrips2D::descriptor_show_labels().component
        ),
        vec![true]
    );
    assert_eq!(
        c.show_labels(
            paths::OUTLIER_POINTS,
            rerun::Points3D::descriptor_show_labels().component
        ),
        vec![false]
    );
    assert_eq!(
        c.show_labels(
            paths::POINTS,
            rerun::Points3D::descriptor_show_labels().component
        ),
        vec![false]
    );
    let rgb = c.colors(
        paths::TRAJECTORIES,
        rerun::LineStrips2D::descriptor_colors().component,
    );
    let red: Vec<usize> = (0..table.n_tracks())
        .filter(|&p| rgb[p][0] > rgb[p][1])
        .collect();
    assert_eq!(red, result.outlier_tracks);
    let kept_entries: usize = result
        .kept_frames
        .iter()
        .map(|&f| {
            result
                .kept_tracks
                .iter()
                .filter(|&&p| table.is_visible(f, p))
                .count()
        })
        .sum();
    assert_eq!(
        c.get(paths::RESIDUAL_ARROWS, "Arrows2D:vectors").total(),
        kept_entries
    );
    assert_eq!(c.get(paths::SUMMARY, "TextDocument:text").rows(), 1);
    std::fs::remove_dir_all(&dir).ok();
}

/// A run that fails before its fit is chosen still records its input and the error, and
/// the thread that waits for the fit's frames and tracks does not hang.
#[test]
fn reconstruct_recorded_records_a_failed_run() {
    // Two tracks cannot be factorized: the pipeline fails before the factorization.
    let mut table = TrackTable::new((0..5).map(Id::Int).collect(), (0..2).map(Id::Int).collect());
    for f in 0..5 {
        for p in 0..2 {
            table.set(f, p, f as f64 + 3.0 * p as f64, p as f64);
        }
    }
    let (dir, path, rec) = temp_recording("fail");
    let err = recording::reconstruct_recorded(Some(&rec), &table, &Config::default());
    assert!(err.is_err(), "a 5 × 2 table reconstructs?");
    drop(rec);
    let c = read_rrd(&path);
    assert_eq!(c.get(paths::TRACKS, "Points2D:positions").total(), 10);
    assert_eq!(c.get(paths::LOG_ERRORS, "TextLog:text").rows(), 1);
    assert!(
        !c.columns
            .contains_key(&(paths::W.to_string(), "Tensor:data".to_string()))
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Residual arrows go out in blocks of frames; split into many chunks they are still one
/// row per kept frame, in frame order, each arrow from the observation to the prediction.
#[test]
fn residual_arrows_in_many_chunks_keep_every_frame() {
    let (table, n_used) = table();
    let nf = table.n_frames();
    let result = Reconstruction::from_tracks(&table, &Config::default()).unwrap();
    let (dir, path, rec) = temp_recording("arrows");
    let options = recording::RecordingOptions {
        residual_arrows_per_chunk: 2 * n_used + 1,
        ..Default::default()
    };
    recording::log_reconstruction_with(&rec, &table, &result, &options).unwrap();
    drop(rec);
    let c = read_rrd(&path);
    let arrows = c.get(paths::RESIDUAL_ARROWS, "Arrows2D:vectors");
    assert_eq!((arrows.rows(), arrows.total()), (nf, nf * n_used));
    assert_eq!(arrows.times["frame"], (0..nf as i64).collect::<Vec<_>>());
    let chunks: Vec<&Chunk> = c
        .chunks
        .iter()
        .filter(|ch| ch.entity_path().to_string().trim_start_matches('/') == paths::RESIDUAL_ARROWS)
        .collect();
    assert_eq!(chunks.len(), nf.div_ceil(2), "two frames per chunk");
    let (origins, vectors): (Vec<[f32; 2]>, Vec<[f32; 2]>) = chunks
        .iter()
        .flat_map(|ch| {
            let o = ch
                .iter_component::<rerun::components::Position2D>(
                    rerun::Arrows2D::descriptor_origins().component,
                )
                .flat_map(|row| row.iter().map(|p| [p.x(), p.y()]).collect::<Vec<_>>())
                .collect::<Vec<_>>();
            let v = ch
                .iter_component::<rerun::components::Vector2D>(
                    rerun::Arrows2D::descriptor_vectors().component,
                )
                .flat_map(|row| row.iter().map(|v| [v.x(), v.y()]).collect::<Vec<_>>())
                .collect::<Vec<_>>();
            o.into_iter().zip(v)
        })
        .unzip();
    let mut k = 0;
    for (kf, &f) in result.kept_frames.iter().enumerate() {
        for (kp, &p) in result.kept_tracks.iter().enumerate() {
            let [x, y] = table.get(f, p).unwrap();
            let q = result.model.project(kf, kp);
            assert_eq!(origins[k], [x as f32, y as f32]);
            assert_eq!(vectors[k], [(q[0] - x) as f32, (q[1] - y) as f32]);
            k += 1;
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn summary_names_the_choices() {
    let (table, _) = table();
    let result = Reconstruction::from_tracks(&table, &Config::default()).unwrap();
    let md = recording::summary_markdown(&result);
    for needle in [
        "## Input",
        "## Choices",
        "## Timings",
        "## Warnings",
        "σ4/σ3",
    ] {
        assert!(md.contains(needle), "{needle} missing from\n{md}");
    }
    assert!(md.contains(&format!("{} frames × {} tracks", 9, 32)));
    assert!(md.contains("set aside"));
}

/// Runs the `rank3` binary and asserts that it succeeded.
fn rank3_ok<S: AsRef<std::ffi::OsStr>>(args: impl IntoIterator<Item = S>) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rank3"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn cli_rrd_flag_records_synth_and_reconstruct() {
    let dir = std::env::temp_dir().join(format!("rank3-recording-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let run = |args: &[&str]| rank3_ok(args);
    let d = dir.to_str().unwrap();
    run(&[
        "synth",
        "--out",
        &format!("{d}/scene"),
        "--frames",
        "8",
        "--points",
        "25",
        "--rrd",
        &format!("{d}/rrd/synth.rrd"), // the directory is created
    ]);
    run(&[
        "reconstruct",
        &format!("{d}/scene/tracks.csv"),
        "--out",
        &format!("{d}/out"),
        "--rrd",
        &format!("{d}/run.rrd"),
    ]);
    let synth = read_rrd(&dir.join("rrd/synth.rrd"));
    assert_eq!(synth.get(paths::TRACKS, "Points2D:positions").rows(), 8);
    assert_eq!(
        synth.get(paths::TRUTH_POINTS, "Points3D:positions").total(),
        25
    );
    assert_eq!(synth.get("truth/camera", "Transform3D:mat3x3").rows(), 8);
    let run = read_rrd(&dir.join("run.rrd"));
    assert_eq!(run.get(paths::POINTS, "Points3D:positions").total(), 25);
    assert_eq!(run.get(paths::CAMERA, "Transform3D:mat3x3").rows(), 8);
    assert_eq!(run.get(paths::SUMMARY, "TextDocument:text").rows(), 1);
    // A bad destination is a clean error, not a panic.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rank3"))
        .args([
            "reconstruct",
            &format!("{d}/scene/tracks.csv"),
            "--out",
            &format!("{d}/out2"),
            "--rrd",
            &format!("{d}/scene/tracks.csv/x.rrd"),
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).starts_with("error: "));
    std::fs::remove_dir_all(&dir).ok();
}

/// One viewer layout (blueprint) saved in a recording.
#[derive(Default, Debug)]
struct SavedBlueprint {
    /// View blueprint path → (class, origin).
    views: BTreeMap<String, (String, String)>,
    /// The timeline the time panel opens on.
    timeline: Option<String>,
    /// View blueprint path → the `EyeControls3D` (position, look target) it opens with.
    eyes: BTreeMap<String, ([f32; 3], [f32; 3])>,
    /// Sent complete and activated.
    activated: bool,
}

impl SavedBlueprint {
    /// The (class, origin) of every view.
    fn view_list(&self) -> Vec<(String, String)> {
        self.views.values().cloned().collect()
    }

    /// The eye (position, look target) of the view with origin `origin`.
    fn eye_of(&self, origin: &str) -> Option<([f32; 3], [f32; 3])> {
        let (path, _) = self.views.iter().find(|(_, (_, o))| o == origin)?;
        self.eyes.get(path).copied()
    }
}

/// The viewer layouts (blueprints) saved in `path`, in the order they were sent (the last
/// activated one is the layout the viewer opens with).
fn saved_blueprints(path: &Path) -> Vec<SavedBlueprint> {
    use rerun::external::arrow::array::{Array as _, StringArray};
    let file = std::fs::File::open(path).unwrap();
    let mut order: Vec<String> = Vec::new();
    let mut blueprints = BTreeMap::<String, SavedBlueprint>::new();
    for msg in DecoderApp::decode_lazy(BufReader::new(file)) {
        match msg.unwrap() {
            LogMsg::BlueprintActivationCommand(cmd) => {
                let id = format!("{:?}", cmd.blueprint_id);
                blueprints.entry(id).or_default().activated |= cmd.make_active;
            }
            LogMsg::ArrowMsg(store, arrow) if store.is_blueprint() => {
                let id = format!("{store:?}");
                if !order.contains(&id) {
                    order.push(id.clone());
                }
                let bp = blueprints.entry(id).or_default();
                let chunk = Chunk::from_arrow_msg(&arrow).unwrap();
                let entity = chunk.entity_path().to_string();
                let entity = entity.trim_start_matches('/');
                if let Some(view) = entity.strip_suffix("/EyeControls3D") {
                    let id = |name: &str| {
                        chunk
                            .components()
                            .0
                            .values()
                            .find(|c| c.descriptor.component.as_str() == name)
                            .map(|c| c.descriptor.component)
                    };
                    let point = |name: &str| {
                        let id = id(name).unwrap_or_else(|| panic!("{name} missing"));
                        let p = chunk
                            .iter_component::<Position3D>(id)
                            .next()
                            .and_then(|row| row.first().copied())
                            .unwrap_or_else(|| panic!("{name} empty"));
                        [p.x(), p.y(), p.z()]
                    };
                    bp.eyes.insert(
                        format!("/{view}"),
                        (
                            point("EyeControls3D:position"),
                            point("EyeControls3D:look_target"),
                        ),
                    );
                    continue;
                }
                for col in chunk.components().0.values() {
                    let field = col.descriptor.component.to_string();
                    let values = col.list_array.values();
                    let Some(text) = values.as_any().downcast_ref::<StringArray>() else {
                        continue;
                    };
                    if field == "TimePanelBlueprint:timeline" {
                        bp.timeline = Some(text.value(0).to_string());
                    }
                    if !entity.starts_with("view/") {
                        continue;
                    }
                    let view = bp.views.entry(format!("/{entity}")).or_default();
                    match field.as_str() {
                        "ViewBlueprint:class_identifier" => view.0 = text.value(0).to_string(),
                        "ViewBlueprint:space_origin" => view.1 = text.value(0).to_string(),
                        _ => {}
                    }
                }
            }
            _ => {}
        }
    }
    order
        .into_iter()
        .filter_map(|id| blueprints.remove(&id))
        .collect()
}

/// The views (class, origin) of the viewer layout (blueprint) saved in `path`, and whether
/// the blueprint is sent complete and activated.
fn saved_layout(path: &Path) -> (Vec<(String, String)>, bool) {
    let last = saved_blueprints(path)
        .into_iter()
        .rev()
        .find(|b| b.activated)
        .expect("no activated layout");
    (last.view_list(), last.activated)
}

/// The layout the viewer opens `path` with: the last activated one.
fn opening_layout(path: &Path) -> SavedBlueprint {
    saved_blueprints(path)
        .into_iter()
        .rev()
        .find(|b| b.activated)
        .expect("no activated layout")
}

/// `rank3 reconstruct --rrd` saves a viewer layout with the file: a 2D view of the image
/// plane, 3D views of the metric and affine structure, W as a tensor, and the bar charts,
/// time series and texts, each on its entity path. `rank3 synth` adds the ground truth.
#[test]
fn cli_recordings_carry_a_viewer_layout() {
    let dir = std::env::temp_dir().join(format!("rank3-recording-layout-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let d = dir.display().to_string();
    synth_small_run_scene(&d);
    rank3_ok([
        "reconstruct",
        &format!("{d}/scene/tracks.csv"),
        "--out",
        &format!("{d}/out"),
        "--rrd",
        &format!("{d}/run.rrd"),
    ]);
    let (views, activated) = saved_layout(&dir.join("run.rrd"));
    assert!(activated, "the layout is not activated");
    let view = |class: &str, origin: &str| (class.to_string(), origin.to_string());
    for want in [
        view("2D", "/image"),
        view("3D", "/world"),
        view("3D", "/affine"),
        view("Tensor", &format!("/{}", paths::W)),
        view("2D", &format!("/{}", paths::VISIBILITY)),
        view("BarChart", &format!("/{}", paths::SINGULAR_VALUES)),
        view("BarChart", &format!("/{}", paths::EIGENVALUES)),
        view("BarChart", &format!("/{}", paths::POINT_RMS)),
        // The solvers' quantities each on their own axis: cost and λ as log₁₀.
        view("TimeSeries", &format!("/{}", paths::SOLVER_LOG10_COST)),
        view("TimeSeries", &format!("/{}", paths::SOLVER_LOG10_LAMBDA)),
        view("TimeSeries", &format!("/{}", paths::SOLVER_RMS)),
        view("TimeSeries", &format!("/{}", paths::SOLVER_INLIERS)),
        view("TimeSeries", &format!("/{}", paths::FRAME_RMS)),
        view("TextDocument", &format!("/{}", paths::SUMMARY)),
        view("TextLog", "/log"),
    ] {
        assert!(views.contains(&want), "{want:?} not in {views:?}");
    }
    assert!(!views.iter().any(|v| v.1 == "/truth"), "{views:?}");
    // No plot mixes the solvers' quantities on one linear axis.
    assert!(
        !views
            .iter()
            .any(|v| v.0 == "TimeSeries" && (v.1 == "/solver" || v.1 == "/")),
        "{views:?}"
    );
    let c = read_rrd(&dir.join("run.rrd"));
    for quantity in [paths::SOLVER_LOG10_COST, paths::SOLVER_RMS] {
        assert!(
            c.columns
                .keys()
                .any(|(e, _)| e.starts_with(&format!("{quantity}/lm-refine/"))),
            "no {quantity} series of the refinement"
        );
    }
    // The layout the viewer opens: on the `stage` timeline, the 3D views framed on their
    // points (the eye looks at the points' centroid from about twice their radius).
    let layout = opening_layout(&dir.join("run.rrd"));
    assert_eq!(layout.timeline.as_deref(), Some("stage"));
    let points = c.positions3(paths::POINTS);
    assert_eq!(points.len(), 20);
    let n = points.len() as f32;
    let centroid: [f32; 3] = std::array::from_fn(|a| points.iter().map(|p| p[a]).sum::<f32>() / n);
    let radius = points
        .iter()
        .map(|p| {
            (0..3)
                .map(|a| (p[a] - centroid[a]).powi(2))
                .sum::<f32>()
                .sqrt()
        })
        .fold(0.0, f32::max);
    let (eye, target) = layout.eye_of("/world").expect("the metric view has no eye");
    let dist = |a: [f32; 3], b: [f32; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt();
    assert!(
        dist(target, centroid) < 1e-3 * radius.max(1e-6),
        "{target:?} vs {centroid:?}"
    );
    let eye_distance = dist(eye, target);
    assert!(
        eye_distance > 0.5 * radius && eye_distance < 4.0 * radius,
        "eye {eye_distance} from the centroid, radius {radius}"
    );
    assert!(
        layout.eye_of("/affine").is_some(),
        "the affine view has no eye"
    );
    rank3_ok([
        "synth",
        "--out",
        &format!("{d}/scene2"),
        "--frames",
        "6",
        "--points",
        "20",
        "--rrd",
        &format!("{d}/synth.rrd"),
    ]);
    let (views, _) = saved_layout(&dir.join("synth.rrd"));
    assert!(views.contains(&view("3D", "/truth")), "{views:?}");
    assert!(
        opening_layout(&dir.join("synth.rrd"))
            .eye_of("/truth")
            .is_some(),
        "the truth view has no eye"
    );
    assert!(views.contains(&view("2D", "/image")), "{views:?}");
    assert!(!views.iter().any(|v| v.1 == "/world"), "{views:?}");
    std::fs::remove_dir_all(&dir).ok();
}

/// The Rerun CLI 0.36.3 (`$RERUN_BIN` or `rerun` on PATH), or `None` with a message saying
/// why the calling test is skipped. Install it with `pip install rerun-sdk==0.36.3` or
/// `cargo install rerun-cli --version 0.36.3 --locked` (`.ci/run` does the former).
fn rerun_cli() -> Option<String> {
    let bin = std::env::var("RERUN_BIN").unwrap_or_else(|_| "rerun".into());
    let version = std::process::Command::new(&bin)
        .arg("--version")
        .env("RERUN_ANALYTICS", "0")
        .output();
    let version = match version {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
        _ => {
            eprintln!("SKIPPED: no `rerun` CLI on PATH (pip install rerun-sdk==0.36.3)");
            return None;
        }
    };
    if !version.contains(" 0.36.3 ") {
        eprintln!("SKIPPED: `rerun` is not 0.36.3 ({})", version.trim());
        return None;
    }
    Some(bin)
}

/// The viewer's own loader (`rerun rrd verify`, Rerun CLI 0.36.3) accepts the file. Skipped
/// with a message when the Rerun CLI is missing ([`rerun_cli`]).
#[test]
fn rerun_viewer_verifies_the_recording() {
    let Some(bin) = rerun_cli() else { return };
    let (table, _) = table();
    let (dir, path, rec) = temp_recording("verify");
    let result = recording::reconstruct_recorded(Some(&rec), &table, &Config::default()).unwrap();
    let n = table.n_tracks();
    recording::log_robust(&rec, &table, &vec![true; n], &[(0, 0)], &[n]).unwrap();
    drop(rec);
    assert_eq!(result.kept_frames.len(), table.n_frames());
    viewer_verifies(&bin, &path);
    std::fs::remove_dir_all(&dir).ok();
}

/// `rerun rrd verify PATH` (the viewer's own loader) succeeds.
fn viewer_verifies(bin: &str, path: &std::path::Path) {
    let out = std::process::Command::new(bin)
        .args(["rrd", "verify"])
        .arg(path)
        .env("RERUN_ANALYTICS", "0")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rerun rrd verify failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `rank3 synth --frames 6 --points 20` into `{dir}/scene`: the scene of the small CLI run
/// ([`SMALL_RUN_EXPECTED`]).
fn synth_small_run_scene(dir: &str) {
    rank3_ok([
        "synth",
        "--out",
        &format!("{dir}/scene"),
        "--frames",
        "6",
        "--points",
        "20",
    ]);
}

/// What the small CLI run (`synth --frames 6 --points 20`, then `reconstruct`) must put in a
/// recording: (entity, component, count rows instead of instances, count).
const SMALL_RUN_EXPECTED: [(&str, &str, bool, usize); 4] = [
    (paths::TRACKS, "Points2D:positions", false, 6 * 20),
    (paths::POINTS, "Points3D:positions", false, 20),
    (paths::CAMERA, "Transform3D:mat3x3", true, 6),
    (paths::SUMMARY, "TextDocument:text", true, 1),
];

/// Polls `received`, the file a headless Rerun server saves what it receives to (it writes
/// each message as it arrives), until it holds everything in [`SMALL_RUN_EXPECTED`] or 60 s
/// have passed; then kills the server's process group `pgid` (the pip-installed `rerun` is a
/// Python wrapper around the binary, and a background CI job may ignore SIGINT, so no
/// Ctrl-C) and returns the counts found, in the order of [`SMALL_RUN_EXPECTED`].
fn await_small_run(received: &Path, pgid: u32) -> Result<Vec<Option<usize>>, String> {
    let count = |c: &Contents, entity: &str, component: &str, rows: bool| {
        c.columns
            .get(&(entity.to_string(), component.to_string()))
            .map(|col| if rows { col.rows() } else { col.total() })
    };
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let last = loop {
        let state = try_read_rrd(received).map(|c| {
            SMALL_RUN_EXPECTED
                .iter()
                .map(|&(e, comp, rows, _)| count(&c, e, comp, rows))
                .collect::<Vec<_>>()
        });
        let done = state.as_ref().is_ok_and(|got| {
            got.iter()
                .zip(&SMALL_RUN_EXPECTED)
                .all(|(g, e)| *g == Some(e.3))
        });
        if done || std::time::Instant::now() > deadline {
            break state;
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    // SAFETY: kill(2) with a negative pid signals that process group; no memory is involved.
    unsafe {
        libc::kill(-(pgid as libc::pid_t), libc::SIGKILL);
    }
    last
}

/// `rank3 reconstruct --connect URL` streams the recording to a running Rerun server: a
/// headless `rerun --port P --save FILE` (the Rerun CLI 0.36.3, skipped without it) receives
/// it and saves what arrived, which is then decoded and checked.
#[test]
fn cli_connect_streams_to_a_rerun_server() {
    let Some(bin) = rerun_cli() else { return };
    let dir = std::env::temp_dir().join(format!("rank3-recording-connect-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let d = dir.display().to_string();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let received = dir.join("received.rrd");
    let mut server = std::process::Command::new(&bin)
        .args(["--port", &port.to_string(), "--save"])
        .arg(&received)
        .env("RERUN_ANALYTICS", "0")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .process_group(0)
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            std::time::Instant::now() < deadline,
            "the Rerun server did not listen"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    synth_small_run_scene(&d);
    rank3_ok([
        "reconstruct",
        &format!("{d}/scene/tracks.csv"),
        "--out",
        &format!("{d}/out"),
        "--connect",
        &format!("rerun+http://127.0.0.1:{port}/proxy"),
    ]);
    let got = await_small_run(&received, server.id());
    let _ = server.wait();
    assert_eq!(
        got,
        Ok(SMALL_RUN_EXPECTED.iter().map(|e| Some(e.3)).collect()),
        "received vs expected (tracks, points, cameras, summary)"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `rank3 reconstruct --spawn` starts a viewer and streams the recording to it. The SDK
/// spawns `rerun --port=9876 --memory-limit=… --expect-data-soon` from PATH; here PATH leads
/// first to a stand-in script that runs the real Rerun CLI 0.36.3 (skipped without it) as a
/// headless `rerun --port 9876 --save FILE` instead of a window, so the test checks what the
/// spawned process received, not the viewer's drawing. Skipped, saying so, when port 9876
/// is already taken (the SDK would then stream to whatever listens there).
/// The spawn tests share the SDK's spawn port (9876): they run one at a time.
static SPAWN_PORT: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// `bin` (a command name or path) as an absolute path, looked up on PATH.
fn absolute_command(bin: String) -> String {
    if bin.contains('/') {
        return bin;
    }
    std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())
        .map(|d| d.join(&bin))
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("{bin} is not on PATH"))
        .display()
        .to_string()
}

/// Writes `script` as a stand-in `rerun` in `dir/bin` and runs `rank3 reconstruct
/// {dir}/scene/tracks.csv --camera orthographic --out {dir}/out --spawn` with that directory first on PATH (the
/// SDK spawns `rerun` from PATH) and `envs` set.
fn reconstruct_spawning_stand_in(
    dir: &Path,
    script: &str,
    envs: &[(&str, &std::ffi::OsStr)],
) -> std::process::Output {
    let stand_in = dir.join("bin");
    std::fs::create_dir_all(&stand_in).unwrap();
    let file = stand_in.join("rerun");
    std::fs::write(&file, script).unwrap();
    std::fs::set_permissions(&file, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let mut path = vec![stand_in];
    path.extend(std::env::split_paths(
        &std::env::var_os("PATH").unwrap_or_default(),
    ));
    let d = dir.display();
    std::process::Command::new(env!("CARGO_BIN_EXE_rank3"))
        .args(["reconstruct", &format!("{d}/scene/tracks.csv")])
        // The affine camera: the viewer screenshots the window once its first frames are
        // drawn, and the result must have arrived by then (the automatic choice fits the
        // projective camera too, which takes seconds in a debug build).
        .args(["--camera", "orthographic"])
        .args(["--out", &format!("{d}/out"), "--spawn"])
        .env("PATH", std::env::join_paths(path).unwrap())
        .env("RERUN_ANALYTICS", "0")
        .envs(envs.iter().copied())
        .output()
        .unwrap()
}

#[test]
fn cli_spawn_streams_to_the_spawned_viewer() {
    let Some(bin) = rerun_cli() else { return };
    let _port = SPAWN_PORT.lock().unwrap_or_else(|e| e.into_inner());
    if std::net::TcpStream::connect(("127.0.0.1", 9876)).is_ok() {
        eprintln!("SKIPPED: port 9876 is in use (a viewer is running?)");
        return;
    }
    // The real CLI by absolute path: the stand-in below takes the name `rerun` on PATH.
    let real = absolute_command(bin);
    let dir = std::env::temp_dir().join(format!("rank3-recording-spawn-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let d = dir.display().to_string();
    let (received, pid_file) = (dir.join("received.rrd"), dir.join("viewer.pid"));
    synth_small_run_scene(&d);
    // Its own output goes to /dev/null: the spawned process would otherwise hold rank3's
    // stdout/stderr pipes open, and `output()` would wait for it.
    let out = reconstruct_spawning_stand_in(
        &dir,
        r#"#!/bin/sh
if [ "$1" = "--version" ]; then exec "$RANK3_TEST_RERUN" --version; fi
port=
for a in "$@"; do case "$a" in --port=*) port="${a#--port=}" ;; esac; done
echo $$ > "$RANK3_TEST_PID.tmp" && mv "$RANK3_TEST_PID.tmp" "$RANK3_TEST_PID"
exec "$RANK3_TEST_RERUN" --port "$port" --save "$RANK3_TEST_SAVE" >/dev/null 2>&1
"#,
        &[
            ("RANK3_TEST_RERUN", real.as_ref()),
            ("RANK3_TEST_SAVE", received.as_os_str()),
            ("RANK3_TEST_PID", pid_file.as_os_str()),
        ],
    );
    // The spawned process is its own session leader (the SDK detaches it), so its pid is
    // its process group.
    let pid: Option<u32> = std::fs::read_to_string(&pid_file)
        .ok()
        .and_then(|s| s.trim().parse().ok());
    let got = pid.map(|pid| await_small_run(&received, pid));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        got,
        Some(Ok(SMALL_RUN_EXPECTED.iter().map(|e| Some(e.3)).collect())),
        "received by the spawned process vs expected (tracks, points, cameras, summary); None: \
         nothing was spawned"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `rank3 reconstruct --spawn` opens the real Rerun 0.36.3 viewer window, which draws the
/// streamed run. The window lives on a virtual X display (`Xvfb`) and renders with a software
/// Vulkan driver (Mesa's lavapipe); a stand-in `rerun` on PATH runs the real viewer with
/// `--screenshot-to`, so the viewer saves what its window shows and quits. The screenshot
/// must show the run's camera viewing directions, drawn in their colour (60, 90, 255):
/// hundreds of such pixels, where the viewer's welcome screen (no data) has none. Skipped,
/// saying so, without the Rerun CLI, `Xvfb` or a Vulkan driver (`.ci/run` installs them).
#[test]
fn cli_spawn_opens_the_viewer_window() {
    let Some(bin) = rerun_cli() else { return };
    let icds = ["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d"];
    if !icds
        .iter()
        .any(|d| std::fs::read_dir(d).is_ok_and(|mut entries| entries.next().is_some()))
    {
        eprintln!("SKIPPED: no Vulkan driver (apt-get install mesa-vulkan-drivers)");
        return;
    }
    let Some(display) = (90..200).find(|n| !Path::new(&format!("/tmp/.X11-unix/X{n}")).exists())
    else {
        eprintln!("SKIPPED: no free X display number");
        return;
    };
    let xvfb = std::process::Command::new("Xvfb")
        .arg(format!(":{display}"))
        .args(["-screen", "0", "1600x1000x24", "-nolisten", "tcp"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn();
    let mut xvfb = match xvfb {
        Ok(child) => child,
        Err(e) => {
            eprintln!("SKIPPED: cannot start Xvfb ({e}; apt-get install xvfb)");
            return;
        }
    };
    let _port = SPAWN_PORT.lock().unwrap_or_else(|e| e.into_inner());
    let socket = format!("/tmp/.X11-unix/X{display}");
    let started = std::time::Instant::now();
    while !Path::new(&socket).exists() && started.elapsed().as_secs() < 20 {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let real = absolute_command(bin);
    let dir = std::env::temp_dir().join(format!("rank3-recording-window-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // Also the viewer's XDG_RUNTIME_DIR, which must be private.
    std::fs::set_permissions(&dir, std::os::unix::fs::PermissionsExt::from_mode(0o700)).unwrap();
    let d = dir.display().to_string();
    let (shot, pid_file) = (dir.join("window.png"), dir.join("viewer.pid"));
    rank3_ok([
        "synth",
        "--out",
        &format!("{d}/scene"),
        "--frames",
        "30",
        "--points",
        "60",
    ]);
    let display_var = format!(":{display}");
    let out = reconstruct_spawning_stand_in(
        &dir,
        r#"#!/bin/sh
if [ "$1" = "--version" ]; then exec "$RANK3_TEST_RERUN" --version; fi
echo $$ > "$RANK3_TEST_PID.tmp" && mv "$RANK3_TEST_PID.tmp" "$RANK3_TEST_PID"
exec "$RANK3_TEST_RERUN" "$@" --screenshot-to "$RANK3_TEST_SHOT" --window-size 1600x1000 \
  >/dev/null 2>&1
"#,
        &[
            ("DISPLAY", display_var.as_ref()),
            ("XDG_RUNTIME_DIR", dir.as_os_str()),
            ("RANK3_TEST_RERUN", real.as_ref()),
            ("RANK3_TEST_SHOT", shot.as_os_str()),
            ("RANK3_TEST_PID", pid_file.as_os_str()),
        ],
    );
    // The viewer writes the screenshot, then quits; a half-written file fails to decode.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(90);
    let image = loop {
        if let Ok(img) = image::open(&shot) {
            break Some(img.to_rgb8());
        }
        if std::time::Instant::now() > deadline {
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    // The spawned viewer is its own process group (the SDK detaches it).
    if let Some(pid) = std::fs::read_to_string(&pid_file)
        .ok()
        .and_then(|s| s.trim().parse::<i32>().ok())
    {
        // SAFETY: kill(2) with a negative pid signals that process group; no memory involved.
        unsafe { libc::kill(-pid, libc::SIGKILL) };
    }
    xvfb.kill().ok();
    xvfb.wait().ok();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let image = image.expect("the spawned viewer saved no screenshot within 90 s");
    let camera_blue = image
        .pixels()
        .filter(|p| {
            let [r, g, b] = p.0;
            r.abs_diff(60) <= 15 && g.abs_diff(90) <= 15 && b.abs_diff(255) <= 15
        })
        .count();
    eprintln!("the viewer's window shows {camera_blue} pixels of the cameras' blue");
    assert!(
        camera_blue >= 300,
        "the viewer's window shows {camera_blue} pixels of the cameras' blue ({}×{} \
         screenshot at {})",
        image.width(),
        image.height(),
        shot.display()
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `rank3 track --rrd` records the frames it tracked on (JPEG), the tracker's per-frame
/// counts and the resulting tracks.
#[test]
fn cli_track_records_frames_counts_and_tracks() {
    use rank3::tracking::synthetic::{Motion, Sequence, SequenceConfig};
    let dir = std::env::temp_dir().join(format!("rank3-recording-track-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let frames_dir = dir.join("frames");
    std::fs::create_dir_all(&frames_dir).unwrap();
    let nf = 6;
    let seq = Sequence::new(SequenceConfig {
        width: 160,
        height: 120,
        frames: nf,
        motion: Motion {
            translation: [1.5, 0.5],
            ..Motion::default()
        },
        ..SequenceConfig::default()
    });
    for k in 0..nf {
        seq.render(k)
            .save_png(&frames_dir.join(format!("f{k}.png")))
            .unwrap();
    }
    let rrd = dir.join("track.rrd");
    rank3_ok([
        "track".as_ref(),
        frames_dir.as_os_str(),
        "--out".as_ref(),
        dir.join("tracks.csv").as_os_str(),
        "--rrd".as_ref(),
        rrd.as_os_str(),
    ]);
    let table = rank3::TrackTable::read(dir.join("tracks.csv")).unwrap();
    assert!(table.n_tracks() > 10, "{} tracks", table.n_tracks());
    let c = read_rrd(&rrd);
    let frames = c.get(paths::FRAME_IMAGE, "EncodedImage:blob");
    assert_eq!(frames.rows(), nf);
    assert_eq!(frames.times["frame"], (0..nf as i64).collect::<Vec<_>>());
    let alive = c.get(&format!("{}/alive", paths::TRACKING), "Scalars:scalars");
    assert_eq!(alive.rows(), nf);
    assert_eq!(
        c.get(
            &format!("{}/lost/forward_backward", paths::TRACKING),
            "Scalars:scalars"
        )
        .rows(),
        nf
    );
    let tracks = c.get(paths::TRACKS, "Points2D:positions");
    assert_eq!((tracks.rows(), tracks.total()), (nf, table.n_observed()));
    // The recording opens on the `frame` timeline, where its frames, tracks and tracker
    // counts live (on `stage` its plots are empty).
    let layout = opening_layout(&rrd);
    assert_eq!(layout.timeline.as_deref(), Some("frame"));
    assert!(
        layout
            .view_list()
            .contains(&("TimeSeries".to_string(), format!("/{}", paths::TRACKING))),
        "{:?}",
        layout.view_list()
    );
    assert_eq!(
        c.get(paths::TRAJECTORIES, "LineStrips2D:strips").total(),
        table.n_tracks()
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A small strong-perspective scene with missing entries (10 frames × 40 tracks).
fn perspective_scene() -> rank3::synth::SynthScene {
    generate(&SynthConfig {
        camera: rank3::CameraModel::Perspective,
        frames: 10,
        points: 40,
        noise: 0.3,
        missing: 0.3,
        distance: 2.5,
        seed: 3,
        ..Default::default()
    })
    .unwrap()
}
/// The projective camera's stages are recorded: the pOSE and bundle-adjustment iterations,
/// residual arrows to `π(P_f X_p)` for every kept entry, per-frame RMS and the stage table.
#[test]
fn reconstruct_recorded_projective_stages() {
    let scene = perspective_scene();
    let table = &scene.table;
    let (dir, path, rec) = temp_recording("projective");
    let config = Config {
        camera: rank3::CameraModel::Projective,
        robust: None,
        ..Config::default()
    };
    let result = recording::reconstruct_recorded(Some(&rec), table, &config).unwrap();
    drop(rec);
    let p = result.projective.as_ref().expect("projective result");
    let c = read_rrd(&path);
    let kept_entries: usize = result
        .kept_frames
        .iter()
        .map(|&f| {
            result
                .kept_tracks
                .iter()
                .filter(|&&t| table.is_visible(f, t))
                .count()
        })
        .sum();
    assert_eq!(
        c.get(paths::PROJECTIVE_RESIDUALS, "Arrows2D:vectors")
            .total(),
        kept_entries
    );
    assert_eq!(
        c.get(paths::PROJECTIVE_FRAME_RMS, "Scalars:scalars")
            .total(),
        result.kept_frames.len()
    );
    assert_eq!(
        c.get(paths::PROJECTIVE_STAGES, "TextDocument:text").rows(),
        1
    );
    for st in &p.stages {
        // One cost scalar per accepted step plus the start.
        let cost = c.get(
            &format!("{}/{}/run0", paths::SOLVER_COST, st.stage),
            "Scalars:scalars",
        );
        assert!(
            cost.total() >= 2,
            "{}: {} cost rows",
            st.stage,
            cost.total()
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The perspective camera's recording: residual arrows, the Euclidean points, one pinhole
/// (with the estimated focal length) and pose per fitted frame, static frustums, the report.
#[test]
fn reconstruct_recorded_perspective_frustums() {
    let scene = perspective_scene();
    let table = &scene.table;
    let (dir, path, rec) = temp_recording("perspective");
    let mut config = Config {
        camera: rank3::CameraModel::Perspective,
        robust: None,
        ..Config::default()
    };
    config.perspective.intrinsics.image_size = Some([641, 481]);
    let result = recording::reconstruct_recorded(Some(&rec), table, &config).unwrap();
    drop(rec);
    let p = result.perspective.as_ref().expect("perspective result");
    let c = read_rrd(&path);
    assert_eq!(
        c.get(paths::PERSPECTIVE_POINTS, "Points3D:positions")
            .total(),
        result.kept_tracks.len()
    );
    let nf = result.kept_frames.len();
    let pin = c.get(paths::PERSPECTIVE_CAMERA, "Pinhole:image_from_camera");
    assert_eq!(pin.rows(), nf, "one pinhole per fitted frame");
    assert_eq!(pin.times["frame"].len(), nf);
    assert_eq!(
        c.get(paths::PERSPECTIVE_CAMERA, "Transform3D:translation")
            .rows(),
        nf
    );
    let f0 = c.get(
        &format!("{}/0", paths::PERSPECTIVE_FRUSTUMS),
        "Pinhole:image_from_camera",
    );
    assert!(f0.is_static);
    assert_eq!(
        c.get(paths::PERSPECTIVE_REPORT, "TextDocument:text").rows(),
        1
    );
    assert!(p.intrinsics.focal_px > 0.0);
    // The viewer's own loader accepts the pinholes and frustums (when the CLI is there).
    if let Some(bin) = rerun_cli() {
        viewer_verifies(&bin, &path);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `reconstruct --objects auto --rrd`: trajectories and per-frame points coloured by object
/// in the image view, outliers in red, each object's points and cameras under `objects/<k>`
/// in their own 3D view, a summary; the viewer's loader accepts the file.
#[test]
fn cli_objects_recording() {
    let dir = std::env::temp_dir().join(format!("rank3-recording-objects-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let d = dir.display().to_string();
    rank3_ok([
        "synth",
        "--out",
        &format!("{d}/scene"),
        "--frames",
        "16",
        "--points",
        "120",
        "--camera",
        "orthographic",
        "--objects",
        "0.35:rotating",
        "--outliers",
        "0.05",
        "--outlier-kind",
        "random-walk",
    ]);
    rank3_ok([
        "reconstruct",
        &format!("{d}/scene/tracks.csv"),
        "--out",
        &format!("{d}/out"),
        "--objects",
        "auto",
        "--camera",
        "orthographic",
        "--rrd",
        &format!("{d}/run.rrd"),
    ]);
    let path = dir.join("run.rrd");
    let run = read_rrd(&path);
    for k in 0..2 {
        assert!(
            run.get(
                &format!("image/objects/{k}/trajectories"),
                "LineStrips2D:strips"
            )
            .total()
                > 20
        );
        assert_eq!(
            run.get(&format!("image/objects/{k}"), "Points2D:positions")
                .rows(),
            16
        );
        assert!(
            run.get(&format!("objects/{k}/points"), "Points3D:positions")
                .total()
                > 20
        );
    }
    assert_eq!(
        run.get("image/objects/outliers/trajectories", "LineStrips2D:strips")
            .total(),
        6
    );
    assert_eq!(run.get("objects/summary", "TextDocument:text").rows(), 1);
    let (views, _) = saved_layout(&path);
    assert!(
        views
            .iter()
            .any(|(class, origin)| class == "3D" && origin == "/objects"),
        "{views:?}"
    );
    if let Some(bin) = rerun_cli() {
        viewer_verifies(&bin, &path);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The textured mesh is logged beside the points it was built on (Mesh3D with positions,
/// triangles, normals, texture coordinates and the atlas as albedo texture), with its report;
/// the viewer's loader accepts it.
#[test]
fn mesh_is_recorded_with_its_texture() {
    let (table, _) = table();
    let result = rank3::Reconstruction::from_tracks(&table, &Config::default()).unwrap();
    let scene = rank3::mesh::Scene::from_reconstruction(&result, &table, None).unwrap();
    let ids = table.frame_ids().to_vec();
    let mut k = 0;
    let mut feed = || {
        k += 1;
        Ok(ids.get(k - 1).map(|id| {
            let img = image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([x as u8, y as u8, 90]));
            (id.clone(), img)
        }))
    };
    let mesh =
        rank3::mesh::build(&scene, &rank3::mesh::MeshConfig::default(), Some(&mut feed)).unwrap();
    assert!(mesh.triangles.len() > 10, "{:?}", mesh.report);
    let (dir, path, rec) = temp_recording("mesh");
    recording::log_mesh(&rec, &result, &mesh).unwrap();
    drop(rec);
    let c = read_rrd(&path);
    let n = mesh.positions.len();
    let get = |component: &str| c.get(paths::MESH, &format!("Mesh3D:{component}"));
    assert_eq!(get("vertex_positions").total(), n);
    assert_eq!(get("vertex_normals").total(), n);
    assert_eq!(get("vertex_texcoords").total(), n);
    assert_eq!(get("triangle_indices").total(), mesh.triangles.len());
    assert_eq!(get("albedo_texture_buffer").rows(), 1);
    assert!(get("vertex_positions").is_static);
    assert_eq!(c.get(paths::MESH_REPORT, "TextDocument:text").rows(), 1);
    if let Some(bin) = rerun_cli() {
        viewer_verifies(&bin, &path);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `--connect` to a port where no viewer listens: the reconstruction's files are written,
/// and the run says the recording did not reach its viewer and exits non-zero.
#[test]
fn cli_connect_to_a_dead_port_is_an_error() {
    let dir = std::env::temp_dir().join(format!("rank3-recording-dead-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let tracks =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/toy-house/tracks.csv");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rank3"))
        .arg("reconstruct")
        .arg(&tracks)
        .arg("--out")
        .arg(&dir)
        .args([
            "--camera",
            "orthographic",
            "--connect",
            "rerun+http://127.0.0.1:9/proxy",
        ])
        .env("RERUN_ANALYTICS", "0")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "exit 0: {err}");
    assert!(err.contains("was not completed"), "{err}");
    assert!(dir.join("reconstruction.json").exists());
    std::fs::remove_dir_all(&dir).ok();
}
