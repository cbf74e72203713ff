//! NumPy arrays of tracks: `.npy` and `.npz` (docs/formats.md).
//!
//! Layouts of the coordinates (little-endian `float64` or `float32`, C or Fortran order,
//! NaN for a missing entry):
//!
//! * `(F, N, 2)` — frame, track, `x`/`y`: `a[f, n] = (x, y)`;
//! * `(2F, N)` — the dense measurement matrix of the `.txt` format: row `2f` holds the x and
//!   row `2f + 1` the y coordinates of frame `f`;
//! * in a `.npz`, two `(F, N)` arrays `x` and `y` instead of `tracks`.
//!
//! A `.npz` (`np.savez`, `np.savez_compressed`) holds the coordinates as `tracks` (either
//! layout above) or as `x` and `y`, and optionally `frame_ids` (shape `(F,)`) and `track_ids`
//! (`(N,)`): integers or strings (`<U`, `|S`; a string that is an integer becomes an integer
//! id, as in the CSV format). A `.npz` whose only array besides the ids has another name is
//! read as `tracks` (`np.savez(path, a)` names it `arr_0`). Any other member is reported in the
//! warnings, never dropped silently. Without ids, frames are `0..F` and tracks `0..N`.
//!
//! The `.npy` reader is written here (magic, version 1.0 / 2.0 / 3.0, header length, a
//! Python dict literal with `descr`, `fortran_order` and `shape`); `.npz` members are read
//! with the `zip` crate (stored or deflated). Every fault is an [`Error::Array`] naming the
//! file, the member, the field (`header.descr`, `shape`, an element `[f, n, c]`) and its
//! [`ArrayFault`]; nothing panics on user data.

use std::io::{Read, Seek};
use std::path::Path;

use super::{Id, TrackTable};
use crate::{Error, Result};

/// A `.npy` / `.npz` input rank3 cannot read ([`Error::Array`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{}: {field}: {message}", path.display(), array_suffix(.array))]
pub struct ArrayError {
    /// The file.
    pub path: std::path::PathBuf,
    /// The `.npz` member (without `.npy`); `None` for a `.npy` file.
    pub array: Option<String>,
    /// The part at fault: `magic`, `version`, `header`, `header.descr`, `header.shape`,
    /// `shape`, `data`, an element `[f, n, c]`, an id `[k]`, `members`, `archive`.
    pub field: String,
    /// The kind of fault.
    pub fault: ArrayFault,
    /// What is wrong, and what to do.
    pub message: String,
}

fn array_suffix(array: &Option<String>) -> String {
    match array {
        Some(a) => format!(", array `{a}`"),
        None => String::new(),
    }
}

/// The kind of fault of an [`ArrayError`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum ArrayFault {
    /// The file does not start with the `.npy` magic `\x93NUMPY`.
    Magic,
    /// A `.npy` format version other than 1.0, 2.0 and 3.0.
    Version,
    /// The header is not a Python dict literal with exactly the keys `descr`,
    /// `fortran_order` and `shape`, or a value has the wrong type.
    Header,
    /// An element type rank3 does not read (coordinates: little-endian `f8` or `f4`; ids:
    /// integers or strings).
    Dtype,
    /// A shape that is not one of the layouts, or arrays whose shapes disagree.
    Shape,
    /// The file ends before the header or the data the header announces.
    Truncated,
    /// Bytes after the data the header announces.
    TrailingData,
    /// A bad value: an infinite coordinate, `x` without `y`, a duplicate or invalid id.
    Value,
    /// A `.npz` without the arrays of a layout (`tracks`, or `x` and `y`).
    Missing,
    /// A `.npz` with both layouts (`tracks` and `x`/`y`).
    Ambiguous,
    /// A `.npz` that is not a zip archive rank3 reads (or a member that fails to
    /// decompress).
    Archive,
}

/// A fault before the file and member are known to it.
#[derive(Debug)]
struct Fault {
    fault: ArrayFault,
    field: String,
    message: String,
}

fn fault(fault: ArrayFault, field: impl Into<String>, message: impl Into<String>) -> Fault {
    Fault {
        fault,
        field: field.into(),
        message: message.into(),
    }
}

/// Where an array came from, for errors.
#[derive(Clone, Copy)]
struct Ctx<'a> {
    path: &'a Path,
    array: Option<&'a str>,
}

impl Ctx<'_> {
    fn err(&self, f: Fault) -> Error {
        Error::Array(Box::new(ArrayError {
            path: self.path.to_path_buf(),
            array: self.array.map(str::to_string),
            field: f.field,
            fault: f.fault,
            message: f.message,
        }))
    }
}

const MAGIC: &[u8; 6] = b"\x93NUMPY";

/// The element type of an array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Dtype {
    F4,
    F8,
    Int {
        size: usize,
        signed: bool,
    },
    /// `<U{chars}`: UTF-32LE, NUL-padded.
    Unicode(usize),
    /// `|S{bytes}`: NUL-padded bytes.
    Bytes(usize),
}

impl Dtype {
    fn itemsize(self) -> Option<usize> {
        match self {
            Dtype::F4 => Some(4),
            Dtype::F8 => Some(8),
            Dtype::Int { size, .. } => Some(size),
            Dtype::Unicode(n) => n.checked_mul(4),
            Dtype::Bytes(n) => Some(n),
        }
    }
}

