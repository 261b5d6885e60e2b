//! `kalibra eval`'s JSON log reader, with the evaluation it feeds, on any bytes.

#![no_main]

use kalibra_io::input::LogFormat;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    kalibra_fuzz::eval(LogFormat::Json, "log.json", data);
});
