//! Frame sources: a folder of PNG/JPEG images or a video file, delivered one grayscale
//! frame at a time so long videos never sit in memory whole.
//!
//! * Folder: files with extension `.png`, `.jpg` or `.jpeg` (any case), in *natural* order of
//!   their names (`hotel.seq2` before `hotel.seq10`), decoded with the `image` crate and
//!   converted to luma. Frame ids are the file stems, parsed with [`Id::parse`] (so a stem
//!   `0042` becomes the integer id 42 and `hotel.seq7` stays a string).
//! * Video: any other file. Decoded by FFmpeg's command-line programs (Debian package
//!   `ffmpeg`): `ffprobe` gives the frame size, `ffmpeg -i FILE -f rawvideo -pix_fmt gray -`
//!   streams raw 8-bit gray frames through a pipe. Frame ids are the 0-based frame indices.
//!
//! Intensities are `f32` in `[0, 1]` (8-bit value / 255). [`FrameSource::next_color_frame`]
//! delivers the same frames in 8-bit RGB (for texturing and point colours); a source is
//! read either in gray or in colour ([`FrameSource::open_color`]).

// Negated comparisons are deliberate: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::cmp::Ordering;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};

use crate::table::Id;
use crate::{Error, Result};

/// A grayscale image, row-major, intensities in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    pub width: usize,
    pub height: usize,
    /// `height × width` values, pixel `(x, y)` at `y * width + x`.
    pub data: Vec<f32>,
}

impl GrayImage {
    /// An image from row-major data; `data.len()` must be `width * height`.
    pub fn new(width: usize, height: usize, data: Vec<f32>) -> Result<GrayImage> {
        if data.len() != width * height {
            return Err(Error::Dimension {
                context: "GrayImage::new",
                expected: format!("{} values ({width}×{height})", width * height),
                got: format!("{}", data.len()),
            });
        }
        Ok(GrayImage {
            width,
            height,
            data,
        })
    }

    /// An image from 8-bit gray values.
    pub fn from_u8(width: usize, height: usize, bytes: &[u8]) -> Result<GrayImage> {
        GrayImage::new(
            width,
            height,
            bytes.iter().map(|&b| b as f32 * (1.0 / 255.0)).collect(),
        )
    }

    /// Pixel `(x, y)` (no bounds check beyond the slice's).
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Reads a PNG or JPEG file and converts it to gray.
    pub fn open(path: &Path) -> Result<GrayImage> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        GrayImage::decode(&bytes, path)
    }

    /// Decodes PNG or JPEG bytes, refusing an image above [`crate::budget::FRAME_PIXELS`]
    /// from its header before decoding it; `name` names the source in errors.
    pub fn decode(bytes: &[u8], name: &Path) -> Result<GrayImage> {
        let luma = decode_checked(bytes, name)?.into_luma8();
        let (w, h) = luma.dimensions();
        GrayImage::from_u8(w as usize, h as usize, luma.as_raw())
    }

    /// Writes the image as an 8-bit PNG (values clamped to `[0, 1]`).
    pub fn save_png(&self, path: &Path) -> Result<()> {
        let bytes: Vec<u8> = self
            .data
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let buf = image::GrayImage::from_raw(self.width as u32, self.height as u32, bytes)
            .ok_or_else(|| Error::Image {
                path: path.to_path_buf(),
                message: "image buffer has the wrong size".into(),
            })?;
        buf.save(path).map_err(|e| Error::Image {
            path: path.to_path_buf(),
            message: format!("cannot write PNG: {e}"),
        })
    }
}

/// Compares file names in natural order: runs of ASCII digits compare as numbers
/// (`seq2` < `seq10`), everything else character by character.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i].is_ascii_digit() && b[j].is_ascii_digit() {
            let si = i;
            while i < a.len() && a[i].is_ascii_digit() {
                i += 1;
            }
            let sj = j;
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            let na = trim_zeros(&a[si..i]);
            let nb = trim_zeros(&b[sj..j]);
            let ord = na
                .len()
                .cmp(&nb.len())
                .then_with(|| na.cmp(nb))
                .then_with(|| (i - si).cmp(&(j - sj)));
            if ord != Ordering::Equal {
                return ord;
            }
        } else {
            if a[i] != b[j] {
                return a[i].cmp(&b[j]);
            }
            i += 1;
            j += 1;
        }
    }
    (a.len() - i).cmp(&(b.len() - j))
}

fn trim_zeros(d: &[u8]) -> &[u8] {
    let k = d.iter().position(|&c| c != b'0').unwrap_or(d.len());
    &d[k..]
}

fn is_image_file(p: &Path) -> bool {
    matches!(
        p.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("png" | "jpg" | "jpeg")
    )
}