/// Parses a `descr` string such as `<f8`.
fn parse_descr(descr: &str) -> std::result::Result<Dtype, String> {
    let mut chars = descr.chars();
    let (Some(order), Some(kind)) = (chars.next(), chars.next()) else {
        return Err(format!(
            "`{descr}` is not a NumPy type string such as `<f8`"
        ));
    };
    let size_text = chars.as_str();
    if kind == 'O' {
        return Err(format!(
            "`{descr}` is an object array (pickled Python objects), which rank3 does not \
             unpickle; save numbers or fixed-width strings (`a.astype(str)`)"
        ));
    }
    let size: usize = size_text
        .parse()
        .map_err(|_| format!("`{descr}` is not a NumPy type string such as `<f8`"))?;
    let dtype = match kind {
        'f' if size == 4 => Dtype::F4,
        'f' if size == 8 => Dtype::F8,
        'f' => {
            return Err(format!(
                "`{descr}`: {}-bit floats are not read (little-endian float64 `<f8` or float32 \
                 `<f4`); convert with `a.astype('<f8')`",
                8 * size
            ));
        }
        'i' | 'u' if matches!(size, 1 | 2 | 4 | 8) => Dtype::Int {
            size,
            signed: kind == 'i',
        },
        'U' => Dtype::Unicode(size),
        'S' | 'a' => Dtype::Bytes(size),
        'b' => return Err(format!("`{descr}` is a boolean array")),
        'c' => return Err(format!("`{descr}` is a complex array")),
        'M' | 'm' => return Err(format!("`{descr}` is a date/time array")),
        _ => return Err(format!("`{descr}`: element type `{kind}` is not read")),
    };
    let one_byte = dtype.itemsize() == Some(1) || matches!(dtype, Dtype::Bytes(_));
    match order {
        '<' => Ok(dtype),
        '|' | '>' | '=' if one_byte => Ok(dtype),
        '>' => Err(format!(
            "`{descr}` is big-endian; rank3 reads little-endian arrays (convert with \
             `a.astype('<{}')`)",
            &descr[1..]
        )),
        '=' | '|' => Err(format!(
            "`{descr}` does not record its byte order; save the array with an explicit \
             little-endian type (`a.astype('<{}')`)",
            &descr[1..]
        )),
        _ => Err(format!("`{descr}`: `{order}` is not a NumPy byte order")),
    }
}

/// A Python literal of a `.npy` header.
#[derive(Debug, Clone, PartialEq)]
enum Lit {
    Str(String),
    Bool(bool),
    Int(u64),
    None,
    /// A tuple or a list.
    Seq(Vec<Lit>),
    Dict(Vec<(Lit, Lit)>),
}

/// A recursive-descent parser of the Python literals a `.npy` header holds.
struct LitParser<'a> {
    s: &'a [char],
    i: usize,
}

impl LitParser<'_> {
    fn ws(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_whitespace() {
            self.i += 1;
        }
    }

    fn peek(&mut self) -> Option<char> {
        self.ws();
        self.s.get(self.i).copied()
    }

    fn expect(&mut self, c: char) -> std::result::Result<(), String> {
        match self.peek() {
            Some(d) if d == c => {
                self.i += 1;
                Ok(())
            }
            Some(d) => Err(format!(
                "expected `{c}` at character {}, found `{d}`",
                self.i
            )),
            None => Err(format!("expected `{c}`, the header ends")),
        }
    }

    fn value(&mut self, depth: usize) -> std::result::Result<Lit, String> {
        if depth > 16 {
            return Err("literals nested too deeply".into());
        }
        match self.peek() {
            None => Err("a value is missing: the header ends".into()),
            Some('{') => {
                self.i += 1;
                let mut items = Vec::new();
                loop {
                    if self.peek() == Some('}') {
                        self.i += 1;
                        return Ok(Lit::Dict(items));
                    }
                    let k = self.value(depth + 1)?;
                    self.expect(':')?;
                    let v = self.value(depth + 1)?;
                    items.push((k, v));
                    match self.peek() {
                        Some(',') => self.i += 1,
                        Some('}') => {}
                        _ => return Err(format!("expected `,` or `}}` at character {}", self.i)),
                    }
                }
            }
            Some(open @ ('(' | '[')) => {
                self.i += 1;
                let close = if open == '(' { ')' } else { ']' };
                let mut items = Vec::new();
                loop {
                    if self.peek() == Some(close) {
                        self.i += 1;
                        return Ok(Lit::Seq(items));
                    }
                    items.push(self.value(depth + 1)?);
                    match self.peek() {
                        Some(',') => self.i += 1,
                        Some(c) if c == close => {}
                        _ => {
                            return Err(format!(
                                "expected `,` or `{close}` at character {}",
                                self.i
                            ));
                        }
                    }
                }
            }
            Some(q @ ('\'' | '"')) => {
                self.i += 1;
                let mut out = String::new();
                loop {
                    match self.s.get(self.i) {
                        None => return Err("a string is not closed".into()),
                        Some('\\') => {
                            let c = *self.s.get(self.i + 1).ok_or("a string is not closed")?;
                            out.push(c);
                            self.i += 2;
                        }
                        Some(&c) if c == q => {
                            self.i += 1;
                            return Ok(Lit::Str(out));
                        }
                        Some(&c) => {
                            out.push(c);
                            self.i += 1;
                        }
                    }
                }
            }
            Some(c) if c.is_ascii_digit() => {
                let start = self.i;
                while self.i < self.s.len() && self.s[self.i].is_ascii_digit() {
                    self.i += 1;
                }
                let text: String = self.s[start..self.i].iter().collect();
                // Python 2 wrote long integers as `3L`.
                if matches!(self.s.get(self.i), Some('L' | 'l')) {
                    self.i += 1;
                }
                text.parse()
                    .map(Lit::Int)
                    .map_err(|_| format!("integer `{text}` is too large"))
            }
            Some(c) if c.is_ascii_alphabetic() => {
                let start = self.i;
                while self.i < self.s.len() && self.s[self.i].is_ascii_alphanumeric() {
                    self.i += 1;
                }
                let word: String = self.s[start..self.i].iter().collect();
                match word.as_str() {
                    "True" => Ok(Lit::Bool(true)),
                    "False" => Ok(Lit::Bool(false)),
                    "None" => Ok(Lit::None),
                    _ => Err(format!("`{word}` is not a Python literal")),
                }
            }
            Some(c) => Err(format!("unexpected `{c}` at character {}", self.i)),
        }
    }
}

