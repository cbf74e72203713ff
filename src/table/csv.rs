//! Long CSV format (`.csv`): a header naming `frame`, `track`, `x`, `y` (any order, any
//! case), then one row per observation. Frame and track ids are integers or strings.
//! Columns other than those four are ignored with one warning.
//!
//! Order: frames and tracks are sorted ascending when all their ids are integers, and kept
//! in order of first appearance otherwise.

use std::fmt::Write as _;
use std::io::Read;
use std::path::Path;

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::{Id, TrackTable, order_ids};
use crate::{Error, Result};

const FIELDS: [&str; 4] = ["frame", "track", "x", "y"];

/// Integer ids below this are looked up in a table (at most 16 MB) instead of a hash map.
const DIRECT_IDS: usize = 1 << 22;

/// Parses CSV text; returns the table and the reader's warnings.
pub fn parse(text: &str, path: &Path) -> Result<(TrackTable, Vec<String>)> {
    parse_reader(text.as_bytes(), path)
}

/// Ids as they appear, each mapped to its index in order of first appearance. Integer ids
/// (the common case) are hashed as integers, and the last id looked up is remembered (long
/// tables are usually frame-major, so the frame id repeats row after row).
#[derive(Default)]
struct Ids {
    /// Index of each small non-negative integer id (`u32::MAX`: not seen), grown on demand
    /// up to `DIRECT_IDS` entries: ids numbered from 0, the common case, skip the hash.
    direct: Vec<u32>,
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
        let i = self.intern(Id::parse(text));
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

    /// Adds the ids of `later` (read from a later part of the input) that are new here, in
    /// their order of first appearance; returns, per index of `later`, its index here.
    fn merge(&mut self, later: Ids) -> Vec<u32> {
        later.ids.into_iter().map(|id| self.intern(id)).collect()
    }

