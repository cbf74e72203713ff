//! Synthetic scenes with ground truth: the basis of the tests and the README's first example.
//!
//! A shape (toy house, random cloud, cube) is seen by a (scaled) orthographic camera that
//! moves on a turntable or along a handheld arc. Image noise, missing entries (each track
//! visible in one contiguous window, as a tracker loses points), outlier tracks and gross
//! per-entry errors can be added; the truth records which tracks/entries are corrupted.
//!
//! Projection (the same model as [`crate::MetricModel`]):
//! `[x, y] = s_f R_f[0..2] X_p + t_f`.

use nalgebra::{Rotation3, Vector2, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::tracks::{Id, TrackTable};
use crate::{CameraModel, Error, MetricModel, Result};

/// Scene shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// A toy house: a box (walls at right angles) with a gable roof; points on the walls
    /// and roof.
    #[default]
    House,
    /// Gaussian point cloud with anisotropic spread.
    Cloud,
    /// Points on the faces of a cube.
    Cube,
}

/// Camera motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Motion {
    /// The object turns about its vertical axis by 90° in front of a camera tilted down by
    /// 20°.
    #[default]
    Turntable,
    /// A handheld camera on an arc: yaw sweeps 60°, with smooth pitch and roll wobble.
    HandheldArc,
}

/// Kind of outlier track.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutlierKind {
    /// Cycle through the kinds below.
    #[default]
    Mixed,
    /// A random walk from a true start position.
    RandomWalk,
    /// A point of a second rigid object that moves differently.
    SecondObject,
    /// A point that slides along an image line (as on an edge).
    Sliding,
}

/// Settings of a synthetic scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SynthConfig {
    pub shape: Shape,
    pub motion: Motion,
    pub camera: CameraModel,
    /// Number of frames F. Default 30.
    pub frames: usize,
    /// Number of tracks N. Default 200.
    pub points: usize,
    /// Image noise standard deviation, pixels. Default 0.5.
    pub noise: f64,
    /// Target fraction of missing (frame, track) entries in [0, 0.9]; each track is visible
    /// in one contiguous window of at least `min_track_length` frames. Default 0.
    pub missing: f64,
    /// Shortest visible window when `missing > 0`. Default 3.
    pub min_track_length: usize,
    /// Fraction of tracks replaced by outlier tracks, in [0, 1). Default 0.
    pub outliers: f64,
    pub outlier_kind: OutlierKind,
    /// Fraction of observed entries (of inlier tracks) given a gross error of 15–60 px.
    /// Default 0.
    pub gross: f64,
    /// Total rotation of the motion in degrees (turntable turn, arc yaw sweep); `None`
    /// for the motion's default (90° turntable, 60° arc). Small sweeps make the metric
    /// upgrade ill-conditioned.
    pub sweep_deg: Option<f64>,
    /// Approximate image extent of the object, pixels. Default 400.
    pub image_size: f64,
    pub seed: u64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            shape: Shape::House,
            motion: Motion::Turntable,
            camera: CameraModel::Orthographic,
            frames: 30,
            points: 200,
            noise: 0.5,
            missing: 0.0,
            min_track_length: 3,
            outliers: 0.0,
            outlier_kind: OutlierKind::Mixed,
            gross: 0.0,
            sweep_deg: None,
            image_size: 400.0,
            seed: 0,
        }
    }
}

/// A generated scene: the observed table and the truth.
#[derive(Debug, Clone)]
pub struct SynthScene {
    pub config: SynthConfig,
    pub table: TrackTable,
    /// Noise-free projections of the true model for every entry (outlier tracks: the
    /// projection of the true point they replaced).
    pub truth: MetricModel,
    /// Which tracks are outliers, and of which kind.
    pub outlier_tracks: Vec<Option<OutlierKind>>,
    /// Observed entries with a gross error, as (frame, track) indices.
    pub gross_entries: Vec<(usize, usize)>,
}

#[derive(Serialize)]
struct TruthFrame {
    frame: usize,
    rotation: [[f64; 3]; 3],
    translation: [f64; 2],
    scale: f64,
}

#[derive(Serialize)]
struct TruthPoint {
    track: usize,
    xyz: [f64; 3],
    outlier: bool,
    outlier_kind: Option<OutlierKind>,
}

#[derive(Serialize)]
struct TruthEntry {
    frame: usize,
    track: usize,
}

#[derive(Serialize)]
struct TruthFile<'a> {
    config: &'a SynthConfig,
    camera_model: CameraModel,
    frames: Vec<TruthFrame>,
    points: Vec<TruthPoint>,
    gross_entries: Vec<TruthEntry>,
    observations: usize,
    fill: f64,
}

