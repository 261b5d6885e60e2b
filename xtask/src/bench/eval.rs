//! `cargo xtask bench eval`: `kalibra eval` against a pandas + numpy script and a polars + numpy
//! script on the same logs.
//!
//! `cargo xtask bench eval [--runs R] [--steps K] [--seed S] [--repeats N]` (defaults 1000 x
//! 1000, seed 2012, best of 3):
//!
//! 1. **Logs.** Simulates W1 (a 2-D constant-velocity target, state `[x, y, vx, vy]`, position
//!    measurements, `R = 100 I2`) for R runs of K steps through the library (`Simulator`,
//!    `Kf`; run `i` draws from ChaCha8 stream `i` of the seed), so the filter is consistent and
//!    every statistic is meaningful, and writes its truth, estimate, full covariance,
//!    innovation and full innovation covariance in the three formats `kalibra eval` reads:
//!    CSV (one row per run and step, run-major, 32 columns), NPZ (`np.savez`'s layout,
//!    float64, stored uncompressed) and JSON (nested lists). Values are written in Rust's
//!    shortest round-trip decimal form, so all three hold the same numbers bit for bit. Files
//!    go to `target/bench-eval/log-rR-kK-sS.{csv,npz,json}` and are reused when present (they
//!    are written under a temporary name and renamed, so a present file is complete); the bench
//!    prints their sizes.
//! 2. **Python.** Creates the virtual environment `target/bench-eval/venv` with `python3 -m
//!    venv` and installs pandas, numpy and polars into it from PyPI with pip, unless they
//!    import already. Needs python3 with its venv module and network to PyPI the first time; Unix only
//!    (the timer uses the `resource` module).
//! 3. **Binary.** Builds `kalibra` with `cargo build --release -p kalibra-cli`.
//! 4. **Timing.** For each format, alternately (so that machine noise hits both alike) runs
//!    `kalibra eval LOG --out DIR --window W`, `xtask/bench/eval_pandas.py LOG --out
//!    RESULTS.json --window W` and `xtask/bench/eval_polars.py` likewise (`W = max(2, K /
//!    10)`, the default of all three; both scripts compute with `eval_stats.py`) `--repeats` times,
//!    each under a fresh `xtask/bench/measure.py`, which records the wall time and the peak
//!    resident memory of that one child (`getrusage(RUSAGE_CHILDREN)`). The best wall time
//!    and the largest peak are reported. Every peak includes the driver's own resident
//!    memory, which the child holds until it executes the command; the bench prints it,
//!    measured on `true`. kalibra's time includes writing report.md,
//!    report.html and the SVG figures; a script's includes starting Python and importing
//!    pandas or polars. Outputs go to `target/bench-eval/out/`.
//! 5. **Agreement.** Compares kalibra's `report.json` with each script's results: per-step
//!    ANEES, ANIS, NCI and RMSE, run 0's sliding windows, the summary (ANEES, ANIS, NCI, t
//!    statistics) and run 0's whiteness must agree to [`TOLERANCE`] (the largest difference
//!    relative to the series' largest magnitude), else the bench fails after printing
//!    everything: a speed-up between programs that did different work means nothing. The
//!    chi-square bands are printed for information only (the scripts approximate them).
//! 6. **Report.** A table per format (file size, rows, wall time, rows per second and peak
//!    memory of kalibra and of both scripts, kalibra's speed-up over each), then the goals
//!    with the measured figure and "met" or "not met", each against the faster script on that
//!    format: kalibra at least 3x on the CSV and the JSON, at least 4x on the NPZ, and
//!    kalibra's peak memory on the CSV and the JSON under a quarter of the file's size. A
//!    missed goal does not fail the bench: it is a measurement.
//!
//! MB are 10^6 bytes throughout.

use std::ffi::OsStr;
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail, ensure};
use kalibra_filters::{Filter, Kf};
use kalibra_models::{Simulator, sample_with_factor};
use kalibra_sim::MonteCarlo;
use kalibra_studies::w1;
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};
use serde_json::Value;

use super::{Args, Figures, timed};

/// The largest difference allowed between kalibra's statistics and the script's, relative to
/// the largest magnitude of the series compared (or of the two values, for a scalar).
const TOLERANCE: f64 = 1e-9;

/// Size and seed of a generated log.
#[derive(Clone, Copy, Debug)]
struct LogSize {
    runs: usize,
    steps: usize,
    seed: u64,
}

impl LogSize {
    fn rows(&self) -> usize {
        self.runs * self.steps
    }

    /// The file name of the log in `format`; it encodes size and seed, so a log of another
    /// size is never reused.
    fn file_name(&self, format: Format) -> String {
        format!(
            "log-r{}-k{}-s{}.{}",
            self.runs,
            self.steps,
            self.seed,
            format.ext()
        )
    }
}

/// The log formats of `kalibra eval`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Csv,
    Npz,
    Json,
}

const FORMATS: [Format; 3] = [Format::Csv, Format::Npz, Format::Json];

impl Format {
    fn ext(self) -> &'static str {
        match self {
            Format::Csv => "csv",
            Format::Npz => "npz",
            Format::Json => "json",
        }
    }
}

/// The per-cell arrays of the log, in the order every format stores them.
#[derive(Clone, Copy, Debug)]
enum Array {
    Truth,
    Estimate,
    Covariance,
    Innovation,
    InnovationCov,
}

const ARRAYS: [Array; 5] = [
    Array::Truth,
    Array::Estimate,
    Array::Covariance,
    Array::Innovation,
    Array::InnovationCov,
];

