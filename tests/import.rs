//! Importers of the track shapes users hold: NumPy `.npy` / `.npz`, separate x and y
//! matrices, and the tracks of a COLMAP text model. Every input is written by the test
//! itself (the `.npy` bytes by hand, independently of rank3's own writer).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use rank3::Error;
use rank3::colmap::{
    ColmapCamera, ColmapCameraModel, ColmapImage, ColmapModel, ColmapPoint, PIXEL_CENTRE_OFFSET,
};
use rank3::table::npy::ArrayFault;
use rank3::table::{Id, TrackTable, read_tracks, read_xy};

mod common;
use common::{bin, run_err, run_ok};

fn tmp(name: &str) -> PathBuf {
    common::tmp_dir("import", name)
}

const NAN: f64 = f64::NAN;

/// A `.npy` file written by hand: `version` 1, 2 or 3, the header dict literal `dict`
/// (padded to a multiple of 64 bytes and ended by a newline), then `data`.
fn npy_raw(version: u8, dict: &str, data: &[u8]) -> Vec<u8> {
    let pre = if version == 1 { 10 } else { 12 };
    let total = (pre + dict.len() + 1).div_ceil(64) * 64;
    let mut header = dict.to_string();
    header.push_str(&" ".repeat(total - pre - dict.len() - 1));
    header.push('\n');
    let mut out = b"\x93NUMPY".to_vec();
    out.extend_from_slice(&[version, 0]);
    if version == 1 {
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    } else {
        out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    }
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

fn shape_text(shape: &[usize]) -> String {
    match shape {
        [a] => format!("({a},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// A float array as `.npy` bytes: `values` in C (row-major) order of `shape`, stored in the
/// given order as `<f8` or `<f4`.
fn npy_f(values: &[f64], shape: &[usize], f4: bool, fortran: bool, version: u8) -> Vec<u8> {
    assert_eq!(values.len(), shape.iter().product::<usize>());
    // Storage order: Fortran stores the first index fastest.
    let mut order: Vec<usize> = (0..values.len()).collect();
    if fortran {
        let mut strides = vec![1usize; shape.len()];
        for k in (0..shape.len().saturating_sub(1)).rev() {
            strides[k] = strides[k + 1] * shape[k + 1];
        }
        order.sort_by_key(|&i| {
            let idx: Vec<usize> = (0..shape.len())
                .map(|k| (i / strides[k]) % shape[k])
                .rev()
                .collect();
            idx
        });
    }
    let mut data = Vec::new();
    for i in order {
        if f4 {
            data.extend_from_slice(&(values[i] as f32).to_le_bytes());
        } else {
            data.extend_from_slice(&values[i].to_le_bytes());
        }
    }
    let dict = format!(
        "{{'descr': '{}', 'fortran_order': {}, 'shape': {}, }}",
        if f4 { "<f4" } else { "<f8" },
        if fortran { "True" } else { "False" },
        shape_text(shape)
    );
    npy_raw(version, &dict, &data)
}

/// An `.npy` of 1-D ids: `<i8` integers.
fn npy_ints(ids: &[i64]) -> Vec<u8> {
    let data: Vec<u8> = ids.iter().flat_map(|v| v.to_le_bytes()).collect();
    npy_raw(
        1,
        &format!(
            "{{'descr': '<i8', 'fortran_order': False, 'shape': ({},), }}",
            ids.len()
        ),
        &data,
    )
}

/// An `.npy` of 1-D strings: `<U{width}` (UTF-32LE, NUL padded).
fn npy_strings(ids: &[&str]) -> Vec<u8> {
    let width = ids.iter().map(|s| s.chars().count()).max().unwrap_or(1);
    let mut data = Vec::new();
    for s in ids {
        let n = s.chars().count();
        for c in s.chars() {
            data.extend_from_slice(&(c as u32).to_le_bytes());
        }
        data.resize(data.len() + 4 * (width - n), 0);
    }
    npy_raw(
        1,
        &format!(
            "{{'descr': '<U{width}', 'fortran_order': False, 'shape': ({},), }}",
            ids.len()
        ),
        &data,
    )
}

/// A zip archive of `.npy` members, stored or deflated (`np.savez`,
/// `np.savez_compressed`).
fn npz(members: &[(&str, Vec<u8>)], deflate: bool) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let method = if deflate {
        zip::CompressionMethod::Deflated
    } else {
        zip::CompressionMethod::Stored
    };
    let opts = zip::write::SimpleFileOptions::default().compression_method(method);
    for (name, bytes) in members {
        zip.start_file(name.to_string(), opts).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The (F, N, 2) values of the test table: 3 frames × 4 tracks, entries (0, 2) and (2, 3)
/// missing; values exactly representable in f32.
fn tracks_fn2() -> Vec<f64> {
    let mut v = Vec::new();
    for f in 0..3 {
        for n in 0..4 {
            if (f, n) == (0, 2) || (f, n) == (2, 3) {
                v.extend([NAN, NAN]);
            } else {
                v.extend([
                    10.0 * n as f64 + f as f64 + 0.25,
                    -5.5 * n as f64 + f as f64,
                ]);
            }
        }
    }
    v
}

/// The table `tracks_fn2` describes.
fn expected() -> TrackTable {
    let v = tracks_fn2();
    let mut t = TrackTable::new(
        (0..3).map(Id::from).collect(),
        (0..4).map(Id::from).collect(),
    );
    for f in 0..3 {
        for n in 0..4 {
            let (x, y) = (v[(f * 4 + n) * 2], v[(f * 4 + n) * 2 + 1]);
            if !x.is_nan() {
                t.set(f, n, x, y);
            }
        }
    }
    t
}

fn array_fault(e: Error) -> (ArrayFault, Option<String>, String) {
    match e {
        Error::Array(e) => (e.fault, e.array, e.field),
        e => panic!("expected Error::Array, got {e:?}"),
    }
}

#[test]
fn npy_f8_f4_c_and_fortran_order_all_versions() {
    let d = tmp("npy");
    let want = expected();
    for f4 in [false, true] {
        for fortran in [false, true] {
            for version in [1, 2, 3] {
                let name = format!("t_{f4}_{fortran}_{version}.npy");
                let p = write(
                    &d,
                    &name,
                    &npy_f(&tracks_fn2(), &[3, 4, 2], f4, fortran, version),
                );
                let got = read_tracks(&p).unwrap();
                assert_eq!(got.table, want, "{name}");
                assert!(got.warnings.is_empty());
                assert!(!got.table.is_visible(0, 2) && !got.table.is_visible(2, 3));
            }
        }
    }
    // A 3.0 header may hold UTF-8; 1.0 is latin-1.
    let dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 1, 2), }";
    let data: Vec<u8> = [1.0f64, 2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
    let p = write(&d, "v3.npy", &npy_raw(3, dict, &data));
    assert_eq!(read_tracks(&p).unwrap().table.get(0, 0), Some([1.0, 2.0]));
    std::fs::remove_dir_all(&d).ok();
}

/// The (2F, N) layout is the dense `.txt` measurement matrix: both formats agree.
#[test]
fn npy_measurement_matrix_agrees_with_dense_txt() {
    let d = tmp("w");
    let t = expected();
    let txt = d.join("w.txt");
    t.write(&txt).unwrap();
    let mut w = Vec::new();
    for f in 0..3 {
        for c in 0..2 {
            for n in 0..4 {
                w.push(t.get(f, n).map_or(NAN, |q| q[c]));
            }
        }
    }
    for fortran in [false, true] {
        let p = write(&d, "w.npy", &npy_f(&w, &[6, 4], false, fortran, 1));
        assert_eq!(
            read_tracks(&p).unwrap().table,
            read_tracks(&txt).unwrap().table
        );
    }
    // rank3 writes .npy too, and reads it back.
    let back = d.join("back.npy");
    t.write(&back).unwrap();
    assert_eq!(TrackTable::read(&back).unwrap(), t);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn npy_bad_input_gives_the_right_error() {
    let d = tmp("npybad");
    let good = npy_f(&tracks_fn2(), &[3, 4, 2], false, false, 1);
    let header_end = good.len() - 3 * 4 * 2 * 8;
    let dict = |descr: &str, shape: &str| {
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}")
    };
    let zeros = |n: usize| vec![0u8; n];
    let mut with_inf = tracks_fn2();
    with_inf[9] = f64::INFINITY;
    let mut x_only = tracks_fn2();
    x_only[4 * 2 + 1] = NAN; // frame 1, track 0: y missing
    let cases: Vec<(&str, Vec<u8>, ArrayFault, &str)> = vec![
        (
            "magic",
            b"PK\x03\x04 not numpy".to_vec(),
            ArrayFault::Magic,
            "magic",
        ),
        ("empty", Vec::new(), ArrayFault::Truncated, "version"),
        (
            "preamble",
            good[..9].to_vec(),
            ArrayFault::Truncated,
            "header length",
        ),
        (
            "header",
            good[..40].to_vec(),
            ArrayFault::Truncated,
            "header",
        ),
        (
            "data",
            good[..good.len() - 5].to_vec(),
            ArrayFault::Truncated,
            "data",
        ),
        (
            "no data",
            good[..header_end].to_vec(),
            ArrayFault::Truncated,
            "data",
        ),
        (
            "trailing",
            [good.clone(), vec![0; 8]].concat(),
            ArrayFault::TrailingData,
            "data",
        ),
        (
            "version",
            {
                let mut b = good.clone();
                b[6] = 4;
                b
            },
            ArrayFault::Version,
            "version",
        ),
        (
            "big-endian",
            npy_raw(1, &dict(">f8", "(1, 1, 2)"), &zeros(16)),
            ArrayFault::Dtype,
            "header.descr",
        ),
        (
            "f2",
            npy_raw(1, &dict("<f2", "(1, 1, 2)"), &zeros(4)),
            ArrayFault::Dtype,
            "header.descr",
        ),
        (
            "int coords",
            npy_raw(1, &dict("<i4", "(1, 1, 2)"), &zeros(8)),
            ArrayFault::Dtype,
            "header.descr",
        ),
        (
            "object",
            npy_raw(1, &dict("|O", "(1, 1, 2)"), &zeros(16)),
            ArrayFault::Dtype,
            "header.descr",
        ),
        (
            "record",
            npy_raw(
                1,
                "{'descr': [('x', '<f8'), ('y', '<f8')], 'fortran_order': False, 'shape': (2,), }",
                &zeros(32),
            ),
            ArrayFault::Dtype,
            "header.descr",
        ),
        (
            "no shape",
            npy_raw(1, "{'descr': '<f8', 'fortran_order': False, }", &[]),
            ArrayFault::Header,
            "header.shape",
        ),
        (
            "extra key",
            npy_raw(
                1,
                "{'descr': '<f8', 'fortran_order': False, 'shape': (), 'x': 1}",
                &zeros(8),
            ),
            ArrayFault::Header,
            "header.x",
        ),
        (
            "not a dict",
            npy_raw(1, "('<f8', False, (1,))", &zeros(8)),
            ArrayFault::Header,
            "header",
        ),
        (
            "syntax",
            npy_raw(
                1,
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 2,",
                &zeros(16),
            ),
            ArrayFault::Header,
            "header",
        ),
        (
            "fortran_order",
            npy_raw(
                1,
                "{'descr': '<f8', 'fortran_order': 0, 'shape': (1, 1, 2), }",
                &zeros(16),
            ),
            ArrayFault::Header,
            "header.fortran_order",
        ),
        (
            "shape 3",
            npy_raw(1, &dict("<f8", "(1, 1, 3)"), &zeros(24)),
            ArrayFault::Shape,
            "shape",
        ),
        (
            "odd rows",
            npy_raw(1, &dict("<f8", "(3, 1)"), &zeros(24)),
            ArrayFault::Shape,
            "shape",
        ),
        // A header announcing far more data than the file holds is refused before any
        // allocation of that size, and an overflowing shape too.
        (
            "huge",
            npy_raw(1, &dict("<f8", "(1000000000, 1000000000, 2)"), &zeros(16)),
            ArrayFault::Truncated,
            "data",
        ),
        (
            "overflow",
            npy_raw(
                1,
                &dict("<f8", "(4294967296, 4294967296, 4294967296, 2)"),
                &[],
            ),
            ArrayFault::Shape,
            "header.shape",
        ),
        (
            "inf",
            npy_f(&with_inf, &[3, 4, 2], false, false, 1),
            ArrayFault::Value,
            "[1, 0, 1]",
        ),
        (
            "x without y",
            npy_f(&x_only, &[3, 4, 2], false, false, 1),
            ArrayFault::Value,
            "[1, 0, 1]",
        ),
    ];
    for (name, bytes, fault, field) in cases {
        let p = write(&d, &format!("{}.npy", name.replace(' ', "_")), &bytes);
        let e = read_tracks(&p).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains(&p.display().to_string()), "{name}: {msg}");
        let (got_fault, array, got_field) = array_fault(e);
        assert_eq!(
            (got_fault, got_field.as_str()),
            (fault, field),
            "{name}: {msg}"
        );
        assert_eq!(array, None);
    }
    // Shapes without entries and all-NaN arrays are empty tables.
    let p = write(&d, "zero.npy", &npy_raw(1, &dict("<f8", "(0, 5, 2)"), &[]));
    assert!(matches!(read_tracks(&p), Err(Error::EmptyTable { .. })));
    let p = write(
        &d,
        "nan.npy",
        &npy_f(&[NAN; 8], &[2, 2, 2], false, false, 1),
    );
    assert!(matches!(read_tracks(&p), Err(Error::EmptyTable { .. })));
    assert!(matches!(
        read_tracks(d.join("absent.npy")),
        Err(Error::Io { .. })
    ));
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn npz_layouts_ids_and_compression() {
    let d = tmp("npz");
    let want = expected();
    let v = tracks_fn2();
    let (xs, ys): (Vec<f64>, Vec<f64>) = (
        v.iter().step_by(2).copied().collect(),
        v.iter().skip(1).step_by(2).copied().collect(),
    );
    for deflate in [false, true] {
        // `tracks` with string frame ids and integer track ids.
        let p = write(
            &d,
            "ids.npz",
            &npz(
                &[
                    ("tracks.npy", npy_f(&v, &[3, 4, 2], true, true, 1)),
                    (
                        "frame_ids.npy",
                        npy_strings(&["img2.png", "img10.png", "ü.png"]),
                    ),
                    ("track_ids.npy", npy_ints(&[40, -1, 7, 3])),
                ],
                deflate,
            ),
        );
        let got = read_tracks(&p).unwrap();
        assert!(got.warnings.is_empty(), "{:?}", got.warnings);
        let t = &got.table;
        assert_eq!(
            t.frame_ids(),
            &[
                Id::Str("img2.png".into()),
                Id::Str("img10.png".into()),
                Id::Str("ü.png".into())
            ]
        );
        assert_eq!(
            t.track_ids(),
            &[Id::Int(40), Id::Int(-1), Id::Int(7), Id::Int(3)]
        );
        assert_eq!(t.n_observed(), want.n_observed());
        for f in 0..3 {
            for n in 0..4 {
                assert_eq!(t.get(f, n), want.get(f, n));
            }
        }
        // `x` and `y`, and an extra member (reported, not silently dropped).
        let p = write(
            &d,
            "xy.npz",
            &npz(
                &[
                    ("x.npy", npy_f(&xs, &[3, 4], false, false, 1)),
                    ("y.npy", npy_f(&ys, &[3, 4], false, true, 2)),
                    ("notes.npy", npy_ints(&[1])),
                ],
                deflate,
            ),
        );
        let got = read_tracks(&p).unwrap();
        assert_eq!(got.table, want);
        assert_eq!(got.warnings.len(), 1);
        assert!(got.warnings[0].contains("notes.npy"), "{:?}", got.warnings);
        // A single array of any name (np.savez(path, a) names it arr_0).
        let p = write(
            &d,
            "arr0.npz",
            &npz(
                &[("arr_0.npy", npy_f(&v, &[3, 4, 2], false, false, 1))],
                deflate,
            ),
        );
        assert_eq!(read_tracks(&p).unwrap().table, want);
    }
    // rank3 writes .npz with its ids, and reads it back.
    let named = want.select(&[2, 0, 1], &[3, 1, 0, 2]);
    let back = d.join("back.npz");
    named.write(&back).unwrap();
    assert_eq!(TrackTable::read(&back).unwrap(), named);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn npz_bad_input_gives_the_right_error() {
    let d = tmp("npzbad");
    let v = tracks_fn2();
    let tracks = || npy_f(&v, &[3, 4, 2], false, false, 1);
    let x = || npy_f(&[1.0; 12], &[3, 4], false, false, 1);
    // (name, archive, fault, member, field)
    type Case<'a> = (&'a str, Vec<u8>, ArrayFault, Option<&'a str>, &'a str);
    let cases: Vec<Case> = vec![
        (
            "not zip",
            b"\x93NUMPY not a zip".to_vec(),
            ArrayFault::Archive,
            None,
            "archive",
        ),
        (
            "both",
            npz(
                &[("tracks.npy", tracks()), ("x.npy", x()), ("y.npy", x())],
                false,
            ),
            ArrayFault::Ambiguous,
            None,
            "members",
        ),
        (
            "x only",
            npz(&[("x.npy", x())], false),
            ArrayFault::Missing,
            None,
            "members",
        ),
        (
            "none",
            npz(&[("a.npy", x()), ("b.npy", x())], false),
            ArrayFault::Missing,
            None,
            "members",
        ),
        (
            "empty",
            npz(&[], false),
            ArrayFault::Missing,
            None,
            "members",
        ),
        (
            "xy shapes",
            npz(
                &[
                    ("x.npy", x()),
                    ("y.npy", npy_f(&[1.0; 8], &[2, 4], false, false, 1)),
                ],
                false,
            ),
            ArrayFault::Shape,
            Some("y"),
            "shape",
        ),
        (
            "xy 3-D",
            npz(&[("x.npy", tracks()), ("y.npy", tracks())], false),
            ArrayFault::Shape,
            Some("x"),
            "shape",
        ),
        (
            "frame ids",
            npz(
                &[
                    ("tracks.npy", tracks()),
                    ("frame_ids.npy", npy_ints(&[1, 2])),
                ],
                false,
            ),
            ArrayFault::Shape,
            Some("frame_ids"),
            "shape",
        ),
        (
            "dup ids",
            npz(
                &[
                    ("tracks.npy", tracks()),
                    ("track_ids.npy", npy_ints(&[1, 2, 1, 3])),
                ],
                false,
            ),
            ArrayFault::Value,
            Some("track_ids"),
            "[2]",
        ),
        (
            "float ids",
            npz(
                &[
                    ("tracks.npy", tracks()),
                    ("track_ids.npy", npy_f(&[1.0; 4], &[4], false, false, 1)),
                ],
                false,
            ),
            ArrayFault::Dtype,
            Some("track_ids"),
            "header.descr",
        ),
        (
            "bad member",
            npz(&[("tracks.npy", tracks()[..50].to_vec())], true),
            ArrayFault::Truncated,
            Some("tracks"),
            "header",
        ),
    ];
    for (name, bytes, fault, array, field) in cases {
        let p = write(&d, &format!("{}.npz", name.replace(' ', "_")), &bytes);
        let e = read_tracks(&p).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains(&p.display().to_string()), "{name}: {msg}");
        assert_eq!(
            array_fault(e),
            (fault, array.map(str::to_string), field.to_string()),
            "{name}: {msg}"
        );
    }
    // A corrupted deflate stream (or CRC) is an archive fault, not a panic.
    let mut bytes = npz(&[("tracks.npy", tracks())], true);
    let at = bytes.windows(10).position(|w| w == b"tracks.npy").unwrap() + 20;
    for b in &mut bytes[at..at + 16] {
        *b ^= 0x5a;
    }
    let p = write(&d, "corrupt.npz", &bytes);
    let e = read_tracks(&p).unwrap_err();
    assert!(
        matches!(
            &e,
            Error::Array(a) if matches!(
                a.fault,
                ArrayFault::Archive | ArrayFault::Magic | ArrayFault::Header
            )
        ),
        "{e}"
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn separate_x_and_y_matrices() {
    let d = tmp("xy");
    let want = expected();
    let mat = |c: usize| {
        (0..3)
            .map(|f| {
                (0..4)
                    .map(|n| {
                        want.get(f, n)
                            .map_or("nan".to_string(), |q| q[c].to_string())
                    })
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let xt = write(&d, "xs.txt", format!("# x\n{}\n", mat(0)).as_bytes());
    let yt = write(&d, "ys.txt", format!("# y\n{}\n", mat(1)).as_bytes());
    assert_eq!(read_xy(&xt, &yt).unwrap().table, want);
    let v = tracks_fn2();
    let xs: Vec<f64> = v.iter().step_by(2).copied().collect();
    let ys: Vec<f64> = v.iter().skip(1).step_by(2).copied().collect();
    let xn = write(&d, "xs.npy", &npy_f(&xs, &[3, 4], true, false, 1));
    let yn = write(&d, "ys.npy", &npy_f(&ys, &[3, 4], false, true, 1));
    assert_eq!(read_xy(&xn, &yn).unwrap().table, want);
    assert!(matches!(
        read_xy(&xn, &yt),
        Err(Error::InvalidConfig { .. })
    ));
    let short = write(&d, "short.npy", &npy_f(&ys[..8], &[2, 4], false, false, 1));
    let (fault, _, field) = array_fault(read_xy(&xn, &short).unwrap_err());
    assert_eq!((fault, field.as_str()), (ArrayFault::Shape, "shape"));
    std::fs::remove_dir_all(&d).ok();
}

/// The CMU hotel reference tracks (51 frames × 491 complete tracks), when the data set is
/// present.
#[test]
fn hotel_reference_tracks() {
    let (Some(xs), Some(ys)) = (
        rank3::datasets::find("hotel/tracked_points_Xs.txt"),
        rank3::datasets::find("hotel/tracked_points_Ys.txt"),
    ) else {
        return;
    };
    let t = read_xy(&xs, &ys).unwrap().table;
    assert_eq!((t.n_frames(), t.n_tracks()), (51, 491));
    assert!(t.is_complete());
}

fn rot_z(a: f64) -> nalgebra::Matrix3<f64> {
    *nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), a).matrix()
}

/// A COLMAP model whose keypoints are the observations of `t` (shifted to COLMAP's pixel
/// convention), plus unmatched keypoints; images named `names` (one per frame) and listed
/// in a shuffled order, 3D point ids `100 + 3 p`.
fn model_of(t: &TrackTable, names: &[&str]) -> ColmapModel {
    let order: Vec<usize> = (0..t.n_frames()).rev().collect();
    let mut points: Vec<ColmapPoint> = (0..t.n_tracks())
        .map(|p| ColmapPoint {
            id: 100 + 3 * p as u64,
            xyz: [p as f64, 0.0, 1.0],
            rgb: [1, 2, 3],
            error: -1.0,
            track: Vec::new(),
        })
        .collect();
    let mut images = Vec::new();
    for (k, &f) in order.iter().enumerate() {
        let id = 7 + k as u32;
        let mut points2d = vec![([1.0, 2.0], None)];
        for p in (0..t.n_tracks()).rev() {
            if let Some([x, y]) = t.get(f, p) {
                points[p].track.push((id, points2d.len()));
                points2d.push((
                    [x + PIXEL_CENTRE_OFFSET, y + PIXEL_CENTRE_OFFSET],
                    Some(points[p].id),
                ));
                points2d.push(([x + 3.0, y], None));
            }
        }
        images.push(ColmapImage {
            id,
            camera_id: 1,
            name: names[f].to_string(),
            rotation: rot_z(0.1 * k as f64),
            translation: nalgebra::Vector3::new(0.0, 0.0, 5.0),
            points2d,
        });
    }
    points.retain(|p| !p.track.is_empty());
    ColmapModel {
        cameras: vec![ColmapCamera {
            id: 1,
            model: ColmapCameraModel::SimplePinhole {
                f: 500.0,
                cx: 320.0,
                cy: 240.0,
            },
            width: 640,
            height: 480,
        }],
        images,
        points,
    }
}

fn assert_tracks_match(got: &TrackTable, want: &TrackTable, track_id: impl Fn(usize) -> Id) {
    assert_eq!(got.n_observed(), want.n_observed());
    for f in 0..want.n_frames() {
        let gf = got
            .frame_ids()
            .iter()
            .position(|i| *i == want.frame_ids()[f])
            .unwrap();
        for p in 0..want.n_tracks() {
            let q = want.get(f, p);
            let gp = got.track_ids().iter().position(|i| *i == track_id(p));
            match (q, gp) {
                (Some(q), Some(gp)) => {
                    let r = got.get(gf, gp).unwrap();
                    assert!(
                        (r[0] - q[0]).abs() < 1e-9 && (r[1] - q[1]).abs() < 1e-9,
                        "frame {f} track {p}: {r:?} vs {q:?}"
                    );
                }
                (None, Some(gp)) => assert!(!got.is_visible(gf, gp)),
                (Some(_), None) => panic!("track {p} lost"),
                (None, None) => {}
            }
        }
    }
}

#[test]
fn colmap_tracks_round_trip_hand_built_model() {
    let d = tmp("colmap");
    let names = ["img10.png", "img2.png", "img1.png"];
    let mut t = expected();
    t = TrackTable::from_observations(
        names.iter().map(|n| Id::Str(n.to_string())).collect(),
        t.track_ids().to_vec(),
        &(0..3)
            .flat_map(|f| {
                let t = &t;
                (0..4).filter_map(move |p| {
                    t.get(f, p)
                        .map(|q| (f as u32, p as u32, q[0] + 300.0, q[1] + 200.0))
                })
            })
            .collect::<Vec<_>>(),
    )
    .unwrap();
    let m = model_of(&t, &names);
    let model_dir = d.join("model");
    m.write_text(&model_dir).unwrap();
    let loaded = read_tracks(&model_dir).unwrap();
    let got = &loaded.table;
    // Frames in natural name order; tracks by 3D point id.
    assert_eq!(
        got.frame_ids(),
        &[
            Id::Str("img1.png".into()),
            Id::Str("img2.png".into()),
            Id::Str("img10.png".into())
        ]
    );
    assert_eq!(
        got.track_ids(),
        &[Id::Int(100), Id::Int(103), Id::Int(106), Id::Int(109)]
    );
    assert_tracks_match(got, &t, |p| Id::Int(100 + 3 * p as i64));
    // The unmatched keypoints are reported, not silently dropped.
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].contains("POINT3D_ID -1"));
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn colmap_tracks_bad_input() {
    let d = tmp("colmapbad");
    // No model / a binary model: an I/O error that says what to do.
    let e = read_tracks(&d).unwrap_err();
    assert!(
        matches!(e, Error::Io { .. }) && e.to_string().contains("COLMAP"),
        "{e}"
    );
    std::fs::write(d.join("images.bin"), b"").unwrap();
    let e = read_tracks(&d).unwrap_err();
    assert!(e.to_string().contains("model_converter"), "{e}");
    let head = |id: u32, name: &str| format!("{id} 1 0 0 0 0 0 0 1 {name}\n");
    let cases: Vec<(&str, String, usize, &str)> = vec![
        (
            "same name",
            format!("{}1 2 5\n{}3 4 5\n", head(1, "a.png"), head(2, "a.png")),
            3,
            "NAME",
        ),
        (
            "nan",
            format!("{}1 nan 5\n", head(1, "a.png")),
            2,
            "POINTS2D[0].Y",
        ),
        (
            "triple",
            format!("{}1 2 5 3\n", head(1, "a.png")),
            2,
            "POINTS2D[1].Y",
        ),
        (
            "id",
            format!("{}1 2 x\n", head(1, "a.png")),
            2,
            "POINTS2D[0].POINT3D_ID",
        ),
    ];
    for (name, text, line, field) in cases {
        let m = d.join(name.replace(' ', "_"));
        std::fs::create_dir_all(&m).unwrap();
        std::fs::write(m.join("images.txt"), text).unwrap();
        match read_tracks(&m).unwrap_err() {
            Error::Parse {
                line: l, field: f, ..
            } => assert_eq!((l, f.as_str()), (line, field), "{name}"),
            e => panic!("{name}: {e}"),
        }
    }
    // Only unmatched keypoints: an empty table.
    let m = d.join("unmatched");
    std::fs::create_dir_all(&m).unwrap();
    std::fs::write(m.join("images.txt"), format!("{}1 2 -1\n", head(1, "a"))).unwrap();
    assert!(matches!(read_tracks(&m), Err(Error::EmptyTable { .. })));
    // A 3D point seen twice in one image keeps its first keypoint, with a warning.
    let m = d.join("twice");
    std::fs::create_dir_all(&m).unwrap();
    std::fs::write(
        m.join("images.txt"),
        format!(
            "{}1.5 2.5 9 3.5 4.5 9\n{}5.5 6.5 9\n",
            head(1, "a"),
            head(2, "b")
        ),
    )
    .unwrap();
    let l = read_tracks(&m).unwrap();
    assert_eq!(l.table.get(0, 0), Some([1.0, 2.0]));
    assert_eq!(l.table.get(1, 0), Some([5.0, 6.0]));
    assert!(
        l.warnings
            .iter()
            .any(|w| w.contains("1 keypoint(s) name a 3D point already seen")),
        "{:?}",
        l.warnings
    );
    std::fs::remove_dir_all(&d).ok();
}

/// Round trip through rank3's own COLMAP export: a perspective reconstruction written by
/// `output::colmap_model` + `ColmapModel::write_text`, its tracks read back, compared with
/// the input observations.
#[test]
fn colmap_tracks_round_trip_through_the_perspective_export() {
    use rank3::synth::{Shape, SynthConfig, generate};
    use rank3::{CameraModel, Config, Reconstruction};
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 10,
        points: 50,
        noise: 0.0,
        missing: 0.3,
        distance: 2.5,
        seed: 7,
        ..SynthConfig::default()
    })
    .unwrap();
    let mut cfg = Config {
        camera: CameraModel::Perspective,
        ..Config::default()
    };
    cfg.perspective.intrinsics.image_size = Some([641, 481]);
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let d = tmp("export");
    let dir = d.join("colmap");
    assert!(rank3::output::write_colmap(&rec, &s.table, &dir).unwrap());
    let back = read_tracks(&dir).unwrap().table;
    // 3D point k + 1 is kept track k; images are named by frame id.
    let want = s.table.select(&rec.kept_frames, &rec.kept_tracks);
    assert_eq!(back.n_frames(), want.n_frames());
    assert_eq!(back.n_tracks(), want.n_tracks());
    assert_tracks_match(&back, &want, |k| Id::Int(k as i64 + 1));
    std::fs::remove_dir_all(&d).ok();
}

/// `rank3 reconstruct` takes every new input: .npy, .npz, --x/--y, a COLMAP folder.
#[test]
fn cli_reconstructs_from_the_new_inputs() {
    use rank3::synth::{SynthConfig, generate};
    let d = tmp("cli");
    let s = generate(&SynthConfig {
        frames: 8,
        points: 30,
        noise: 0.1,
        seed: 3,
        ..SynthConfig::default()
    })
    .unwrap();
    let npy = d.join("t.npy");
    s.table.write(&npy).unwrap();
    let npz_path = d.join("t.npz");
    s.table.write(&npz_path).unwrap();
    let mut xs = String::new();
    let mut ys = String::new();
    for f in 0..s.table.n_frames() {
        for p in 0..s.table.n_tracks() {
            let q = s.table.get(f, p).unwrap();
            xs.push_str(&format!("{} ", q[0]));
            ys.push_str(&format!("{} ", q[1]));
        }
        xs.push('\n');
        ys.push('\n');
    }
    let xp = write(&d, "xs.txt", xs.as_bytes());
    let yp = write(&d, "ys.txt", ys.as_bytes());
    let names: Vec<String> = (0..s.table.n_frames())
        .map(|f| format!("f{f}.jpg"))
        .collect();
    let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let model = d.join("model");
    model_of(&s.table, &name_refs).write_text(&model).unwrap();
    let fast = [
        "--camera",
        "scaled-orthographic",
        "--no-robust",
        "--no-refine",
    ];
    for (k, input) in [
        vec![npy.into_os_string()],
        vec![npz_path.into_os_string()],
        vec![
            "--x".into(),
            xp.into_os_string(),
            "--y".into(),
            yp.into_os_string(),
        ],
        vec![model.into_os_string()],
    ]
    .into_iter()
    .enumerate()
    {
        let out = d.join(format!("out{k}"));
        let log = run_ok(
            bin()
                .arg("reconstruct")
                .args(&input)
                .arg("--out")
                .arg(&out)
                .args(fast),
        );
        assert!(log.contains("8 frames × 30 tracks"), "{log}");
        assert!(out.join("reconstruction.json").is_file());
    }
    let help = run_ok(bin().args(["reconstruct", "--help"]));
    for word in [".npy", ".npz", "COLMAP", "--x", "--y"] {
        assert!(help.contains(word), "{word} not in --help: {help}");
    }
    let err = run_err(
        bin()
            .args(["reconstruct", "--x"])
            .arg(&d)
            .arg("--out")
            .arg(d.join("o")),
    );
    assert!(err.contains("--y"), "{err}");
    std::fs::remove_dir_all(&d).ok();
}

/// Files written by NumPy itself (`np.save`, `np.savez`, `np.savez_compressed`), when a
/// Python with NumPy is on PATH; skipped, saying so, otherwise.
#[test]
fn numpy_written_files() {
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    let has_numpy = std::process::Command::new(&python)
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_numpy {
        eprintln!("{python} with numpy not found; skipping the NumPy interoperability test");
        return;
    }
    let d = tmp("numpy");
    let script = r#"
import sys, numpy as np
d = sys.argv[1]
a = np.arange(3 * 4 * 2, dtype=np.float64).reshape(3, 4, 2) * 1.25 - 7.0
a[0, 2] = np.nan
a[2, 3] = np.nan
np.save(d + '/c8.npy', a)
np.save(d + '/f4.npy', np.asfortranarray(a.astype(np.float32)))
w = np.empty((6, 4))
w[0::2] = a[:, :, 0]
w[1::2] = a[:, :, 1]
np.save(d + '/w.npy', w)
np.savez_compressed(d + '/z.npz', tracks=a, frame_ids=np.array(['f10', 'f2', 'f3']),
                    track_ids=np.array([5, 6, 7, 8], dtype=np.uint16))
np.savez(d + '/xy.npz', x=a[:, :, 0], y=np.asfortranarray(a[:, :, 1].astype(np.float32)))
np.save(d + '/be.npy', a.astype('>f8'))
np.save(d + '/i4.npy', np.zeros((3, 4, 2), dtype=np.int32))
"#;
    let out = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(&d)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut want = TrackTable::new(
        (0..3).map(Id::from).collect(),
        (0..4).map(Id::from).collect(),
    );
    for f in 0..3 {
        for n in 0..4 {
            if (f, n) != (0, 2) && (f, n) != (2, 3) {
                let base = ((f * 4 + n) * 2) as f64 * 1.25 - 7.0;
                want.set(f, n, base, base + 1.25);
            }
        }
    }
    for name in ["c8.npy", "f4.npy", "w.npy", "xy.npz"] {
        assert_eq!(read_tracks(d.join(name)).unwrap().table, want, "{name}");
    }
    let z = read_tracks(d.join("z.npz")).unwrap().table;
    assert_eq!(
        z.frame_ids(),
        &[
            Id::Str("f10".into()),
            Id::Str("f2".into()),
            Id::Str("f3".into())
        ]
    );
    assert_eq!(
        z.track_ids(),
        &[Id::Int(5), Id::Int(6), Id::Int(7), Id::Int(8)]
    );
    assert_eq!(z.n_observed(), want.n_observed());
    for (name, fault) in [("be.npy", ArrayFault::Dtype), ("i4.npy", ArrayFault::Dtype)] {
        let (f, _, field) = array_fault(read_tracks(d.join(name)).unwrap_err());
        assert_eq!((f, field.as_str()), (fault, "header.descr"), "{name}");
    }
    // And NumPy reads what rank3 writes.
    want.write(d.join("rank3.npy")).unwrap();
    let named = want.select(&[2, 1, 0], &[0, 1, 2, 3]);
    named.write(d.join("rank3.npz")).unwrap();
    let check = r#"
import sys, numpy as np
d = sys.argv[1]
a = np.load(d + '/rank3.npy')
assert a.shape == (3, 4, 2) and a.dtype == np.float64, (a.shape, a.dtype)
assert np.isnan(a[0, 2]).all() and a[1, 1, 0] == 10 * 1.25 - 7.0, a[1, 1]
z = np.load(d + '/rank3.npz')
assert sorted(z.files) == ['frame_ids', 'track_ids', 'tracks'], z.files
assert list(z['frame_ids']) == [2, 1, 0], z['frame_ids']
assert np.array_equal(z['tracks'], a[::-1], equal_nan=True)
print('ok')
"#;
    let out = std::process::Command::new(&python)
        .args(["-c", check])
        .arg(&d)
        .output()
        .unwrap();
    assert!(
        out.status.success() && String::from_utf8_lossy(&out.stdout).contains("ok"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&d).ok();
}

/// NumPy arrays are dense: writing a large, sparse table as one is refused before any
/// allocation (the sparse `.csv` is the format for it), and all-NaN x/y text matrices are an
/// empty table.
#[test]
fn dense_array_output_is_budgeted_and_empty_xy_refused() {
    let d = tmp("budget");
    let mut t = TrackTable::new(
        (0..100_000).map(Id::from).collect(),
        (0..100_000).map(Id::from).collect(),
    );
    t.set(0, 0, 1.0, 2.0);
    for name in ["big.npy", "big.npz"] {
        let e = t.write(d.join(name)).unwrap_err();
        assert!(matches!(e, Error::TooLarge { .. }), "{e}");
        assert!(!d.join(name).exists());
    }
    let xs = write(&d, "xs.txt", b"nan nan\nnan nan\n");
    let ys = write(&d, "ys.txt", b"nan nan\nnan nan\n");
    assert!(matches!(read_xy(&xs, &ys), Err(Error::EmptyTable { .. })));
    std::fs::remove_dir_all(&d).ok();
}