/// Parses a whole header: one dict literal, then only white space.
fn parse_literal(text: &str) -> std::result::Result<Lit, String> {
    let chars: Vec<char> = text.chars().collect();
    let mut p = LitParser { s: &chars, i: 0 };
    let v = p.value(0)?;
    if p.peek().is_some() {
        return Err(format!(
            "unexpected text after the dict at character {}",
            p.i
        ));
    }
    Ok(v)
}

/// A parsed `.npy` header.
#[derive(Debug, Clone, PartialEq)]
struct Header {
    version: (u8, u8),
    descr: String,
    dtype: Dtype,
    fortran_order: bool,
    shape: Vec<usize>,
    /// Where the data start.
    offset: usize,
    /// Bytes of data the header announces.
    nbytes: usize,
}

fn le_u32(b: &[u8]) -> usize {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize
}

/// Parses the header of a `.npy` file (the whole file in `bytes`).
fn parse_header(bytes: &[u8]) -> std::result::Result<Header, Fault> {
    use ArrayFault as A;
    let n = bytes.len().min(MAGIC.len());
    if bytes[..n] != MAGIC[..n] {
        return Err(fault(
            A::Magic,
            "magic",
            "not a NumPy .npy array: the file does not start with `\\x93NUMPY`",
        ));
    }
    if bytes.len() < 8 {
        return Err(fault(
            A::Truncated,
            "version",
            format!(
                "the file ends after {} bytes, inside the preamble",
                bytes.len()
            ),
        ));
    }
    let version = (bytes[6], bytes[7]);
    let len_bytes = match version {
        (1, 0) => 2,
        (2, 0) | (3, 0) => 4,
        (a, b) => {
            return Err(fault(
                A::Version,
                "version",
                format!("format version {a}.{b}; rank3 reads versions 1.0, 2.0 and 3.0"),
            ));
        }
    };
    if bytes.len() < 8 + len_bytes {
        return Err(fault(
            A::Truncated,
            "header length",
            format!(
                "the file ends after {} bytes, inside the preamble",
                bytes.len()
            ),
        ));
    }
    let hlen = if len_bytes == 2 {
        u16::from_le_bytes([bytes[8], bytes[9]]) as usize
    } else {
        le_u32(&bytes[8..12])
    };
    let start = 8 + len_bytes;
    let offset = start.saturating_add(hlen);
    if bytes.len() < offset {
        return Err(fault(
            A::Truncated,
            "header",
            format!(
                "the header is {hlen} bytes long, the file ends {} bytes into it",
                bytes.len() - start
            ),
        ));
    }
    let raw = &bytes[start..offset];
    let text: String = if version.0 == 3 {
        std::str::from_utf8(raw)
            .map_err(|_| fault(A::Header, "header", "not valid UTF-8 (format 3.0)"))?
            .to_string()
    } else {
        // Versions 1 and 2: latin-1, one byte per character.
        raw.iter().map(|&b| b as char).collect()
    };
    let dict = match parse_literal(&text) {
        Ok(Lit::Dict(d)) => d,
        Ok(_) => return Err(fault(A::Header, "header", "the header is not a dict")),
        Err(e) => return Err(fault(A::Header, "header", e)),
    };
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    for (k, v) in dict {
        let Lit::Str(k) = k else {
            return Err(fault(A::Header, "header", "a key is not a string"));
        };
        let slot = match k.as_str() {
            "descr" => &mut descr,
            "fortran_order" => &mut fortran,
            "shape" => &mut shape,
            _ => {
                return Err(fault(
                    A::Header,
                    format!("header.{k}"),
                    "unexpected key (a .npy header has exactly `descr`, `fortran_order` and \
                     `shape`)",
                ));
            }
        };
        if slot.replace(v).is_some() {
            return Err(fault(A::Header, format!("header.{k}"), "key given twice"));
        }
    }
    let missing = |k: &str| fault(A::Header, format!("header.{k}"), "missing key");
    let descr = match descr.ok_or_else(|| missing("descr"))? {
        Lit::Str(s) => s,
        Lit::Seq(_) => {
            return Err(fault(
                A::Dtype,
                "header.descr",
                "a structured (record) array; rank3 reads plain float arrays (save \
                 `np.stack([a['x'], a['y']], -1)`)",
            ));
        }
        _ => return Err(fault(A::Header, "header.descr", "not a type string")),
    };
    let fortran_order = match fortran.ok_or_else(|| missing("fortran_order"))? {
        Lit::Bool(b) => b,
        _ => {
            return Err(fault(
                A::Header,
                "header.fortran_order",
                "not True or False",
            ));
        }
    };
    let shape: Vec<usize> = match shape.ok_or_else(|| missing("shape"))? {
        Lit::Seq(items) => items
            .into_iter()
            .map(|l| match l {
                Lit::Int(i) => usize::try_from(i)
                    .map_err(|_| fault(A::Shape, "header.shape", format!("{i} is too large"))),
                _ => Err(fault(
                    A::Header,
                    "header.shape",
                    "not a tuple of non-negative integers",
                )),
            })
            .collect::<std::result::Result<_, _>>()?,
        _ => {
            return Err(fault(
                A::Header,
                "header.shape",
                "not a tuple of non-negative integers",
            ));
        }
    };
    let dtype = parse_descr(&descr).map_err(|m| fault(A::Dtype, "header.descr", m))?;
    let nbytes = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .and_then(|c| c.checked_mul(dtype.itemsize()?))
        .ok_or_else(|| {
            fault(
                A::Shape,
                "header.shape",
                format!("shape {} of `{descr}` is too large", shape_text(&shape)),
            )
        })?;
    Ok(Header {
        version,
        descr,
        dtype,
        fortran_order,
        shape,
        offset,
        nbytes,
    })
}

