//! `kalibra eval`'s NPZ reader on archives built from the input (`kalibra_fuzz::npz_of_pieces`),
//! so that the fuzzer explores the `.npy` headers and values rather than the zip's checksums.

#![no_main]

use kalibra_io::input::LogFormat;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let archive = kalibra_fuzz::npz_of_pieces(data);
    kalibra_fuzz::eval(LogFormat::Npz, "log.npz", &archive);
});
