//! Long CSV format (`.csv`): a header naming `frame`, `track`, `x`, `y` (any order, any
//! case), then one row per observation. Frame and track ids are integers or strings.
//! Columns other than those four are ignored with one warning.
//!
//! Order: frames and tracks are sorted ascending when all their ids are integers, and kept
//! in order of first appearance otherwise.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use super::{Id, TrackTable, order_ids};
use crate::{Error, Result};

const FIELDS: [&str; 4] = ["frame", "track", "x", "y"];

/// Parses CSV text; returns the table and the reader's warnings.
pub fn parse(text: &str, path: &Path) -> Result<(TrackTable, Vec<String>)> {
    let mut rdr = ::csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(::csv::Trim::All)
        .from_reader(text.as_bytes());
    let headers = rdr
        .headers()
        .map_err(|e| Error::parse(path, 1, "header", e.to_string()))?
        .clone();
    let mut col = [usize::MAX; 4];
    let mut extra = Vec::new();
    for (i, h) in headers.iter().enumerate() {
        let h = h.trim_start_matches('\u{feff}').to_ascii_lowercase();
        match FIELDS.iter().position(|f| *f == h) {
            Some(k) if col[k] == usize::MAX => col[k] = i,
            Some(_) => {
                return Err(Error::parse(
                    path,
                    1,
                    h.clone(),
                    format!("column `{h}` appears twice in the header"),
                ));
            }
            None => extra.push(h),
        }
    }
    for (k, name) in FIELDS.iter().enumerate() {
        if col[k] == usize::MAX {
            return Err(Error::parse(
                path,
                1,
                *name,
                format!(
                    "header has no `{name}` column (expected `frame,track,x,y`, found `{}`)",
                    headers.iter().collect::<Vec<_>>().join(",")
                ),
            ));
        }
    }
    let mut warnings = Vec::new();
    if !extra.is_empty() {
        warnings.push(format!(
            "{}: ignoring extra column(s) {}",
            path.display(),
            extra.join(", ")
        ));
    }

    struct Obs {
        frame: Id,
        track: Id,
        x: f64,
        y: f64,
    }
    let mut obs = Vec::new();
    let mut first_seen: HashMap<(Id, Id), usize> = HashMap::new();
    let mut frames: Vec<Id> = Vec::new();
    let mut tracks: Vec<Id> = Vec::new();
    let mut frame_set: HashMap<Id, ()> = HashMap::new();
    let mut track_set: HashMap<Id, ()> = HashMap::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            Error::parse(path, line, "row", e.to_string())
        })?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        if rec.iter().all(|f| f.is_empty()) {
            continue;
        }
        let field = |k: usize| -> &str { rec.get(col[k]).unwrap_or("") };
        for k in 0..2 {
            if field(k).is_empty() {
                return Err(Error::parse(
                    path,
                    line,
                    FIELDS[k],
                    format!("missing {} id", FIELDS[k]),
                ));
            }
        }
        let (xs, ys) = (field(2), field(3));
        match (xs.is_empty(), ys.is_empty()) {
            (false, true) => {
                return Err(Error::parse(path, line, "y", "x given without y"));
            }
            (true, false) => {
                return Err(Error::parse(path, line, "x", "y given without x"));
            }
            (true, true) => {
                return Err(Error::parse(
                    path,
                    line,
                    "x",
                    "x and y are empty (leave a missing observation out instead)",
                ));
            }
            _ => {}
        }
        let num = |k: usize, s: &str| -> Result<f64> {
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(_) => Err(Error::parse(
                    path,
                    line,
                    FIELDS[k],
                    format!("`{s}` is not finite (leave a missing observation out)"),
                )),
                Err(_) => Err(Error::parse(
                    path,
                    line,
                    FIELDS[k],
                    format!("`{s}` is not a number"),
                )),
            }
        };
        let (x, y) = (num(2, xs)?, num(3, ys)?);
        let frame = Id::parse(field(0));
        let track = Id::parse(field(1));
        if let Some(prev) = first_seen.insert((frame.clone(), track.clone()), line) {
            return Err(Error::parse(
                path,
                line,
                "track",
                format!("frame {frame} track {track} is given twice (first on line {prev})"),
            ));
        }
        if frame_set.insert(frame.clone(), ()).is_none() {
            frames.push(frame.clone());
        }
        if track_set.insert(track.clone(), ()).is_none() {
            tracks.push(track.clone());
        }
        obs.push(Obs { frame, track, x, y });
    }
    if obs.is_empty() {
        return Err(Error::EmptyTable {
            path: Some(path.to_path_buf()),
            reason: "no observation rows after the header".into(),
        });
    }
    order_ids(&mut frames);
    order_ids(&mut tracks);
    let fidx: HashMap<&Id, usize> = frames.iter().enumerate().map(|(i, f)| (f, i)).collect();
    let tidx: HashMap<&Id, usize> = tracks.iter().enumerate().map(|(i, t)| (t, i)).collect();
    let pos: Vec<(usize, usize, f64, f64)> = obs
        .iter()
        .map(|o| (fidx[&o.frame], tidx[&o.track], o.x, o.y))
        .collect();
    crate::budget::check_table(Some(path), frames.len(), tracks.len(), pos.len())?;
    let mut t = TrackTable::new(frames.clone(), tracks.clone());
    for (f, p, x, y) in pos {
        t.set(f, p, x, y);
    }
    Ok((t, warnings))
}

