//! The whole pipeline on small arbitrary tables: byte 0 and 1 give F (2..9) and N (3..19),
//! byte 2 the camera, then each entry takes 5 bytes (a presence byte and two i16 coordinates
//! in tenths of a pixel). Any `Result` is fine; a panic or a non-finite accepted result is not.
#![no_main]
use libfuzzer_sys::fuzz_target;
use rank3::{CameraModel, Config, Id, Reconstruction, TrackTable};

fuzz_target!(|data: &[u8]| {
    if data.len() < 3 {
        return;
    }
    let (nf, nt) = (2 + data[0] as usize % 8, 3 + data[1] as usize % 17);
    let camera = match data[2] % 4 {
        0 => CameraModel::Orthographic,
        1 => CameraModel::ScaledOrthographic,
        2 => CameraModel::Projective,
        _ => CameraModel::Auto,
    };
    let mut t = TrackTable::new(
        (0..nf).map(Id::from).collect(),
        (0..nt).map(Id::from).collect(),
    );
    let mut bytes = data[3..].chunks_exact(5);
    for f in 0..nf {
        for p in 0..nt {
            let Some(c) = bytes.next() else { break };
            if c[0] % 4 != 0 {
                let x = i16::from_le_bytes([c[1], c[2]]) as f64 / 10.0;
                let y = i16::from_le_bytes([c[3], c[4]]) as f64 / 10.0;
                t.set(f, p, x, y);
            }
        }
    }
    let config = Config {
        camera,
        ..Config::default()
    };
    if let Ok(r) = Reconstruction::from_tracks(&t, &config) {
        assert!(
            r.rms_px.is_finite() || r.rms_px.is_nan(),
            "rms {}",
            r.rms_px
        );
    }
});
