//! The KLT tracker against synthetic sequences with known motion, and bad input.

use std::path::PathBuf;

use rank3::Error;
use rank3::tracking::synthetic::{Motion, Sequence, SequenceConfig};
use rank3::tracking::{
    DetectConfig, FrameSource, GrayImage, Pyramid, Tracker, TrackerConfig, detect_corners,
    read_init_points, track_path,
};
use rank3::{Id, TrackTable};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rank3-track-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(seq: &Sequence, cfg: TrackerConfig, init: Option<Vec<[f64; 2]>>) -> TrackTable {
    let mut t = match init {
        Some(p) => Tracker::with_points(cfg, p).unwrap(),
        None => Tracker::new(cfg).unwrap(),
    };
    for k in 0..seq.cfg.frames {
        t.push(Id::from(k), &seq.render(k)).unwrap();
    }
    t.finish().0
}

fn small_cfg() -> TrackerConfig {
    let mut c = TrackerConfig::default();
    c.detect.max_features = 60;
    c.klt.window = 11;
    c.klt.max_level = 2;
    c
}

fn seq(motion: Motion, frames: usize) -> Sequence {
    Sequence::new(SequenceConfig {
        frames,
        motion,
        noise: 0.01,
        ..SequenceConfig::default()
    })
}

/// Known motions: sub-pixel median error, few wrong tracks, most tracks followed.
#[test]
fn known_motions_are_tracked_to_subpixel_accuracy() {
    let motions = [
        (
            "translation",
            Motion {
                translation: [2.3, -1.4],
                ..Motion::default()
            },
            0.1,
        ),
        (
            "rotation",
            Motion {
                rotation: 2f64.to_radians(),
                ..Motion::default()
            },
            0.3,
        ),
        (
            "zoom",
            Motion {
                zoom: 1.02,
                ..Motion::default()
            },
            0.3,
        ),
    ];
    for (name, m, tol) in motions {
        let s = seq(m, 6);
        let table = run(&s, small_cfg(), None);
        let score = s.score(&table, 2.0);
        assert!(score.tracks >= 30, "{name}: only {} tracks", score.tracks);
        assert!(
            score.median() < tol,
            "{name}: median error {}",
            score.median()
        );
        assert!(
            score.quantile(0.95) < 3.0 * tol,
            "{name}: p95 error {}",
            score.quantile(0.95)
        );
        assert!(
            score.wrong_fraction() < 0.05,
            "{name}: {} of {} tracks wrong",
            score.wrong_tracks,
            score.tracks
        );
        // Tracks that start in frame 0 and do not leave the image mostly survive.
        let full = (0..table.n_tracks())
            .filter(|&p| table.track_len(p) == table.n_frames())
            .count();
        assert!(full >= 20, "{name}: only {full} full-length tracks");
    }
}

/// A textureless region gets no corners, and points placed in it die at once.
#[test]
fn textureless_region_has_no_tracks() {
    let flat = [40.0, 30.0, 120.0, 90.0];
    let s = Sequence::new(SequenceConfig {
        frames: 4,
        flat: Some(flat),
        shapes: 0,
        motion: Motion {
            translation: [1.0, 0.5],
            ..Motion::default()
        },
        ..SequenceConfig::default()
    });
    let table = run(&s, small_cfg(), None);
    assert!(table.n_tracks() > 10);
    for p in 0..table.n_tracks() {
        let f0 = (0..table.n_frames())
            .find(|&f| table.is_visible(f, p))
            .unwrap();
        let xy = table.get(f0, p).unwrap();
        let sc = s.to_scene(f0, xy);
        // Corners need texture within the 3×3 block: nothing deep inside the flat area.
        assert!(
            !(sc[0] > flat[0] + 3.0
                && sc[0] < flat[2] - 3.0
                && sc[1] > flat[1] + 3.0
                && sc[1] < flat[3] - 3.0),
            "corner at {xy:?} inside the flat region"
        );
    }
    // Given points in the middle of the flat region are lost in frame 1.
    let init = vec![[80.0, 60.0], [70.0, 55.0], [20.0, 15.0]];
    let table = run(&s, small_cfg(), Some(init));
    assert_eq!(table.n_tracks(), 3);
    assert_eq!(table.track_len(0), 1);
    assert_eq!(table.track_len(1), 1);
    assert_eq!(table.track_ids(), &[Id::Int(0), Id::Int(1), Id::Int(2)]);
}

