//! `kalibra`: judge any Kalman-type filter from its logs.
//!
//! * `kalibra eval LOG [--out DIR] [--confidence 0.95] [--window W] [--group NAME=i,j ...]
//!   [--lags L]` reads a filter log (JSON, CSV or NPZ, chosen by the extension), evaluates it
//!   with `kalibra_eval::Evaluation` and writes `report.json`, `report.md`, SVG figures and a
//!   self-contained `report.html` into DIR.
//! * `kalibra tune MODEL.toml MEASUREMENTS.csv [--p FROM:TO:STEP] [--truth TRUTH.csv]
//!   [--out DIR] [--threads N]` sweeps `Q = 10^p Q_nom` with `kalibra_tune::Tuning` and writes
//!   the crossover, the recommended `Q` and the sweep's figures the same way.
//! * `kalibra tune MODEL.toml MEASUREMENTS.csv --method ml|em|als|j1j2 [--truth TRUTH.csv]
//!   [--out DIR] [--iterations N] [--p FROM:TO:STEP]` estimates the free parameters of `Q` and
//!   `R` (the forms of MODEL.toml's `[Q]` and `[R]` tables) and writes the estimate, its
//!   intervals, identifiability and consistency (`kalibra_io::noise_report`).
//!
//! This binary is a thin layer: it parses arguments, reads the files and writes the report
//! through `kalibra_io`, and evaluates with `kalibra_eval` and tunes with `kalibra_tune`. Exit codes: 0 success, 1
//! the run failed (bad input, or a report that could not be written), 2 bad usage (clap's own
//! errors). Errors are one message naming the file and the row and column (CSV), the array and
//! index (JSON, NPZ), the key (MODEL.toml) or the option; never a panic or a backtrace.

#![allow(clippy::print_stdout, clippy::print_stderr)]
#![deny(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};
use kalibra_eval::{EvalError, Evaluation};
use kalibra_io::noise_report::NoiseReportFile;
use kalibra_io::{Error, document, input, output, tune_input};
use kalibra_tune::{
    Als, Em, MaximumLikelihood, NoiseReport, ParameterSweep, ReportOptions, Tuning,
};

/// Judge a Kalman-type filter from its logs: is its covariance telling the truth?
#[derive(Debug, Parser)]
#[command(name = "kalibra", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Evaluate a filter log: ANEES, ANIS, NCI, RMSE, whiteness, J1/J2 and a verdict.
    Eval(EvalArgs),
    /// Choose Q and R of a linear model from recorded measurements (J1/J2 sweep, or --method).
    Tune(TuneArgs),
}

/// Arguments of `kalibra tune`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = tune_input::TUNE_HELP, after_help = tune_input::TUNE_HELP)]
struct TuneArgs {
    /// The linear model: F, H, the nominal Q, R, x0 and P0 (see below).
    #[arg(value_parser = non_empty_file)]
    model: PathBuf,
    /// The measurements: columns step, z_0, ..., z_{m-1} (see below).
    #[arg(value_parser = non_empty_file)]
    measurements: PathBuf,
    /// The grid of exponents p of Q = 10^p Q_nom, as FROM:TO:STEP (TO included); with
    /// --method j1j2, of each parameter times 10^p [default: -6:6:0.5, with --method j1j2
    /// -3:3:0.25].
    #[arg(
        long = "p",
        value_name = "FROM:TO:STEP",
        allow_hyphen_values = true,
        value_parser = parse_grid
    )]
    grid: Option<(f64, f64, f64)>,
    /// The estimator of the free parameters of Q and R (see METHODS below).
    #[arg(long, value_enum)]
    method: Option<Method>,
    /// With --method em: run exactly N iterations (otherwise to a relative tolerance of 1e-8
    /// on the log-likelihood).
    #[arg(long, value_name = "N")]
    iterations: Option<usize>,
    /// The true states (columns step, x_0, ..., x_{n-1}), for the RMSE at every p (the sweep),
    /// or the tuned filter's ANEES and RMSE (--method).
    #[arg(long, value_parser = non_empty_file)]
    truth: Option<PathBuf>,
    /// Directory the report is written to (replaced if it holds an earlier report).
    #[arg(long, short, default_value = "kalibra-tune", value_parser = non_empty_dir)]
    out: PathBuf,
    /// Threads for the sweep (0: one per core). The results do not depend on it.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    threads: usize,
}

/// The estimators of `--method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Method {
    /// Maximum likelihood, with standard errors, 95% intervals and identifiability.
    Ml,
    /// Expectation-maximisation.
    Em,
    /// Autocovariance least squares.
    Als,
    /// The J1/J2 crossover of every free parameter.
    J1j2,
}

/// A directory that is not an empty path: an empty `--out` would write into the current
/// directory (clap names the option in the error).
fn non_empty_dir(s: &str) -> Result<PathBuf, String> {
    if s.trim().is_empty() {
        Err("empty; name the directory the report is written to".to_string())
    } else {
        Ok(PathBuf::from(s))
    }
}

