//! The pixels' aspect ratio `f_x / f_y`: where rank3 learns it when the user does not give it.
//!
//! A camera's intrinsic matrix has `f_x = f / w_px` and `f_y = f / h_px` for pixels `w_px`
//! wide and `h_px` high, so `f_x / f_y = h_px / w_px` (the reciprocal of video's *pixel* or
//! *sample aspect ratio*, `SAR = w_px : h_px`). Under every camera model the ratio cannot be
//! told from the tracks when the camera mostly turns about the image's vertical axis: for a
//! rotation about `y`, scaling the scene's `X` and `Z` by `a` scales every image `x` by `a`
//! and leaves `y` alone, so the reprojection error is the same for every ratio while the
//! angles of the reconstruction are not (the CMU hotel sequence, docs/results.md § Hotel:
//! reprojection RMS within 2 % over ratios 0.7–1.3, walls meeting at 81° to 90°). The ratio
//! has to come from what is known about the pixels, in this order:
//!
//! 1. **Given** ([`crate::Config::aspect_ratio`], `--aspect-ratio`).
//! 2. **Stated by the input file**: a PNG's `pHYs` chunk (pixels per unit along x and y:
//!    `f_x / f_y = ppu_x / ppu_y`; W3C PNG specification §11.3.5.3), a JPEG's JFIF `APP0`
//!    densities (`X_density / Y_density`; JFIF 1.02), a video stream's sample aspect ratio
//!    as FFprobe reports it (`f_x / f_y = den / num` for `SAR = num:den`).
//! 3. **The frame size of digitised analogue video**, when the file states nothing: frames
//!    of these sizes hold a 4:3 picture whose pixels are not square, by the standards that
//!    define them:
//!    * 512×480: RS-170 (NTSC) lines sampled 512 times by a frame grabber; the 480 active
//!      lines and the 4:3 picture give pixels `(4/3 · 480) / 512 = 1.25` times as wide as
//!      high, `f_x / f_y = 0.8` (the CMU image sequences are of this kind);
//!    * 720×480, 720×486, 704×480: ITU-R BT.601 525-line sampling, `SAR = 10:11`,
//!      `f_x / f_y = 1.1`;
//!    * 720×576, 704×576: BT.601 625-line sampling (PAL), `SAR = 12:11`,
//!      `f_x / f_y = 11/12`.
//!
//!    This is an assumption (a 16:9 picture in the same frame has other pixels), so it is
//!    reported as one, and `--aspect-ratio 1` overrides it.
//! 4. Otherwise square pixels.
//!
//! Cost: reading a header, O(size of the chunks before the image data).

use std::io::Read;
use std::path::Path;

/// An aspect ratio `f_x / f_y` and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelAspect {
    /// `f_x / f_y` (1: square pixels).
    pub ratio: f64,
    /// Where it came from, in words (`"PNG pHYs 2835×3543 pixels per metre"`,
    /// `"assumed: 512×480 frames hold a 4:3 picture (RS-170 frame grabber)"`).
    pub source: String,
}

/// The ratio of frames of `width × height` pixels of digitised analogue video (rule 3 of the
/// module documentation), `None` for every other size.
pub fn from_frame_size(width: u32, height: u32) -> Option<PixelAspect> {
    let (ratio, standard) = match (width, height) {
        (512, 480) => (0.8, "RS-170 (NTSC) frame grabber, a 4:3 picture"),
        (720, 480) | (720, 486) | (704, 480) => (
            1.1,
            "ITU-R BT.601 525-line sampling, SAR 10:11, a 4:3 picture",
        ),
        (720, 576) | (704, 576) => (
            11.0 / 12.0,
            "ITU-R BT.601 625-line sampling, SAR 12:11, a 4:3 picture",
        ),
        _ => return None,
    };
    Some(PixelAspect {
        ratio,
        source: format!("assumed from the {width}×{height} frame size: {standard}"),
    })
}

