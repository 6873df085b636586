//! Fuzzes the calibration reader: any JSON gives a validated calibration
//! (finite, rank 2, not parallel) or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(value) = serde_json::from_slice::<serde_json::Value>(data) {
        if let Ok((calibration, _)) =
            sheen::io::calibration::calibration_from_value(&value, std::path::Path::new("fuzz/calibration.json"))
        {
            assert!(calibration.validate().is_ok());
        }
    }
});