/// Writes the observed entries as `frame,track,x,y` rows, frame-major.
pub fn to_string(t: &TrackTable) -> String {
    let mut s = String::from("frame,track,x,y\n");
    for f in 0..t.n_frames() {
        for p in 0..t.n_tracks() {
            if let Some([x, y]) = t.get(f, p) {
                let _ = writeln!(
                    s,
                    "{},{},{x},{y}",
                    csv_field(&t.frame_ids()[f]),
                    csv_field(&t.track_ids()[p])
                );
            }
        }
    }
    s
}

fn csv_field(id: &Id) -> String {
    let s = id.to_string();
    if s.contains([',', '"', '\n', '\r']) || s.trim() != s {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.csv")
    }

    #[test]
    fn parses_any_column_order_and_warns_once_on_extras() {
        let txt = "track,frame,y,x,score,note\n7,2,20,10,0.9,a\n7,1,21,11,0.8,b\n3,1,1,2,0,c\n";
        let (t, w) = parse(txt, p()).unwrap();
        assert_eq!(w.len(), 1);
        assert!(w[0].contains("score") && w[0].contains("note"));
        assert_eq!(t.frame_ids(), &[Id::Int(1), Id::Int(2)]);
        assert_eq!(t.track_ids(), &[Id::Int(3), Id::Int(7)]);
        assert_eq!(t.get(0, 1), Some([11.0, 21.0]));
        assert_eq!(t.get(1, 0), None);
        let (back, _) = parse(&to_string(&t), p()).unwrap();
        assert_eq!(back, t);
    }

    #[test]
    fn string_ids_keep_first_appearance_order() {
        let txt = "frame,track,x,y\nimg_b,corner,1,2\nimg_a,\"edge, left\",3,4\nimg_a,corner,5,6\n";
        let (t, _) = parse(txt, p()).unwrap();
        assert_eq!(
            t.frame_ids(),
            &[Id::Str("img_b".into()), Id::Str("img_a".into())]
        );
        assert_eq!(t.track_ids()[1], Id::Str("edge, left".into()));
        let (back, _) = parse(&to_string(&t), p()).unwrap();
        assert_eq!(back, t);
    }

    fn err(txt: &str) -> (usize, String, String) {
        crate::tracks::parse_error_parts(parse(txt, p()).unwrap_err())
    }

    #[test]
    fn errors_name_line_and_field() {
        let (l, f, m) = err("frame,track,x,y\n0,0,1,2\n0,1,abc,2\n");
        assert_eq!((l, f.as_str()), (3, "x"));
        assert!(m.contains("not a number"));
        let (l, f, _) = err("frame,track,x,y\n0,0,1,inf\n");
        assert_eq!((l, f.as_str()), (2, "y"));
        let (l, f, m) = err("frame,track,x,y\n0,0,1,2\n1,0,3,4\n0,0,5,6\n");
        assert_eq!((l, f.as_str()), (4, "track"));
        assert!(m.contains("twice") && m.contains("line 2"));
        let (l, f, m) = err("frame,track,x,y\n0,0,1,\n");
        assert_eq!((l, f.as_str()), (2, "y"));
        assert!(m.contains("x given without y"));
        let (l, f, _) = err("frame,track,x,y\n0,0,1\n");
        assert_eq!((l, f.as_str()), (2, "y"));
        let (l, f, _) = err("frame,x,y\n0,1,2\n");
        assert_eq!((l, f.as_str()), (1, "track"));
        assert!(matches!(
            parse("frame,track,x,y\n", p()),
            Err(Error::EmptyTable { .. })
        ));
    }
}