    /// The index of `id`, added at the end when it is new.
    fn intern(&mut self, id: Id) -> u32 {
        let next = self.ids.len() as u32;
        match id {
            Id::Int(v) if (0..DIRECT_IDS as i64).contains(&v) => {
                let v = v as usize;
                if v >= self.direct.len() {
                    self.direct
                        .resize((v + 1).max(2 * self.direct.len()).min(DIRECT_IDS), u32::MAX);
                }
                if self.direct[v] == u32::MAX {
                    self.direct[v] = next;
                    self.ids.push(Id::Int(v as i64));
                }
                self.direct[v]
            }
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
        }
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

/// Bytes parsed by one thread at a time: a block of the file is
/// `PIECE_BYTES × threads` and is split at line ends into that many pieces.
const PIECE_BYTES: usize = 4 << 20;

/// Parses CSV from a reader (a file is streamed, never held whole in memory); returns the
/// table and the reader's warnings.
///
/// Both cores are used: the file is read a block at a time (`PIECE_BYTES` per thread), the
/// block is cut at line ends into one piece per thread and the pieces are parsed in
/// parallel, each with its own id tables, which are then merged in file order (so ids keep
/// their order of first appearance). A block that holds a quote or a lone carriage return,
/// where a line end need not end a record, and everything after it, is parsed by one
/// streaming reader instead, with the same results. Errors name the first bad line in file
/// order, as a sequential reader would.
///
/// Cost: one pass over the bytes with one hash look-up per id (none when the frame id
/// repeats), then a sort of the observations by (frame, track) to build the table and find
/// repeated pairs: `O(n log n)` time and 24 bytes per observation plus 4 for its line, plus
/// one block of text.
pub fn parse_reader<R: Read>(reader: R, path: &Path) -> Result<(TrackTable, Vec<String>)> {
    let threads = rayon::current_num_threads().max(1);
    parse_in_pieces(reader, path, PIECE_BYTES, threads)
}

/// [`parse_reader`] with blocks of `pieces` pieces of about `piece_bytes` each.
fn parse_in_pieces<R: Read>(
    reader: R,
    path: &Path,
    piece_bytes: usize,
    pieces: usize,
) -> Result<(TrackTable, Vec<String>)> {
    let mut rows = Rows::default();
    let warnings = read_in_pieces(reader, path, piece_bytes, pieces, &mut |part| {
        rows.append(part);
        Ok(())
    })?;
    rows.finish(path, warnings)
}

/// Records the streaming fallback reader hands on at a time (bounded memory).
const FALLBACK_RECORDS: usize = 1 << 20;

/// The reading loop of [`parse_in_pieces`] and [`scan_reader`]: hands the parsed rows to
/// `take` a part at a time, in file order, each part with its own id tables (merge them in
/// the order received); returns the header's warnings.
fn read_in_pieces<R: Read>(
    mut reader: R,
    path: &Path,
    piece_bytes: usize,
    pieces: usize,
    take: &mut dyn FnMut(Rows) -> Result<()>,
) -> Result<Vec<String>> {
    let block = piece_bytes * pieces;
    let mut data = Vec::new();
    let mut eof = fill(&mut reader, &mut data, block).map_err(|e| Error::io(path, e))?;
    // (A blank first line goes to the streaming reader, which skips it as before.)
    let header_end = memchr::memchr(b'\n', &data)
        .filter(|&nl| plain(&data[..=nl]) && !data[..nl].trim_ascii().is_empty());
    let Some(nl) = header_end else {
        // A quoted or unusual header: one streaming reader for the whole file.
        let mut rdr = csv_reader(
            LineEnds::new(std::io::Cursor::new(data).chain(reader)),
            true,
        );
        let (col, warnings) = header(&mut rdr, path)?;
        read_all_in_parts(&mut rdr, &col, 1, path, take)?;
        return Ok(warnings);
    };
    let (col, warnings) = header(&mut csv_reader(&data[..nl], true), path)?;
    data.drain(..=nl);
    // `data` starts at the start of line `line`.
    let mut line = 2;
    loop {
        if !eof && data.len() < block {
            eof = fill(&mut reader, &mut data, block).map_err(|e| Error::io(path, e))?;
        }
        let cut = if eof {
            Some(data.len())
        } else {
            memchr::memrchr(b'\n', &data).map(|i| i + 1)
        };
        let Some(cut) = cut.filter(|&c| plain(&data[..c])) else {
            // No line end in a whole block, or quotes: stream the rest with one reader.
            let mut rdr = csv_reader(
                LineEnds::new(std::io::Cursor::new(data).chain(reader)),
                false,
            );
            read_all_in_parts(&mut rdr, &col, line, path, take)?;
            break;
        };
        let parts = split_at_lines(&data[..cut], pieces);
        let mut starts = Vec::with_capacity(parts.len());
        for piece in &parts {
            starts.push(line);
            line += memchr::memchr_iter(b'\n', piece).count();
        }
        let parsed: Vec<Result<Rows>> = parts
            .par_iter()
            .zip(&starts)
            .map(|(piece, &start)| {
                let mut part = Rows::default();
                part.read_plain(piece, &col, start, path)?;
                Ok(part)
            })
            .collect();
        for part in parsed {
            take(part?)?;
        }
        data.drain(..cut);
        if eof && data.is_empty() {
            break;
        }
    }
    Ok(warnings)
}

/// Every record of `rdr` (whose input starts on line `first_line`), handed to `take`
/// [`FALLBACK_RECORDS`] at a time.
fn read_all_in_parts<R: Read>(
    rdr: &mut ::csv::Reader<LineEnds<R>>,
    col: &[usize; 4],
    first_line: usize,
    path: &Path,
    take: &mut dyn FnMut(Rows) -> Result<()>,
) -> Result<()> {
    loop {
        let mut part = Rows::default();
        let done = part.read_all(rdr, col, first_line, path, FALLBACK_RECORDS)?;
        take(part)?;
        if done {
            return Ok(());
        }
    }
}

/// One observation of a scanned CSV file ([`scan_reader`]): frame and track as indices into
/// [`Scanned::frame_ids`] / [`Scanned::track_ids`] (order of first appearance in the file),
/// and the line it is on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScannedObservation {
    pub frame: u32,
    pub track: u32,
    pub x: f64,
    pub y: f64,
    pub line: u32,
}

/// What a scan of a CSV file found besides its observations.
#[derive(Debug, Clone, Default)]
pub struct Scanned {
    /// Frame ids in order of first appearance (the index of [`ScannedObservation::frame`]).
    pub frame_ids: Vec<Id>,
    /// Track ids in order of first appearance.
    pub track_ids: Vec<Id>,
    /// For each frame (first-appearance index), its position in rank3's order (ascending
    /// when all ids are integers, else first appearance), as [`parse_reader`] orders them.
    pub frame_order: Vec<u32>,
    /// The same for tracks.
    pub track_order: Vec<u32>,
    /// Observation rows read.
    pub observations: usize,
    pub warnings: Vec<String>,
}

/// Reads a CSV table without holding it: hands its observations to `visit` a block at a
/// time (about `PIECE_BYTES` per thread), in file order, with ids numbered in order of first
/// appearance — the same numbers on every scan of the same file. Memory: one block of
/// text and its rows, plus the id tables. Errors name the file, line and field as
/// [`parse_reader`]'s; a repeated (frame, track) pair is not detected here (that needs
/// every pair: the caller's business). Used by the streaming factorization
/// ([`crate::stream`]), which reads a file more than once.
pub fn scan_reader<R: Read>(
    reader: R,
    path: &Path,
    visit: &mut dyn FnMut(&[ScannedObservation]) -> Result<()>,
) -> Result<Scanned> {
    let threads = rayon::current_num_threads().max(1);
    let (mut frames, mut tracks) = (Ids::default(), Ids::default());
    let mut observations = 0;
    let mut buf = Vec::new();
    let warnings = read_in_pieces(reader, path, PIECE_BYTES, threads, &mut |part| {
        let frame_map = frames.merge(part.frames);
        let track_map = tracks.merge(part.tracks);
        buf.clear();
        buf.extend(
            part.obs
                .iter()
                .zip(&part.lines)
                .map(|(&(f, p, x, y), &line)| ScannedObservation {
                    frame: frame_map[f as usize],
                    track: track_map[p as usize],
                    x,
                    y,
                    line,
                }),
        );
        observations += buf.len();
        visit(&buf)
    })?;
    if observations == 0 {
        return Err(Error::EmptyTable {
            path: Some(path.to_path_buf()),
            reason: "no observation rows after the header".into(),
        });
    }
    let (frame_ids, track_ids) = (frames.ids.clone(), tracks.ids.clone());
    let (_, frame_order) = frames.finish();
    let (_, track_order) = tracks.finish();
    Ok(Scanned {
        frame_ids,
        track_ids,
        frame_order,
        track_order,
        observations,
        warnings,
    })
}

/// A reader that notes where the lines end in what passes through it, so that a record's
/// position gives its line: a line ends at `\n`, at `\r\n` and at a lone `\r` (the csv
/// crate's record terminators; a quoted field's line end counts too, as in the text).
/// Memory: the line ends read ahead of the last position asked for (one buffer's worth).
struct LineEnds<R> {
    inner: R,
    /// Bytes passed so far.
    offset: u64,
    /// Each line end passed and not yet counted: its first byte and the byte after it.
    ends: std::collections::VecDeque<(u64, u64)>,
    /// The position of the last `\r` passed.
    last_cr: Option<u64>,
    /// Line ends counted by [`LineEnds::line_ends_before_record`] so far.
    counted: usize,
}

impl<R> LineEnds<R> {
    fn new(inner: R) -> Self {
        Self {
            inner,
            offset: 0,
            ends: std::collections::VecDeque::new(),
            last_cr: None,
            counted: 0,
        }
    }

