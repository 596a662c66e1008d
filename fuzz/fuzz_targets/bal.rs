//! Bundle-Adjustment-in-the-Large parser: any text gives a problem or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = tumble::io::bal::parse_bal(std::path::Path::new("fuzz.txt"), text);
    }
});