/// Points that move out of the frame end there and never reappear at a wrong place.
#[test]
fn points_leaving_the_frame_end() {
    let s = seq(
        Motion {
            translation: [6.0, 0.0],
            ..Motion::default()
        },
        8,
    );
    let table = run(&s, small_cfg(), None);
    let score = s.score(&table, 2.0);
    assert!(score.wrong_fraction() < 0.05, "{score:?}");
    let edge = 5.0; // half window of 11
    let w = s.cfg.width as f64;
    let mut ended_at_edge = 0;
    for p in 0..table.n_tracks() {
        let frames: Vec<usize> = (0..table.n_frames())
            .filter(|&f| table.is_visible(f, p))
            .collect();
        // Observed frames are contiguous: a track never restarts.
        assert_eq!(
            frames.last().unwrap() - frames[0] + 1,
            frames.len(),
            "track {p} has a gap"
        );
        for &f in &frames {
            let [x, _] = table.get(f, p).unwrap();
            assert!(x >= 0.0 && x <= w - 1.0, "x = {x} in frame {f}");
        }
        let last = *frames.last().unwrap();
        if last + 1 < table.n_frames() {
            // Lost before the end: its true next position is (nearly) outside.
            let first = table.get(frames[0], p).unwrap();
            let sc = s.to_scene(frames[0], first);
            let nx = s.to_image(last + 1, sc)[0];
            if nx > w - 1.0 - edge - 1.0 {
                ended_at_edge += 1;
            }
        }
    }
    assert!(
        ended_at_edge >= 5,
        "only {ended_at_edge} tracks ended at the edge"
    );
}

/// Frames from a folder are read in natural order, and initial points give line-number ids.
#[test]
fn folder_input_natural_order_and_init_points() {
    let d = tmp("folder");
    let s = seq(
        Motion {
            translation: [1.5, 1.0],
            ..Motion::default()
        },
        11,
    );
    for k in 0..11 {
        s.render(k)
            .save_png(&d.join(format!("f.seq{k}.png")))
            .unwrap();
    }
    // Two strong corners of frame 0, written as a points file with a sub-pixel offset.
    let pyr = Pyramid::new(&s.render(0), 0, 8);
    let dc = DetectConfig {
        max_features: 2,
        min_distance: 30.0,
        ..Default::default()
    };
    let c = detect_corners(&pyr.levels[0], &dc, 10, None);
    let pts = d.join("points.txt");
    std::fs::write(
        &pts,
        format!(
            "# x y\n{} {}\n{},{}\n",
            c[0].x + 0.25,
            c[0].y,
            c[1].x,
            c[1].y - 0.5
        ),
    )
    .unwrap();
    let init = read_init_points(&pts).unwrap();
    assert_eq!(
        init,
        vec![
            [c[0].x as f64 + 0.25, c[0].y as f64],
            [c[1].x as f64, c[1].y as f64 - 0.5]
        ]
    );
    let (table, summary) = track_path(&d, &small_cfg(), Some(init)).unwrap();
    assert_eq!(summary.frames, 11);
    assert_eq!(table.frame_ids()[2], Id::Str("f.seq2".into()));
    assert_eq!(table.frame_ids()[10], Id::Str("f.seq10".into()));
    assert_eq!(table.n_tracks(), 2);
    for p in 0..2 {
        let p0 = table.get(0, p).unwrap();
        let last = table.get(10, p).expect("followed to the last frame");
        let t = s.truth(10, p0);
        assert!(
            (last[0] - t[0]).hypot(last[1] - t[1]) < 0.5,
            "{last:?} vs {t:?}"
        );
    }
}

