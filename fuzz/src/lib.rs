//! What every fuzz target checks: the input gives an error naming the file, or a report whose
//! numbers are all finite. A panic, an allocation beyond libFuzzer's `-rss_limit_mb` or a
//! run beyond its `-timeout` is a finding too, reported by libFuzzer itself.

use std::path::Path;

use kalibra_cli::finite::first_non_finite;
use kalibra_cli::input::{LogFormat, evaluate_bytes};
use kalibra_cli::tune_input::{parse_model, parse_series};
use kalibra_eval::{Evaluation, Tuning};

/// Asserts the promise of the readers on one result.
fn judged<T: serde::Serialize>(files: &[&str], result: Result<T, String>) {
    match result {
        Ok(report) => {
            if let Some(at) = first_non_finite(&report) {
                panic!("{files:?}: Ok with a non-finite number at {at}");
            }
        }
        Err(message) => assert!(
            files.iter().any(|f| message.contains(f)),
            "the error names none of {files:?}: {message}"
        ),
    }
}

/// `kalibra eval` on a log of `format` held in `data`, named `file` in messages.
pub fn eval(format: LogFormat, file: &str, data: &[u8]) {
    judged(
        &[file],
        evaluate_bytes(Path::new(file), format, data, &Evaluation::new()),
    );
}

/// `kalibra tune` on `data`: MODEL.toml before the first NUL byte, the measurements CSV after
/// it (the fixtures' measurements when there is no NUL), read, made a problem and swept over
/// three exponents on one thread.
pub fn tune(data: &[u8], default_series: &[u8]) {
    let (model, series) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, default_series),
    };
    let files = ["model.toml", "measurements.csv"];
    let result = (|| {
        let path = Path::new(files[0]);
        let model = parse_model(path, &String::from_utf8_lossy(model))?;
        let m = model.meas_dim();
        let z = parse_series(
            Path::new(files[1]),
            series,
            "z",
            m,
            &format!("H has {m} row(s)"),
        )?;
        let problem = model.problem(path, z, None)?;
        let mut tuning = Tuning::new()
            .exponents(-1.0, 1.0, 1.0)
            .map_err(|e| e.to_string())?
            .threads(1);
        if let Some(position) = &model.position {
            tuning = tuning.position(position.clone());
        }
        tuning
            .tune(&problem)
            .map_err(|e| format!("model.toml: {e}"))
    })();
    judged(&files, result);
}

/// The `eval_npy` target's input as an NPZ archive: pieces separated by `--npy--`, each an
/// array's name chosen by its first byte and its `.npy` bytes, zipped as `np.savez` does
/// (stored, with correct checksums, so that the fuzzer reaches the arrays rather than the
/// zip's checks).
pub fn npz_of_pieces(data: &[u8]) -> Vec<u8> {
    // Every array kalibra reads, and one it does not.
    let names: Vec<&str> = kalibra_cli::ARRAY_NAMES
        .into_iter()
        .chain(["other"])
        .collect();
    const SEPARATOR: &[u8] = b"--npy--";
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