    /// Line ends before the first byte of the record the csv reader says starts at byte
    /// `pos`. (The reader's position is where it began to look for the record: right after
    /// the last record's terminator byte — inside a `\r\n` — and before the blank lines it
    /// skips; so the line ends that follow `pos` without a byte between them are before
    /// the record too.) Positions must not decrease from one call to the next. `O(1)`
    /// amortized.
    fn line_ends_before_record(&mut self, pos: u64) -> usize {
        let mut cursor = pos;
        while let Some(&(at, next)) = self.ends.front() {
            if at < pos || at == cursor {
                cursor = cursor.max(next);
                self.ends.pop_front();
                self.counted += 1;
            } else {
                break;
            }
        }
        self.counted
    }

    /// The line of the record at `pos` (the csv reader's position of it) when the input
    /// starts on line `first_line`; 0 without a position.
    fn line(&mut self, first_line: usize, pos: Option<&::csv::Position>) -> usize {
        pos.map_or(0, |pos| {
            first_line + self.line_ends_before_record(pos.byte())
        })
    }
}

impl<R: Read> Read for LineEnds<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        for i in memchr::memchr2_iter(b'\n', b'\r', &buf[..n]) {
            let at = self.offset + i as u64;
            let crlf = buf[i] == b'\n' && at > 0 && self.last_cr == Some(at - 1);
            match self.ends.back_mut() {
                // The `\n` of a `\r\n`: one line end with its `\r`.
                Some(last) if crlf && last.0 + 1 == at => last.1 = at + 1,
                _ => self.ends.push_back((at, at + 1)),
            }
            if buf[i] == b'\r' {
                self.last_cr = Some(at);
            }
        }
        self.offset += n as u64;
        Ok(n)
    }
}