/// Rules 2 and 3 of the module documentation for a sequence of frames: what their files
/// state (`stated`, e.g. [`crate::tracking::FrameSource::pixel_aspect`]), else what their
/// `size` (width, height) implies, else `None` (square pixels).
pub fn of_frames(stated: Option<PixelAspect>, size: Option<[u32; 2]>) -> Option<PixelAspect> {
    stated.or_else(|| size.and_then(|[w, h]| from_frame_size(w, h)))
}

/// `f_x / f_y` from a positive pair `x : y` of densities (or `den : num` of a SAR); `None`
/// when either is zero or the ratio is 1 (square pixels need no report) or implausible
/// (outside 1/4 … 4).
fn ratio_of(x: u64, y: u64) -> Option<f64> {
    if x == 0 || y == 0 || x == y {
        return None;
    }
    let r = x as f64 / y as f64;
    (0.25..=4.0).contains(&r).then_some(r)
}

/// The ratio a PNG or JPEG file's header states (rule 2), `None` when it states none, states
/// square pixels, or cannot be read (the decoder reports unreadable files).
pub fn from_image_file(path: &Path) -> Option<PixelAspect> {
    let mut head = Vec::with_capacity(1 << 16);
    std::fs::File::open(path)
        .ok()?
        .take(1 << 16)
        .read_to_end(&mut head)
        .ok()?;
    from_png_header(&head).or_else(|| from_jfif_header(&head))
}

/// The `pHYs` chunk of a PNG whose first bytes are `head` (chunks before `IDAT` only).
pub fn from_png_header(head: &[u8]) -> Option<PixelAspect> {
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    if head.get(..8)? != SIGNATURE {
        return None;
    }
    let mut at = 8;
    while at + 8 <= head.len() {
        let len = u32::from_be_bytes(head[at..at + 4].try_into().ok()?) as usize;
        let kind = &head[at + 4..at + 8];
        let data = head.get(at + 8..at.checked_add(8 + len)?)?;
        match kind {
            b"pHYs" if len == 9 => {
                let px = u32::from_be_bytes(data[0..4].try_into().ok()?);
                let py = u32::from_be_bytes(data[4..8].try_into().ok()?);
                let ratio = ratio_of(px.into(), py.into())?;
                let unit = if data[8] == 1 {
                    "pixels per metre"
                } else {
                    "(unit unknown)"
                };
                return Some(PixelAspect {
                    ratio,
                    source: format!("the PNG's pHYs chunk: {px}×{py} {unit}"),
                });
            }
            b"IDAT" | b"IEND" => return None,
            _ => {}
        }
        at += 12 + len;
    }
    None
}

/// The JFIF `APP0` densities of a JPEG whose first bytes are `head`.
pub fn from_jfif_header(head: &[u8]) -> Option<PixelAspect> {
    if head.get(..2)? != [0xff, 0xd8] {
        return None;
    }
    let mut at = 2;
    while at + 4 <= head.len() && head[at] == 0xff {
        let marker = head[at + 1];
        let len = u16::from_be_bytes([head[at + 2], head[at + 3]]) as usize;
        if marker == 0xda || len < 2 {
            return None; // start of scan: no JFIF segment before the image data
        }
        let data = head.get(at + 4..at + 2 + len)?;
        if marker == 0xe0 && data.len() >= 12 && &data[..5] == b"JFIF\0" {
            let dx = u16::from_be_bytes([data[8], data[9]]);
            let dy = u16::from_be_bytes([data[10], data[11]]);
            let ratio = ratio_of(dx.into(), dy.into())?;
            return Some(PixelAspect {
                ratio,
                source: format!("the JPEG's JFIF densities {dx}×{dy}"),
            });
        }
        at += 2 + len;
    }
    None
}