/// `(3, 4, 2)` as Python prints it.
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

/// An array: header and the file's bytes.
struct Array {
    header: Header,
    bytes: Vec<u8>,
}

impl Array {
    /// Parses a whole `.npy` file.
    fn parse(bytes: Vec<u8>) -> std::result::Result<Array, Fault> {
        let header = parse_header(&bytes)?;
        let have = bytes.len() - header.offset;
        let need = header.nbytes;
        let what = || format!("shape {} of `{}`", shape_text(&header.shape), header.descr);
        if have < need {
            return Err(fault(
                ArrayFault::Truncated,
                "data",
                format!(
                    "{} needs {need} bytes of data, the file holds {have}",
                    what()
                ),
            ));
        }
        if have > need {
            return Err(fault(
                ArrayFault::TrailingData,
                "data",
                format!(
                    "{} needs {need} bytes of data, the file holds {have} ({} more)",
                    what(),
                    have - need
                ),
            ));
        }
        Ok(Array { header, bytes })
    }

    fn shape(&self) -> &[usize] {
        &self.header.shape
    }

    /// The storage position of the element at `idx` (C or Fortran order).
    fn flat(&self, idx: &[usize]) -> usize {
        let shape = self.shape();
        let mut flat = 0;
        if self.header.fortran_order {
            for k in (0..shape.len()).rev() {
                flat = flat * shape[k] + idx[k];
            }
        } else {
            for k in 0..shape.len() {
                flat = flat * shape[k] + idx[k];
            }
        }
        flat
    }

    fn element(&self, flat: usize) -> &[u8] {
        let size = self.header.dtype.itemsize().unwrap_or(0);
        let at = self.header.offset + flat * size;
        &self.bytes[at..at + size]
    }