/// A CSV reader with rank3's settings: flexible rows, the header's fields trimmed (a
/// record's fields are trimmed where they are read, [`Rows::push`]: the csv crate's record
/// trim allocates a new record per row).
fn csv_reader<R: Read>(reader: R, has_headers: bool) -> ::csv::Reader<R> {
    ::csv::ReaderBuilder::new()
        .has_headers(has_headers)
        .flexible(true)
        .trim(::csv::Trim::Headers)
        .buffer_capacity(1 << 20)
        .from_reader(reader)
}

/// Reads from `reader` until `data` holds at least `block` bytes or the input ends; true at
/// the end of the input.
fn fill<R: Read>(reader: &mut R, data: &mut Vec<u8>, block: usize) -> std::io::Result<bool> {
    while data.len() < block {
        let want = (block - data.len()) as u64;
        let got = reader.by_ref().take(want).read_to_end(data)?;
        if got == 0 {
            return Ok(true);
        }
    }
    Ok(false)
}

/// True when every line end in `text` ends a record: no quote (a quoted field may hold a
/// line end) and no carriage return other than in `\r\n` (a lone `\r` also ends a record).
fn plain(text: &[u8]) -> bool {
    memchr::memchr(b'"', text).is_none()
        && memchr::memchr_iter(b'\r', text).all(|i| text.get(i + 1) == Some(&b'\n'))
}

/// `text` cut after line ends into at most `n` pieces of about equal size.
fn split_at_lines(text: &[u8], n: usize) -> Vec<&[u8]> {
    let mut pieces = Vec::with_capacity(n);
    let mut from = 0;
    for k in 1..n {
        let target = (text.len() * k / n).max(from);
        match memchr::memchr(b'\n', &text[target..]) {
            Some(i) if target + i + 1 < text.len() => {
                pieces.push(&text[from..target + i + 1]);
                from = target + i + 1;
            }
            _ => break,
        }
    }
    pieces.push(&text[from..]);
    pieces
}

/// The header of `rdr`: the column of each of `frame, track, x, y`, and a warning naming
/// the extra columns.
fn header<R: Read>(rdr: &mut ::csv::Reader<R>, path: &Path) -> Result<([usize; 4], Vec<String>)> {
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
    Ok((col, warnings))
}

/// Observations read so far: `(frame, track, x, y)` with frame and track as indices into
/// `frames` / `tracks` (order of first appearance), and each one's line.
#[derive(Default)]
struct Rows {
    obs: Vec<(u32, u32, f64, f64)>,
    lines: Vec<u32>,
    frames: Ids,
    tracks: Ids,
}

impl Rows {
    /// Reads the records of `rdr` (columns `col`), at most `limit`; true when the input
    /// ended. Line numbers: `first_line` for the input's first byte, then one more after
    /// each line end before a record's first byte ([`LineEnds`]; the csv crate's own count
    /// is one short after a CRLF: it numbers a record before consuming the `\n` left over
    /// from the previous record's `\r\n`).
    fn read_all<R: Read>(
        &mut self,
        rdr: &mut ::csv::Reader<LineEnds<R>>,
        col: &[usize; 4],
        first_line: usize,
        path: &Path,
        limit: usize,
    ) -> Result<bool> {
        let mut rec = ::csv::ByteRecord::new();
        let mut records = 0;
        loop {
            if records == limit {
                return Ok(false);
            }
            records += 1;
            match rdr.read_byte_record(&mut rec) {
                Ok(true) => {}
                Ok(false) => return Ok(true),
                Err(e) => {
                    let line = rdr.get_mut().line(first_line, e.position());
                    return Err(Error::parse(path, line, "row", e.to_string()));
                }
            }
            let line = rdr.get_mut().line(first_line, rec.position());
            self.push(&rec, col, line, path)?;
        }
    }