impl Array {
    /// The name in every format (the CSV's column prefix).
    fn name(self) -> &'static str {
        match self {
            Array::Truth => "truth",
            Array::Estimate => "estimate",
            Array::Covariance => "covariance",
            Array::Innovation => "innovation",
            Array::InnovationCov => "innovation_cov",
        }
    }

    /// The shape of one cell: `[n]` for a vector, `[n, n]` for a matrix.
    fn cell_shape(self) -> &'static [usize] {
        match self {
            Array::Truth | Array::Estimate => &[4],
            Array::Covariance => &[4, 4],
            Array::Innovation => &[2],
            Array::InnovationCov => &[2, 2],
        }
    }

    /// The CSV columns: `name_i`, or `name_i_j` row by row.
    fn csv_columns(self) -> Vec<String> {
        match *self.cell_shape() {
            [d] => (0..d).map(|i| format!("{}_{i}", self.name())).collect(),
            [r, c] => (0..r)
                .flat_map(|i| (0..c).map(move |j| format!("{}_{i}_{j}", self.name())))
                .collect(),
            _ => unreachable!("cells are vectors or matrices"),
        }
    }
}

/// What the filter logged at one run and step.
struct Cell {
    truth: Vector4<f64>,
    estimate: Vector4<f64>,
    covariance: Matrix4<f64>,
    innovation: Vector2<f64>,
    innovation_cov: Matrix2<f64>,
}

impl Cell {
    /// Replaces `out` with the values of `array`, matrices row by row (C order, as the CSV
    /// columns and numpy have them; nalgebra stores columns first).
    fn values(&self, array: Array, out: &mut Vec<f64>) {
        out.clear();
        match array {
            Array::Truth => out.extend(self.truth.iter()),
            Array::Estimate => out.extend(self.estimate.iter()),
            Array::Covariance => out.extend(self.covariance.transpose().iter()),
            Array::Innovation => out.extend(self.innovation.iter()),
            Array::InnovationCov => out.extend(self.innovation_cov.transpose().iter()),
        }
    }
}

/// Simulates the log and hands every cell to `visit`, run by run. Each writer calls it once
/// per array it writes in turn: the simulation is deterministic and far cheaper than the
/// writing, and nothing has to be held in memory.
fn for_each_cell(
    size: LogSize,
    mut visit: impl FnMut(usize, usize, &Cell) -> Result<()>,
) -> Result<()> {
    let (f, h) = w1::models()?;
    let (m0, p0) = w1::prior();
    let p0_factor = kalibra_linalg::PsdMatrix::new(p0)?.factor().clone_owned();
    let mc = MonteCarlo::new(size.runs, size.seed);
    for run in 0..size.runs {
        let mut rng = mc.rng(run);
        let x0 = m0 + sample_with_factor(&p0_factor, &mut rng);
        let mut truth = Simulator::new(&f, &h, x0, 0)?;
        let mut kf = Kf::new(&f, &h, m0, p0)?;
        for step in 0..size.steps {
            let (x, z) = truth.step(&mut rng)?;
            if step > 0 {
                kf.predict()?;
            }
            let rec = kf.update(&z)?;
            let s = rec
                .s()
                .context("the KF's record has no factored innovation covariance")?;
            let cell = Cell {
                truth: x,
                estimate: rec.posterior().mean,
                covariance: rec.posterior().cov,
                innovation: *rec.innovation(),
                innovation_cov: *s.matrix(),
            };
            visit(run, step, &cell)?;
        }
    }
    Ok(())
}

