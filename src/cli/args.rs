//! The value enums of the arguments and the parsers of structured values.

use clap::ValueEnum;
use rank3::CameraModel;

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CameraArg {
    /// Chosen from the data: the perspective camera when it explains the tracks
    /// significantly better than the scaled orthographic one (BIC), else the latter.
    Auto,
    /// Orthographic projection (affine, unit scale).
    Orthographic,
    /// Scaled orthographic / weak perspective (affine, one scale per frame).
    ScaledOrthographic,
    /// Projective camera `w ≃ P X` (3×4 P per frame, homogeneous points; up to a 4×4
    /// homography). Not for `synth`.
    Projective,
    /// Pinhole perspective camera `K [R | t]`: projective factorization, self-calibration
    /// (or the given `--focal`), metric bundle adjustment.
    Perspective,
}

impl CameraArg {
    /// The name on the command line.
    pub fn name(self) -> String {
        self.to_possible_value()
            .map_or_else(String::new, |v| v.get_name().to_string())
    }
}

impl From<CameraArg> for CameraModel {
    fn from(c: CameraArg) -> Self {
        match c {
            CameraArg::Orthographic => CameraModel::Orthographic,
            CameraArg::ScaledOrthographic => CameraModel::ScaledOrthographic,
            CameraArg::Perspective => CameraModel::Perspective,
            CameraArg::Projective => CameraModel::Projective,
            CameraArg::Auto => CameraModel::Auto,
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LossArg {
    /// Plain least squares.
    None,
    /// Huber: quadratic within the scale, linear beyond.
    Huber,
    /// Cauchy: logarithmic beyond the scale.
    Cauchy,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum SolverArg {
    Wiberg,
    Als,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum InitArg {
    Auto,
    Random,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum ShapeArg {
    House,
    Cloud,
    Cube,
    Plane,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum MotionArg {
    Turntable,
    HandheldArc,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum OutlierArg {
    Mixed,
    RandomWalk,
    SecondObject,
    Sliding,
}

/// Parses `A,B` (or `AxB`) into two values.
pub fn parse_pair<T: std::str::FromStr>(s: &str) -> Result<[T; 2], String> {
    let parts: Vec<&str> = s.split([',', 'x', 'X']).map(str::trim).collect();
    match parts.as_slice() {
        [a, b] => match (a.parse(), b.parse()) {
            (Ok(a), Ok(b)) => Ok([a, b]),
            _ => Err(format!("`{s}`: expected two numbers as A,B")),
        },
        _ => Err(format!("`{s}`: expected two numbers as A,B")),
    }
}

/// Parses one `SHARE:MOTION` item of `synth --objects`.
pub fn parse_synth_object(item: &str) -> Result<rank3::synth::SynthObject, String> {
    use rank3::synth::{ObjectMotion, SynthObject};
    let (share, motion) = item
        .trim()
        .split_once(':')
        .ok_or_else(|| format!("`{item}` is not SHARE:MOTION (e.g. 0.2:rotating)"))?;
    let share: f64 = share
        .trim()
        .parse()
        .map_err(|_| format!("`{share}` is not a fraction"))?;
    let motion = match motion.trim() {
        "rotating" => ObjectMotion::Rotating,
        "translating" => ObjectMotion::Translating,
        m => {
            return Err(format!(
                "motion `{m}` is neither `rotating` nor `translating`"
            ));
        }
    };
    Ok(SynthObject { share, motion })
}

/// Parses `--objects auto|K`.
pub fn parse_objects(s: &str) -> Result<rank3::segment::Objects, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(rank3::segment::Objects::Auto);
    }
    match s.parse::<usize>() {
        Ok(k) if (1..=1000).contains(&k) => Ok(rank3::segment::Objects::Count(k)),
        _ => Err(format!("`{s}` is neither `auto` nor a count in 1..=1000")),
    }
}

/// A byte count: a number with an optional suffix K, M, G or T (powers of 1024), e.g.
/// `512M`.
pub fn parse_bytes(s: &str) -> Result<usize, String> {
    let t = s.trim();
    let (num, mult) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let m: u64 = match c.to_ascii_uppercase() {
                'K' => 1 << 10,
                'M' => 1 << 20,
                'G' => 1 << 30,
                'T' => 1 << 40,
                _ => return Err(format!("`{s}`: the suffix must be K, M, G or T")),
            };
            (&t[..i], m)
        }
        _ => (t, 1),
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a byte count (e.g. 512M, 2G)"))?;
    if !(v.is_finite() && v >= 1.0) {
        return Err(format!("`{s}`: at least one byte"));
    }
    Ok((v * mult as f64).min(usize::MAX as f64) as usize)
}
