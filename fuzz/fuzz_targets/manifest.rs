//! Fuzzes the fringe-set manifest parser: any bytes give a manifest or an
//! error naming the file, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = sheen::io::manifest::parse_manifest_bytes(data, std::path::Path::new("fuzz/fringe-set.json"));
});