    /// A float element (the dtype is `F4` or `F8`).
    fn float(&self, idx: &[usize]) -> f64 {
        let b = self.element(self.flat(idx));
        match self.header.dtype {
            Dtype::F4 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            _ => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }

    /// Checks the array holds coordinates.
    fn require_float(&self) -> std::result::Result<(), Fault> {
        match self.header.dtype {
            Dtype::F4 | Dtype::F8 => Ok(()),
            _ => Err(fault(
                ArrayFault::Dtype,
                "header.descr",
                format!(
                    "coordinates must be little-endian float64 (`<f8`) or float32 (`<f4`), \
                     not `{}`; convert with `a.astype('<f8')` (NaN marks a missing entry)",
                    self.header.descr
                ),
            )),
        }
    }

    /// Element `k` of a 1-D id array.
    fn id(&self, k: usize) -> std::result::Result<Id, String> {
        let b = self.element(k);
        match self.header.dtype {
            Dtype::Int { size, signed } => {
                let mut buf = [0u8; 8];
                buf[..size].copy_from_slice(b);
                let negative = signed && b[size - 1] & 0x80 != 0;
                if negative {
                    buf[size..].fill(0xff);
                }
                let v = u64::from_le_bytes(buf);
                if signed {
                    Ok(Id::Int(v as i64))
                } else {
                    i64::try_from(v)
                        .map(Id::Int)
                        .map_err(|_| format!("{v} is larger than the largest id (2^63 - 1)"))
                }
            }
            Dtype::Unicode(_) => {
                let mut s = String::new();
                for c in b.chunks_exact(4) {
                    let u = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    s.push(
                        char::from_u32(u)
                            .ok_or_else(|| format!("U+{u:X} is not a Unicode character"))?,
                    );
                }
                string_id(s.trim_end_matches('\0'))
            }
            Dtype::Bytes(_) => {
                let end = b.iter().rposition(|&c| c != 0).map_or(0, |p| p + 1);
                let s = std::str::from_utf8(&b[..end]).map_err(|_| "not UTF-8 text".to_string())?;
                string_id(s)
            }
            Dtype::F4 | Dtype::F8 => Err("ids must be integers or strings".into()),
        }
    }
}

fn string_id(s: &str) -> std::result::Result<Id, String> {
    if s.trim().is_empty() {
        Err("an empty id".into())
    } else {
        Ok(Id::parse(s))
    }
}

/// Reads a `.npy` file's bytes into an [`Array`].
fn array_of(bytes: Vec<u8>, ctx: Ctx<'_>) -> Result<Array> {
    Array::parse(bytes).map_err(|f| ctx.err(f))
}

/// The ids of a 1-D array of `n` ids.
fn ids_of(a: &Array, n: usize, what: &str, ctx: Ctx<'_>) -> Result<Vec<Id>> {
    if a.shape() != [n] {
        return Err(ctx.err(fault(
            ArrayFault::Shape,
            "shape",
            format!(
                "{what} ids must have shape ({n},), one per {what}; got {}",
                shape_text(a.shape())
            ),
        )));
    }
    if matches!(a.header.dtype, Dtype::F4 | Dtype::F8) {
        return Err(ctx.err(fault(
            ArrayFault::Dtype,
            "header.descr",
            format!("ids must be integers or strings, not `{}`", a.header.descr),
        )));
    }
    let mut ids = Vec::with_capacity(n);
    let mut seen = std::collections::HashMap::with_capacity(n);
    for k in 0..n {
        let id = a
            .id(k)
            .map_err(|m| ctx.err(fault(ArrayFault::Value, format!("[{k}]"), m)))?;
        if let Some(first) = seen.insert(id.clone(), k) {
            return Err(ctx.err(fault(
                ArrayFault::Value,
                format!("[{k}]"),
                format!("{what} id `{id}` repeats [{first}]"),
            )));
        }
        ids.push(id);
    }
    Ok(ids)
}

/// Coordinates `(x, y)` of frame `f`, track `n`.
type Coord<'a> = dyn Fn(usize, usize) -> (f64, f64) + 'a;
/// The element index naming coordinate `c` (0 = x, 1 = y) of frame `f`, track `n`.
type Field<'a> = dyn Fn(usize, usize, usize) -> String + 'a;

/// Builds the table from a coordinate accessor, checking every value.
fn build(
    (f, n): (usize, usize),
    coord: &Coord<'_>,
    field: &Field<'_>,
    ctx_x: Ctx<'_>,
    ctx_y: Ctx<'_>,
) -> Result<TrackTable> {
    if f == 0 || n == 0 {
        return Err(Error::EmptyTable {
            path: Some(ctx_x.path.to_path_buf()),
            reason: format!("{f} frames × {n} tracks"),
        });
    }
    let mut t = TrackTable::new(
        (0..f).map(Id::from).collect(),
        (0..n).map(Id::from).collect(),
    );
    for fi in 0..f {
        for p in 0..n {
            let (x, y) = coord(fi, p);
            for (c, v, ctx) in [(0, x, ctx_x), (1, y, ctx_y)] {
                if v.is_infinite() {
                    return Err(ctx.err(fault(
                        ArrayFault::Value,
                        field(fi, p, c),
                        format!(
                            "frame {fi} track {p}: {v} is not finite (NaN marks a missing entry)"
                        ),
                    )));
                }
            }
            match (x.is_nan(), y.is_nan()) {
                (false, false) => t.set(fi, p, x, y),
                (true, true) => {}
                (false, true) => {
                    return Err(ctx_y.err(fault(
                        ArrayFault::Value,
                        field(fi, p, 1),
                        format!("frame {fi} track {p}: x given without y (y is NaN)"),
                    )));
                }
                (true, false) => {
                    return Err(ctx_x.err(fault(
                        ArrayFault::Value,
                        field(fi, p, 0),
                        format!("frame {fi} track {p}: y given without x (x is NaN)"),
                    )));
                }
            }
        }
    }
    if t.n_observed() == 0 {
        return Err(Error::EmptyTable {
            path: Some(ctx_x.path.to_path_buf()),
            reason: "every entry is NaN".into(),
        });
    }
    Ok(t)
}

/// The table of a coordinates array in the `(F, N, 2)` or `(2F, N)` layout.
fn table_of_tracks(a: &Array, ctx: Ctx<'_>) -> Result<TrackTable> {
    a.require_float().map_err(|f| ctx.err(f))?;
    match *a.shape() {
        [f, n, 2] => build(
            (f, n),
            &|fi, p| (a.float(&[fi, p, 0]), a.float(&[fi, p, 1])),
            &|fi, p, c| format!("[{fi}, {p}, {c}]"),
            ctx,
            ctx,
        ),
        [rows, n] if rows % 2 == 0 => build(
            (rows / 2, n),
            &|fi, p| (a.float(&[2 * fi, p]), a.float(&[2 * fi + 1, p])),
            &|fi, p, c| format!("[{}, {p}]", 2 * fi + c),
            ctx,
            ctx,
        ),
        _ => Err(ctx.err(fault(
            ArrayFault::Shape,
            "shape",
            format!(
                "shape {}: track arrays have shape (F, N, 2) (frame, track, x/y) or (2F, N) \
                 (the dense measurement matrix: rows x, y of each frame)",
                shape_text(a.shape())
            ),
        ))),
    }
}

/// The table of two `(F, N)` arrays of x and y coordinates.
fn table_of_xy(x: &Array, cx: Ctx<'_>, y: &Array, cy: Ctx<'_>) -> Result<TrackTable> {
    x.require_float().map_err(|f| cx.err(f))?;
    y.require_float().map_err(|f| cy.err(f))?;
    let [f, n] = *x.shape() else {
        return Err(cx.err(fault(
            ArrayFault::Shape,
            "shape",
            format!(
                "shape {}: x and y are (F, N) matrices (frames × tracks)",
                shape_text(x.shape())
            ),
        )));
    };
    if y.shape() != x.shape() {
        return Err(cy.err(fault(
            ArrayFault::Shape,
            "shape",
            format!(
                "shape {} differs from the x array's {}",
                shape_text(y.shape()),
                shape_text(x.shape())
            ),
        )));
    }
    build(
        (f, n),
        &|fi, p| (x.float(&[fi, p]), y.float(&[fi, p])),
        &|fi, p, _| format!("[{fi}, {p}]"),
        cx,
        cy,
    )
}

/// Parses the bytes of a `.npy` file of tracks (`path` names it in errors).
pub fn parse_npy(bytes: Vec<u8>, path: &Path) -> Result<TrackTable> {
    let ctx = Ctx { path, array: None };
    table_of_tracks(&array_of(bytes, ctx)?, ctx)
}

/// Reads a `.npy` file of tracks: shape `(F, N, 2)` or `(2F, N)`.
pub fn read_npy(path: &Path) -> Result<TrackTable> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_npy(bytes, path)
}

