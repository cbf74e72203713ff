//! Dense measurement matrix text format (`.txt`).
//!
//! 2F rows × N columns, row `2f` = x and row `2f+1` = y of frame `f`, whitespace-separated
//! numbers, `nan` (any case) for a missing observation, `#` starts a comment line, blank
//! lines are skipped. Frame ids are `0..F` and track ids `0..N` (0-based positions). This
//! is the layout of the Oxford and CMU measurement matrices (`M_dense.txt`).

use std::io::Write as _;
use std::path::Path;

use super::{Id, TrackTable};
use crate::{Error, Result};

/// Parses dense text; `path` is used in error messages.
pub fn parse(text: &str, path: &Path) -> Result<TrackTable> {
    // (line number, values)
    let mut rows: Vec<(usize, Vec<f64>)> = Vec::new();
    let mut width: Option<(usize, usize)> = None; // (columns, line where first seen)
    for (li, raw) in text.lines().enumerate() {
        let line_no = li + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let row_index = rows.len();
        let mut vals = Vec::new();
        for (c, tok) in line.split_whitespace().enumerate() {
            let v = if tok.eq_ignore_ascii_case("nan") {
                f64::NAN
            } else {
                match tok.parse::<f64>() {
                    Ok(v) if v.is_finite() => v,
                    Ok(_) => {
                        return Err(Error::parse(
                            path,
                            line_no,
                            format!("row {row_index} column {c}"),
                            format!("value `{tok}` is not finite (use `nan` for missing)"),
                        ));
                    }
                    Err(_) => {
                        return Err(Error::parse(
                            path,
                            line_no,
                            format!("row {row_index} column {c}"),
                            format!("`{tok}` is not a number"),
                        ));
                    }
                }
            };
            vals.push(v);
        }
        match width {
            None => width = Some((vals.len(), line_no)),
            Some((w, first)) if w != vals.len() => {
                return Err(Error::parse(
                    path,
                    line_no,
                    format!("row {row_index}"),
                    format!(
                        "ragged row: {} values, but line {first} has {w}",
                        vals.len()
                    ),
                ));
            }
            _ => {}
        }
        rows.push((line_no, vals));
    }
    if rows.is_empty() {
        return Err(Error::EmptyTable {
            path: Some(path.to_path_buf()),
            reason: "no data rows".into(),
        });
    }
    if !rows.len().is_multiple_of(2) {
        let (line, _) = rows[rows.len() - 1];
        return Err(Error::parse(
            path,
            line,
            format!("row {}", rows.len() - 1),
            format!(
                "{} rows: a measurement matrix needs an even number (x and y per frame); the \
                 last frame has x without y",
                rows.len()
            ),
        ));
    }
    let f = rows.len() / 2;
    let n = rows[0].1.len();
    let mut t = TrackTable::new(
        (0..f).map(Id::from).collect(),
        (0..n).map(Id::from).collect(),
    );
    for fi in 0..f {
        let (lx, xs) = &rows[2 * fi];
        let (ly, ys) = &rows[2 * fi + 1];
        for p in 0..n {
            match (xs[p].is_nan(), ys[p].is_nan()) {
                (false, false) => t.set(fi, p, xs[p], ys[p]),
                (true, true) => {}
                (false, true) => {
                    return Err(Error::parse(
                        path,
                        *ly,
                        format!("row {} column {p}", 2 * fi + 1),
                        format!("frame {fi} track {p}: x given without y"),
                    ));
                }
                (true, false) => {
                    return Err(Error::parse(
                        path,
                        *lx,
                        format!("row {} column {p}", 2 * fi),
                        format!("frame {fi} track {p}: y given without x"),
                    ));
                }
            }
        }
    }
    if t.n_observed() == 0 {
        return Err(Error::EmptyTable {
            path: Some(path.to_path_buf()),
            reason: "every entry is nan".into(),
        });
    }
    Ok(t)
}

