//! The tracker's `--init-points` parser on arbitrary text: an error or finite points.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(pts) = rank3::tracking::parse_init_points(text, std::path::Path::new("fuzz.txt")) {
        assert!(pts.iter().all(|p| p[0].is_finite() && p[1].is_finite()));
    }
});
