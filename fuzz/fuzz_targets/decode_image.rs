//! Frame decoding (PNG/JPEG bytes, after the size check) on arbitrary bytes: an error, or an
//! image whose buffer matches its size and stays within the frame budget.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(img) = rank3::tracking::GrayImage::decode(data, std::path::Path::new("fuzz.png")) {
        assert_eq!(img.data.len(), img.width * img.height);
        assert!((img.width * img.height) as u64 <= rank3::budget::FRAME_PIXELS);
    }
});
