//! `kalibra`: judge any Kalman-type filter from its logs.
//!
//! * `kalibra eval LOG [--out DIR] [--confidence 0.95] [--window W] [--group NAME=i,j ...]
//!   [--lags L]` reads a filter log (JSON or CSV, chosen by the extension), evaluates it with
//!   `kalibra_eval::Evaluation` and writes `report.json`, `report.md`, SVG figures and a
//!   self-contained `report.html` into DIR.
//!
//! This binary is a thin layer: it parses arguments, reads files into a
//! `kalibra_eval::FilterLog`, and writes what `kalibra_eval` and `kalibra_plot` return. Exit
//! codes: 0 success, 1 the run failed (bad input, or a report that could not be written), 2 bad
//! usage (clap's own errors). Errors are one message naming the file and the row and column
//! (CSV) or the array and index (JSON); never a panic or a backtrace.

#![allow(clippy::print_stdout, clippy::print_stderr)]

mod csv_log;
mod document;
mod input;
mod json_log;
mod output;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use kalibra_eval::Evaluation;

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
}

/// Arguments of `kalibra eval`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = input::FORMATS_HELP, after_help = input::FORMATS_HELP)]
struct EvalArgs {
    /// The filter log: a .json or .csv file (format chosen by the extension).
    log: PathBuf,
    /// Directory the report is written to (replaced if it holds an earlier report).
    #[arg(long, short, default_value = "kalibra-report")]
    out: PathBuf,
    /// Confidence of every band and test, in (0, 1).
    #[arg(long, default_value_t = 0.95, value_parser = parse_confidence)]
    confidence: f64,
    /// Sliding window in samples, at least 2 (default: a tenth of the steps, at least 2).
    #[arg(long, value_parser = clap::value_parser!(u64).range(2..))]
    window: Option<u64>,
    /// A group of state components whose joint RMSE is reported, as NAME=i,j,... (0-based;
    /// repeat for several groups).
    #[arg(long = "group", value_name = "NAME=i,j", value_parser = parse_group)]
    groups: Vec<(String, Vec<usize>)>,
    /// Largest lag of the innovation whiteness test, at least 1.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
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
    let result = match Cli::parse().command {
        Command::Eval(args) => eval(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("kalibra: {message}");
            ExitCode::from(1)
        }
    }
}

/// `kalibra eval`: read, evaluate, write. The error is the one message to print.
fn eval(args: &EvalArgs) -> Result<(), String> {
    let log = input::read_log(&args.log)?;
    let report = evaluation(args)
        .and_then(|e| e.evaluate(&log))
        .map_err(|e| format!("{}: cannot evaluate the log: {e}", args.log.display()))?;
    let doc = document::Document::new(&args.log, &report);
    output::write_report(&args.out, &report, &doc)?;
    println!("{}", doc.headline());
    println!("report written to {}", args.out.display());
    Ok(())
}

fn evaluation(args: &EvalArgs) -> Result<Evaluation, kalibra_eval::EvalError> {
    let mut e = Evaluation::new()
        .confidence(args.confidence)?
        .lags(usize::try_from(args.lags).unwrap_or(usize::MAX))?;
    if let Some(w) = args.window {
        e = e.window(usize::try_from(w).unwrap_or(usize::MAX))?;
    }
    for (name, components) in &args.groups {
        e = e.group(name.clone(), components.clone())?;
    }
    Ok(e)
}
