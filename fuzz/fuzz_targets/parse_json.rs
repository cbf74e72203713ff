//! The .json track-table parser on arbitrary text: an error is fine, a panic is not; a table
//! it accepts has finite observations only.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(t) = rank3::table::json::parse(text, std::path::Path::new("fuzz.json")) {
        for f in 0..t.n_frames() {
            for p in 0..t.n_tracks() {
                if let Some([x, y]) = t.get(f, p) {
                    assert!(x.is_finite() && y.is_finite());
                }
            }
        }
    }
});
