//! The bad-input matrix of the `rank3` binary, kept as a test: every case with its input,
//! the exit status and a fragment of the message, run end to end; and a full disk during
//! the writes, which must leave every previous output whole.
//!
//! `RANK3_BAD_INPUT_TABLE=FILE cargo test --test bad_input` also writes the matrix, as run,
//! to FILE as a Markdown table (case, command, exit status, message).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

mod common;
use common::{bin, run_ok};

/// What a case's input file holds.
enum Input {
    /// No input file (the arguments name what they need).
    None,
    Text(&'static str),
    /// Generated (deterministic) content.
    Gen(fn() -> String),
}

struct Case {
    name: &'static str,
    /// The input file's name in the case's folder, `{in}` in `args`.
    file: &'static str,
    input: Input,
    /// Arguments; `{in}` is the input file, run in the case's folder (so messages show
    /// relative names).
    args: &'static [&'static str],
    code: i32,
    /// A fragment of stderr (or, for exit 0, of stdout + stderr).
    message: &'static str,
}

const RECONSTRUCT: &[&str] = &["reconstruct", "{in}", "--out", "out"];

const CASES: &[Case] = &[
    Case {
        name: "malformed number",
        file: "bad.csv",
        input: Input::Text("frame,track,x,y\n0,0,1.0,2.0\n0,1,oops,2.0\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "bad.csv:3: field `x`: `oops` is not a number",
    },
    Case {
        name: "row with a field missing",
        file: "short.csv",
        input: Input::Text("frame,track,x,y\n0,0,1.0,2.0\n0,1,2.0\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "short.csv:3: field `y`: x given without y",
    },
    Case {
        name: "header without a column",
        file: "nocol.csv",
        input: Input::Text("frame,track,x\n0,0,1.0\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "nocol.csv:1: field `y`: header has no `y` column",
    },
    Case {
        name: "empty file",
        file: "empty.csv",
        input: Input::Text(""),
        args: RECONSTRUCT,
        code: 1,
        message: "empty.csv:1: field `frame`: header has no `frame` column",
    },
    Case {
        name: "header only",
        file: "header.csv",
        input: Input::Text("frame,track,x,y\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "empty track table (header.csv): no observation rows after the header",
    },
    Case {
        name: "NaN coordinate",
        file: "nan.csv",
        input: Input::Text("frame,track,x,y\n0,0,nan,2.0\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "nan.csv:2: field `x`: `nan` is not finite",
    },
    Case {
        name: "infinite coordinate",
        file: "inf.csv",
        input: Input::Text("frame,track,x,y\n0,0,1.0,-inf\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "inf.csv:2: field `y`: `-inf` is not finite",
    },
    Case {
        name: "number that overflows (1e400)",
        file: "overflow.csv",
        input: Input::Text("frame,track,x,y\n0,0,1.0,2.0\n0,1,1e400,2.0\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "overflow.csv:3: field `x`: `1e400` is not finite",
    },
    Case {
        name: "repeated (frame, track) pair",
        file: "dup.csv",
        input: Input::Text("frame,track,x,y\n0,0,1.0,2.0\n0,0,1.5,2.0\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "dup.csv:3: field `track`: frame 0 track 0 is given twice (first on line 2)",
    },
    Case {
        name: "ragged dense matrix",
        file: "ragged.txt",
        input: Input::Text("# m\n1 2 3\n4 5\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "ragged.txt:3: field `row 1`: ragged row",
    },
    Case {
        name: "truncated JSON",
        file: "bad.json",
        input: Input::Text("{\"frames\": ["),
        args: RECONSTRUCT,
        code: 1,
        message: "bad.json:1: field `json`",
    },
    Case {
        name: "unknown format",
        file: "tracks.xyz",
        input: Input::Text("1 2 3\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "tracks.xyz: unknown track-table format",
    },
    Case {
        name: "input file absent",
        file: "absent.csv",
        input: Input::None,
        args: RECONSTRUCT,
        code: 1,
        message: "absent.csv: No such file or directory",
    },
    Case {
        name: "a single frame",
        file: "one.csv",
        input: Input::Text("frame,track,x,y\n0,0,1,2\n0,1,3,4\n0,2,5,1\n0,3,7,7\n"),
        args: RECONSTRUCT,
        code: 1,
        message: "not enough usable frames",
    },
    Case {
        name: "too few tracks (2 tracks, 3 frames)",
        file: "two.csv",
        input: Input::Text(
            "frame,track,x,y\n0,0,1,2\n0,1,3,4\n1,0,1.5,2\n1,1,3.2,4\n2,0,1,2.2\n2,1,3,4.1\n",
        ),
        args: RECONSTRUCT,
        code: 1,
        message: "not enough usable frames",
    },
    Case {
        name: "static camera (0.3 px noise)",
        file: "static.csv",
        input: Input::Gen(static_camera),
        args: RECONSTRUCT,
        code: 1,
        message: "degenerate input: static camera",
    },
    Case {
        name: "static camera, robust pass off",
        file: "static.csv",
        input: Input::Gen(static_camera),
        args: &["reconstruct", "{in}", "--out", "out", "--no-robust"],
        code: 1,
        message: "degenerate input: static camera",
    },
    Case {
        name: "static camera with 30 % missing entries",
        file: "static_missing.csv",
        input: Input::Gen(static_camera_missing),
        args: RECONSTRUCT,
        code: 1,
        message: "degenerate input: static camera",
    },
    Case {
        name: "collinear points (noise-free, 6 decimals)",
        file: "collinear.csv",
        input: Input::Gen(collinear_exact),
        args: RECONSTRUCT,
        code: 1,
        message: "degenerate input: collinear points",
    },
    Case {
        name: "collinear points, robust pass off",
        file: "collinear.csv",
        input: Input::Gen(collinear_exact),
        args: &["reconstruct", "{in}", "--out", "out", "--no-robust"],
        code: 1,
        message: "degenerate input: collinear points",
    },
    Case {
        name: "collinear points, 0.3 px noise, 30 % missing",
        file: "collinear_missing.csv",
        input: Input::Gen(collinear_missing),
        args: RECONSTRUCT,
        code: 1,
        message: "degenerate input: collinear points",
    },
    Case {
        name: "coplanar points",
        file: "planar.csv",
        input: Input::Gen(coplanar),
        args: RECONSTRUCT,
        code: 1,
        message: "(rank < 3)",
    },
    Case {
        name: "image translation only",
        file: "translate.csv",
        input: Input::Gen(translating),
        args: RECONSTRUCT,
        code: 1,
        message: "the image only translates",
    },
    Case {
        name: "coordinates 1e15 + sub-pixel motion",
        file: "huge.csv",
        input: Input::Gen(huge_subpixel),
        args: RECONSTRUCT,
        code: 1,
        message: "coordinates too large for double precision",
    },
    Case {
        name: "toy house + 1e10 px (reconstructed as unshifted)",
        file: "far.csv",
        input: Input::Gen(toy_house_far),
        args: RECONSTRUCT,
        code: 0,
        message: "200 points fitted, RMS 0.480805 px",
    },
    Case {
        name: "two blocks joined by one track (toy house split in frames 0..15 and 15..30)",
        file: "weak.csv",
        input: Input::Gen(toy_house_weak),
        args: RECONSTRUCT,
        code: 0,
        message: "joined to the main block by only 1 track(s)",
    },
    Case {
        name: "--rrd is the input",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &["reconstruct", "{in}", "--out", "out", "--rrd", "{in}"],
        code: 1,
        message: "--rrd tracks.csv would overwrite the input tracks.csv",
    },
    Case {
        name: "--out is the input",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &["reconstruct", "{in}", "--out", "{in}"],
        code: 1,
        message: "--out tracks.csv would overwrite the input tracks.csv",
    },
    Case {
        name: "unknown flag",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &["reconstruct", "{in}", "--out", "out", "--no-such-flag"],
        code: 2,
        message: "unexpected argument '--no-such-flag'",
    },
    Case {
        name: "--out missing",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &["reconstruct", "{in}"],
        code: 2,
        message: "the following required arguments were not provided",
    },
    Case {
        name: "--x without --y",
        file: "x.txt",
        input: Input::Text("1 2 3\n4 5 6\n"),
        args: &["reconstruct", "--x", "{in}", "--out", "out"],
        code: 2,
        message: "--y <FILE>",
    },
    Case {
        name: "option that does nothing (--focal, orthographic)",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &[
            "reconstruct",
            "{in}",
            "--out",
            "out",
            "--camera",
            "orthographic",
            "--focal",
            "500",
        ],
        code: 2,
        message: "--focal is an option of the perspective camera",
    },
    Case {
        name: "malformed option value (--principal-point 1,2,3)",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &[
            "reconstruct",
            "{in}",
            "--out",
            "out",
            "--principal-point",
            "1,2,3",
        ],
        code: 2,
        message: "invalid value '1,2,3' for '--principal-point <X,Y>'",
    },
    Case {
        name: "negative --threshold",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &["reconstruct", "{in}", "--out", "out", "--threshold=-1"],
        code: 1,
        message: "invalid configuration `ransac.threshold_px`: -1 is not positive",
    },
    Case {
        name: "unknown subcommand",
        file: "tracks.csv",
        input: Input::None,
        args: &["frobnicate"],
        code: 2,
        message: "unrecognized subcommand 'frobnicate'",
    },
    Case {
        name: "eval of a missing reconstruction",
        file: "tracks.csv",
        input: Input::Gen(toy_house),
        args: &["eval", "missing.json", "-r", "{in}"],
        code: 1,
        message: "missing.json: No such file or directory",
    },
];

/// Deterministic standard normal samples (xorshift64* and Box–Muller).
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// A `frame,track,x,y` table of `frames` frames of `points`, each frame's positions from
/// `pos(frame, point)` plus `noise` px of Gaussian noise, each entry missing with
/// probability `missing`; `decimals` digits.
fn table(
    frames: usize,
    points: &[[f64; 3]],
    pos: impl Fn(usize, [f64; 3]) -> [f64; 2],
    noise: f64,
    missing: f64,
    decimals: usize,
) -> String {
    let mut rng = Noise(0x9E37_79B9_7F4A_7C15);
    let mut s = String::from("frame,track,x,y\n");
    for f in 0..frames {
        for (p, &x) in points.iter().enumerate() {
            let [u, v] = pos(f, x);
            let (du, dv) = (noise * rng.normal(), noise * rng.normal());
            if rng.uniform() < missing {
                continue;
            }
            writeln!(s, "{f},{p},{:.*},{:.*}", decimals, u + du, decimals, v + dv).unwrap();
        }
    }
    s
}

fn cube(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Noise(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| 2.0 * rng.uniform() - 1.0))
        .collect()
}

/// Orthographic view, 150 px per unit, centred at (320, 240), after turning the point by
/// `yaw` about the vertical axis and `pitch` about the horizontal one.
fn view(x: [f64; 3], yaw: f64, pitch: f64) -> [f64; 2] {
    let (cy, sy, cp, sp) = (yaw.cos(), yaw.sin(), pitch.cos(), pitch.sin());
    let (a, b, c) = (cy * x[0] + sy * x[2], x[1], -sy * x[0] + cy * x[2]);
    [320.0 + 150.0 * a, 240.0 + 150.0 * (cp * b - sp * c)]
}

fn static_camera() -> String {
    table(10, &cube(40, 1), |_, x| view(x, 0.0, 0.0), 0.3, 0.0, 4)
}

fn static_camera_missing() -> String {
    table(12, &cube(40, 2), |_, x| view(x, 0.0, 0.0), 0.3, 0.3, 4)
}

fn line(n: usize) -> Vec<[f64; 3]> {
    let mut rng = Noise(3);
    (0..n)
        .map(|_| {
            let s = 2.0 * rng.uniform() - 1.0;
            [s, 0.5 * s, -0.3 * s]
        })
        .collect()
}

fn turning(f: usize, x: [f64; 3]) -> [f64; 2] {
    view(x, 0.2 * f as f64, 0.1 * f as f64)
}

fn collinear_exact() -> String {
    table(10, &line(40), turning, 0.0, 0.0, 6)
}

fn collinear_missing() -> String {
    table(12, &line(40), turning, 0.3, 0.3, 4)
}

fn coplanar() -> String {
    let mut pts = cube(40, 4);
    pts.iter_mut().for_each(|x| x[2] = 0.0);
    table(10, &pts, turning, 0.3, 0.0, 4)
}

fn translating() -> String {
    table(
        10,
        &cube(40, 5),
        |f, x| {
            let [u, v] = view(x, 0.0, 0.0);
            [u + 5.0 * f as f64, v - 3.0 * f as f64]
        },
        0.3,
        0.0,
        4,
    )
}

/// A cube turning by 0.1° per frame (the tracks move by about half a pixel) at 10¹⁵ px.
fn huge_subpixel() -> String {
    let mut s = String::from("frame,track,x,y\n");
    for (p, &x) in cube(40, 6).iter().enumerate() {
        for f in 0..10 {
            let [u, v] = view(x, (0.1 * f as f64).to_radians(), 0.0);
            writeln!(s, "{f},{p},{:?},{:?}", 1e15 + u, 1e15 + v).unwrap();
        }
    }
    s
}

fn toy_house_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/toy-house/tracks.csv")
}

fn toy_house() -> String {
    std::fs::read_to_string(toy_house_path()).unwrap()
}

/// The toy house with 10¹⁰ px added to every coordinate.
fn toy_house_far() -> String {
    let text = toy_house();
    let mut lines = text.lines();
    let mut s = format!("{}\n", lines.next().unwrap());
    for l in lines {
        let v: Vec<&str> = l.split(',').collect();
        let (x, y): (f64, f64) = (v[2].parse().unwrap(), v[3].parse().unwrap());
        writeln!(s, "{},{},{:?},{:?}", v[0], v[1], x + 1e10, y + 1e10).unwrap();
    }
    s
}

/// The toy house cut in two blocks, frames 0..15 seeing tracks 0..100 and frames 15..30
/// tracks 100..200, joined by one observation (track 0 in frame 15).
fn toy_house_weak() -> String {
    let text = toy_house();
    let mut lines = text.lines();
    let mut s = format!("{}\n", lines.next().unwrap());
    for l in lines {
        let v: Vec<&str> = l.split(',').collect();
        let (f, t): (usize, usize) = (v[0].parse().unwrap(), v[1].parse().unwrap());
        if (f < 15) == (t < 100) || (t == 0 && f == 15) {
            writeln!(s, "{l}").unwrap();
        }
    }
    s
}

/// The message of a run: the first `error:` line of stderr with the indented lines that
/// continue it, else the last line of stdout.
fn message(stdout: &str, stderr: &str) -> String {
    let mut lines = stderr.lines().skip_while(|l| !l.starts_with("error:"));
    match lines.next() {
        Some(first) => std::iter::once(first)
            .chain(lines.take_while(|l| l.starts_with(' ') && !l.trim().is_empty()))
            .map(str::trim)
            .collect::<Vec<_>>()
            .join(" "),
        None => stdout.lines().last().unwrap_or("").to_string(),
    }
}

#[test]
fn bad_input_matrix() {
    assert!(CASES.len() >= 20);
    let root = common::tmp_dir("bad-input", "matrix");
    let mut table = String::from("| case | command | exit | message |\n|---|---|---|---|\n");
    let mut failures = Vec::new();
    for (i, case) in CASES.iter().enumerate() {
        let dir = root.join(format!("{i:02}"));
        std::fs::create_dir_all(&dir).unwrap();
        match &case.input {
            Input::None => {}
            Input::Text(t) => std::fs::write(dir.join(case.file), t).unwrap(),
            Input::Gen(g) => std::fs::write(dir.join(case.file), g()).unwrap(),
        }
        let args: Vec<String> = case
            .args
            .iter()
            .map(|a| a.replace("{in}", case.file))
            .collect();
        let out = bin().args(&args).current_dir(&dir).output().unwrap();
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        let code = out.status.code();
        let text = if case.code == 0 {
            format!("{stdout}{stderr}")
        } else {
            stderr.to_string()
        };
        if code != Some(case.code) || !text.contains(case.message) {
            failures.push(format!(
                "{}: exit {code:?} (expected {}), expected message `{}`, got:\n{stderr}",
                case.name, case.code, case.message
            ));
        }
        // No output folder is left by a run that failed before writing.
        if case.code != 0 && dir.join("out").join("reconstruction.json").exists() {
            failures.push(format!("{}: a failed run wrote outputs", case.name));
        }
        let cell = |s: &str| s.replace('|', "\\|").replace('\n', " ");
        writeln!(
            table,
            "| {} | `rank3 {}` | {} | {} |",
            cell(case.name),
            cell(&args.join(" ")),
            code.map_or("signal".into(), |c| c.to_string()),
            cell(&message(&stdout, &stderr))
        )
        .unwrap();
    }
    println!("{table}");
    if let Ok(path) = std::env::var("RANK3_BAD_INPUT_TABLE") {
        std::fs::write(path, &table).unwrap();
    }
    std::fs::remove_dir_all(&root).ok();
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// Every file under `dir` (relative path → bytes).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.insert(
                    p.strip_prefix(root).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// A full disk, simulated without root by a file-size limit (`RLIMIT_FSIZE`, with
/// `SIGXFSZ` ignored so that a write past it fails with `EFBIG` instead of killing the
/// process): a run into a folder holding a previous run's outputs fails, names the file,
/// and leaves every file either byte-identical to the previous one or a complete new one
/// (smaller than the limit: a cut-off file would be exactly the limit), with no temporary
/// file left behind.
#[test]
fn a_full_disk_leaves_every_previous_output_whole() {
    let d = common::tmp_dir("bad-input", "fsize");
    let tracks = d.join("tracks.csv");
    std::fs::write(&tracks, toy_house()).unwrap();
    let out = d.join("out");
    let reconstruct = |extra: &[&str]| {
        let mut cmd = bin();
        cmd.arg("reconstruct")
            .arg(&tracks)
            .arg("--out")
            .arg(&out)
            .args(["--camera", "scaled-orthographic"])
            .args(extra);
        cmd
    };
    run_ok(&mut reconstruct(&[]));
    let before = snapshot(&out);
    assert!(before.len() >= 3, "{:?}", before.keys());
    let mut sizes: Vec<u64> = before.values().map(|b| b.len() as u64).collect();
    sizes.sort_unstable();
    // The smallest limit stops the first file written; the median lets the smaller files
    // through and stops the larger ones.
    for limit in [512, sizes[sizes.len() / 2]] {
        // Different settings, so that a new file differs from the old one.
        let mut cmd = reconstruct(&["--no-refine"]);
        limit_file_size(&mut cmd, limit);
        let run = cmd.output().unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "limit {limit}: {stderr}");
        assert!(
            stderr.contains("File too large")
                && before
                    .keys()
                    .any(|k| stderr.contains(&out.join(k).display().to_string())),
            "limit {limit}: the error must name the output file: {stderr}"
        );
        let after = snapshot(&out);
        assert_eq!(
            after.keys().collect::<Vec<_>>(),
            before.keys().collect::<Vec<_>>(),
            "limit {limit}: files appeared or vanished (a temporary file left behind?)"
        );
        let mut replaced = 0;
        for (k, old) in &before {
            let new = &after[k];
            if new != old {
                replaced += 1;
                assert!(
                    (new.len() as u64) < limit,
                    "limit {limit}: {} was cut off at {} bytes",
                    k.display(),
                    new.len()
                );
                if k.extension().is_some_and(|e| e == "json") {
                    serde_json::from_slice::<serde_json::Value>(new)
                        .unwrap_or_else(|e| panic!("{}: not whole JSON: {e}", k.display()));
                }
            }
        }
        // The three outputs are one set (`atomic::FileSet`): a file that cannot be written
        // replaces none of them, so the folder still holds the earlier run whole.
        assert_eq!(
            replaced, 0,
            "limit {limit}: a file of the earlier run was replaced"
        );
    }
    std::fs::remove_dir_all(&d).ok();
}

/// Runs `cmd` with every file it writes limited to `limit` bytes (`RLIMIT_FSIZE`, a full
/// disk for each file), `SIGXFSZ` ignored so that the write fails with `EFBIG` instead.
fn limit_file_size(cmd: &mut std::process::Command, limit: u64) {
    // SAFETY: `pre_exec` runs in the child between fork and exec; the closure only calls
    // the async-signal-safe `signal` and `setrlimit`.
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(move || {
            if libc::signal(libc::SIGXFSZ, libc::SIG_IGN) == libc::SIG_ERR {
                return Err(std::io::Error::last_os_error());
            }
            let lim = libc::rlimit {
                rlim_cur: limit,
                rlim_max: limit,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

/// A recording that cannot be written whole (a full disk during `--rrd`, the outputs
/// themselves fitting) is an error naming the recording, exit 1, and the outputs are whole.
#[test]
fn a_full_disk_during_the_recording_is_an_error() {
    let d = common::tmp_dir("bad-input", "rrd-fsize");
    let tracks = d.join("tracks.csv");
    std::fs::write(&tracks, toy_house()).unwrap();
    let reconstruct = |out: &str, rrd: &str| {
        let mut cmd = bin();
        cmd.arg("reconstruct")
            .arg(&tracks)
            .arg("--out")
            .arg(d.join(out))
            .arg("--rrd")
            .arg(d.join(rrd))
            .args(["--camera", "scaled-orthographic"]);
        cmd
    };
    run_ok(&mut reconstruct("full", "full.rrd"));
    let outputs = snapshot(&d.join("full"));
    let largest = outputs.values().map(|b| b.len() as u64).max().unwrap();
    let rrd = std::fs::metadata(d.join("full.rrd")).unwrap().len();
    assert!(
        rrd > 2 * largest,
        "recording {rrd} bytes, largest output {largest}"
    );
    // Room for every output, not for the recording.
    let mut cmd = reconstruct("cut", "cut.rrd");
    limit_file_size(&mut cmd, (largest + rrd) / 2);
    let run = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("the recording to") && stderr.contains("was not completed"),
        "{stderr}"
    );
    let cut = snapshot(&d.join("cut"));
    assert_eq!(
        cut.keys().collect::<Vec<_>>(),
        outputs.keys().collect::<Vec<_>>()
    );
    for (k, v) in &cut {
        if k.extension().is_some_and(|e| e == "json") {
            serde_json::from_slice::<serde_json::Value>(v)
                .unwrap_or_else(|e| panic!("{}: not whole JSON: {e}", k.display()));
        } else {
            assert_eq!(v.len(), outputs[k].len(), "{}", k.display());
        }
    }
    std::fs::remove_dir_all(&d).ok();
}