    /// The records of `text`, a piece of plain CSV ([`plain`]: no quote, no lone `\r`)
    /// whose first line is line `first_line` of the file, split directly: in plain text
    /// every line end ends a record (`\r\n` too) and every comma a field, so the rows,
    /// their lines and the errors are [`Rows::read_all`]'s with a csv reader (checked by
    /// `plain_split_reads_what_the_csv_reader_reads`), at about twice its speed.
    /// Blank lines, like all-empty records, are skipped. `O(bytes)`.
    fn read_plain(
        &mut self,
        text: &[u8],
        col: &[usize; 4],
        first_line: usize,
        path: &Path,
    ) -> Result<()> {
        let need = col.iter().max().map_or(0, |&c| c + 1);
        let (mut start, mut line) = (0, first_line);
        while start < text.len() {
            let end = memchr::memchr(b'\n', &text[start..]).map_or(text.len(), |i| start + i);
            let record = &text[start..end];
            let record = record.strip_suffix(b"\r").unwrap_or(record);
            let mut fields = [&b""[..]; 4];
            let (mut index, mut from) = (0, 0);
            while index < need {
                let to = memchr::memchr(b',', &record[from..]).map_or(record.len(), |i| from + i);
                for (k, &c) in col.iter().enumerate() {
                    if c == index {
                        fields[k] = record[from..to].trim_ascii();
                    }
                }
                index += 1;
                if to == record.len() {
                    break;
                }
                from = to + 1;
            }
            let blank = fields.iter().all(|f| f.is_empty())
                && record.iter().all(|&b| b == b',' || b.is_ascii_whitespace());
            if !blank {
                self.push_fields(fields, line, path)?;
            }
            start = end + 1;
            line += 1;
        }
        Ok(())
    }

    /// One record (`line` its line in the file); an all-empty record is skipped.
    fn push(
        &mut self,
        rec: &::csv::ByteRecord,
        col: &[usize; 4],
        line: usize,
        path: &Path,
    ) -> Result<()> {
        if rec.iter().all(|f| f.trim_ascii().is_empty()) {
            return Ok(());
        }
        let field = |k: usize| -> &[u8] { rec.get(col[k]).unwrap_or(b"").trim_ascii() };
        self.push_fields([field(0), field(1), field(2), field(3)], line, path)
    }

