//! Long CSV format (`.csv`): a header naming `frame`, `track`, `x`, `y` (any order, any
//! case), then one row per observation. Frame and track ids are integers or strings.
//! Columns other than those four are ignored with one warning.
//!
//! Order: frames and tracks are sorted ascending when all their ids are integers, and kept
//! in order of first appearance otherwise.

use std::fmt::Write as _;
use std::io::Read;
use std::path::Path;

use rustc_hash::FxHashMap;

use super::{Id, TrackTable, order_ids};
use crate::{Error, Result};

const FIELDS: [&str; 4] = ["frame", "track", "x", "y"];

/// Parses CSV text; returns the table and the reader's warnings.
pub fn parse(text: &str, path: &Path) -> Result<(TrackTable, Vec<String>)> {
    parse_reader(text.as_bytes(), path)
}

/// Ids as they appear, each mapped to its index in order of first appearance. Integer ids
/// (the common case) are hashed as integers, and the last id looked up is remembered (long
/// tables are usually frame-major, so the frame id repeats row after row).
#[derive(Default)]
struct Ids {
    ints: FxHashMap<i64, u32>,
    strs: FxHashMap<Box<str>, u32>,
    ids: Vec<Id>,
    last: Option<(Vec<u8>, u32)>,
}

impl Ids {
    fn index(&mut self, field: &[u8]) -> std::result::Result<u32, String> {
        if let Some((bytes, i)) = &self.last
            && bytes.as_slice() == field
        {
            return Ok(*i);
        }
        let text = std::str::from_utf8(field).map_err(|_| "is not valid UTF-8".to_string())?;
        let next = self.ids.len() as u32;
        let i = match Id::parse(text) {
            Id::Int(v) => *self.ints.entry(v).or_insert_with(|| {
                self.ids.push(Id::Int(v));
                next
            }),
            Id::Str(s) => match self.strs.get(s.as_str()) {
                Some(&i) => i,
                None => {
                    self.strs.insert(s.clone().into_boxed_str(), next);
                    self.ids.push(Id::Str(s));
                    next
                }
            },
        };
        match &mut self.last {
            Some((bytes, j)) => {
                bytes.clear();
                bytes.extend_from_slice(field);
                *j = i;
            }
            None => self.last = Some((field.to_vec(), i)),
        }
        Ok(i)
    }

    /// The ids in rank3's order ([`order_ids`]) and, per index of first appearance, its new
    /// index.
    fn finish(self) -> (Vec<Id>, Vec<u32>) {
        let mut ids = self.ids;
        let n = ids.len();
        if ids.iter().all(|i| matches!(i, Id::Int(_))) {
            let mut order: Vec<u32> = (0..n as u32).collect();
            order.sort_unstable_by(|&a, &b| ids[a as usize].cmp(&ids[b as usize]));
            let mut remap = vec![0u32; n];
            for (new, &old) in order.iter().enumerate() {
                remap[old as usize] = new as u32;
            }
            order_ids(&mut ids);
            (ids, remap)
        } else {
            (ids, (0..n as u32).collect())
        }
    }
}

/// Parses CSV from a reader (a file is streamed, never held whole in memory); returns the
/// table and the reader's warnings.
///
/// Cost: one pass over the bytes with one hash look-up per id (none when the frame id
/// repeats), then a sort of the observations by (frame, track) to build the table and find
/// repeated pairs: `O(n log n)` time and 24 bytes per observation plus 4 for its line.
pub fn parse_reader<R: Read>(reader: R, path: &Path) -> Result<(TrackTable, Vec<String>)> {
    let mut rdr = ::csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(::csv::Trim::All)
        .buffer_capacity(1 << 20)
        .from_reader(reader);
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

    let mut obs: Vec<(u32, u32, f64, f64)> = Vec::new();
    let mut lines: Vec<u32> = Vec::new();
    let mut frames = Ids::default();
    let mut tracks = Ids::default();
    let mut rec = ::csv::ByteRecord::new();
    loop {
        match rdr.read_byte_record(&mut rec) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => {
                let line = e.position().map_or(0, |p| p.line() as usize);
                return Err(Error::parse(path, line, "row", e.to_string()));
            }
        }
        let line = rec.position().map_or(0, |p| p.line() as usize);
        if rec.iter().all(|f| f.is_empty()) {
            continue;
        }
        let field = |k: usize| -> &[u8] { rec.get(col[k]).unwrap_or(b"") };
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
        let num = |k: usize, b: &[u8]| -> Result<f64> {
            let s = String::from_utf8_lossy(b);
            match std::str::from_utf8(b).ok().map(str::parse::<f64>) {
                Some(Ok(v)) if v.is_finite() => Ok(v),
                Some(Ok(_)) => Err(Error::parse(
                    path,
                    line,
                    FIELDS[k],
                    format!(
                        "`{}` is not finite (leave a missing observation out)",
                        super::excerpt(&s)
                    ),
                )),
                _ => Err(Error::parse(
                    path,
                    line,
                    FIELDS[k],
                    format!("`{}` is not a number", super::excerpt(&s)),
                )),
            }
        };
        let (x, y) = (num(2, xs)?, num(3, ys)?);
        let f = frames
            .index(field(0))
            .map_err(|m| Error::parse(path, line, "frame", format!("the frame id {m}")))?;
        let p = tracks
            .index(field(1))
            .map_err(|m| Error::parse(path, line, "track", format!("the track id {m}")))?;
        obs.push((f, p, x, y));
        lines.push(u32::try_from(line).unwrap_or(u32::MAX));
    }
    if obs.is_empty() {
        return Err(Error::EmptyTable {
            path: Some(path.to_path_buf()),
            reason: "no observation rows after the header".into(),
        });
    }
    let (frame_ids, frame_map) = frames.finish();
    let (track_ids, track_map) = tracks.finish();
    for o in &mut obs {
        o.0 = frame_map[o.0 as usize];
        o.1 = track_map[o.1 as usize];
    }
    TrackTable::from_observations(frame_ids, track_ids, &obs)
        .map(|t| (t, warnings))
        .map_err(|d| {
            let (first, second) = if lines[d.first] <= lines[d.second] {
                (d.first, d.second)
            } else {
                (d.second, d.first)
            };
            let o = obs[first];
            Error::parse(
                path,
                lines[second] as usize,
                "track",
                format!(
                    "frame {} track {} is given twice (first on line {})",
                    d.frame_ids[o.0 as usize], d.track_ids[o.1 as usize], lines[first]
                ),
            )
        })
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
        crate::table::parse_error_parts(parse(txt, p()).unwrap_err())
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