impl SynthScene {
    /// `truth.json`: config, true cameras and points, corrupted tracks and entries.
    pub fn truth_json(&self) -> String {
        let m = &self.truth;
        let file = TruthFile {
            config: &self.config,
            camera_model: self.config.camera,
            frames: (0..m.n_frames())
                .map(|f| {
                    let r = m.rotations[f].matrix();
                    TruthFrame {
                        frame: f,
                        rotation: std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)])),
                        translation: [m.translations[f][0], m.translations[f][1]],
                        scale: m.scales[f],
                    }
                })
                .collect(),
            points: (0..m.n_points())
                .map(|p| TruthPoint {
                    track: p,
                    xyz: [m.points[p][0], m.points[p][1], m.points[p][2]],
                    outlier: self.outlier_tracks[p].is_some(),
                    outlier_kind: self.outlier_tracks[p],
                })
                .collect(),
            gross_entries: self
                .gross_entries
                .iter()
                .map(|&(frame, track)| TruthEntry { frame, track })
                .collect(),
            observations: self.table.n_observed(),
            fill: self.table.fill(),
        };
        serde_json::to_string_pretty(&file).unwrap_or_default()
    }
}

fn check(cfg: &SynthConfig) -> Result<()> {
    let bad = |field: &'static str, message: String| Err(Error::InvalidConfig { field, message });
    if cfg.frames < 3 {
        return bad("frames", format!("{} < 3", cfg.frames));
    }
    if cfg.points < 4 {
        return bad("points", format!("{} < 4", cfg.points));
    }
    if !(cfg.noise >= 0.0 && cfg.noise.is_finite()) {
        return bad(
            "noise",
            format!("{} is not a non-negative number", cfg.noise),
        );
    }
    if !(0.0..=0.9).contains(&cfg.missing) {
        return bad("missing", format!("{} is not in [0, 0.9]", cfg.missing));
    }
    if cfg.min_track_length < 2 || cfg.min_track_length > cfg.frames {
        return bad(
            "min_track_length",
            format!("{} is not in [2, frames]", cfg.min_track_length),
        );
    }
    if !(0.0..1.0).contains(&cfg.outliers) {
        return bad("outliers", format!("{} is not in [0, 1)", cfg.outliers));
    }
    if !(0.0..0.5).contains(&cfg.gross) {
        return bad("gross", format!("{} is not in [0, 0.5)", cfg.gross));
    }
    if let Some(s) = cfg.sweep_deg
        && !(s.is_finite() && s.abs() <= 360.0)
    {
        return bad("sweep_deg", format!("{s} is not in [-360, 360]"));
    }
    if !(cfg.image_size > 0.0 && cfg.image_size.is_finite()) {
        return bad("image_size", format!("{} is not positive", cfg.image_size));
    }
    Ok(())
}

fn shape_points(shape: Shape, n: usize, rng: &mut StdRng) -> Vec<Vector3<f64>> {
    let u = |rng: &mut StdRng, a: f64, b: f64| rng.random_range(a..b);
    (0..n)
        .map(|_| match shape {
            Shape::House => {
                // Box 2 (x) × 1.2 (y, up is -y in image terms: y down) × 1.4 (z), roof
                // ridge along x at height 0.6 above the walls.
                let (hw, hd, hh, rh) = (1.0, 0.7, 0.6, 0.6);
                let face = rng.random_range(0..6u32);
                match face {
                    0 | 1 => {
                        let z = if face == 0 { -hd } else { hd };
                        Vector3::new(u(rng, -hw, hw), u(rng, -hh, hh), z)
                    }
                    2 | 3 => {
                        let x = if face == 2 { -hw } else { hw };
                        Vector3::new(x, u(rng, -hh, hh), u(rng, -hd, hd))
                    }
                    _ => {
                        // Roof planes from the wall tops (y = -hh, z = ±hd) to the ridge
                        // (y = -hh - rh, z = 0).
                        let a = u(rng, 0.0, 1.0);
                        let side = if face == 4 { -1.0 } else { 1.0 };
                        Vector3::new(u(rng, -hw, hw), -hh - rh * a, side * hd * (1.0 - a))
                    }
                }
            }
            Shape::Cloud => {
                let g = Normal::new(0.0, 1.0).unwrap_or_else(|_| unreachable!());
                Vector3::new(
                    g.sample(rng) * 1.0,
                    g.sample(rng) * 0.7,
                    g.sample(rng) * 0.5,
                )
            }
            Shape::Cube => {
                let face = rng.random_range(0..6usize);
                let mut v = Vector3::new(u(rng, -1.0, 1.0), u(rng, -1.0, 1.0), u(rng, -1.0, 1.0));
                v[face / 2] = if face % 2 == 0 { -1.0 } else { 1.0 };
                v
            }
        })
        .collect()
}

