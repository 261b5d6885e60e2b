//! `kalibra tune`'s readers (MODEL.toml, then the measurements CSV after a NUL byte), with the
//! problem's checks and a short sweep, on any bytes.

#![no_main]

use libfuzzer_sys::fuzz_target;

/// The measurements of the tuning fixture, for inputs that hold a model only.
const SERIES: &[u8] =
    include_bytes!("../../crates/kalibra-cli/tests/fixtures/tune_measurements.csv");

fuzz_target!(|data: &[u8]| {
    kalibra_fuzz::tune(data, SERIES);
});
