//! JSON format (`.json`):
//!
//! ```json
//! { "frames": [0, 1, 2],            // optional: frame order (ids: integers or strings)
//!   "tracks": ["a", "b"],           // optional: track order
//!   "observations": [ {"frame": 0, "track": "a", "x": 10.5, "y": 20.0}, ... ] }
//! ```
//!
//! Without `frames`/`tracks` the order is the CSV one (ascending integer ids, else first
//! appearance). Errors name the line of the offending observation.

use std::collections::HashMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::value::RawValue;

use super::{Id, TrackTable, order_ids};
use crate::{Error, Result};

#[derive(Deserialize)]
struct FileIn<'a> {
    frames: Option<Vec<Id>>,
    tracks: Option<Vec<Id>>,
    #[serde(borrow)]
    observations: Vec<&'a RawValue>,
}

#[derive(Serialize, Deserialize)]
struct Observation {
    frame: Id,
    track: Id,
    x: Option<f64>,
    y: Option<f64>,
}

type Row = (usize, usize, Id, Id, f64, f64);

/// Line numbers of positions in `text` visited in increasing order: each call counts the
/// newlines since the previous position only, so a whole file costs one pass (O(length)),
/// not one rescan from the start per observation.
struct Lines<'a> {
    text: &'a str,
    offset: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    fn new(text: &'a str) -> Self {
        Lines {
            text,
            offset: 0,
            line: 1,
        }
    }

    /// The 1-based line where `raw` (a slice of `text`) starts.
    fn of(&mut self, raw: &RawValue) -> usize {
        let offset = (raw.get().as_ptr() as usize)
            .saturating_sub(self.text.as_ptr() as usize)
            .min(self.text.len());
        if offset < self.offset {
            // Not in order (never for serde's array order): count from the start.
            self.offset = 0;
            self.line = 1;
        }
        self.line += self.text.as_bytes()[self.offset..offset]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.offset = offset;
        self.line
    }
}

/// Parses JSON text; `path` is used in error messages.
pub fn parse(text: &str, path: &Path) -> Result<TrackTable> {
    let file: FileIn = serde_json::from_str(text)
        .map_err(|e| Error::parse(path, e.line(), "json", e.to_string()))?;
    let mut obs = Vec::with_capacity(file.observations.len());
    let mut lines = Lines::new(text);
    for (k, raw) in file.observations.iter().enumerate() {
        let line = lines.of(raw);
        let o: Observation = serde_json::from_str(raw.get())
            .map_err(|e| Error::parse(path, line, format!("observations[{k}]"), e.to_string()))?;
        let (x, y) = match (o.x, o.y) {
            (Some(x), Some(y)) => (x, y),
            (Some(_), None) => {
                return Err(Error::parse(
                    path,
                    line,
                    format!("observations[{k}].y"),
                    "x given without y",
                ));
            }
            (None, Some(_)) => {
                return Err(Error::parse(
                    path,
                    line,
                    format!("observations[{k}].x"),
                    "y given without x",
                ));
            }
            (None, None) => {
                return Err(Error::parse(
                    path,
                    line,
                    format!("observations[{k}].x"),
                    "x and y are missing",
                ));
            }
        };
        obs.push((line, k, o.frame, o.track, x, y));
    }
    if obs.is_empty() {
        return Err(Error::EmptyTable {
            path: Some(path.to_path_buf()),
            reason: "`observations` is empty".into(),
        });
    }
    let collect = |given: Option<Vec<Id>>,
                   pick: &dyn Fn(&Row) -> Id,
                   what: &str|
     -> Result<Vec<Id>> {
        match given {
            Some(ids) => {
                let mut seen = HashMap::new();
                for id in &ids {
                    if seen.insert(id.clone(), ()).is_some() {
                        return Err(Error::parse(path, 1, what, format!("id {id} listed twice")));
                    }
                }
                Ok(ids)
            }
            None => {
                let mut seen = HashMap::new();
                let mut ids = Vec::new();
                for o in &obs {
                    let id = pick(o);
                    if seen.insert(id.clone(), ()).is_none() {
                        ids.push(id);
                    }
                }
                order_ids(&mut ids);
                Ok(ids)
            }
        }
    };
    let frames = collect(file.frames, &|o| o.2.clone(), "frames")?;
    let tracks = collect(file.tracks, &|o| o.3.clone(), "tracks")?;
    let fidx: HashMap<&Id, usize> = frames.iter().enumerate().map(|(i, f)| (f, i)).collect();
    let tidx: HashMap<&Id, usize> = tracks.iter().enumerate().map(|(i, t)| (t, i)).collect();
    let mut indexed: Vec<(u32, u32, f64, f64)> = Vec::with_capacity(obs.len());
    for (line, k, frame, track, x, y) in &obs {
        for (v, name) in [(x, "x"), (y, "y")] {
            if !v.is_finite() {
                return Err(Error::parse(
                    path,
                    *line,
                    format!("observations[{k}].{name}"),
                    "not finite",
                ));
            }
        }
        let f = *fidx.get(frame).ok_or_else(|| {
            Error::parse(
                path,
                *line,
                format!("observations[{k}].frame"),
                format!("frame {frame} is not in `frames`"),
            )
        })?;
        let p = *tidx.get(track).ok_or_else(|| {
            Error::parse(
                path,
                *line,
                format!("observations[{k}].track"),
                format!("track {track} is not in `tracks`"),
            )
        })?;
        indexed.push((f as u32, p as u32, *x, *y));
    }
    TrackTable::from_observations(frames, tracks, &indexed).map_err(|d| {
        let (a, b) = (d.first.min(d.second), d.first.max(d.second));
        let (line, k, frame, track) = (obs[b].0, obs[b].1, &obs[b].2, &obs[b].3);
        Error::parse(
            path,
            line,
            format!("observations[{k}]"),
            format!(
                "frame {frame} track {track} is given twice (first on line {})",
                obs[a].0
            ),
        )
    })
}