/// Writes the log in `format` to `path` unless it is there: under a temporary name first,
/// renamed when complete.
fn ensure_log(size: LogSize, format: Format, path: &Path) -> Result<()> {
    if path.is_file() {
        return Ok(());
    }
    let tmp = path.with_extension(format!("{}.partial", format.ext()));
    let file = File::create(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    let writer = BufWriter::with_capacity(1 << 20, file);
    let (seconds, written) = timed(|| match format {
        Format::Csv => write_csv(size, writer),
        Format::Npz => write_npz(size, writer),
        Format::Json => write_json(size, writer),
    });
    written.with_context(|| format!("writing {}", tmp.display()))?;
    fs::rename(&tmp, path).with_context(|| format!("renaming {} into place", tmp.display()))?;
    println!(
        "  wrote {} ({:.1} MB) in {:.1} s",
        path.display(),
        megabytes(fs::metadata(path)?.len()),
        seconds
    );
    Ok(())
}

/// The CSV log: a header, then one row per run and step in run-major order. `{}` on an `f64`
/// is the shortest decimal that reads back to the same value.
fn write_csv(size: LogSize, mut w: impl Write) -> Result<()> {
    let mut header = vec!["run".to_string(), "step".to_string()];
    header.extend(ARRAYS.iter().flat_map(|a| a.csv_columns()));
    writeln!(w, "{}", header.join(","))?;
    let mut buf = Vec::with_capacity(16);
    for_each_cell(size, |run, step, cell| {
        write!(w, "{run},{step}")?;
        for array in ARRAYS {
            cell.values(array, &mut buf);
            for v in &buf {
                write!(w, ",{v}")?;
            }
        }
        writeln!(w)?;
        Ok(())
    })?;
    w.flush()?;
    Ok(())
}

/// The header of a version 1.0 `.npy` file of little-endian float64 in C order: the magic, the
/// version, the header's length and the dictionary numpy writes, padded with spaces so that
/// the data start at a multiple of 64 bytes, as numpy aligns them.
fn npy_header(shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(ToString::to_string).collect();
    // A one-element tuple needs its trailing comma in Python.
    let comma = if shape.len() == 1 { "," } else { "" };
    let mut dict = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': ({}{comma}), }}",
        dims.join(", ")
    );
    let unpadded = 10 + dict.len() + 1;
    dict.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    dict.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    let len = u16::try_from(dict.len()).expect("a short header");
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

/// The NPZ log as `np.savez` writes it: a zip archive of one stored (uncompressed) `NAME.npy`
/// per array, of shape `(R, K, ...cell shape)`.
fn write_npz<W: Write + std::io::Seek>(size: LogSize, w: W) -> Result<()> {
    let mut zip = zip::ZipWriter::new(w);
    let mut buf = Vec::with_capacity(16);
    let mut bytes = Vec::with_capacity(16 * 8);
    for array in ARRAYS {
        let mut shape = vec![size.runs, size.steps];
        shape.extend_from_slice(array.cell_shape());
        let header = npy_header(&shape);
        let len = header.len() + 8 * shape.iter().product::<usize>();
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .large_file(len > u32::MAX as usize);
        zip.start_file(format!("{}.npy", array.name()), options)?;
        zip.write_all(&header)?;
        for_each_cell(size, |_, _, cell| {
            cell.values(array, &mut buf);
            bytes.clear();
            bytes.extend(buf.iter().flat_map(|v| v.to_le_bytes()));
            zip.write_all(&bytes)?;
            Ok(())
        })?;
    }
    zip.finish()?.flush()?;
    Ok(())
}

/// The JSON log: an object of the five arrays as nested lists, `[run][step]` then the cell
/// (a matrix as a list of rows).
fn write_json(size: LogSize, mut w: impl Write) -> Result<()> {
    let mut buf = Vec::with_capacity(16);
    write!(w, "{{")?;
    for (a, array) in ARRAYS.into_iter().enumerate() {
        let sep = if a == 0 { "" } else { "," };
        write!(w, "{sep}\n\"{}\": [", array.name())?;
        let cols = array.cell_shape().get(1).copied();
        for_each_cell(size, |run, step, cell| {
            match (run, step) {
                (0, 0) => write!(w, "[")?,
                (_, 0) => write!(w, "],\n[")?,
                _ => write!(w, ",")?,
            }
            cell.values(array, &mut buf);
            match cols {
                None => write_list(&mut w, &buf)?,
                Some(c) => {
                    write!(w, "[")?;
                    for (i, row) in buf.chunks(c).enumerate() {
                        if i > 0 {
                            write!(w, ",")?;
                        }
                        write_list(&mut w, row)?;
                    }
                    write!(w, "]")?;
                }
            }
            Ok(())
        })?;
        write!(w, "]]")?;
    }
    writeln!(w, "\n}}")?;
    w.flush()?;
    Ok(())
}

fn write_list(w: &mut impl Write, values: &[f64]) -> Result<()> {
    write!(w, "[")?;
    for (i, v) in values.iter().enumerate() {
        if i > 0 {
            write!(w, ",")?;
        }
        write!(w, "{v}")?;
    }
    write!(w, "]")?;
    Ok(())
}

/// Runs `cmd` to completion, failing with its output if it fails.
fn run_command(cmd: &mut Command) -> Result<()> {
    let out = cmd.output().with_context(|| format!("starting {cmd:?}"))?;
    ensure!(
        out.status.success(),
        "{cmd:?} failed ({}):\n{}{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(())
}

/// The packages of the eval bench's environment (W4's numpy script shares it).
pub(crate) const PANDAS: &[(&str, &str)] = &[("numpy", "numpy"), ("pandas", "pandas")];

/// The virtual environment `dir/venv` with `packages` (module to import, pip requirement),
/// created and installed from PyPI if a module does not import; returns its Python and the
/// versions of Python and of each module.
pub(crate) fn python_env(dir: &Path, packages: &[(&str, &str)]) -> Result<(PathBuf, String)> {
    let venv = dir.join("venv");
    let python = venv.join("bin").join("python");
    if !python.exists() {
        println!("  creating the virtual environment {}", venv.display());
        run_command(Command::new("python3").args(["-m", "venv"]).arg(&venv)).context(
            "creating the Python virtual environment (the bench needs python3 with its venv \
             module)",
        )?;
    }
    let modules: Vec<&str> = packages.iter().map(|(module, _)| *module).collect();
    let requirements: Vec<&str> = packages.iter().map(|(_, pip)| *pip).collect();
    let script = format!(
        "import importlib, sys; print(', '.join(['Python ' + sys.version.split()[0]] + \
         [m + ' ' + importlib.import_module(m).__version__ for m in {modules:?}]))"
    );
    let versions = || Command::new(&python).args(["-c", &script]).output();
    let mut out = versions().with_context(|| format!("starting {}", python.display()))?;
    if !out.status.success() {
        println!(
            "  installing {} from PyPI into {}",
            requirements.join(", "),
            venv.display()
        );
        run_command(
            Command::new(&python)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--quiet",
                    "--disable-pip-version-check",
                ])
                .args(&requirements),
        )
        .with_context(|| format!("installing {requirements:?} into {}", venv.display()))?;
        out = versions()?;
        ensure!(
            out.status.success(),
            "{modules:?} do not import after installing them: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok((
        python,
        String::from_utf8_lossy(&out.stdout).trim().to_string(),
    ))
}

/// Installs polars into the virtual environment of [`python_env`] from PyPI unless it
/// imports already; returns its version.
fn ensure_polars(python: &Path) -> Result<String> {
    let version = || {
        Command::new(python)
            .args(["-c", "import polars; print(f'polars {polars.__version__}')"])
            .output()
    };
    let mut out = version().with_context(|| format!("starting {}", python.display()))?;
    if !out.status.success() {
        println!("  installing polars from PyPI");
        run_command(Command::new(python).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "polars",
        ]))
        .context("installing polars into the eval bench's virtual environment")?;
        out = version()?;
        ensure!(
            out.status.success(),
            "polars does not import after installing it: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Builds the `kalibra` executable in release mode and returns its path.
fn build_kalibra(root: &Path) -> Result<PathBuf> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(root)
        .args([
            "build",
            "--release",
            "--quiet",
            "-p",
            "kalibra-cli",
            "--bin",
            "kalibra",
        ])
        .status()
        .context("starting cargo to build kalibra")?;
    ensure!(status.success(), "cargo build -p kalibra-cli failed");
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"));
    let exe = target
        .join("release")
        .join(format!("kalibra{}", std::env::consts::EXE_SUFFIX));
    ensure!(exe.is_file(), "no kalibra executable at {}", exe.display());
    Ok(exe)
}

