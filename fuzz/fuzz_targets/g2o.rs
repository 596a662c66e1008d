//! g2o pose-graph parser: any text gives a graph or an error naming a line.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tumble::io::g2o::{parse_g2o, BadInformation, G2oOptions};

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        for bad in [BadInformation::Refuse, BadInformation::Repair] {
            let _ = parse_g2o(std::path::Path::new("fuzz.g2o"), text, &G2oOptions { bad_information: bad });
        }
    }
});