/// Parses a pair of F×N matrices, one of x and one of y coordinates (frames as rows,
/// tracks as columns, `nan` for missing, `#` comments) — the layout of the CMU hotel
/// reference tracks (`tracked_points_Xs.txt`, `tracked_points_Ys.txt`).
pub fn parse_xy(xs: &str, xs_path: &Path, ys: &str, ys_path: &Path) -> Result<TrackTable> {
    let rows = |text: &str, path: &Path| -> Result<Vec<(usize, Vec<f64>)>> {
        let mut out: Vec<(usize, Vec<f64>)> = Vec::new();
        for (li, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let mut vals = Vec::new();
            for (c, tok) in line.split_whitespace().enumerate() {
                let field = || format!("row {} column {c}", out.len());
                if tok.eq_ignore_ascii_case("nan") {
                    vals.push(f64::NAN);
                    continue;
                }
                match tok.parse::<f64>() {
                    Ok(v) if v.is_finite() => vals.push(v),
                    _ => {
                        return Err(Error::parse(
                            path,
                            li + 1,
                            field(),
                            format!("`{tok}` is not a finite number"),
                        ));
                    }
                }
            }
            if let Some((first, r)) = out.first()
                && r.len() != vals.len()
            {
                return Err(Error::parse(
                    path,
                    li + 1,
                    format!("row {}", out.len()),
                    format!(
                        "ragged row: {} values, but line {first} has {}",
                        vals.len(),
                        r.len()
                    ),
                ));
            }
            out.push((li + 1, vals));
        }
        Ok(out)
    };
    let (rx, ry) = (rows(xs, xs_path)?, rows(ys, ys_path)?);
    let shape = |r: &Vec<(usize, Vec<f64>)>| (r.len(), r.first().map_or(0, |x| x.1.len()));
    if shape(&rx) != shape(&ry) {
        return Err(Error::Dimension {
            context: "x and y matrices",
            expected: format!(
                "{:?} (frames, tracks) as in {}",
                shape(&rx),
                xs_path.display()
            ),
            got: format!("{:?} in {}", shape(&ry), ys_path.display()),
        });
    }
    let (f, n) = shape(&rx);
    if f == 0 || n == 0 {
        return Err(Error::EmptyTable {
            path: Some(xs_path.to_path_buf()),
            reason: "no data rows".into(),
        });
    }
    let mut t = TrackTable::new(
        (0..f).map(Id::from).collect(),
        (0..n).map(Id::from).collect(),
    );
    for fi in 0..f {
        for p in 0..n {
            let (x, y) = (rx[fi].1[p], ry[fi].1[p]);
            match (x.is_nan(), y.is_nan()) {
                (false, false) => t.set(fi, p, x, y),
                (true, true) => {}
                (false, true) => {
                    return Err(Error::parse(
                        ys_path,
                        ry[fi].0,
                        format!("row {fi} column {p}"),
                        "x given without y",
                    ));
                }
                (true, false) => {
                    return Err(Error::parse(
                        xs_path,
                        rx[fi].0,
                        format!("row {fi} column {p}"),
                        "y given without x",
                    ));
                }
            }
        }
    }
    Ok(t)
}

/// Reads an x/y matrix pair (see [`parse_xy`]).
pub fn read_xy(xs_path: &Path, ys_path: &Path) -> Result<TrackTable> {
    let xs = std::fs::read_to_string(xs_path).map_err(|e| Error::io(xs_path, e))?;
    let ys = std::fs::read_to_string(ys_path).map_err(|e| Error::io(ys_path, e))?;
    parse_xy(&xs, xs_path, &ys, ys_path)
}

/// Writes a table as a dense matrix (`nan` for missing), with comment lines naming the ids.
pub fn to_string(t: &TrackTable) -> String {
    let ids = |v: &[Id]| {
        v.iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut bytes = Vec::new();
    // Writing to a Vec cannot fail.
    let _ = write!(
        bytes,
        "# rank3 dense measurement matrix: {} rows (x, y per frame) x {} tracks; nan = \
         missing\n# frames: {}\n# tracks: {}\n",
        2 * t.n_frames(),
        t.n_tracks(),
        ids(t.frame_ids()),
        ids(t.track_ids())
    );
    let _ = write_matrix_to(&mut bytes, 2 * t.n_frames(), t.n_tracks(), |r, p| {
        t.get(r / 2, p).map_or(f64::NAN, |xy| xy[r % 2])
    });
    // The ids' text and ASCII numbers: valid UTF-8.
    String::from_utf8(bytes).unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned())
}

