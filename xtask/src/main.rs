//! `cargo xtask`: the project's task runner.
//!
//! * `cargo xtask reproduce [STUDY ...] [--quick] [--out DIR] [--seed N] [--threads N]`: runs
//!   the studies of `kalibra_studies::REGISTRY` (all, or those named) and writes each one's
//!   Markdown report, `results.json` and SVG figures, and `index.md`, under `target/reproduce/`.
//! * `cargo xtask reproduce STUDY... --shard I/S --out DIR`: runs shard I of S of each study's
//!   Monte Carlo and writes its partial result to `DIR/<study>/shard-I-of-S.cbor`;
//!   `cargo xtask merge DIR... [--out DIR]` merges all shards into the reports and index the
//!   unsharded run writes, bit for bit (docs/distributed.md).
//! * `cargo xtask compare BEFORE AFTER`: compares two `reproduce --out` trees value by value,
//!   skipping only the commit and the values measured with a clock (`compare.rs`).
//! * `cargo xtask bench [w1|w2|w3|w4|eval|shards|smooth|all|table] [--out DIR] ...`: runs the
//!   benchmark workloads through the public API and through hand-written nalgebra loops in the same
//!   process, prints steps per second and their ratio, and writes the figures as JSON into
//!   `DIR` (default `docs/benchmarks/`) with the Markdown table generated from them
//!   (`bench/mod.rs` lists the workloads; `eval` times the release `kalibra eval` against a
//!   pandas + numpy script and is not part of `all`, which needs no Python).
//!
//! The studies live in `kalibra-studies`; this binary parses arguments, loops over the
//! registry, renders figure data to SVG, writes files and times.

#![allow(clippy::print_stdout, clippy::print_stderr)]

mod bench;
mod compare;
mod reproduce;

use clap::{Parser, Subcommand};

/// The project's task runner: reproductions and benchmarks.
#[derive(Debug, Parser)]
#[command(name = "cargo xtask", bin_name = "cargo xtask")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Re-run the published studies and write reports beside the published numbers.
    Reproduce(reproduce::Args),
    /// Time the library against hand-written nalgebra loops on the benchmark workloads.
    Bench(bench::Args),
    /// Merge the shard files of `reproduce STUDY --shard I/S` into the unsharded reports.
    Merge(reproduce::MergeArgs),
    /// Compare two `reproduce --out` trees value by value (a refactor must keep the numbers).
    Compare(compare::Args),
}

fn main() -> std::process::ExitCode {
    let result = match Cli::parse().command {
        Command::Reproduce(args) => reproduce::main(&args),
        Command::Bench(args) => bench::main(&args),
        Command::Merge(args) => reproduce::merge(&args),
        Command::Compare(args) => compare::main(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // One line with the chain of causes; no backtrace, whatever RUST_BACKTRACE says
            // (returning the error from main would print one).
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(1)
        }
    }
}

/// The instruction set `KALIBRA_SIMD` asks for (`avx512`, `avx2`, `neon`, `scalar`, `auto`),
/// `None` when it is unset: the library reads no environment, so the task runner passes it on.
pub(crate) fn simd_from_env() -> anyhow::Result<Option<kalibra_filters::batch::Isa>> {
    match std::env::var("KALIBRA_SIMD") {
        Ok(text) => {
            Ok(Some(text.parse().map_err(|e| {
                anyhow::anyhow!("KALIBRA_SIMD={text}: {e}")
            })?))
        }
        Err(std::env::VarError::NotPresent) => Ok(None),
        Err(e) => anyhow::bail!("KALIBRA_SIMD: {e}"),
    }
}

/// The workspace root (the parent of this crate's directory).
fn workspace_root() -> std::path::PathBuf {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    here.parent().unwrap_or(here).to_path_buf()
}
