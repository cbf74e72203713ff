//! KLT accuracy on rendered sequences with known motion (translation, rotation, zoom):
//! median / p95 endpoint error and the fraction of wrong tracks kept, with and without the
//! forward–backward check and the sub-pixel corner refinement.
//!
//! `cargo run --release --example klt_synthetic [WIDTH HEIGHT FRAMES [DUMP_DIR]]` (default
//! 640 480 20). With `DUMP_DIR`, each motion's frames (PNG), frame-0 corners (`init.txt`) and
//! their true positions in every frame (`truth.csv`: frame,track,x,y) are written to
//! `DUMP_DIR/<motion>/` for `examples/klt_vs_opencv.py --synthetic DUMP_DIR`.

use rank3::Id;
use rank3::tracking::synthetic::{Motion, Sequence, SequenceConfig};
use rank3::tracking::{Tracker, TrackerConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    let dump = raw.get(3).map(std::path::PathBuf::from);
    let args: Vec<usize> = raw
        .iter()
        .take(3)
        .map(|a| a.parse())
        .collect::<Result<_, _>>()?;
    let (w, h, frames) = match args[..] {
        [w, h, f] => (w, h, f),
        _ => (640, 480, 20),
    };
    let s = w.min(h) as f64 / 480.0;
    let motions = [
        (
            "translation (3.1, −1.7) px/frame",
            Motion {
                translation: [3.1 * s, -1.7 * s],
                ..Motion::default()
            },
        ),
        (
            "rotation 1°/frame",
            Motion {
                rotation: 1f64.to_radians(),
                ..Motion::default()
            },
        ),
        (
            "zoom 1.5 %/frame",
            Motion {
                zoom: 1.015,
                ..Motion::default()
            },
        ),
        (
            "fast translation (12, 7) px/frame",
            Motion {
                translation: [12.0 * s, 7.0 * s],
                ..Motion::default()
            },
        ),
    ];
    println!("{w}×{h}, {frames} frames, noise σ = 0.01, window 21, 3 levels, 500 features");
    println!(
        "| motion | FB check | sub-pixel corners | tracks | median EPE (px) | p95 EPE (px) | wrong tracks kept (> 2 px) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (k, (name, m)) in motions.into_iter().enumerate() {
        let seq = Sequence::new(SequenceConfig {
            width: w,
            height: h,
            frames,
            motion: m,
            noise: 0.01,
            shapes: 40,
            seed: 7,
            ..SequenceConfig::default()
        });
        let images: Vec<_> = (0..frames).map(|k| seq.render(k)).collect();
        if let Some(dir) = &dump {
            let d = dir.join(["translation", "rotation", "zoom", "fast"][k]);
            std::fs::create_dir_all(d.join("frames"))?;
            for (f, img) in images.iter().enumerate() {
                img.save_png(&d.join("frames").join(format!("{f:03}.png")))?;
            }
            let pyr = rank3::tracking::Pyramid::new(&images[0], 0, 8);
            let dcfg = rank3::tracking::DetectConfig::default();
            let corners = rank3::tracking::detect_corners(&pyr.levels[0], &dcfg, 11, None);
            let mut init = String::new();
            let mut truth = String::from("frame,track,x,y\n");
            for (p, c) in corners.iter().enumerate() {
                init += &format!("{} {}\n", c.x, c.y);
                for f in 0..frames {
                    let t = seq.truth(f, [c.x as f64, c.y as f64]);
                    truth += &format!("{f},{p},{},{}\n", t[0], t[1]);
                }
            }
            std::fs::write(d.join("init.txt"), init)?;
            std::fs::write(d.join("truth.csv"), truth)?;
        }
        for (fb, sub) in [(true, true), (true, false), (false, true), (false, false)] {
            let mut cfg = TrackerConfig::default();
            if !fb {
                cfg.klt.fb_threshold = None;
            }
            if !sub {
                cfg.subpixel = None;
            }
            let mut t = Tracker::new(cfg)?;
            for (k, img) in images.iter().enumerate() {
                t.push(Id::from(k), img)?;
            }
            let (table, _) = t.finish();
            let sc = seq.score(&table, 2.0);
            println!(
                "| {name} | {} | {} | {} | {:.3} | {:.3} | {:.2} % ({}) |",
                if fb { "on" } else { "off" },
                if sub { "on" } else { "off" },
                sc.tracks,
                sc.median(),
                sc.quantile(0.95),
                100.0 * sc.wrong_fraction(),
                sc.wrong_tracks
            );
        }
    }
    Ok(())
}