/// Decodes PNG or JPEG bytes after checking the size in their header against
/// [`crate::budget::FRAME_PIXELS`] (nothing is allocated for a frame over the budget).
fn decode_checked(bytes: &[u8], name: &Path) -> Result<image::DynamicImage> {
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| Error::io(name, e))?;
    let (w, h) = reader.into_dimensions().map_err(|e| Error::Image {
        path: name.to_path_buf(),
        message: format!("cannot read the image header: {e}"),
    })?;
    crate::budget::check_frame(name, w as u64, h as u64)?;
    image::load_from_memory(bytes).map_err(|e| Error::Image {
        path: name.to_path_buf(),
        message: format!("cannot decode image: {e}"),
    })
}

/// The next image of a folder source, decoded, with its id (`None` after the last); an image
/// of another size than the first is an [`Error::Image`].
fn next_folder_image(
    files: &[PathBuf],
    next: &mut usize,
    size: &mut Option<(usize, usize)>,
) -> Result<Option<(Id, image::DynamicImage)>> {
    let Some(file) = files.get(*next) else {
        return Ok(None);
    };
    *next += 1;
    let bytes = std::fs::read(file).map_err(|e| Error::io(file, e))?;
    let img = decode_checked(&bytes, file)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    match *size {
        None => *size = Some((w, h)),
        Some((w0, h0)) if (w0, h0) != (w, h) => {
            return Err(Error::Image {
                path: file.clone(),
                message: format!("frame size {w}×{h} differs from the first frame's {w0}×{h0}"),
            });
        }
        Some(_) => {}
    }
    Ok(Some((frame_id(file), img)))
}

/// A frame's id: its file stem, parsed with [`Id::parse`].
fn frame_id(file: &Path) -> Id {
    let stem = file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    Id::parse(&stem)
}

/// A sequence of frames read lazily from a folder of images or a video.
pub enum FrameSource {
    /// Images of a folder, in natural order.
    Images {
        dir: PathBuf,
        files: Vec<PathBuf>,
        next: usize,
        size: Option<(usize, usize)>,
    },
    /// Raw gray frames piped from `ffmpeg`.
    Video(VideoReader),
}

impl FrameSource {
    /// Opens a folder of images (when `path` is a directory) or a video file.
    pub fn open(path: impl AsRef<Path>) -> Result<FrameSource> {
        FrameSource::open_as(path.as_ref(), false)
    }

    /// [`FrameSource::open`] for [`FrameSource::next_color_frame`] (a video is decoded to
    /// RGB; a folder's images are converted when read).
    pub fn open_color(path: impl AsRef<Path>) -> Result<FrameSource> {
        FrameSource::open_as(path.as_ref(), true)
    }

    fn open_as(path: &Path, color: bool) -> Result<FrameSource> {
        let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
        if meta.is_dir() {
            FrameSource::images(path)
        } else {
            Ok(FrameSource::Video(VideoReader::open_as(path, color)?))
        }
    }

    /// The next frame in 8-bit RGB and its id, `None` at the end (a video must have been
    /// opened with [`FrameSource::open_color`]).
    pub fn next_color_frame(&mut self) -> Result<Option<(Id, image::RgbImage)>> {
        match self {
            FrameSource::Images {
                files, next, size, ..
            } => Ok(next_folder_image(files, next, size)?.map(|(id, img)| (id, img.into_rgb8()))),
            FrameSource::Video(v) => v.next_color_frame(),
        }
    }

    /// Opens a folder of PNG/JPEG images; errors when it holds none.
    pub fn images(dir: &Path) -> Result<FrameSource> {
        let rd = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
        let mut files = Vec::new();
        for entry in rd {
            let entry = entry.map_err(|e| Error::io(dir, e))?;
            let p = entry.path();
            if p.is_file() && is_image_file(&p) {
                files.push(p);
            }
        }
        if files.is_empty() {
            return Err(Error::Image {
                path: dir.to_path_buf(),
                message: "the folder contains no PNG or JPEG images".into(),
            });
        }
        files.sort_by(|a, b| {
            let na = a
                .file_name()
                .map(|s| s.to_string_lossy())
                .unwrap_or_default();
            let nb = b
                .file_name()
                .map(|s| s.to_string_lossy())
                .unwrap_or_default();
            natural_cmp(&na, &nb)
        });
        Ok(FrameSource::Images {
            dir: dir.to_path_buf(),
            files,
            next: 0,
            size: None,
        })
    }

    /// Number of frames when known in advance (folders; videos when FFprobe reports it).
    pub fn len_hint(&self) -> Option<usize> {
        match self {
            FrameSource::Images { files, .. } => Some(files.len()),
            FrameSource::Video(v) => v.frames_hint,
        }
    }