/// A file that is not an empty path: reading `` would fail with a message naming nothing.
fn non_empty_file(s: &str) -> Result<PathBuf, String> {
    if s.trim().is_empty() {
        Err("empty; name the file".to_string())
    } else {
        Ok(PathBuf::from(s))
    }
}

fn parse_grid(s: &str) -> Result<(f64, f64, f64), String> {
    let parts: Vec<&str> = s.split(':').collect();
    let [from, to, step] = parts[..] else {
        return Err(format!("`{s}` is not FROM:TO:STEP (for instance -6:6:0.5)"));
    };
    let number = |t: &str| {
        t.trim()
            .parse::<f64>()
            .map_err(|_| format!("`{t}` in `{s}` is not a number"))
    };
    let grid = (number(from)?, number(to)?, number(step)?);
    Tuning::new()
        .exponents(grid.0, grid.1, grid.2)
        .map_err(|e| format!("`{s}`: {e} (STEP must be positive and TO at least FROM)"))?;
    Ok(grid)
}

/// Arguments of `kalibra eval`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = input::FORMATS_HELP, after_help = input::FORMATS_HELP)]
struct EvalArgs {
    /// The filter log: a .json, .csv or .npz file (format chosen by the extension).
    #[arg(value_parser = non_empty_file)]
    log: PathBuf,
    /// Directory the report is written to (replaced if it holds an earlier report).
    #[arg(long, short, default_value = "kalibra-report", value_parser = non_empty_dir)]
    out: PathBuf,
    /// Confidence of every band and test, in (0, 1).
    #[arg(long, default_value_t = 0.95, value_parser = parse_confidence, allow_negative_numbers = true)]
    confidence: f64,
    /// Sliding window in samples, at least 2 (default: a tenth of the steps, at least 2).
    #[arg(long, value_parser = clap::value_parser!(u64).range(2..), allow_negative_numbers = true)]
    window: Option<u64>,
    /// A group of state components whose joint RMSE is reported, as NAME=i,j,... (0-based;
    /// repeat for several groups).
    #[arg(long = "group", value_name = "NAME=i,j", value_parser = parse_group)]
    groups: Vec<(String, Vec<usize>)>,
    /// Largest lag of the innovation whiteness test, at least 1.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..), allow_negative_numbers = true)]
    lags: u64,
}

fn parse_confidence(s: &str) -> Result<f64, String> {
    let c: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    if c > 0.0 && c < 1.0 {
        Ok(c)
    } else {
        Err(format!("{c} is not between 0 and 1"))
    }
}

