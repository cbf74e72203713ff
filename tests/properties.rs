//! Property tests (proptest): the reconstruction changes only as it should when the input is
//! permuted (frames, tracks), its image coordinates translated or scaled, or a track
//! duplicated. Scenes are generated per case (orthographic camera, 0.5 px noise, missing
//! entries); each property runs a few dozen cases (the pipeline is not cheap in a debug build).
//! And no input aborts: small, sparse and degenerate tables under every camera model give a
//! reconstruction that accounts for every track, or a typed error.

use nalgebra::Vector3;
use proptest::prelude::*;
use rank3::synth::{SynthConfig, generate};
use rank3::{CameraModel, Config, Id, Reconstruction, TrackTable};

fn scene(seed: u64, missing: f64) -> TrackTable {
    generate(&SynthConfig {
        frames: 8,
        points: 40,
        noise: 0.5,
        missing,
        seed,
        ..Default::default()
    })
    .unwrap()
    .table
}

fn config() -> Config {
    Config {
        camera: CameraModel::Orthographic,
        ..Config::default()
    }
}

/// Points by track id, for comparisons across orderings.
fn points(r: &Reconstruction) -> std::collections::HashMap<Id, Vector3<f64>> {
    r.points
        .iter()
        .map(|p| (p.track.clone(), Vector3::from(p.xyz)))
        .collect()
}

/// Structure error (relative, up to a similarity and the mirror) between two results on the
/// same track ids.
fn structure_gap(a: &Reconstruction, b: &Reconstruction) -> f64 {
    let (pa, pb) = (points(a), points(b));
    let (mut ea, mut eb) = (Vec::new(), Vec::new());
    for (id, x) in &pa {
        if let Some(y) = pb.get(id) {
            ea.push(*x);
            eb.push(*y);
        }
    }
    rank3::eval::structure_error(&ea, &eb)
}

fn map_table(t: &TrackTable, f: impl Fn(f64, f64) -> (f64, f64)) -> TrackTable {
    let mut out = TrackTable::new(t.frame_ids().to_vec(), t.track_ids().to_vec());
    for fi in 0..t.n_frames() {
        for p in 0..t.n_tracks() {
            if let Some([x, y]) = t.get(fi, p) {
                let (u, v) = f(x, y);
                out.set(fi, p, u, v);
            }
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, .. ProptestConfig::default() })]

    #[test]
    fn permuting_frames_and_tracks_permutes_the_result(seed in 0u64..1000, missing in 0.0f64..0.3, shuffle in any::<u64>()) {
        let t = scene(seed, missing);
        let mut frames: Vec<usize> = (0..t.n_frames()).collect();
        let mut tracks: Vec<usize> = (0..t.n_tracks()).collect();
        // A deterministic shuffle from `shuffle`.
        let mut s = shuffle | 1;
        for v in [&mut frames, &mut tracks] {
            for i in (1..v.len()).rev() {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                v.swap(i, (s % (i as u64 + 1)) as usize);
            }
        }
        let a = Reconstruction::from_tracks(&t, &config()).unwrap();
        let b = Reconstruction::from_tracks(&t.permuted(&frames, &tracks), &config()).unwrap();
        prop_assert!((a.rms_px - b.rms_px).abs() <= 1e-6 * a.rms_px.max(1e-9), "{} vs {}", a.rms_px, b.rms_px);
        let gap = structure_gap(&a, &b);
        prop_assert!(gap < 1e-5, "structure differs by {gap}");
    }

    #[test]
    fn translating_the_image_origin_changes_nothing(seed in 0u64..1000, missing in 0.0f64..0.3, tx in -1e4f64..1e4, ty in -1e4f64..1e4) {
        let t = scene(seed, missing);
        let a = Reconstruction::from_tracks(&t, &config()).unwrap();
        let b = Reconstruction::from_tracks(&map_table(&t, |x, y| (x + tx, y + ty)), &config()).unwrap();
        prop_assert!((a.rms_px - b.rms_px).abs() <= 1e-5 * a.rms_px, "{} vs {}", a.rms_px, b.rms_px);
        let gap = structure_gap(&a, &b);
        prop_assert!(gap < 1e-5, "structure differs by {gap}");
    }

    /// Without the robust pass: its thresholds have floors in pixels (2 px per track, 4 px
    /// per entry: tracker noise and model error are pixel quantities), so scaling the image
    /// by k legitimately changes which entries it flags once kσ passes the floors (found by
    /// this property: seed 690, k = 14.5).
    #[test]
    fn scaling_the_image_scales_the_residuals(seed in 0u64..1000, missing in 0.0f64..0.3, k in 0.05f64..20.0) {
        let t = scene(seed, missing);
        let cfg = Config { robust: None, ..config() };
        let a = Reconstruction::from_tracks(&t, &cfg).unwrap();
        let b = Reconstruction::from_tracks(&map_table(&t, |x, y| (k * x, k * y)), &cfg).unwrap();
        prop_assert!((k * a.rms_px - b.rms_px).abs() <= 1e-5 * b.rms_px, "{} × {k} vs {}", a.rms_px, b.rms_px);
        let gap = structure_gap(&a, &b);
        prop_assert!(gap < 1e-5, "structure differs by {gap}");
    }

    #[test]
    fn a_duplicated_track_gets_the_same_point(seed in 0u64..1000, which in 0usize..40) {
        let t = scene(seed, 0.0);
        let mut ids = t.track_ids().to_vec();
        ids.push(Id::Str("copy".into()));
        let mut d = TrackTable::new(t.frame_ids().to_vec(), ids);
        for f in 0..t.n_frames() {
            for p in 0..t.n_tracks() {
                if let Some([x, y]) = t.get(f, p) {
                    d.set(f, p, x, y);
                    if p == which {
                        d.set(f, t.n_tracks(), x, y);
                    }
                }
            }
        }
        let r = Reconstruction::from_tracks(&d, &config()).unwrap();
        let pts = points(&r);
        let (orig, copy) = (pts[&t.track_ids()[which]], pts[&Id::Str("copy".into())]);
        let spread = (pts.values().map(|x| x.norm_squared()).sum::<f64>() / pts.len() as f64).sqrt();
        prop_assert!((orig - copy).norm() <= 1e-9 * spread, "{orig} vs {copy}");
        // The rest of the structure is the original's, up to the copy's weight.
        let a = Reconstruction::from_tracks(&t, &config()).unwrap();
        prop_assert!(structure_gap(&a, &r) < 0.02);
    }
}