fn camera_motion(cfg: &SynthConfig) -> (Vec<Rotation3<f64>>, Vec<f64>, Vec<Vector2<f64>>) {
    let f = cfg.frames;
    let mut rots = Vec::with_capacity(f);
    let mut scales = Vec::with_capacity(f);
    let mut trans = Vec::with_capacity(f);
    for k in 0..f {
        let a = k as f64 / (f - 1) as f64; // 0..1
        let r = match cfg.motion {
            Motion::Turntable => {
                let tilt = Rotation3::from_axis_angle(&Vector3::x_axis(), (-20.0f64).to_radians());
                let sweep = cfg.sweep_deg.unwrap_or(90.0);
                let turn = Rotation3::from_axis_angle(&Vector3::y_axis(), (sweep * a).to_radians());
                tilt * turn
            }
            Motion::HandheldArc => {
                let sweep = cfg.sweep_deg.unwrap_or(60.0);
                let w = sweep / 60.0;
                let yaw = (sweep * (a - 0.5)).to_radians();
                let pitch = (w * 10.0 * (2.0 * std::f64::consts::PI * a).sin() - 15.0).to_radians();
                let roll = (w * 5.0 * (3.0 * std::f64::consts::PI * a).cos()).to_radians();
                Rotation3::from_euler_angles(pitch, yaw, roll)
            }
        };
        rots.push(r);
        scales.push(match cfg.camera {
            CameraModel::Orthographic => 1.0,
            // The camera comes closer and goes back: magnification 1 → 1.3 → 1.
            CameraModel::ScaledOrthographic => 1.0 + 0.3 * (std::f64::consts::PI * a).sin(),
        });
        trans.push(Vector2::new(320.0 + 40.0 * a, 240.0 - 25.0 * a));
    }
    (rots, scales, trans)
}