/// The ratio of a video stream whose sample aspect ratio FFprobe printed as `sar`
/// (`"10:11"`; `"0:1"`, `"1:1"` or `"N/A"` state nothing).
pub fn from_sample_aspect_ratio(sar: &str) -> Option<PixelAspect> {
    let (num, den) = sar.trim().split_once(':')?;
    let (num, den): (u64, u64) = (num.trim().parse().ok()?, den.trim().parse().ok()?);
    let ratio = ratio_of(den, num)?;
    Some(PixelAspect {
        ratio,
        source: format!("the video's sample aspect ratio {num}:{den}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png_with(chunks: &[(&[u8; 4], Vec<u8>)]) -> Vec<u8> {
        let mut v = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
        for (kind, data) in chunks {
            v.extend((data.len() as u32).to_be_bytes());
            v.extend(*kind);
            v.extend(data);
            v.extend([0; 4]); // CRC, not checked here
        }
        v
    }

    fn phys(px: u32, py: u32, unit: u8) -> Vec<u8> {
        let mut d = px.to_be_bytes().to_vec();
        d.extend(py.to_be_bytes());
        d.push(unit);
        d
    }

    #[test]
    fn png_phys_gives_ppu_x_over_ppu_y() {
        let head = png_with(&[(b"IHDR", vec![0; 13]), (b"pHYs", phys(4000, 5000, 1))]);
        let a = from_png_header(&head).unwrap();
        assert!((a.ratio - 0.8).abs() < 1e-15, "{a:?}");
        assert!(a.source.contains("4000×5000 pixels per metre"), "{a:?}");
        // Square pixels, no chunk, or the chunk after the image data: nothing stated.
        let square = png_with(&[(b"IHDR", vec![0; 13]), (b"pHYs", phys(2835, 2835, 1))]);
        assert_eq!(from_png_header(&square), None);
        let none = png_with(&[(b"IHDR", vec![0; 13]), (b"IDAT", vec![1, 2, 3])]);
        assert_eq!(from_png_header(&none), None);
        let late = png_with(&[(b"IDAT", vec![1]), (b"pHYs", phys(4000, 5000, 1))]);
        assert_eq!(from_png_header(&late), None);
        // Truncated or foreign bytes never panic.
        for cut in 0..head.len() {
            let _ = from_png_header(&head[..cut]);
            let _ = from_jfif_header(&head[..cut]);
        }
        assert_eq!(from_png_header(b"GIF89a"), None);
    }

    #[test]
    fn jfif_densities() {
        let mut head = vec![0xff, 0xd8, 0xff, 0xe0, 0, 16];
        head.extend(b"JFIF\0");
        head.extend([1, 2, 0, 0, 10, 0, 11, 0, 0]);
        let a = from_jfif_header(&head).unwrap();
        assert!((a.ratio - 10.0 / 11.0).abs() < 1e-15, "{a:?}");
        head[15] = 11; // X density 11, Y density 11: square
        assert_eq!(from_jfif_header(&head), None);
        for cut in 0..head.len() {
            let _ = from_jfif_header(&head[..cut]);
        }
    }

    #[test]
    fn video_sar_and_frame_sizes() {
        let a = from_sample_aspect_ratio("10:11").unwrap();
        assert!((a.ratio - 1.1).abs() < 1e-15);
        for unknown in ["0:1", "1:1", "N/A", "", "1:0", "x:y"] {
            assert_eq!(from_sample_aspect_ratio(unknown), None, "{unknown}");
        }
        assert_eq!(from_frame_size(512, 480).unwrap().ratio, 0.8);
        assert_eq!(from_frame_size(720, 480).unwrap().ratio, 1.1);
        assert!((from_frame_size(720, 576).unwrap().ratio - 11.0 / 12.0).abs() < 1e-15);
        for square in [(640, 480), (1920, 1080), (480, 512), (1280, 720)] {
            assert_eq!(from_frame_size(square.0, square.1), None);
        }
    }
}