    /// The pixels' aspect ratio `f_x / f_y` when the input states one: the first image's
    /// PNG `pHYs` chunk or JPEG JFIF densities, the video's sample aspect ratio
    /// ([`crate::pixel_aspect`]); `None` when it states none or square pixels.
    pub fn pixel_aspect(&self) -> Option<crate::pixel_aspect::PixelAspect> {
        match self {
            FrameSource::Images { files, .. } => {
                let first = files.first()?;
                let mut a = crate::pixel_aspect::from_image_file(first)?;
                a.source = format!("{} ({})", a.source, first.display());
                Some(a)
            }
            FrameSource::Video(v) => v.pixel_aspect.clone(),
        }
    }

    /// [`FrameSource::pixel_aspect`] of the folder or video at `path`, without decoding a
    /// frame or starting `ffmpeg` (a folder's first image header; `ffprobe` for a video).
    pub fn pixel_aspect_of(path: &Path) -> Result<Option<crate::pixel_aspect::PixelAspect>> {
        let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
        if meta.is_dir() {
            Ok(FrameSource::images(path)?.pixel_aspect())
        } else {
            Ok(probe(path)?.pixel_aspect)
        }
    }

    /// A folder source's images as `(frame id, file name)` in the order they are read (the
    /// ids [`FrameSource::next_frame`] gives them); `None` for a video, whose frames have no
    /// files.
    pub fn image_files(&self) -> Option<Vec<(Id, String)>> {
        match self {
            FrameSource::Images { files, .. } => Some(
                files
                    .iter()
                    .map(|f| {
                        let name = f
                            .file_name()
                            .map(|s| s.to_string_lossy().into_owned())
                            .unwrap_or_default();
                        (frame_id(f), name)
                    })
                    .collect(),
            ),
            FrameSource::Video(_) => None,
        }
    }

    /// The input path.
    pub fn path(&self) -> &Path {
        match self {
            FrameSource::Images { dir, .. } => dir,
            FrameSource::Video(v) => &v.path,
        }
    }

    /// The next frame and its id, `None` at the end. Frames of a different size than the
    /// first are an [`Error::Image`].
    pub fn next_frame(&mut self) -> Result<Option<(Id, GrayImage)>> {
        match self {
            FrameSource::Images {
                files, next, size, ..
            } => {
                let Some((id, img)) = next_folder_image(files, next, size)? else {
                    return Ok(None);
                };
                let luma = img.into_luma8();
                let (w, h) = luma.dimensions();
                Ok(Some((
                    id,
                    GrayImage::from_u8(w as usize, h as usize, luma.as_raw())?,
                )))
            }
            FrameSource::Video(v) => v.next_frame(),
        }
    }
}

/// Streams gray frames from `ffmpeg` (see the module documentation).
pub struct VideoReader {
    path: PathBuf,
    width: usize,
    height: usize,
    frames_hint: Option<usize>,
    pixel_aspect: Option<crate::pixel_aspect::PixelAspect>,
    child: Child,
    stdout: ChildStdout,
    index: usize,
    buf: Vec<u8>,
    done: bool,
}

fn not_installed(path: &Path, program: &str, e: &std::io::Error) -> Error {
    Error::Video {
        path: path.to_path_buf(),
        message: if e.kind() == std::io::ErrorKind::NotFound {
            format!(
                "`{program}` was not found: install FFmpeg to read videos \
                 (Debian/Ubuntu: apt-get install ffmpeg), or pass a folder of images"
            )
        } else {
            format!("cannot run `{program}`: {e}")
        },
    }
}

/// What `ffprobe` says of a video's first stream.
struct Probe {
    width: usize,
    height: usize,
    frames_hint: Option<usize>,
    pixel_aspect: Option<crate::pixel_aspect::PixelAspect>,
}

/// Runs `ffprobe` on `path` (no decoding): the frame size (checked against the memory
/// budget and for zero), the frame count when known, the sample aspect ratio.
fn probe(path: &Path) -> Result<Probe> {
    let probe = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=width,height,nb_frames,sample_aspect_ratio",
            "-of",
            "default=noprint_wrappers=1",
        ])
        .arg(path)
        .output()
        .map_err(|e| not_installed(path, "ffprobe", &e))?;
    let text = String::from_utf8_lossy(&probe.stdout);
    let field = |name: &str| {
        text.lines()
            .filter_map(|l| l.strip_prefix(name)?.strip_prefix('='))
            .find_map(|v| v.trim().parse::<usize>().ok())
    };
    let (Some(width), Some(height)) = (field("width"), field("height")) else {
        let err = String::from_utf8_lossy(&probe.stderr);
        return Err(Error::Video {
            path: path.to_path_buf(),
            message: format!(
                "FFmpeg cannot read a video stream from this file{}",
                match err.trim() {
                    "" => String::new(),
                    m => format!(": {m}"),
                }
            ),
        });
    };
    crate::budget::check_frame(path, width as u64, height as u64)?;
    if width == 0 || height == 0 {
        return Err(Error::Video {
            path: path.to_path_buf(),
            message: format!("video reports an empty frame size {width}×{height}"),
        });
    }
    Ok(Probe {
        width,
        height,
        frames_hint: field("nb_frames"),
        pixel_aspect: text
            .lines()
            .find_map(|l| l.strip_prefix("sample_aspect_ratio="))
            .and_then(crate::pixel_aspect::from_sample_aspect_ratio),
    })
}

