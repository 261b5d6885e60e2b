//! `cargo xtask`: the project's task runner.
//!
//! * `cargo xtask reproduce [--quick] [--out DIR] [--seed N] [--threads N]`: runs every
//!   reproduction the workspace has and writes Markdown and JSON under `target/reproduce/`.
//! * `cargo xtask bench [--runs N] [--steps N] [--threads N]`: runs the benchmark workloads
//!   through the public API and through hand-written nalgebra loops in the same process, and
//!   prints steps per second and their ratio.
//!
//! The logic lives in library crates (`kalibra-studies`); this binary parses arguments, times,
//! and writes files.

#![allow(clippy::print_stdout, clippy::print_stderr)]

mod bench;
mod bench_w2;
mod figures;
mod figures2013;
mod figures2014;
mod figures2023;
mod figures2025;
mod plot;
mod reproduce;

use anyhow::{Result, bail};

const USAGE: &str = "usage:
  cargo xtask reproduce [w1|000|001|002|003|004 ...] [--quick] [--out DIR] [--seed N] [--threads N]
  cargo xtask bench [w1|w2|all] [--runs N] [--steps N] [--threads N] [--repeats N]";

fn main() -> Result<()> {
    let mut args = std::env::args_os().skip(1);
    let Some(command) = args.next() else {
        bail!("{USAGE}");
    };
    let rest: Vec<_> = args.collect();
    match command.to_str() {
        Some("reproduce") => reproduce::main(rest),
        Some("bench") => bench::main(rest),
        Some("help" | "--help" | "-h") => {
            println!("{USAGE}");
            Ok(())
        }
        _ => bail!("unknown command {command:?}\n{USAGE}"),
    }
}

/// The workspace root (the parent of this crate's directory).
fn workspace_root() -> std::path::PathBuf {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    here.parent().unwrap_or(here).to_path_buf()
}