#[test]
fn bad_folders_are_clear_errors() {
    let d = tmp("empty");
    let e = track_path(&d, &small_cfg(), None).unwrap_err();
    assert!(
        matches!(&e, Error::Image { message, .. } if message.contains("no PNG")),
        "{e}"
    );

    let d = tmp("corrupt");
    std::fs::write(d.join("a.png"), b"not a png").unwrap();
    let e = track_path(&d, &small_cfg(), None).unwrap_err();
    assert!(
        matches!(&e, Error::Image { path, .. } if path.ends_with("a.png")),
        "{e}"
    );

    let d = tmp("mixed");
    GrayImage::new(40, 30, vec![0.5; 1200])
        .unwrap()
        .save_png(&d.join("1.png"))
        .unwrap();
    GrayImage::new(41, 30, vec![0.5; 1230])
        .unwrap()
        .save_png(&d.join("2.png"))
        .unwrap();
    let e = track_path(&d, &small_cfg(), None).unwrap_err();
    assert!(
        matches!(&e, Error::Image { path, message } if path.ends_with("2.png") && message.contains("41×30")),
        "{e}"
    );

    let e = track_path(d.join("missing"), &small_cfg(), None).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");

    let pts = d.join("bad_points.txt");
    std::fs::write(&pts, "1 2\n3 x\n").unwrap();
    let e = read_init_points(&pts).unwrap_err();
    assert!(
        matches!(&e, Error::Parse { line: 2, field, .. } if field == "y"),
        "{e}"
    );
}

fn have_ffmpeg() -> bool {
    let ok = std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!("skipping: ffmpeg not installed (apt-get install -y ffmpeg)");
    }
    ok
}

#[test]
fn unreadable_video_is_a_clear_error() {
    let d = tmp("video");
    let v = d.join("broken.mp4");
    std::fs::write(&v, b"this is not a video").unwrap();
    match FrameSource::open(&v) {
        Err(Error::Video { message, .. }) => {
            if have_ffmpeg() {
                assert!(message.contains("FFmpeg cannot read"), "{message}");
            } else {
                assert!(message.contains("apt-get install ffmpeg"), "{message}");
            }
        }
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("a text file opened as a video"),
    }
}

/// Frames written as PNGs, encoded losslessly by ffmpeg, read back as a video: tracks match
/// the folder's.
#[test]
fn video_input_matches_folder_input() {
    if !have_ffmpeg() {
        return;
    }
    let d = tmp("video-ok");
    let s = seq(
        Motion {
            translation: [1.0, 0.5],
            ..Motion::default()
        },
        5,
    );
    for k in 0..5 {
        s.render(k).save_png(&d.join(format!("{k}.png"))).unwrap();
    }
    let video = d.join("v.mkv");
    let st = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "10", "-i"])
        .arg(d.join("%d.png"))
        .args(["-c:v", "ffv1", "-pix_fmt", "gray"])
        .arg(&video)
        .status()
        .unwrap();
    assert!(st.success());
    let mut src = FrameSource::open(&video).unwrap();
    let mut n = 0;
    while let Some((id, img)) = src.next_frame().unwrap() {
        assert_eq!(id, Id::from(n));
        let png = GrayImage::open(&d.join(format!("{n}.png"))).unwrap();
        assert_eq!(img, png, "frame {n} differs");
        n += 1;
    }
    assert_eq!(n, 5);
}

/// `rank3 track DIR --out tracks.csv` writes a table the readers accept; bad input fails
/// with the error on stderr.
#[test]
fn cli_track_writes_a_table() {
    let d = tmp("cli");
    let frames = d.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let s = seq(
        Motion {
            translation: [1.0, -0.5],
            ..Motion::default()
        },
        4,
    );
    for k in 0..4 {
        s.render(k)
            .save_png(&frames.join(format!("img{k}.png")))
            .unwrap();
    }
    let out = d.join("tracks.csv");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_rank3"))
        .args(["track"])
        .arg(&frames)
        .arg("--out")
        .arg(&out)
        .args(["--max-features", "40", "--window", "11", "--levels", "2"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table = TrackTable::read(&out).unwrap();
    assert_eq!(table.n_frames(), 4);
    assert_eq!(table.frame_ids()[3], Id::Str("img3".into()));
    assert!(table.n_tracks() >= 20 && table.n_tracks() <= 40 + 40);
    assert!(s.score(&table, 2.0).median() < 0.1);

    let o = std::process::Command::new(env!("CARGO_BIN_EXE_rank3"))
        .args(["track"])
        .arg(d.join("nothing-here"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("nothing-here"));
}
