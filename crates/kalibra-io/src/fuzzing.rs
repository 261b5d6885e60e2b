//! The promise the fuzz targets (`fuzz/`) and the readers' property test
//! (`tests/readers_fuzz.rs`) check, defined once: any bytes given to a reader, followed by
//! what the command does with the result, give an error that names the file, or a report
//! whose numbers are all finite. Not part of the stable API.

use std::path::Path;

use kalibra_eval::{Evaluation, Report};
use kalibra_tune::{TuneReport, Tuning};

use crate::error::Error;
use crate::finite::first_non_finite;
use crate::input::{LogFormat, evaluate_bytes};
use crate::raw::ARRAY_NAMES;
use crate::tune_input::{parse_model, parse_series};

/// The files the tune harness names: the model, then the measurements.
pub const TUNE_FILES: [&str; 2] = ["model.toml", "measurements.csv"];

/// Where `result` breaks the readers' promise: an error naming none of `files`, or a result
/// holding a non-finite number; `None` when it keeps it.
pub fn broken_promise<T: serde::Serialize>(
    files: &[&str],
    result: &Result<T, Error>,
) -> Option<String> {
    match result {
        Ok(report) => first_non_finite(report)
            .map(|at| format!("{files:?}: Ok with a non-finite number at {at}")),
        Err(e) => {
            let message = e.to_string();
            (!files.iter().any(|f| message.contains(f)))
                .then(|| format!("the error names none of {files:?}: {message}"))
        }
    }
}

/// `kalibra eval` on the log in `bytes`, of `format`, named `file` in messages, with the
/// default evaluation.
pub fn eval(file: &str, format: LogFormat, bytes: &[u8]) -> Result<Report, Error> {
    evaluate_bytes(Path::new(file), format, bytes, &Evaluation::new())
}

/// `kalibra tune` on the MODEL.toml in `model` and the measurements CSV in `series` (named
/// as [`TUNE_FILES`]): read, made a problem and swept over three exponents on one thread.
pub fn tune(model: &[u8], series: &[u8]) -> Result<TuneReport, Error> {
    let model_file = Path::new(TUNE_FILES[0]);
    let model = parse_model(model_file, &String::from_utf8_lossy(model))?;
    let m = model.meas_dim();
    let z = parse_series(
        Path::new(TUNE_FILES[1]),
        series,
        "z",
        m,
        &format!("H has {m} row(s)"),
    )?;
    let problem = model.problem(model_file, z, None)?;
    // A valid grid: the Tuning's own checks cannot refuse it.
    let mut tuning = Tuning::new()
        .exponents(-1.0, 1.0, 1.0)
        .unwrap_or_default()
        .threads(1);
    if let Some(position) = &model.position {
        tuning = tuning.position(position.clone());
    }
    tuning.tune(&problem).map_err(|source| Error::Tune {
        file: model_file.to_path_buf(),
        source,
    })
}

/// The input of the `tune` harness split: MODEL.toml before the first NUL byte, the
/// measurements CSV after it (`default_series` when there is no NUL).
pub fn tune_split<'a>(data: &'a [u8], default_series: &'a [u8]) -> (&'a [u8], &'a [u8]) {
    match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, default_series),
    }
}

/// The `eval_npy` target's input as an NPZ archive: pieces separated by `--npy--`, each an
/// array's name chosen by its first byte and its `.npy` bytes, zipped as `np.savez` does
/// (stored, with correct checksums, so that the fuzzer reaches the arrays rather than the
/// zip's checks).
pub fn npz_of_pieces(data: &[u8]) -> Vec<u8> {
    const SEPARATOR: &[u8] = b"--npy--";
    // Every array kalibra reads, and one it does not.
    let names: Vec<&str> = ARRAY_NAMES.into_iter().chain(["other"]).collect();
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let mut rest = data;
    while let Some((&first, body)) = rest.split_first() {
        let end = body
            .windows(SEPARATOR.len())
            .position(|w| w == SEPARATOR)
            .unwrap_or(body.len());
        let name = names[usize::from(first) % names.len()];
        // A repeated name is an error of the zip writer, not of the reader: skip it.
        if zip.start_file(format!("{name}.npy"), options).is_ok() {
            let _ = std::io::Write::write_all(&mut zip, &body[..end]);
        }
        rest = body.get(end + SEPARATOR.len()..).unwrap_or(&[]);
    }
    zip.finish()
        .map(std::io::Cursor::into_inner)
        .unwrap_or_default()
}