fn parse_group(s: &str) -> Result<(String, Vec<usize>), String> {
    let (name, list) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not NAME=i,j,..."))?;
    if name.is_empty() {
        return Err(format!("`{s}` has no group name before `=`"));
    }
    let components = list
        .split(',')
        .map(|i| {
            i.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{i}` in `{s}` is not a component index (0, 1, ...)"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((name.to_string(), components))
}

fn main() -> ExitCode {
    // A panic is a bug in kalibra: say so in one line, without a backtrace. Unwinding still
    // runs the output guard, which removes a half-written report.
    std::panic::set_hook(Box::new(|info| {
        eprintln!("kalibra: internal error (please report it): {info}");
    }));
    let cli = Cli::parse();
    if let Command::Tune(a) = &cli.command
        && a.iterations.is_some()
        && a.method != Some(Method::Em)
    {
        Cli::command()
            .error(
                clap::error::ErrorKind::ArgumentConflict,
                "--iterations applies to --method em only",
            )
            .exit();
    }
    let result = match cli.command {
        Command::Eval(args) => eval(&args),
        Command::Tune(args) => tune(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("kalibra: {message}");
            ExitCode::from(1)
        }
    }
}

/// The one message of a reader's or the writer's error. A `--group` naming a component the
/// log's state does not have is the option's fault, not the log's, and says so.
fn message(e: Error) -> String {
    match e {
        Error::Evaluate {
            file,
            source: EvalError::GroupIndex { group, index, dim },
            ..
        } => format!(
            "--group {group}: component {index} is not in the state of {}, which has {dim} \
             components (0 to {})",
            file.display(),
            dim.saturating_sub(1)
        ),
        other => other.to_string(),
    }
}

/// `kalibra eval`: read, evaluate, write. The error is the one message to print.
fn eval(args: &EvalArgs) -> Result<(), String> {
    let evaluation = evaluation(args)?;
    // The output first: an unwritable --out fails before a long evaluation.
    let target = output::Target::prepare(&args.out).map_err(message)?;
    let report = input::evaluate_log(&args.log, &evaluation).map_err(message)?;
    let doc = document::Document::new(&args.log, &report);
    target.write(&report, &doc).map_err(message)?;
    println!("{}", doc.headline());
    println!("report written to {}", args.out.display());
    Ok(())
}

/// `kalibra tune`: read the model and the sequences, sweep or estimate, write.
fn tune(args: &TuneArgs) -> Result<(), String> {
    // The output first: an unwritable --out fails before any work.
    let target = output::Target::prepare(&args.out).map_err(message)?;
    let model = tune_input::read_model(&args.model).map_err(message)?;
    let method = match args.method {
        Some(Method::J1j2) | None if model.is_plain() => None,
        Some(m) => Some(m),
        None => Some(Method::Ml),
    };
    if let Some(method) = method {
        return estimate(args, target, &model, method);
    }
    let m = model.meas_dim();
    let measurements =
        tune_input::read_series(&args.measurements, "z", m, &format!("H has {m} row(s)"))
            .map_err(message)?;
    let truth = match &args.truth {
        Some(path) => {
            let n = model.state_dim();
            let t = tune_input::read_series(path, "x", n, &format!("F has {n} row(s)"))
                .map_err(message)?;
            Some((path.as_path(), t))
        }
        None => None,
    };
    let problem = model
        .problem(&args.model, measurements, truth)
        .map_err(message)?;
    let (from, to, step) = args.grid.unwrap_or((-6.0, 6.0, 0.5));
    let mut tuning = Tuning::new()
        .exponents(from, to, step)
        .map_err(|e| format!("--p: {e}"))?
        .threads(args.threads);
    if let Some(position) = &model.position {
        tuning = tuning.position(position.clone());
    }
    let report = tuning
        .tune(&problem)
        .map_err(|e| format!("{}: cannot tune: {e}", args.model.display()))?;
    let doc = document::Document::tune(&args.model, &args.measurements, &report);
    target.write(&report, &doc).map_err(message)?;
    println!("{}", doc.headline());
    println!("report written to {}", args.out.display());
    Ok(())
}

/// `kalibra tune --method`: read the measurements (and truth), estimate, write.
fn estimate(
    args: &TuneArgs,
    target: output::Target,
    model: &tune_input::Model,
    method: Method,
) -> Result<(), String> {
    let m = model.meas_dim();
    let measurements =
        tune_input::read_series(&args.measurements, "z", m, &format!("H has {m} row(s)"))
            .map_err(message)?;
    let truth = match &args.truth {
        Some(path) => {
            let n = model.state_dim();
            let t = tune_input::read_series(path, "x", n, &format!("F has {n} row(s)"))
                .map_err(message)?;
            if t.len() != measurements.len() {
                return Err(format!(
                    "{}: {} steps, but {} has {}; the truth covers the same steps",
                    path.display(),
                    t.len(),
                    args.measurements.display(),
                    measurements.len()
                ));
            }
            Some(t)
        }
        None => None,
    };
    let problem = model
        .noise_problem(&args.model, &args.measurements, vec![measurements])
        .map_err(message)?;
    let method = match method {
        Method::Ml => kalibra_tune::Method::MaximumLikelihood(MaximumLikelihood::new()),
        Method::Em => kalibra_tune::Method::Em(match args.iterations {
            Some(n) => Em::new().exact_iterations(n),
            None => Em::new(),
        }),
        Method::Als => kalibra_tune::Method::Als(Als::new()),
        Method::J1j2 => {
            let mut sweep = ParameterSweep::new();
            if let Some((from, to, step)) = args.grid {
                let grid = kalibra_tune::grid(from..=to, step).map_err(|e| format!("--p: {e}"))?;
                sweep = sweep.grid(grid).map_err(|e| format!("--p: {e}"))?;
            }
            kalibra_tune::Method::J1J2(sweep)
        }
    };
    let truth = truth.map(|t| vec![t]);
    let estimate = NoiseReport::estimate(&problem, &method, ReportOptions::new(), truth.as_deref())
        .map_err(|e| format!("{}: cannot estimate Q and R: {e}", args.model.display()))?;
    let report = NoiseReportFile::new(&problem, &estimate);
    let doc = document::Document::noise(Some((&args.model, &args.measurements)), &report);
    target.write(&report, &doc).map_err(message)?;
    println!("{}", doc.headline());
    println!("report written to {}", args.out.display());
    Ok(())
}

/// The evaluation the options ask for; an error names the option at fault.
fn evaluation(args: &EvalArgs) -> Result<Evaluation, String> {
    fn option(name: &'static str) -> impl Fn(kalibra_eval::EvalError) -> String {
        move |e| format!("{name}: {e}")
    }
    let mut e = Evaluation::new()
        .confidence(args.confidence)
        .map_err(option("--confidence"))?
        .lags(usize::try_from(args.lags).unwrap_or(usize::MAX))
        .map_err(option("--lags"))?;
    if let Some(w) = args.window {
        e = e
            .window(usize::try_from(w).unwrap_or(usize::MAX))
            .map_err(option("--window"))?;
    }
    for (name, components) in &args.groups {
        e = e
            .group(name.clone(), components.clone())
            .map_err(option("--group"))?;
    }
    Ok(e)
}