impl VideoReader {
    /// Probes the video's size with `ffprobe` and starts `ffmpeg`.
    pub fn open(path: &Path) -> Result<VideoReader> {
        VideoReader::open_as(path, false)
    }

    /// [`VideoReader::open`], streaming 8-bit RGB (`rgb24`) when `color`.
    pub fn open_as(path: &Path, color: bool) -> Result<VideoReader> {
        let Probe {
            width,
            height,
            frames_hint,
            pixel_aspect,
        } = probe(path)?;
        let mut child = Command::new("ffmpeg")
            .args(["-v", "error", "-nostdin", "-i"])
            .arg(path)
            .args([
                "-f",
                "rawvideo",
                "-pix_fmt",
                if color { "rgb24" } else { "gray" },
                "-",
            ])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| not_installed(path, "ffmpeg", &e))?;
        let stdout = child.stdout.take().ok_or_else(|| Error::Video {
            path: path.to_path_buf(),
            message: "cannot capture ffmpeg's output".into(),
        })?;
        Ok(VideoReader {
            path: path.to_path_buf(),
            width,
            height,
            frames_hint,
            pixel_aspect,
            child,
            stdout,
            index: 0,
            buf: vec![0; width * height * if color { 3 } else { 1 }],
            done: false,
        })
    }

    fn stderr_text(&mut self) -> String {
        let mut s = String::new();
        if let Some(e) = self.child.stderr.as_mut() {
            let _ = e.read_to_string(&mut s);
        }
        s.trim().to_string()
    }

    fn next_frame(&mut self) -> Result<Option<(Id, GrayImage)>> {
        if !self.read_raw()? {
            return Ok(None);
        }
        let img = GrayImage::from_u8(self.width, self.height, &self.buf)?;
        let id = Id::from(self.index);
        self.index += 1;
        Ok(Some((id, img)))
    }

    fn next_color_frame(&mut self) -> Result<Option<(Id, image::RgbImage)>> {
        if !self.read_raw()? {
            return Ok(None);
        }
        let img =
            image::RgbImage::from_raw(self.width as u32, self.height as u32, self.buf.clone())
                .ok_or_else(|| Error::Video {
                    path: self.path.clone(),
                    message: "the video was not opened in colour".into(),
                })?;
        let id = Id::from(self.index);
        self.index += 1;
        Ok(Some((id, img)))
    }

    /// Fills `buf` with the next raw frame; false at the end of the stream.
    fn read_raw(&mut self) -> Result<bool> {
        if self.done {
            return Ok(false);
        }
        let mut filled = 0;
        while filled < self.buf.len() {
            match self.stdout.read(&mut self.buf[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Error::io(&self.path, e)),
            }
        }
        if filled < self.buf.len() {
            self.done = true;
            let status = self.child.wait().map_err(|e| Error::io(&self.path, e))?;
            let err = self.stderr_text();
            if !status.success() || (self.index == 0) {
                return Err(Error::Video {
                    path: self.path.clone(),
                    message: format!(
                        "ffmpeg failed after {} frames{}",
                        self.index,
                        if err.is_empty() {
                            String::new()
                        } else {
                            format!(": {err}")
                        }
                    ),
                });
            }
            if filled > 0 {
                return Err(Error::Video {
                    path: self.path.clone(),
                    message: format!("stream ended inside frame {}", self.index),
                });
            }
            return Ok(false);
        }
        Ok(true)
    }
}

impl Drop for VideoReader {
    fn drop(&mut self) {
        if !self.done {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut v = vec![
            "hotel.seq10.png",
            "hotel.seq2.png",
            "hotel.seq0.png",
            "hotel.seq1.png",
            "a02.png",
            "a1.png",
        ];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            [
                "a1.png",
                "a02.png",
                "hotel.seq0.png",
                "hotel.seq1.png",
                "hotel.seq2.png",
                "hotel.seq10.png"
            ]
        );
    }
}
