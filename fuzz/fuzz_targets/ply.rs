//! Fuzzes the PLY reader: any bytes give vertices or an error with the
//! offending position, never a panic or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = sheen::io::ply::parse_ply(data, std::path::Path::new("fuzz/cloud.ply"));
});