/// Bytes of text per batch of rows (about 8 MB): with two batches in flight, the memory
/// [`write_matrix_to`] holds whatever the matrix's size.
const WRITE_BATCH_BYTES: usize = 8 << 20;

/// Writes a rows×cols matrix to `w`, one row per line, values separated by one space, as
/// [`push_f64`] formats them, a batch of rows (about [`WRITE_BATCH_BYTES`] of text) at a
/// time, so the text is never held whole. A pipeline: the caller gathers a batch's values
/// and writes the text of the batches before it in order, while one formatting thread per
/// core (at most [`MAX_FORMAT_THREADS`]) formats the batches handed to it in turn.
/// `O(rows·cols)` time, `O(WRITE_BATCH_BYTES · threads)` memory.
///
/// Measured on the 2 000 × 20 000 `completed.txt` (740 MB, 2-vCPU machine): 10.9 s with one
/// `write!` per value into one string; 3.3–4.3 s with one formatting thread. Rows formatted in
/// parallel by rayon took 7.7–9.5 s in the pipeline's process (4.2 s on one rayon thread),
/// although the same code on a fresh process ran 1.4× faster on two threads than on one
/// (faer's matrix products then shared rayon's global pool; see [`crate::svd::faer_pool`]):
/// the formatting threads are the scope's own.
pub(crate) fn write_matrix_to(
    w: &mut impl std::io::Write,
    rows: usize,
    cols: usize,
    value: impl Fn(usize, usize) -> f64,
) -> std::io::Result<()> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, MAX_FORMAT_THREADS);
    write_matrix_batched(w, rows, cols, WRITE_BATCH_BYTES, threads, value)
}

/// Columns per block of [`write_matrix_batched`]'s gather.
const GATHER_COLS: usize = 64;

/// Most formatting threads [`write_matrix_to`] starts.
const MAX_FORMAT_THREADS: usize = 4;

/// [`write_matrix_to`] with `batch_bytes` of text per batch and `threads` formatting threads.
fn write_matrix_batched(
    w: &mut impl std::io::Write,
    rows: usize,
    cols: usize,
    batch_bytes: usize,
    threads: usize,
    value: impl Fn(usize, usize) -> f64,
) -> std::io::Result<()> {
    use std::sync::mpsc;
    // ~18 bytes per value: the rows of one batch.
    let batch = (batch_bytes / (18 * cols.max(1))).max(1);
    let n_batches = rows.div_ceil(batch);
    let threads = threads.max(1);
    std::thread::scope(|scope| -> std::io::Result<()> {
        // Batch k goes to thread k mod `threads` and its text comes back on that thread's
        // channel, so the text is written in order. At most two batches per thread are in
        // flight: one being formatted or waiting to be written, one queued.
        let mut to_format = Vec::with_capacity(threads);
        let mut formatted = Vec::with_capacity(threads);
        for _ in 0..threads {
            let (tx_in, rx_in) = mpsc::sync_channel::<(Vec<f64>, Vec<u8>, usize)>(1);
            let (tx_out, rx_out) = mpsc::sync_channel::<(Vec<f64>, Vec<u8>)>(1);
            scope.spawn(move || {
                let mut buf = ryu::Buffer::new();
                for (vals, mut text, nr) in rx_in {
                    text.clear();
                    for i in 0..nr {
                        let row = &vals[i * cols..(i + 1) * cols];
                        for (c, &v) in row.iter().enumerate() {
                            if c > 0 {
                                text.push(b' ');
                            }
                            push_f64(&mut text, v, &mut buf);
                        }
                        text.push(b'\n');
                    }
                    if tx_out.send((vals, text)).is_err() {
                        return;
                    }
                }
            });
            to_format.push(tx_in);
            formatted.push(rx_out);
        }
        let mut spare: Vec<(Vec<f64>, Vec<u8>)> = Vec::new();
        let (mut sent, mut written) = (0, 0);
        while written < n_batches {
            if sent < n_batches && sent - written < 2 * threads {
                let (mut vals, text) = spare.pop().unwrap_or_default();
                let start = sent * batch;
                let nr = (start + batch).min(rows) - start;
                vals.clear();
                vals.resize(nr * cols, 0.0);
                // Gathered by blocks of columns, so that a column-major source (faer's
                // matrices) is read a few cache lines per column and the rows are written in
                // runs (a blocked transpose).
                for c0 in (0..cols).step_by(GATHER_COLS) {
                    let c1 = (c0 + GATHER_COLS).min(cols);
                    for i in 0..nr {
                        for c in c0..c1 {
                            vals[i * cols + c] = value(start + i, c);
                        }
                    }
                }
                if to_format[sent % threads].send((vals, text, nr)).is_err() {
                    break;
                }
                sent += 1;
                continue;
            }
            let Ok((vals, text)) = formatted[written % threads].recv() else {
                break;
            };
            written += 1;
            // (An error returns here: the channels are dropped with this closure, which ends
            // the formatting threads before the scope joins them.)
            w.write_all(&text)?;
            spare.push((vals, text));
        }
        drop(to_format);
        Ok(())
    })
}