/// Wall time and peak resident memory of one command.
#[derive(Clone, Copy, Debug)]
struct Measured {
    wall_s: f64,
    peak_bytes: u64,
}

/// Runs `program args` under a fresh `measure.py` and returns what it recorded.
fn measure(
    python: &Path,
    driver: &Path,
    record: &Path,
    program: &Path,
    args: &[&OsStr],
) -> Result<Measured> {
    let shown = format!(
        "{} {}",
        program.display(),
        args.iter()
            .map(|a| a.to_string_lossy())
            .collect::<Vec<_>>()
            .join(" ")
    );
    let _ = fs::remove_file(record);
    let out = Command::new(python)
        .arg(driver)
        .arg(record)
        .arg(program)
        .args(args)
        .output()
        .with_context(|| format!("starting the timer on `{shown}`"))?;
    let text = fs::read_to_string(record).with_context(|| {
        format!(
            "the timer of `{shown}` wrote no record ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        )
    })?;
    let v: Value = serde_json::from_str(&text)
        .with_context(|| format!("reading the timer's record {}", record.display()))?;
    let code = v["exit_code"].as_i64();
    if code != Some(0) {
        bail!(
            "`{shown}` failed (exit code {code:?}):\n{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    match (v["wall_s"].as_f64(), v["peak_rss_bytes"].as_u64()) {
        (Some(wall_s), Some(peak_bytes)) => Ok(Measured { wall_s, peak_bytes }),
        _ => bail!(
            "the timer's record {} lacks a field: {text}",
            record.display()
        ),
    }
}

/// Best wall time and largest peak over the repeats.
fn combine(runs: &[Measured]) -> Measured {
    Measured {
        wall_s: runs.iter().map(|m| m.wall_s).fold(f64::INFINITY, f64::min),
        peak_bytes: runs.iter().map(|m| m.peak_bytes).max().unwrap_or(0),
    }
}

fn megabytes(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

/// The largest difference between two series of numbers (`null` allowed where both have
/// it), relative to their largest magnitude; infinite if their shapes or nulls differ.
fn series_difference(a: &Value, b: &Value) -> f64 {
    let (Some(a), Some(b)) = (a.as_array(), b.as_array()) else {
        return scalar_difference(a, b);
    };
    if a.len() != b.len() || a.is_empty() {
        return f64::INFINITY;
    }
    let mut scale = 0.0f64;
    let mut diff = 0.0f64;
    for (x, y) in a.iter().zip(b) {
        match (x.as_f64(), y.as_f64()) {
            (Some(x), Some(y)) => {
                scale = scale.max(x.abs()).max(y.abs());
                diff = diff.max((x - y).abs());
            }
            _ if x.is_null() && y.is_null() => {}
            _ => return f64::INFINITY,
        }
    }
    if diff == 0.0 { 0.0 } else { diff / scale }
}

fn scalar_difference(a: &Value, b: &Value) -> f64 {
    match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) if x == y => 0.0,
        (Some(x), Some(y)) => (x - y).abs() / x.abs().max(y.abs()),
        _ => f64::INFINITY,
    }
}

/// The JSON pointers of the statistics compared, in groups, for an `n`-state log with
/// `lags` whiteness lags; the last group is for information only.
fn compared(n: usize, lags: usize) -> Vec<(&'static str, Vec<String>)> {
    let mut per_step: Vec<String> = ["/anees_per_step", "/anis_per_step", "/nci_per_step"]
        .map(String::from)
        .to_vec();
    per_step.extend((0..n).map(|i| format!("/rmse_per_step/{i}/values")));
    let window = (0..n)
        .flat_map(|i| ["rmse", "bias", "std"].map(|s| format!("/window/components/{i}/{s}")))
        .collect();
    let summary = [
        "/summary/anees",
        "/summary/anis",
        "/summary/nci",
        "/summary/anees_test/t",
        "/summary/anis_test/t",
    ]
    .map(String::from)
    .to_vec();
    let mut whiteness: Vec<String> = (0..lags)
        .map(|l| format!("/whiteness/lags/{l}/autocorrelation"))
        .collect();
    whiteness.push("/whiteness/box_pierce".into());
    let bands = ["lower", "upper"]
        .into_iter()
        .flat_map(|side| ["anees_band", "anis_band"].map(|b| format!("/{b}/*/{side}")))
        .collect();
    vec![
        ("per-step ANEES, ANIS, NCI, RMSE", per_step),
        ("run 0's window RMSE, bias, std", window),
        ("summary ANEES, ANIS, NCI, t", summary),
        ("run 0's whiteness", whiteness),
        ("chi-square bands (script: Wilson-Hilferty)", bands),
    ]
}

/// The value at `pointer`, where a `*` segment collects that field of every element of the
/// array before it into an array.
fn at(value: &Value, pointer: &str) -> Value {
    match pointer.split_once("/*") {
        None => value.pointer(pointer).cloned().unwrap_or(Value::Null),
        Some((array, field)) => match value.pointer(array).and_then(Value::as_array) {
            Some(items) => Value::Array(items.iter().map(|item| at(item, field)).collect()),
            None => Value::Null,
        },
    }
}

/// The largest difference of each group of [`compared`] between two results.
fn differences(a: &Value, b: &Value) -> Vec<(&'static str, f64)> {
    let n = a["state_dim"].as_u64().unwrap_or(0) as usize;
    let lags = a["whiteness"]["lags"].as_array().map_or(0, Vec::len);
    compared(n, lags)
        .into_iter()
        .map(|(group, pointers)| {
            let worst = pointers
                .iter()
                .map(|p| series_difference(&at(a, p), &at(b, p)))
                .fold(0.0, f64::max);
            (group, worst)
        })
        .collect()
}

fn read_json(path: &Path) -> Result<Value> {
    let text = fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

/// The figures of one format.
struct Row {
    format: Format,
    size_bytes: u64,
    kalibra: Measured,
    /// The pandas + numpy script.
    script: Measured,
    /// The polars + numpy script.
    polars: Measured,
}

impl Row {
    /// The faster script's time: the peer kalibra is held against.
    fn best_script_s(&self) -> f64 {
        self.script.wall_s.min(self.polars.wall_s)
    }
}

/// Runs the eval workload, prints its figures and returns them.
pub(crate) fn run(args: &Args) -> Result<Figures> {
    let size = LogSize {
        runs: args.runs,
        steps: args.steps,
        seed: args.seed,
    };
    ensure!(
        size.runs >= 2,
        "the eval bench needs at least 2 runs (NCI and the t-test need them)"
    );
    let window = (size.steps / 10).max(2);
    ensure!(
        size.steps >= window.max(3),
        "the eval bench needs at least 3 steps (the window and the whiteness lags need them)"
    );
    let root = crate::workspace_root();
    let dir = root.join("target").join("bench-eval");
    let out_dir = dir.join("out");
    fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let title = format!(
        "kalibra eval against pandas + numpy on a W1 log of {} runs x {} steps (n = 4, m = 2), seed {}, window {window}, best of {}",
        size.runs, size.steps, size.seed, args.repeats
    );
    println!("eval: {title}");
    let mut figures = Figures::new("eval", title);
    for format in FORMATS {
        ensure_log(size, format, &dir.join(size.file_name(format)))?;
    }
    let (python, versions) = python_env(&dir, PANDAS)?;
    let polars_version = ensure_polars(&python)?;
    let kalibra = build_kalibra(&root)?;
    println!(
        "  {versions}, {polars_version}; kalibra at {}",
        kalibra.display()
    );
    let bench_dir = root.join("xtask").join("bench");
    let driver = bench_dir.join("measure.py");
    let scripts = [
        ("pandas + numpy", "pandas", bench_dir.join("eval_pandas.py")),
        ("polars + numpy", "polars", bench_dir.join("eval_polars.py")),
    ];
    let record = out_dir.join("measure.json");
    let window_arg = window.to_string();
    // The child shares the driver's memory until it executes the command (vfork), so every
    // peak includes the driver's own resident memory; measured on a command that does nothing.
    let floor = measure(&python, &driver, &record, Path::new("true"), &[])?;
    println!(
        "  timer floor (peak memory of `true` under the driver, included in every peak): {:.1} MB",
        megabytes(floor.peak_bytes)
    );

    let mut rows = Vec::new();
    let mut reports = Vec::new();
    let mut disagreements = Vec::new();
    for format in FORMATS {
        let log = dir.join(size.file_name(format));
        let report_dir = out_dir.join(format!("kalibra-{}", format.ext()));
        let results = scripts
            .each_ref()
            .map(|(_, tag, _)| out_dir.join(format!("{tag}-{}.json", format.ext())));
        let (mut k_runs, mut s_runs) = (Vec::new(), [Vec::new(), Vec::new()]);
        for _ in 0..args.repeats {
            k_runs.push(measure(
                &python,
                &driver,
                &record,
                &kalibra,
                &[
                    OsStr::new("eval"),
                    log.as_os_str(),
                    OsStr::new("--out"),
                    report_dir.as_os_str(),
                    OsStr::new("--window"),
                    OsStr::new(&window_arg),
                ],
            )?);
            for (((_, _, script), results), runs) in scripts.iter().zip(&results).zip(&mut s_runs) {
                runs.push(measure(
                    &python,
                    &driver,
                    &record,
                    &python,
                    &[
                        script.as_os_str(),
                        log.as_os_str(),
                        OsStr::new("--out"),
                        results.as_os_str(),
                        OsStr::new("--window"),
                        OsStr::new(&window_arg),
                    ],
                )?);
            }
        }
        let report = read_json(&report_dir.join("report.json"))?;
        for ((name, _, _), results) in scripts.iter().zip(&results) {
            let theirs = read_json(results)?;
            let diffs = differences(&report, &theirs);
            let shown: Vec<String> = diffs
                .iter()
                .map(|(group, d)| format!("{group} {d:.1e}"))
                .collect();
            // The last group (the bands) is approximated by the scripts, so it is not required.
            let agree = diffs[..diffs.len() - 1]
                .iter()
                .all(|(_, d)| *d <= TOLERANCE);
            println!(
                "  {}: kalibra vs the {name} script, largest relative difference: {}; {}",
                format.ext(),
                shown.join(", "),
                if agree {
                    format!("agree (<= {TOLERANCE:.0e})")
                } else {
                    format!("DISAGREE (> {TOLERANCE:.0e})")
                }
            );
            if !agree {
                disagreements.push(format!("{} ({name})", format.ext()));
            }
        }
        rows.push(Row {
            format,
            size_bytes: fs::metadata(&log)?.len(),
            kalibra: combine(&k_runs),
            script: combine(&s_runs[0]),
            polars: combine(&s_runs[1]),
        });
        reports.push(report);
    }
    // The three logs hold the same numbers bit for bit, so kalibra's statistics should be too.
    let across = reports[1..]
        .iter()
        .flat_map(|r| differences(&reports[0], r))
        .map(|(_, d)| d)
        .fold(0.0, f64::max);
    println!(
        "  kalibra's statistics on NPZ and JSON against CSV: {}",
        if across == 0.0 {
            "identical".to_string()
        } else {
            format!("largest relative difference {across:.1e}")
        }
    );

    print_table(&rows, size.rows());
    print_goals(&rows);
    let split = stage_split(&dir, size, window, &out_dir, args.repeats)?;
    if !disagreements.is_empty() {
        bail!(
            "kalibra and a script disagree on {}: the timings compare different work",
            disagreements.join(", ")
        );
    }
    for (format, stages) in &split {
        let f = format.ext();
        for (stage, seconds) in stages {
            if seconds.is_finite() {
                figures.push(format!("{f}: stage {stage}"), *seconds, "s");
            }
        }
    }
    if let Some((_, orders)) = split.iter().find(|(f, _)| *f == Format::Npz)
        && let Some((_, base)) = orders.first()
    {
        for (label, seconds) in &orders[1..] {
            let label = label.trim_start_matches("evaluate, ");
            figures.push(
                format!("npz: evaluate, run after run / {label}"),
                base / seconds,
                "x",
            );
        }
    }
    for r in &rows {
        let f = r.format.ext();
        figures.push(format!("{f}: log size"), megabytes(r.size_bytes), "MB");
        figures.push(format!("{f}: kalibra eval"), r.kalibra.wall_s, "s");
        figures.push(
            format!("{f}: kalibra eval peak memory"),
            megabytes(r.kalibra.peak_bytes),
            "MB",
        );
        figures.push(format!("{f}: pandas + numpy script"), r.script.wall_s, "s");
        figures.push(
            format!("{f}: pandas + numpy peak memory"),
            megabytes(r.script.peak_bytes),
            "MB",
        );
        figures.push(format!("{f}: polars + numpy script"), r.polars.wall_s, "s");
        figures.push(
            format!("{f}: polars + numpy peak memory"),
            megabytes(r.polars.peak_bytes),
            "MB",
        );
        figures.push(
            format!("{f}: script / kalibra eval"),
            r.script.wall_s / r.kalibra.wall_s,
            "x",
        );
        figures.push(
            format!("{f}: polars script / kalibra eval"),
            r.polars.wall_s / r.kalibra.wall_s,
            "x",
        );
    }
    Ok(figures)
}

/// Per format, each stage's name and seconds.
type StageSplit = Vec<(Format, Vec<(String, f64)>)>;

/// The stage split of kalibra's CSV and JSON readers (`kalibra_io::stages`: each stage alone
/// on one thread, the file in memory), with the report's writing (`kalibra eval`'s
/// `Document` and report files) timed after them; printed, and returned per format as
/// (stage, seconds).
fn stage_split(
    dir: &Path,
    size: LogSize,
    window: usize,
    out_dir: &Path,
    repeats: usize,
) -> Result<StageSplit> {
    let evaluation = kalibra_eval::Evaluation::new().window(window)?;
    let mut split = Vec::new();
    println!(
        "  stages of kalibra's path, each alone on one thread with the file in memory (the \
         command overlaps them on every core):"
    );
    for format in [Format::Csv, Format::Json] {
        let log = dir.join(size.file_name(format));
        let Some((stages, report)) = kalibra_io::stages::stages(&log, &evaluation)? else {
            continue;
        };
        let target_dir = out_dir.join(format!("stages-{}", format.ext()));
        let clock = std::time::Instant::now();
        let doc = kalibra_io::document::Document::new(&log, &report);
        kalibra_io::output::Target::prepare(&target_dir)?.write(&report, &doc)?;
        let report_s = clock.elapsed().as_secs_f64();
        let named: Vec<(String, f64)> = [
            ("read", stages.read),
            ("tokenise", stages.tokenise),
            ("parse numbers", stages.parse),
            ("evaluate", stages.evaluate),
            ("report", report_s),
        ]
        .into_iter()
        .map(|(stage, s)| (stage.to_string(), s))
        .collect();
        let shown: Vec<String> = named
            .iter()
            .filter(|(_, s)| s.is_finite())
            .map(|(stage, s)| format!("{stage} {s:.3} s"))
            .collect();
        let note = match format {
            Format::Csv => format!(
                "{} fields; tokenise = line ends and commas counted, parse numbers = the \
                 reader's pass less that",
                stages.values
            ),
            _ => "tokenise = the first pass (where each array lies), parse numbers = the \
                  second pass with the evaluation overlapped"
                .to_string(),
        };
        println!("    {}: {} ({note})", format.ext(), shown.join(", "));
        split.push((format, named));
    }
    let orders = feed_orders(
        &dir.join(size.file_name(Format::Npz)),
        size,
        window,
        repeats,
    )?;
    let base = orders.first().map_or(f64::NAN, |(_, s)| *s);
    let shown: Vec<String> = orders
        .iter()
        .map(|(label, s)| format!("{label} {s:.3} s ({:.2}x)", base / s))
        .collect();
    println!(
        "    npz, evaluate stage alone (the cells in memory, one thread, best of {repeats}, \
         the same report; x = run after run / this): {}",
        shown.join(", ")
    );
    let orders = orders
        .into_iter()
        .map(|(label, s)| (format!("evaluate, {label}"), s))
        .collect();
    split.push((Format::Npz, orders));
    Ok(split)
}

fn print_table(rows: &[Row], n_rows: usize) {
    println!();
    println!(
        "  {:<6} {:>8} {:>8} | {:>9} {:>11} {:>8} | {:>8} {:>8} | {:>8} {:>8} | {:>7} {:>7}",
        "format",
        "size MB",
        "rows",
        "kalibra s",
        "rows/s",
        "peak MB",
        "pandas s",
        "peak MB",
        "polars s",
        "peak MB",
        "/pandas",
        "/polars"
    );
    for r in rows {
        println!(
            "  {:<6} {:>8.1} {:>8} | {:>9.3} {:>11.0} {:>8.1} | {:>8.3} {:>8.1} | {:>8.3} {:>8.1} | {:>6.1}x {:>6.1}x",
            r.format.ext(),
            megabytes(r.size_bytes),
            n_rows,
            r.kalibra.wall_s,
            n_rows as f64 / r.kalibra.wall_s,
            megabytes(r.kalibra.peak_bytes),
            r.script.wall_s,
            megabytes(r.script.peak_bytes),
            r.polars.wall_s,
            megabytes(r.polars.peak_bytes),
            r.script.wall_s / r.kalibra.wall_s,
            r.polars.wall_s / r.kalibra.wall_s,
        );
    }
    println!();
}

/// The goals, each against the faster script on that format (the best peer), and kalibra's
/// peak memory against a quarter of the file.
fn print_goals(rows: &[Row]) {
    let verdict = |met: bool| if met { "met" } else { "not met" };
    for r in rows {
        let goal = match r.format {
            Format::Csv | Format::Json => 3.0,
            Format::Npz => 4.0,
        };
        let ratio = r.best_script_s() / r.kalibra.wall_s;
        println!(
            "  goal: kalibra at least {goal}x the faster script on the {}: {ratio:.1}x, {}",
            r.format.ext().to_uppercase(),
            verdict(ratio >= goal)
        );
    }
    for r in rows.iter().filter(|r| r.format != Format::Npz) {
        let limit = r.size_bytes / 4;
        println!(
            "  goal: kalibra's peak memory on the {} under a quarter of its size ({:.1} MB): {:.1} MB, {}",
            r.format.ext().to_uppercase(),
            megabytes(limit),
            megabytes(r.kalibra.peak_bytes),
            verdict(r.kalibra.peak_bytes < limit)
        );
    }
}

/// Steps per strip of [`feed_orders`], as `Evaluation::evaluate` feeds its blocks.
const STRIP_STEPS: usize = 32;

/// The groups of runs of [`feed_orders`]' strips across some runs.
const FEED_GROUPS: [usize; 3] = [64, 16, 4];

/// Cells per `push_batch` call of [`feed_orders`]: below the evaluator's threshold for
/// preparing a batch on several threads, so that every cell is prepared on this thread.
const FEED_BATCH: usize = 256;

/// A feeding order of [`feed_orders`]: calls its argument with each (run, step) in turn.
type Order<'a> = dyn Fn(&mut dyn FnMut(usize, usize)) + 'a;

/// The NPZ log's per-cell arrays, read whole (the bench wrote them: `<f8`, C order), in
/// [`ARRAYS`] order.
fn read_npz_arrays(path: &Path) -> Result<Vec<Vec<f64>>> {
    use std::io::Read;
    let mut zip = zip::ZipArchive::new(File::open(path)?)?;
    ARRAYS
        .iter()
        .map(|array| {
            let mut entry = zip.by_name(&format!("{}.npy", array.name()))?;
            let mut bytes = Vec::new();
            entry.read_to_end(&mut bytes)?;
            ensure!(bytes.len() >= 10, "{}.npy is too short", array.name());
            let header = 10 + usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
            Ok(bytes[header..]
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
                .collect())
        })
        .collect()
}

/// The evaluate stage of the NPZ log held in memory, on one thread, fed in several orders:
/// run after run (every run's steps in turn, as `kalibra eval` streams a log), in strips of
/// [`STRIP_STEPS`] steps across all runs, each strip run after run (as
/// `kalibra_eval::Evaluation::evaluate` feeds a block), and in such strips across groups of
/// [`FEED_GROUPS`] runs, group after group (what a reader holding a few whole runs can feed).
/// Best of `repeats` alternations, each from a fresh evaluator to its report; every report
/// must equal the first (the strips keep every sum's order). Returns each order's label and
/// seconds, run after run first.
fn feed_orders(
    path: &Path,
    size: LogSize,
    window: usize,
    repeats: usize,
) -> Result<Vec<(String, f64)>> {
    let arrays = read_npz_arrays(path)?;
    let (runs, steps) = (size.runs, size.steps);
    let widths: Vec<usize> = ARRAYS
        .iter()
        .map(|a| a.cell_shape().iter().product())
        .collect();
    for (array, (values, width)) in ARRAYS.iter().zip(arrays.iter().zip(&widths)) {
        ensure!(
            values.len() == runs * steps * width,
            "{}.npy holds {} values, not {runs} x {steps} x {width}",
            array.name(),
            values.len()
        );
    }
    let cell = |run: usize, step: usize| {
        let at = |a: usize| {
            let i = (run * steps + step) * widths[a];
            &arrays[a][i..i + widths[a]]
        };
        kalibra_eval::Cell {
            truth: Some(at(0)),
            estimate: Some(at(1)),
            covariance: Some(kalibra_eval::MatrixCell::Full(at(2))),
            innovation: Some(at(3)),
            innovation_cov: Some(kalibra_eval::MatrixCell::Full(at(4))),
            model: None,
        }
    };
    let contents = kalibra_eval::Contents {
        truth: Some(4),
        estimate: Some(4),
        covariance: Some(4),
        innovation: Some(2),
        innovation_cov: Some(2),
        model: None,
    };
    let evaluation = kalibra_eval::Evaluation::new().window(window)?;
    let evaluate = |order: &Order<'_>| -> Result<(f64, Value)> {
        let (seconds, report) = timed(|| -> Result<kalibra_eval::Report> {
            let mut evaluator = evaluation.evaluator(contents)?;
            let mut batch = Vec::with_capacity(FEED_BATCH);
            let mut failed = None;
            order(&mut |run, step| {
                batch.push((run, step, cell(run, step)));
                if batch.len() == FEED_BATCH {
                    if let Err((_, e)) = evaluator.push_batch(&batch) {
                        failed.get_or_insert(e);
                    }
                    batch.clear();
                }
            });
            if let Err((_, e)) = evaluator.push_batch(&batch) {
                failed.get_or_insert(e);
            }
            if let Some(e) = failed {
                return Err(e.into());
            }
            Ok(evaluator.finish(None)?)
        });
        Ok((seconds, serde_json::to_value(report?)?))
    };
    // Strips of `group` runs at a time: every step still takes the runs in run order and
    // every run its steps in step order, whatever the group.
    let strips = |group: usize, visit: &mut dyn FnMut(usize, usize)| {
        for first in (0..runs).step_by(group) {
            let group = first..(first + group).min(runs);
            for start in (0..steps).step_by(STRIP_STEPS) {
                for run in group.clone() {
                    for step in start..(start + STRIP_STEPS).min(steps) {
                        visit(run, step);
                    }
                }
            }
        }
    };
    // (Run after run is one strip of every step.)
    let orders: Vec<(String, usize, usize)> = [(runs, steps), (runs, STRIP_STEPS)]
        .into_iter()
        .chain(FEED_GROUPS.iter().map(|&g| (g, STRIP_STEPS)))
        .filter(|&(g, _)| g <= runs)
        .map(|(g, strip)| {
            let label = if strip == steps {
                "run after run".to_string()
            } else if g == runs {
                format!("in strips of {strip} steps across all runs")
            } else {
                format!("in strips of {strip} steps across {g} runs")
            };
            (label, g, strip)
        })
        .collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    pool.install(|| {
        let mut best = vec![f64::INFINITY; orders.len()];
        let mut first: Option<Value> = None;
        for _ in 0..repeats.max(1) {
            for ((label, group, strip), best) in orders.iter().zip(&mut best) {
                let (seconds, report) = evaluate(&|visit: &mut dyn FnMut(usize, usize)| {
                    if *strip == steps {
                        for run in 0..runs {
                            for step in 0..steps {
                                visit(run, step);
                            }
                        }
                    } else {
                        strips(*group, visit);
                    }
                })?;
                match &first {
                    None => first = Some(report),
                    Some(r) => ensure!(
                        *r == report,
                        "the NPZ log's report fed {label} differs from the one fed run after run"
                    ),
                }
                *best = best.min(seconds);
            }
        }
        Ok(orders
            .into_iter()
            .zip(best)
            .map(|((label, _, _), s)| (label, s))
            .collect())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_header_is_aligned_and_names_the_shape() {
        let h = npy_header(&[3, 5, 4, 4]);
        assert_eq!(h.len() % 64, 0);
        assert!(h.starts_with(b"\x93NUMPY\x01\x00"));
        let dict = String::from_utf8_lossy(&h[10..]);
        assert!(dict.contains("'shape': (3, 5, 4, 4)"), "{dict}");
        assert!(dict.ends_with('\n'));
        let one = npy_header(&[7]);
        assert!(String::from_utf8_lossy(&one).contains("'shape': (7,)"));
    }

    #[test]
    fn csv_header_has_the_documented_columns() {
        let columns: Vec<String> = ARRAYS.iter().flat_map(|a| a.csv_columns()).collect();
        assert_eq!(columns.len(), 30);
        assert_eq!(columns[8], "covariance_0_0");
        assert_eq!(columns[9], "covariance_0_1");
        assert_eq!(columns[29], "innovation_cov_1_1");
    }

    #[test]
    fn differences_are_relative_to_the_series_scale() {
        let a = serde_json::json!([1.0, null, -4.0]);
        let b = serde_json::json!([1.0, null, -4.0 + 4e-12]);
        assert!((series_difference(&a, &b) - 1e-12).abs() < 1e-15);
        assert_eq!(series_difference(&a, &a), 0.0);
        let c = serde_json::json!([1.0, 2.0, -4.0]);
        assert!(series_difference(&a, &c).is_infinite());
        let report = serde_json::json!({"b": [{"lower": 1.0}, {"lower": 2.0}]});
        assert_eq!(at(&report, "/b/*/lower"), serde_json::json!([1.0, 2.0]));
    }

    /// The three writers at a tiny size: the CSV has a header and a row per cell, the JSON
    /// parses with the documented shapes, the NPZ holds one entry per array.
    #[test]
    fn writers_produce_the_documented_layouts() {
        let size = LogSize {
            runs: 2,
            steps: 3,
            seed: 7,
        };
        let mut csv = Vec::new();
        write_csv(size, &mut csv).unwrap();
        let csv = String::from_utf8(csv).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 1 + 6);
        assert!(lines[0].starts_with("run,step,truth_0,"));
        assert!(lines[4].starts_with("1,0,"));
        assert!(lines.iter().all(|l| l.split(',').count() == 32));

        let mut json = Vec::new();
        write_json(size, &mut json).unwrap();
        let v: Value = serde_json::from_slice(&json).unwrap();
        assert_eq!(v["covariance"].as_array().unwrap().len(), 2);
        assert_eq!(v["covariance"][1].as_array().unwrap().len(), 3);
        assert_eq!(v["covariance"][1][2][3].as_array().unwrap().len(), 4);
        assert_eq!(v["innovation"][0][1].as_array().unwrap().len(), 2);
        // The CSV and JSON hold the same numbers.
        let row: Vec<f64> = lines[6].split(',').map(|c| c.parse().unwrap()).collect();
        assert_eq!(v["covariance"][1][2][0][1].as_f64(), Some(row[2 + 8 + 1]));

        let mut npz = std::io::Cursor::new(Vec::new());
        write_npz(size, &mut npz).unwrap();
        let npz = npz.into_inner();
        for array in ARRAYS {
            let name = format!("{}.npy", array.name());
            assert!(
                npz.windows(name.len()).any(|w| w == name.as_bytes()),
                "{name}"
            );
        }
    }
}