/// A small table of a rigid scene under a perspective camera turning about it (`frames` ×
/// `tracks`, each entry seen with probability `fill`), degraded by `kind`: 0 none, 1 every
/// point at one position, 2 collinear, 3 coordinates ~10¹⁴, 4 coordinates ~10⁻¹⁰,
/// 5 random positions, 6 a static camera, 7 the camera inside the scene, 8 coordinates
/// rounded to 100 px, 9 half the tracks on a horizontal line.
fn degraded_table(seed: u64, frames: usize, tracks: usize, fill: f64, kind: u32) -> TrackTable {
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};
    let mut rng = StdRng::seed_from_u64(seed);
    let pts: Vec<[f64; 3]> = (0..tracks)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect();
    let mut obs = Vec::new();
    for f in 0..frames {
        let a: f64 = rng.random_range(-0.5..0.5);
        let d: f64 = if kind == 7 {
            1.01
        } else {
            rng.random_range(3.0..10.0)
        };
        for (t, p) in pts.iter().enumerate() {
            if rng.random_range(0.0..1.0) > fill {
                continue;
            }
            let (x, z) = (
                a.cos() * p[0] + a.sin() * p[2],
                -a.sin() * p[0] + a.cos() * p[2] + d,
            );
            let (mut u, mut v) = (500.0 * x / z + 320.0, 500.0 * p[1] / z + 240.0);
            match kind {
                1 => (u, v) = (5.0, 7.0),
                2 => v = 2.0 * u,
                3 => (u, v) = (u * 1e12, v * 1e12),
                4 => (u, v) = (u * 1e-12, v * 1e-12),
                5 => (u, v) = (rng.random_range(0.0..640.0), rng.random_range(0.0..480.0)),
                6 if f > 0 => {
                    (u, v) = (
                        500.0 * p[0] / (p[2] + 5.0) + 320.0 + 1e-9,
                        500.0 * p[1] / (p[2] + 5.0) + 240.0,
                    )
                }
                6 => {
                    (u, v) = (
                        500.0 * p[0] / (p[2] + 5.0) + 320.0,
                        500.0 * p[1] / (p[2] + 5.0) + 240.0,
                    )
                }
                8 => (u, v) = ((u * 0.01).round(), (v * 0.01).round()),
                9 if t % 2 == 0 => (u, v) = (320.0 + t as f64, 240.0),
                _ => {}
            }
            obs.push((f as u32, t as u32, u, v));
        }
    }
    TrackTable::from_observations(
        (0..frames).map(|i| Id::Int(i as i64)).collect(),
        (0..tracks).map(|i| Id::Int(i as i64)).collect(),
        &obs,
    )
    .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, .. ProptestConfig::default() })]

    /// No input aborts: small, sparse and degenerate tables give, under every camera model,
    /// a reconstruction with a finite RMS that accounts for every track (fitted, or set
    /// aside with a reason) or a typed error — never a panic. (A release-build sweep of
    /// 1 560 such tables × 5 models found none, 2026-11-28.)
    #[test]
    fn no_small_or_degenerate_table_panics(
        seed in 0u64..100_000,
        frames in 1usize..14,
        tracks in 1usize..40,
        fill in 0.2f64..1.0,
        kind in 0u32..10,
    ) {
        let t = degraded_table(seed, frames, tracks, fill, kind);
        for camera in [
            CameraModel::Auto,
            CameraModel::Orthographic,
            CameraModel::ScaledOrthographic,
            CameraModel::Projective,
            CameraModel::Perspective,
        ] {
            let cfg = Config { camera, ..Config::default() };
            if let Ok(r) = Reconstruction::from_tracks(&t, &cfg) {
                prop_assert!(r.rms_px.is_finite(), "{camera}: rms {}", r.rms_px);
                for id in t.track_ids() {
                    let fitted = r.points.iter().any(|p| &p.track == id);
                    let aside = r.set_aside.iter().any(|s| {
                        s.kind == rank3::table::SetAsideKind::Track && &s.id == id
                    });
                    prop_assert!(fitted || aside, "{camera}: track {id:?} lost");
                }
            }
        }
    }
}
