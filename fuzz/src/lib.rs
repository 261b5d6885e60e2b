//! What every fuzz target checks, as `kalibra_io::fuzzing` defines it for the readers'
//! property test too (`crates/kalibra-io/tests/it/readers_fuzz.rs`): the input gives an error
//! naming the file, or a report whose numbers are all finite. A panic, an allocation beyond
//! libFuzzer's `-rss_limit_mb` or a run beyond its `-timeout` is a finding too, reported by
//! libFuzzer itself.

use kalibra_io::fuzzing::{self, TUNE_FILES, broken_promise};
use kalibra_io::input::LogFormat;

pub use kalibra_io::fuzzing::npz_of_pieces;

/// `kalibra eval` on a log of `format` held in `data`, named `file` in messages.
pub fn eval(format: LogFormat, file: &str, data: &[u8]) {
    if let Some(broken) = broken_promise(&[file], &fuzzing::eval(file, format, data)) {
        panic!("{broken}");
    }
}

/// `kalibra tune` on `data`: MODEL.toml before the first NUL byte, the measurements CSV after
/// it (the fixtures' measurements when there is no NUL), read, made a problem and swept over
/// three exponents on one thread.
pub fn tune(data: &[u8], default_series: &[u8]) {
    let (model, series) = fuzzing::tune_split(data, default_series);
    if let Some(broken) = broken_promise(&TUNE_FILES, &fuzzing::tune(model, series)) {
        panic!("{broken}");
    }
}
