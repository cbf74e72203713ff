//! Locating the public benchmark data sets (never shipped with rank3).
//!
//! The directory is taken from the `RANK3_DATASETS` environment variable, or defaults to
//! `../shared/datasets` next to this crate's manifest.

use std::path::PathBuf;

/// Directory that holds `dino_trimmed/`, `model_house/`, `hotel/`.
pub fn dir() -> PathBuf {
    match std::env::var_os("RANK3_DATASETS") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets"),
    }
}

/// Path of a file inside the data-set directory if it exists; `None` (with the reason
/// printed to stderr) when it is absent, so tests and examples can say so and skip.
pub fn find(relative: &str) -> Option<PathBuf> {
    let p = dir().join(relative);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "data set file {} not found (set RANK3_DATASETS to the data-set directory); skipping",
            p.display()
        );
        None
    }
}

/// A Hopkins 155 motion-segmentation sequence (Tron & Vidal, CVPR 2007) in the text form
/// of `hopkins_dev/` (its README): `#` comment lines, then `F P G width height`, then `P`
/// group labels in `1..=G`, then `2F` rows of `P` pixel coordinates (row `2f` = x, row
/// `2f+1` = y of frame `f`).
#[derive(Debug, Clone)]
pub struct Hopkins {
    /// The complete tracks.
    pub measurements: crate::Measurements,
    /// The ground-truth group of every track, 0-based.
    pub groups: Vec<usize>,
    /// Number of groups.
    pub n_groups: usize,
    /// Image size in pixels.
    pub image_size: (f64, f64),
}

/// Reads a [`Hopkins`] sequence; typed errors name the file, line and field.
pub fn read_hopkins(path: &std::path::Path) -> crate::Result<Hopkins> {
    use crate::Error;
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let parse_err =
        |line: usize, field: &str, message: String| Error::parse(path, line, field, message);
    let mut rows = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#') && !l.trim().is_empty());
    let mut numbers = |what: &str| -> crate::Result<(usize, Vec<f64>)> {
        let (i, l) = rows
            .next()
            .ok_or_else(|| parse_err(0, what, "the file ends before it".into()))?;
        let v = l
            .split_whitespace()
            .enumerate()
            .map(|(k, s)| {
                s.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        parse_err(
                            i + 1,
                            &format!("{what}, value {}", k + 1),
                            format!("`{s:.20}` is not a finite number"),
                        )
                    })
            })
            .collect::<crate::Result<Vec<f64>>>()?;
        Ok((i + 1, v))
    };
    let (hl, h) = numbers("header `F P G width height`")?;
    let int = |x: f64| (x >= 0.0 && x.fract() == 0.0 && x < 1e9).then_some(x as usize);
    if h.len() != 5 || h[..3].iter().any(|&x| int(x).is_none_or(|v| v == 0)) {
        return Err(parse_err(
            hl,
            "header",
            "must be `F P G width height` with positive integers F, P, G".into(),
        ));
    }
    let (f, p, g) = (h[0] as usize, h[1] as usize, h[2] as usize);
    let (ll, lab) = numbers("group labels")?;
    if lab.len() != p {
        return Err(parse_err(
            ll,
            "group labels",
            format!("{} labels for {p} points", lab.len()),
        ));
    }
    let mut groups = Vec::with_capacity(p);
    for (k, &x) in lab.iter().enumerate() {
        match int(x) {
            Some(v) if (1..=g).contains(&v) => groups.push(v - 1),
            _ => {
                return Err(parse_err(
                    ll,
                    &format!("group label {}", k + 1),
                    format!("{x} is not in 1..={g}"),
                ));
            }
        }
    }
    let mut w = faer::Mat::<f64>::zeros(2 * f, p);
    for r in 0..2 * f {
        let (rl, v) = numbers(&format!("coordinate row {}", r + 1))?;
        if v.len() != p {
            return Err(parse_err(
                rl,
                &format!("coordinate row {}", r + 1),
                format!("{} values for {p} points", v.len()),
            ));
        }
        for (c, x) in v.into_iter().enumerate() {
            w[(r, c)] = x;
        }
    }
    Ok(Hopkins {
        measurements: crate::Measurements::complete(w),
        groups,
        n_groups: g,
        image_size: (h[3], h[4]),
    })
}