/// Serializes a table (one observation per line).
pub fn to_string(t: &TrackTable) -> String {
    let mut observations = Vec::with_capacity(t.n_observed());
    for f in 0..t.n_frames() {
        for p in 0..t.n_tracks() {
            if let Some([x, y]) = t.get(f, p) {
                observations.push(Observation {
                    frame: t.frame_ids()[f].clone(),
                    track: t.track_ids()[p].clone(),
                    x: Some(x),
                    y: Some(y),
                });
            }
        }
    }
    let mut s = String::from("{\n");
    s.push_str(&format!(
        "  \"frames\": {},\n",
        serde_json::to_string(t.frame_ids()).unwrap_or_default()
    ));
    s.push_str(&format!(
        "  \"tracks\": {},\n",
        serde_json::to_string(t.track_ids()).unwrap_or_default()
    ));
    s.push_str("  \"observations\": [\n");
    for (i, o) in observations.iter().enumerate() {
        s.push_str("    ");
        s.push_str(&serde_json::to_string(o).unwrap_or_default());
        if i + 1 < observations.len() {
            s.push(',');
        }
        s.push('\n');
    }
    s.push_str("  ]\n}\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.json")
    }

    #[test]
    fn roundtrip_and_order() {
        let txt = r#"{"observations": [
            {"frame": 2, "track": "b", "x": 1, "y": 2},
            {"frame": 1, "track": "a", "x": 3, "y": 4},
            {"frame": 1, "track": "b", "x": 5, "y": 6}
        ]}"#;
        let t = parse(txt, p()).unwrap();
        assert_eq!(t.frame_ids(), &[Id::Int(1), Id::Int(2)]);
        assert_eq!(t.track_ids(), &[Id::Str("b".into()), Id::Str("a".into())]);
        assert_eq!(parse(&to_string(&t), p()).unwrap(), t);
    }

    #[test]
    fn errors_name_line_and_field() {
        let txt = "{\"observations\": [\n{\"frame\": 0, \"track\": 0, \"x\": 1, \"y\": 2},\n{\"frame\": 0, \"track\": 0, \"x\": 1, \"y\": 2}\n]}";
        match parse(txt, p()).unwrap_err() {
            Error::Parse {
                line,
                field,
                message,
                ..
            } => {
                assert_eq!(line, 3);
                assert_eq!(field, "observations[1]");
                assert!(message.contains("twice"));
            }
            e => panic!("{e}"),
        }
        let txt = "{\"observations\": [\n{\"frame\": 0, \"track\": 0, \"x\": 1}\n]}";
        match parse(txt, p()).unwrap_err() {
            Error::Parse { line, field, .. } => {
                assert_eq!((line, field.as_str()), (2, "observations[0].y"));
            }
            e => panic!("{e}"),
        }
        let txt = "{\"observations\": [\n{\"frame\": 0, \"track\": 0, \"x\": \"a\", \"y\": 1}\n]}";
        assert!(matches!(parse(txt, p()), Err(Error::Parse { line: 2, .. })));
        assert!(matches!(
            parse("{\"observations\": []}", p()),
            Err(Error::EmptyTable { .. })
        ));
        assert!(matches!(parse("{", p()), Err(Error::Parse { .. })));
    }
}