    /// A record's `frame, track, x, y` fields, trimmed (`b""` when absent), on line `line`.
    fn push_fields(&mut self, fields: [&[u8]; 4], line: usize, path: &Path) -> Result<()> {
        let field = |k: usize| -> &[u8] { fields[k] };
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
            match std::str::from_utf8(b).ok().map(str::parse::<f64>) {
                Some(Ok(v)) if v.is_finite() => Ok(v),
                parsed => {
                    let s = String::from_utf8_lossy(b);
                    let what = if matches!(parsed, Some(Ok(_))) {
                        "is not finite (leave a missing observation out)"
                    } else {
                        "is not a number"
                    };
                    Err(Error::parse(
                        path,
                        line,
                        FIELDS[k],
                        format!("`{}` {what}", super::excerpt(&s)),
                    ))
                }
            }
        };
        let (x, y) = (num(2, xs)?, num(3, ys)?);
        let f = self
            .frames
            .index(field(0))
            .map_err(|m| Error::parse(path, line, "frame", format!("the frame id {m}")))?;
        let p = self
            .tracks
            .index(field(1))
            .map_err(|m| Error::parse(path, line, "track", format!("the track id {m}")))?;
        self.obs.push((f, p, x, y));
        self.lines.push(u32::try_from(line).unwrap_or(u32::MAX));
        Ok(())
    }

    /// Appends the rows of a later part of the file, its ids merged into these.
    fn append(&mut self, part: Rows) {
        let frame_map = self.frames.merge(part.frames);
        let track_map = self.tracks.merge(part.tracks);
        self.obs.extend(
            part.obs
                .into_iter()
                .map(|(f, p, x, y)| (frame_map[f as usize], track_map[p as usize], x, y)),
        );
        self.lines.extend(part.lines);
    }

    /// The table, ids in rank3's order; a repeated (frame, track) pair is an error naming
    /// both lines.
    fn finish(self, path: &Path, warnings: Vec<String>) -> Result<(TrackTable, Vec<String>)> {
        let Rows {
            mut obs,
            lines,
            frames,
            tracks,
        } = self;
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

    /// A table written with CRLF line ends, ids out of order and a blank line, and a few
    /// string ids quoted (with a comma and a line end inside) when `quoted`.
    fn long_text(rows: usize, quoted: bool) -> String {
        let mut s = String::from("x,Frame,y,track,score\r\n");
        for i in 0..rows {
            let (f, p) = ((i * 7) % 13, (i * 31) % 997);
            let track = if quoted && i % 97 == 50 {
                format!("\"t{p}, left\nside\"")
            } else {
                format!("{p}")
            };
            let _ = write!(s, "{}.25,{f},{},{track},0.5\r\n", i % 640, i % 480);
            if i == rows / 3 {
                s.push_str("\r\n");
            }
        }
        s
    }

    fn pieces(txt: &str, piece_bytes: usize, n: usize) -> Result<(TrackTable, Vec<String>)> {
        parse_in_pieces(txt.as_bytes(), p(), piece_bytes, n)
    }

    #[test]
    fn pieces_read_what_one_reader_reads() {
        for quoted in [false, true] {
            let txt = long_text(3000, quoted);
            let one = pieces(&txt, 1 << 30, 1).unwrap();
            assert_eq!(one.1.len(), 1, "one warning for the extra column");
            // Duplicates of (frame, track) would be an error: 3000 rows, 13 × 997 pairs.
            assert_eq!(one.0.n_observed(), 3000);
            for (piece_bytes, n) in [(1, 2), (64, 3), (1000, 2), (4096, 5)] {
                let many = pieces(&txt, piece_bytes, n).unwrap();
                assert_eq!(
                    many, one,
                    "quoted {quoted}, pieces of {piece_bytes} bytes × {n}"
                );
            }
        }
    }

    /// The plain split ([`Rows::read_plain`]) against the csv reader ([`Rows::read_all`])
    /// on the same plain text: the same rows and ids, or the same error; the rows' lines are,
    /// for both, those of the text's non-blank lines.
    #[test]
    fn plain_split_reads_what_the_csv_reader_reads() {
        let col = [1, 3, 0, 2]; // x,frame,y,track
        let texts = [
            "1.5,0,2.5,7\n2,1,3,8\n",
            "1.5,0,2.5,7\r\n\r\n2,1,3,8",
            " 1.5 , 0 ,\t2.5, 7 ,extra,more\n,,,\n   \n\n2,1,3,8\n",
            "1.5,0,2.5,7\n2,1,3\n",
            "1.5,0,2.5,7\n,,,,9\n",
            "1.5,0,2.5,t7\n2,f1,3,t8\r\n4,f1,5,t7\n",
            "1.5,0,2.5,7\n2,1,nan,8\n",
            "1.5,0,2.5,7\n2,1,,8\n",
            "1e3,0,-2.5e-1,7\n+2,1,3.,8\n",
            "1.5,0,2.5\n",
            "",
            "\n\n",
        ];
        for text in texts {
            let plain_rows = {
                let mut r = Rows::default();
                r.read_plain(text.as_bytes(), &col, 2, p()).map(|()| r)
            };
            let csv_rows = {
                let mut r = Rows::default();
                r.read_all(
                    &mut csv_reader(LineEnds::new(text.as_bytes()), false),
                    &col,
                    2,
                    p(),
                    usize::MAX,
                )
                .map(|_| r)
            };
            // Line numbers (from 2) of the lines holding anything but commas and spaces.
            let non_blank: Vec<u32> = text
                .split('\n')
                .enumerate()
                .filter(|(_, l)| l.bytes().any(|b| b != b',' && !b.is_ascii_whitespace()))
                .map(|(i, _)| 2 + i as u32)
                .collect();
            match (plain_rows, csv_rows) {
                (Ok(a), Ok(b)) => {
                    assert_eq!(a.obs, b.obs, "{text:?}");
                    assert_eq!(a.lines, non_blank, "{text:?}");
                    assert_eq!(b.lines, non_blank, "{text:?}");
                    assert_eq!(a.frames.ids, b.frames.ids, "{text:?}");
                    assert_eq!(a.tracks.ids, b.tracks.ids, "{text:?}");
                }
                (Err(a), Err(b)) => assert_eq!(
                    crate::table::parse_error_parts(a),
                    crate::table::parse_error_parts(b),
                    "{text:?}"
                ),
                (a, b) => panic!("{text:?}: plain {:?}, csv {:?}", a.is_ok(), b.is_ok()),
            }
        }
    }

    #[test]
    fn pieces_name_the_first_bad_line_of_the_file() {
        let mut txt = long_text(2000, false);
        let lines: Vec<&str> = txt.split("\r\n").collect();
        // Line 1500 (1-based) gets a bad x, line 1800 a bad y: the first is named.
        let mut edited: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
        edited[1499] = edited[1499].replacen(".25", ".2x", 1);
        edited[1799] = "1.5,2,abc,4,0.5".to_string();
        txt = edited.join("\r\n");
        for (piece_bytes, n) in [(1 << 30, 1), (64, 2), (700, 4)] {
            let (l, f, m) =
                crate::table::parse_error_parts(pieces(&txt, piece_bytes, n).unwrap_err());
            assert_eq!((l, f.as_str()), (1500, "x"), "{m}");
        }
        // A pair given twice, in two different pieces: both lines named.
        let mut txt = long_text(2000, false);
        txt.push_str("3.25,0,1,0,0.5\r\n");
        for (piece_bytes, n) in [(1 << 30, 1), (64, 2), (700, 4)] {
            let (l, f, m) =
                crate::table::parse_error_parts(pieces(&txt, piece_bytes, n).unwrap_err());
            assert_eq!((l, f.as_str()), (2003, "track"), "{m}");
            assert!(m.contains("first on line 2"), "{m}");
        }
    }

    #[test]
    fn a_blank_first_line_is_skipped() {
        let (t, _) = parse("\nframe,track,x,y\n0,0,1,2\n", p()).unwrap();
        assert_eq!(t.get(0, 0), Some([1.0, 2.0]));
    }

    #[test]
    fn crlf_lines_are_numbered_as_lines() {
        let (l, f, _) = err("x,frame,y,track\r\n1,0,2,0\r\n\r\n1x,0,2,1\r\n");
        assert_eq!((l, f.as_str()), (4, "x"));
    }

    /// Files the streaming csv reader reads (a quote in the header or in a later block):
    /// errors name the line the text editor shows, after CRLF, blank lines, lone CRs and
    /// a quoted field holding line ends.
    #[test]
    fn quoted_files_name_the_right_line() {
        let cases = [
            (
                "\"frame\",\"track\",x,y\r\n0,0,1,2\r\n0,1,1,2\r\n0,3,abc,2\r\n",
                4,
            ),
            (
                "\"frame\",track,x,y\r\n0,0,1,2\r\n\r\n\r\n0,2,1,2\r\n0,3,abc,2\r\n",
                6,
            ),
            ("\"frame\",track,x,y\n0,0,1,2\n\n0,3,abc,2\n", 4),
            ("\"frame\",track,x,y\r0,0,1,2\r0,3,abc,2\r", 3),
            ("frame,track,x,y\n0,\"a\nb\",1,2\n0,3,abc,2\n", 4),
            (
                "frame,track,x,y\r\n0,\"a\r\nb\",1,2\r\n\r\n0,3,abc,2\r\n",
                5,
            ),
        ];
        for (text, line) in cases {
            for (piece_bytes, n) in [(1 << 30, 1), (8, 2)] {
                let (l, f, m) =
                    crate::table::parse_error_parts(pieces(text, piece_bytes, n).unwrap_err());
                assert_eq!((l, f.as_str()), (line, "x"), "{text:?} {piece_bytes}: {m}");
            }
        }
        // A row's line in a file read whole by the streaming reader: each observation's.
        let text = "\"frame\",track,x,y\r\n0,0,1,2\r\n\r\n0,1,3,4\r\n0,2,3,4\r\n0,1,5,6\r\n";
        let (l, f, m) = crate::table::parse_error_parts(pieces(text, 1 << 30, 1).unwrap_err());
        assert_eq!((l, f.as_str()), (6, "track"), "{m}");
        assert!(m.contains("first on line 4"), "{m}");
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