/// Generates a scene. Errors only for out-of-range settings.
///
/// Cost O(F·N).
pub fn generate(cfg: &SynthConfig) -> Result<SynthScene> {
    check(cfg)?;
    let mut rng = StdRng::seed_from_u64(cfg.seed);
    let (f, n) = (cfg.frames, cfg.points);
    let unit = shape_points(cfg.shape, n, &mut rng);
    // Scale so the object spans about image_size pixels.
    let extent = unit
        .iter()
        .map(|p| p.norm())
        .fold(0.0f64, f64::max)
        .max(1e-9);
    let k = 0.5 * cfg.image_size / extent;
    let points: Vec<Vector3<f64>> = unit.iter().map(|p| p * k).collect();
    let (rotations, scales, translations) = camera_motion(cfg);
    let truth = MetricModel {
        rotations,
        translations,
        scales,
        points,
    };

    // Visibility windows.
    let mut visible = vec![true; f * n];
    if cfg.missing > 0.0 {
        let mean_len = ((1.0 - cfg.missing) * f as f64).max(cfg.min_track_length as f64);
        let spread = (mean_len - cfg.min_track_length as f64).min(f as f64 - mean_len);
        for p in 0..n {
            let len = (mean_len + rng.random_range(-spread..=spread))
                .round()
                .clamp(cfg.min_track_length as f64, f as f64) as usize;
            let start = rng.random_range(0..=(f - len));
            for fi in 0..f {
                visible[fi * n + p] = fi >= start && fi < start + len;
            }
        }
    }

    let noise = Normal::new(0.0, cfg.noise.max(0.0)).map_err(|e| Error::InvalidConfig {
        field: "noise",
        message: e.to_string(),
    })?;
    let mut table = TrackTable::new(
        (0..f).map(Id::from).collect(),
        (0..n).map(Id::from).collect(),
    );

    // Outlier tracks.
    let n_out = (cfg.outliers * n as f64).round() as usize;
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        order.swap(i, j);
    }
    let mut outlier_tracks = vec![None; n];
    let kinds = [
        OutlierKind::RandomWalk,
        OutlierKind::SecondObject,
        OutlierKind::Sliding,
    ];
    for (i, &p) in order.iter().take(n_out).enumerate() {
        outlier_tracks[p] = Some(match cfg.outlier_kind {
            OutlierKind::Mixed => kinds[i % 3],
            k => k,
        });
    }
    // A second rigid object: spins the other way about a tilted axis.
    let second_axis = nalgebra::Unit::new_normalize(Vector3::new(0.3, 1.0, 0.4));
    for p in 0..n {
        let step = 0.02 * cfg.image_size;
        let mut walk = Vector2::zeros();
        let dir = {
            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            Vector2::new(a.cos(), a.sin())
        };
        let slide_speed =
            rng.random_range(1.0..4.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        for fi in 0..f {
            let clean = truth.project(fi, p);
            let xy = match outlier_tracks[p] {
                None | Some(OutlierKind::Mixed) => clean,
                Some(OutlierKind::RandomWalk) => {
                    walk +=
                        Vector2::new(rng.random_range(-step..step), rng.random_range(-step..step));
                    truth.project(0, p) + walk
                }
                Some(OutlierKind::SecondObject) => {
                    let a = fi as f64 / (f - 1) as f64;
                    let r2 =
                        Rotation3::from_axis_angle(&second_axis, -1.2 * a) * truth.rotations[0];
                    let x = truth.points[p];
                    let s = truth.scales[fi];
                    let rm = r2.matrix();
                    Vector2::new(
                        s * rm.row(0).transpose().dot(&x),
                        s * rm.row(1).transpose().dot(&x),
                    ) + truth.translations[0]
                        + Vector2::new(60.0 * a, 0.0)
                }
                Some(OutlierKind::Sliding) => {
                    clean + dir * (slide_speed * fi as f64 * (cfg.image_size / 400.0))
                }
            };
            if visible[fi * n + p] {
                table.set(
                    fi,
                    p,
                    xy[0] + noise.sample(&mut rng),
                    xy[1] + noise.sample(&mut rng),
                );
            }
        }
    }

    // Gross per-entry errors on inlier tracks.
    let mut gross_entries = Vec::new();
    if cfg.gross > 0.0 {
        for fi in 0..f {
            for p in 0..n {
                if outlier_tracks[p].is_none()
                    && table.is_visible(fi, p)
                    && rng.random_bool(cfg.gross)
                {
                    let [x, y] = table.get(fi, p).unwrap_or([0.0, 0.0]);
                    let mag = rng.random_range(15.0..60.0) * (cfg.image_size / 400.0);
                    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                    table.set(fi, p, x + mag * a.cos(), y + mag * a.sin());
                    gross_entries.push((fi, p));
                }
            }
        }
    }

    Ok(SynthScene {
        config: cfg.clone(),
        table,
        truth,
        outlier_tracks,
        gross_entries,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_free_complete_scene_matches_truth() {
        let cfg = SynthConfig {
            noise: 0.0,
            ..Default::default()
        };
        let s = generate(&cfg).unwrap();
        assert!(s.table.is_complete());
        let m = s.table.measurements();
        assert!(s.truth.rms(&m) < 1e-12);
    }

    #[test]
    fn missing_fraction_and_windows() {
        for target in [0.3, 0.5, 0.7] {
            let cfg = SynthConfig {
                frames: 40,
                points: 300,
                missing: target,
                seed: 7,
                ..Default::default()
            };
            let s = generate(&cfg).unwrap();
            let missing = 1.0 - s.table.fill();
            assert!((missing - target).abs() < 0.08, "{missing} vs {target}");
            for p in 0..s.table.n_tracks() {
                let vis: Vec<bool> = (0..40).map(|f| s.table.is_visible(f, p)).collect();
                let len = vis.iter().filter(|&&v| v).count();
                assert!(len >= 3);
                let first = vis.iter().position(|&v| v).unwrap();
                assert!(vis[first..first + len].iter().all(|&v| v), "contiguous");
            }
        }
    }

    #[test]
    fn outliers_and_gross_entries_are_recorded() {
        let cfg = SynthConfig {
            outliers: 0.3,
            gross: 0.02,
            seed: 3,
            ..Default::default()
        };
        let s = generate(&cfg).unwrap();
        let n_out = s.outlier_tracks.iter().filter(|o| o.is_some()).count();
        assert_eq!(n_out, 60);
        assert!(!s.gross_entries.is_empty());
        let m = s.table.measurements();
        for &(f, p) in &s.gross_entries {
            let d =
                (s.truth.project(f, p) - Vector2::new(m.w[(2 * f, p)], m.w[(2 * f + 1, p)])).norm();
            assert!(d > 10.0);
        }
        let v: serde_json::Value = serde_json::from_str(&s.truth_json()).unwrap();
        assert_eq!(v["points"].as_array().unwrap().len(), 200);
    }

    #[test]
    fn bad_settings_are_errors() {
        for cfg in [
            SynthConfig {
                frames: 2,
                ..Default::default()
            },
            SynthConfig {
                missing: 0.95,
                ..Default::default()
            },
            SynthConfig {
                noise: -1.0,
                ..Default::default()
            },
            SynthConfig {
                outliers: 1.0,
                ..Default::default()
            },
        ] {
            assert!(matches!(generate(&cfg), Err(Error::InvalidConfig { .. })));
        }
    }
}