/// Appends `v` as `format!("{v}")` would: the shortest decimal that reads back to `v`, never
/// an exponent, `inf`, `-inf`; NaN is written `nan`. (When two shortest decimals are
/// equally close to `v`, the last digit may differ from `Display`'s; both read back to `v`.)
/// Through Ryū (Adams, "Ryū: fast float-to-string conversion", PLDI 2018), which finds the
/// same shortest digits as the standard formatter in less time (65 against 111 ns per value
/// on 17-digit pixel coordinates, one thread); the values Ryū would print with an exponent
/// (|v| < 1e-5 or ≥ 1e16) fall back to the standard formatter.
pub(crate) fn push_f64(out: &mut Vec<u8>, v: f64, buf: &mut ryu::Buffer) {
    if v.is_nan() {
        out.extend_from_slice(b"nan");
        return;
    }
    if v.is_finite() {
        let t = buf.format_finite(v).as_bytes();
        if !t.contains(&b'e') {
            out.extend_from_slice(t.strip_suffix(b".0").unwrap_or(t));
            return;
        }
    }
    let _ = write!(out, "{v}");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("m.txt")
    }

    /// The fast formatter writes what `Display` writes, over every magnitude and the
    /// special values: the same text, or (a tie between two shortest decimals) text as
    /// short that reads back to the same value.
    #[test]
    fn push_f64_matches_display() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            1e-5,
            9.99e-6,
            1e15,
            1e16,
            123.456,
            f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for _ in 0..20_000 {
            let e: i32 = rng.random_range(-30..30);
            let m: f64 = rng.random_range(-10.0..10.0);
            values.push(m * 10f64.powi(e));
            values.push(f64::from_bits(rng.random::<u64>()));
            values.push((rng.random_range(-5000.0..5000.0f64) * 1000.0).round() / 1000.0);
        }
        let mut buf = ryu::Buffer::new();
        let mut ties = 0;
        let n = values.len();
        for v in values {
            let mut out = Vec::new();
            push_f64(&mut out, v, &mut buf);
            let got = String::from_utf8(out).unwrap();
            let want = if v.is_nan() {
                "nan".into()
            } else {
                format!("{v}")
            };
            if got != want {
                assert_eq!(got.len(), want.len(), "{v:e}: {got} vs {want}");
                assert_eq!(got.parse::<f64>().unwrap(), v, "{v:e}: {got}");
                ties += 1;
            }
        }
        assert!(ties * 1000 < n, "{ties} of {n} differ from Display");
    }

    /// Batches of rows write what one pass writes.
    #[test]
    fn write_matrix_to_in_batches_is_row_major_text() {
        let (rows, cols) = (7, 3);
        let value = |r: usize, c: usize| {
            if r == 2 {
                f64::NAN
            } else {
                r as f64 + 0.5 * c as f64
            }
        };
        let mut got = Vec::new();
        write_matrix_to(&mut got, rows, cols, value).unwrap();
        let mut want = String::new();
        for r in 0..rows {
            let row: Vec<String> = (0..cols)
                .map(|c| match value(r, c) {
                    v if v.is_nan() => "nan".into(),
                    v => format!("{v}"),
                })
                .collect();
            want.push_str(&row.join(" "));
            want.push('\n');
        }
        assert_eq!(String::from_utf8(got).unwrap(), want);
        // Batches of one row, of two rows and of every row, on one to three formatting
        // threads (batches handed out in turn must come back in order).
        for batch_bytes in [1, 18 * cols * 2, 18 * cols * 100] {
            for threads in 1..=3 {
                let mut got = Vec::new();
                write_matrix_batched(&mut got, rows, cols, batch_bytes, threads, value).unwrap();
                assert_eq!(
                    String::from_utf8(got).unwrap(),
                    want,
                    "{batch_bytes} {threads}"
                );
            }
        }
        // No columns: a line per row.
        let mut got = Vec::new();
        write_matrix_batched(&mut got, 3, 0, 1, 2, |_, _| 0.0).unwrap();
        assert_eq!(got, b"\n\n\n");
    }

    #[test]
    fn parses_comments_nan_and_roundtrips() {
        let txt = "# c\n1 2 nan\n3 4 nan\n\n5 6 7\n8 9 10\n";
        let t = parse(txt, p()).unwrap();
        assert_eq!((t.n_frames(), t.n_tracks()), (2, 3));
        assert_eq!(t.get(0, 1), Some([2.0, 4.0]));
        assert_eq!(t.get(0, 2), None);
        assert_eq!(t.get(1, 2), Some([7.0, 10.0]));
        let back = parse(&to_string(&t), p()).unwrap();
        assert_eq!(back, t);
    }

    fn err(txt: &str) -> (usize, String, String) {
        crate::table::parse_error_parts(parse(txt, p()).unwrap_err())
    }

    #[test]
    fn xy_pair() {
        let t = parse_xy("# x\n1 2\n3 nan\n", p(), "10 20\n30 nan\n", p()).unwrap();
        assert_eq!(t.get(1, 0), Some([3.0, 30.0]));
        assert_eq!(t.get(1, 1), None);
        assert!(matches!(
            parse_xy("1 2\n", p(), "1 2\n3 4\n", p()),
            Err(Error::Dimension { .. })
        ));
        assert!(matches!(
            parse_xy("1 2\n", p(), "1 nan\n", p()),
            Err(Error::Parse { line: 1, .. })
        ));
    }

    #[test]
    fn errors_name_line_and_field() {
        let (l, f, m) = err("1 2\n3 x\n");
        assert_eq!((l, f.as_str()), (2, "row 1 column 1"));
        assert!(m.contains("not a number"));
        let (l, _, m) = err("1 2\n3 inf\n");
        assert_eq!(l, 2);
        assert!(m.contains("not finite"));
        let (l, f, m) = err("# h\n1 2\n3 4 5\n");
        assert_eq!((l, f.as_str()), (3, "row 1"));
        assert!(m.contains("ragged"));
        let (l, _, m) = err("1 2\nnan 4\n");
        assert_eq!(l, 2);
        assert!(m.contains("x given without y"));
        let (l, _, m) = err("nan 2\n3 4\n");
        assert_eq!(l, 1);
        assert!(m.contains("y given without x"));
        let (l, _, m) = err("1 2\n3 4\n5 6\n");
        assert_eq!(l, 3);
        assert!(m.contains("even number"));
        assert!(matches!(
            parse("# only comments\n", p()),
            Err(Error::EmptyTable { .. })
        ));
        assert!(matches!(
            parse("nan nan\nnan nan\n", p()),
            Err(Error::EmptyTable { .. })
        ));
    }
}