/// Reads two `.npy` files of `(F, N)` x and y coordinates.
pub fn read_xy_npy(x_path: &Path, y_path: &Path) -> Result<TrackTable> {
    let (cx, cy) = (
        Ctx {
            path: x_path,
            array: None,
        },
        Ctx {
            path: y_path,
            array: None,
        },
    );
    let x = array_of(std::fs::read(x_path).map_err(|e| Error::io(x_path, e))?, cx)?;
    let y = array_of(std::fs::read(y_path).map_err(|e| Error::io(y_path, e))?, cy)?;
    table_of_xy(&x, cx, &y, cy)
}

/// The members a `.npz` may hold (without `.npy`).
const TRACKS: &str = "tracks";
const X: &str = "x";
const Y: &str = "y";
const FRAME_IDS: &str = "frame_ids";
const TRACK_IDS: &str = "track_ids";

/// Parses a `.npz` archive of tracks; returns the table and warnings (members not read).
pub fn parse_npz<R: Read + Seek>(reader: R, path: &Path) -> Result<(TrackTable, Vec<String>)> {
    let archive_ctx = Ctx { path, array: None };
    let zip_err = |e: zip::result::ZipError| {
        archive_ctx.err(fault(
            ArrayFault::Archive,
            "archive",
            format!("not a .npz archive rank3 reads: {e}"),
        ))
    };
    let mut zip = zip::ZipArchive::new(reader).map_err(zip_err)?;
    // Member names without `.npy`, in archive order.
    let mut names: Vec<(String, usize)> = Vec::with_capacity(zip.len());
    let mut others: Vec<String> = Vec::new();
    for i in 0..zip.len() {
        let entry = zip.by_index(i).map_err(zip_err)?;
        let name = entry.name().map_err(zip_err)?.to_string();
        if entry.is_dir() {
            others.push(name);
        } else if let Some(stem) = name.strip_suffix(".npy") {
            names.push((stem.to_string(), i));
        } else {
            others.push(name);
        }
    }
    let index = |n: &str| names.iter().find(|(s, _)| s == n).map(|&(_, i)| i);
    let (tracks, x, y) = (index(TRACKS), index(X), index(Y));
    let member_list = || {
        names
            .iter()
            .map(|(s, _)| format!("`{s}`"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    // The layout, with the members it uses.
    let data_members: Vec<&(String, usize)> = names
        .iter()
        .filter(|(s, _)| s != FRAME_IDS && s != TRACK_IDS)
        .collect();
    enum Layout {
        Tracks(usize, String),
        Xy(usize, usize),
    }
    let layout = match (tracks, x, y) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return Err(archive_ctx.err(fault(
                ArrayFault::Ambiguous,
                "members",
                "holds both `tracks` and `x`/`y`; keep one layout",
            )));
        }
        (Some(t), None, None) => Layout::Tracks(t, TRACKS.to_string()),
        (None, Some(x), Some(y)) => Layout::Xy(x, y),
        (None, Some(_), None) | (None, None, Some(_)) => {
            return Err(archive_ctx.err(fault(
                ArrayFault::Missing,
                "members",
                format!(
                    "holds `{}` without `{}` (members: {})",
                    if x.is_some() { X } else { Y },
                    if x.is_some() { Y } else { X },
                    member_list()
                ),
            )));
        }
        (None, None, None) if data_members.len() == 1 => {
            Layout::Tracks(data_members[0].1, data_members[0].0.clone())
        }
        (None, None, None) => {
            return Err(archive_ctx.err(fault(
                ArrayFault::Missing,
                "members",
                format!(
                    "no array `tracks` (shape (F, N, 2) or (2F, N)) nor `x` and `y` (F, N); \
                     members: {}",
                    if names.is_empty() {
                        "none".to_string()
                    } else {
                        member_list()
                    }
                ),
            )));
        }
    };
    let mut read_member = |i: usize, name: &str| -> Result<Array> {
        let ctx = Ctx {
            path,
            array: Some(name),
        };
        let mut entry = zip.by_index(i).map_err(|e| {
            ctx.err(fault(
                ArrayFault::Archive,
                "archive",
                format!("cannot open the member: {e}"),
            ))
        })?;
        let size = entry.size();
        let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0).min(1 << 26));
        // At most the size the directory declares (and one byte more, to catch a lie).
        (&mut entry)
            .take(size.saturating_add(1))
            .read_to_end(&mut bytes)
            .map_err(|e| {
                ctx.err(fault(
                    ArrayFault::Archive,
                    "archive",
                    format!("cannot decompress the member: {e}"),
                ))
            })?;
        array_of(bytes, ctx)
    };
    let mut used: Vec<String> = Vec::new();
    let mut table = match layout {
        Layout::Tracks(i, name) => {
            let a = read_member(i, &name)?;
            used.push(name.clone());
            table_of_tracks(
                &a,
                Ctx {
                    path,
                    array: Some(&name),
                },
            )?
        }
        Layout::Xy(xi, yi) => {
            let (xa, ya) = (read_member(xi, X)?, read_member(yi, Y)?);
            used.extend([X.to_string(), Y.to_string()]);
            let cx = Ctx {
                path,
                array: Some(X),
            };
            let cy = Ctx {
                path,
                array: Some(Y),
            };
            table_of_xy(&xa, cx, &ya, cy)?
        }
    };
    if let Some(i) = index(FRAME_IDS) {
        let a = read_member(i, FRAME_IDS)?;
        let ctx = Ctx {
            path,
            array: Some(FRAME_IDS),
        };
        table.frame_ids = ids_of(&a, table.n_frames(), "frame", ctx)?;
        used.push(FRAME_IDS.into());
    }
    if let Some(i) = index(TRACK_IDS) {
        let a = read_member(i, TRACK_IDS)?;
        let ctx = Ctx {
            path,
            array: Some(TRACK_IDS),
        };
        table.track_ids = ids_of(&a, table.n_tracks(), "track", ctx)?;
        used.push(TRACK_IDS.into());
    }
    others.extend(
        names
            .iter()
            .filter(|(s, _)| !used.contains(s))
            .map(|(s, _)| format!("{s}.npy")),
    );
    let warnings = if others.is_empty() {
        Vec::new()
    } else {
        vec![format!(
            "{}: ignored member(s) {} (rank3 reads `tracks`, or `x` and `y`, and optional \
             `frame_ids` and `track_ids`)",
            path.display(),
            others
                .iter()
                .map(|s| format!("`{s}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )]
    };
    Ok((table, warnings))
}

/// Reads a `.npz` archive of tracks (see the module docs); returns the warnings too.
pub fn read_npz(path: &Path) -> Result<(TrackTable, Vec<String>)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    parse_npz(std::io::BufReader::new(file), path)
}

/// A `.npy` file (format 1.0, or 2.0 when the header needs it) of a C-order array.
fn npy_bytes(descr: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': {}, }}",
        shape_text(shape)
    );
    // Pad with spaces so the data start at a multiple of 64 bytes, then `\n`.
    let v1 = header.len() + 1 + 10 <= u16::MAX as usize;
    let pre = if v1 { 10 } else { 12 };
    let total = (pre + header.len() + 1).div_ceil(64) * 64;
    header.push_str(&" ".repeat(total - pre - header.len() - 1));
    header.push('\n');
    let mut out = Vec::with_capacity(total + data.len());
    out.extend_from_slice(MAGIC);
    if v1 {
        out.extend_from_slice(&[1, 0]);
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    } else {
        out.extend_from_slice(&[2, 0]);
        out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    }
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

/// The table as a `.npy` file: a `(F, N, 2)` little-endian float64 array in C order, NaN for
/// a missing entry (frame and track ids are not kept: `.npz` keeps them).
pub fn to_npy(t: &TrackTable) -> Vec<u8> {
    let (f, n) = (t.n_frames(), t.n_tracks());
    let mut data = Vec::with_capacity(f * n * 16);
    for fi in 0..f {
        let row = t.frame_row(fi);
        for p in 0..n {
            let [x, y] = row.get(p).unwrap_or([f64::NAN; 2]);
            data.extend_from_slice(&x.to_le_bytes());
            data.extend_from_slice(&y.to_le_bytes());
        }
    }
    npy_bytes("<f8", &[f, n, 2], &data)
}

/// A 1-D id array: `<i8` when every id is an integer, else `<U` strings.
fn ids_npy(ids: &[Id]) -> Vec<u8> {
    if ids.iter().all(|i| matches!(i, Id::Int(_))) {
        let data: Vec<u8> = ids
            .iter()
            .flat_map(|i| match i {
                Id::Int(v) => v.to_le_bytes(),
                Id::Str(_) => [0; 8],
            })
            .collect();
        return npy_bytes("<i8", &[ids.len()], &data);
    }
    let texts: Vec<String> = ids.iter().map(|i| i.to_string()).collect();
    let width = texts
        .iter()
        .map(|s| s.chars().count())
        .max()
        .unwrap_or(0)
        .max(1);
    let mut data = Vec::with_capacity(ids.len() * width * 4);
    for s in &texts {
        let mut k = 0;
        for c in s.chars() {
            data.extend_from_slice(&(c as u32).to_le_bytes());
            k += 1;
        }
        data.resize(data.len() + 4 * (width - k), 0);
    }
    npy_bytes(&format!("<U{width}"), &[ids.len()], &data)
}

/// The table as a `.npz` archive (stored, uncompressed): `tracks` as in [`to_npy`],
/// `frame_ids` and `track_ids`.
pub fn to_npz(t: &TrackTable, path: &Path) -> Result<Vec<u8>> {
    use std::io::Write as _;
    let err = |e: &dyn std::fmt::Display| {
        Error::io(
            path,
            std::io::Error::other(format!("cannot build the .npz archive: {e}")),
        )
    };
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .large_file(t.n_frames().saturating_mul(t.n_tracks()) >= 1 << 27);
    for (name, bytes) in [
        (TRACKS, to_npy(t)),
        (FRAME_IDS, ids_npy(t.frame_ids())),
        (TRACK_IDS, ids_npy(t.track_ids())),
    ] {
        zip.start_file(format!("{name}.npy"), opts)
            .map_err(|e| err(&e))?;
        zip.write_all(&bytes).map_err(|e| err(&e))?;
    }
    Ok(zip.finish().map_err(|e| err(&e))?.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.npy")
    }

    fn fault_of(e: Error) -> (ArrayFault, String) {
        match e {
            Error::Array(e) => (e.fault, e.field),
            e => panic!("unexpected {e}"),
        }
    }

    #[test]
    fn header_literals() {
        let h = "{'descr': '<f4', 'fortran_order': True, 'shape': (3L, 4, 2), }   \n";
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&[1, 0]);
        bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
        bytes.extend_from_slice(h.as_bytes());
        let hd = parse_header(&bytes).unwrap();
        assert_eq!(hd.dtype, Dtype::F4);
        assert!(hd.fortran_order);
        assert_eq!(hd.shape, vec![3, 4, 2]);
        assert_eq!(hd.nbytes, 96);
        assert_eq!(
            parse_literal("{\"a\": (), 'b': (5,), 'c': [('x', '<f8')]}").unwrap(),
            Lit::Dict(vec![
                (Lit::Str("a".into()), Lit::Seq(vec![])),
                (Lit::Str("b".into()), Lit::Seq(vec![Lit::Int(5)])),
                (
                    Lit::Str("c".into()),
                    Lit::Seq(vec![Lit::Seq(vec![
                        Lit::Str("x".into()),
                        Lit::Str("<f8".into())
                    ])])
                ),
            ])
        );
        for bad in [
            "{",
            "{'a' 1}",
            "{'a': 1",
            "{'a': foo}",
            "{} x",
            "'abc",
            "{'a': (1,,)}",
        ] {
            assert!(parse_literal(bad).is_err(), "{bad}");
        }
        assert!(parse_literal(&"[".repeat(100)).is_err());
    }

    #[test]
    fn descr_strings() {
        assert_eq!(parse_descr("<f8"), Ok(Dtype::F8));
        assert_eq!(parse_descr("<f4"), Ok(Dtype::F4));
        assert_eq!(
            parse_descr("|u1"),
            Ok(Dtype::Int {
                size: 1,
                signed: false
            })
        );
        assert_eq!(parse_descr("<U12"), Ok(Dtype::Unicode(12)));
        assert_eq!(parse_descr("|S3"), Ok(Dtype::Bytes(3)));
        for (bad, word) in [
            (">f8", "big-endian"),
            ("<f2", "16-bit"),
            ("|O", "object"),
            ("|b1", "boolean"),
            ("<c16", "complex"),
            ("f8", "type string"),
            ("<i3", "not read"),
        ] {
            let m = parse_descr(bad).unwrap_err();
            assert!(m.contains(word), "{bad}: {m}");
        }
    }

    #[test]
    fn npy_round_trip_and_layouts() {
        let mut t = TrackTable::new(
            (0..3).map(Id::from).collect(),
            (0..2).map(Id::from).collect(),
        );
        t.set(0, 0, 1.5, 2.5);
        t.set(1, 1, 3.0, -4.0);
        t.set(2, 0, 5.0, 6.0);
        let back = parse_npy(to_npy(&t), p()).unwrap();
        assert_eq!(back, t);
        // The (2F, N) layout of the same table.
        let nan = f64::NAN;
        let w = [1.5, nan, 2.5, nan, nan, 3.0, nan, -4.0, 5.0, nan, 6.0, nan];
        let data: Vec<u8> = w.iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(parse_npy(npy_bytes("<f8", &[6, 2], &data), p()).unwrap(), t);
        // Odd rows, 1-D, wrong last axis (12 elements each).
        for shape in [vec![3usize, 4], vec![12], vec![2, 2, 3]] {
            let e = parse_npy(npy_bytes("<f8", &shape, &data), p()).unwrap_err();
            assert_eq!(
                fault_of(e),
                (ArrayFault::Shape, "shape".into()),
                "{shape:?}"
            );
        }
    }

    #[test]
    fn npz_ids_round_trip() {
        let mut t = TrackTable::new(
            vec![Id::Str("img10.png".into()), Id::Str("img2.png".into())],
            vec![Id::Int(7), Id::Int(-3), Id::Int(40)],
        );
        for f in 0..2 {
            for k in 0..3 {
                t.set(f, k, f as f64 + 0.25, k as f64 * 2.0);
            }
        }
        t.unset(1, 2);
        let bytes = to_npz(&t, Path::new("t.npz")).unwrap();
        let (back, warnings) = parse_npz(std::io::Cursor::new(bytes), Path::new("t.npz")).unwrap();
        assert!(warnings.is_empty());
        assert_eq!(back, t);
    }
}
