//! `cargo xtask bench`: the library against hand-written nalgebra loops, in one process, with
//! the figures written as data.
//!
//! `cargo xtask bench [w1|w2|w3|w4|eval|shards|smooth|tune|all] [--out DIR] [--runs N] [--steps N]
//! [--threads N] [--repeats N] [--seed N] [--sizes N,N,...] [--kernels] [--ukf] [--no-python]
//! [--shard-runs N]`; one module per workload:
//!
//! * [`w1`]: a 2-D constant-velocity KF, `--runs` x `--steps`: the scalar library, a
//!   hand-written loop, and the batched study on each instruction set the CPU has.
//! * [`w2`]: paper 001's problem III (bearings), EKF and UKF, `--runs` x 51 steps.
//! * [`w3`]: paper 003's re-entry EKF with J1/J2, 41 values of Q x 100 runs x 59 steps.
//! * [`w4`]: one KF at the run-time sizes `--sizes`, faer's kernels against nalgebra's, and a
//!   numpy script (`--no-python` skips it); minutes at n = 1024, so not part of `all`.
//! * [`eval`]: the `kalibra` executable against a pandas + numpy script on generated logs;
//!   it needs Python, PyPI and over a gigabyte of logs, so not part of `all`.
//! * [`shards`]: W1 as 1, 2 and 4 shards against one process (`--shard-runs` runs).
//! * [`smooth`]: the KF's RTS smoother on W1's model against a hand-written loop and FilterPy
//!   (Python and PyPI unless `--no-python`), and the square-root KF's cost; not part of `all`.
//! * [`tune`]: noise estimation, maximum likelihood against statsmodels' `fit()` and EM against
//!   pykalman (Python and PyPI unless `--no-python`); not part of `all`.
//!
//! `all` runs W1, W2 and W3. Each workload prints its figures and collects them
//! ([`figures::Figures`]); after it, they are written with their provenance to
//! `DIR/<workload>.json` and `DIR/README.md` is regenerated from every JSON file of `DIR`
//! (`--out`, default `docs/benchmarks/`). Timing is [`timing`]'s.

mod eval;
mod figures;
mod shards;
mod smooth;
mod timing;
mod tune;
mod w1;
mod w2;
mod w3;
mod w4;

use std::path::PathBuf;

use anyhow::Result;
use kalibra_filters::batch::Isa;

pub(crate) use figures::Figures;
pub(crate) use timing::{Best, Budget, best_of, timed};

/// Which workloads to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Workloads {
    /// W1, W2 then W3 (not eval, which needs Python and PyPI).
    All,
    /// W1: 2-D constant-velocity KF with per-step NEES and NIS.
    #[value(alias = "W1")]
    W1,
    /// W2: paper 001's problem III, EKF and UKF, 51 steps.
    #[value(alias = "W2")]
    W2,
    /// W3: paper 003's re-entry EKF with J1/J2 at every step, 41 values of Q x 100 runs x 59
    /// steps: library, hand-written loop and batched.
    #[value(alias = "W3")]
    W3,
    /// `kalibra eval` on CSV, NPZ and JSON logs against a pandas + numpy script.
    Eval,
    /// W4: one KF at run-time sizes n = 8 .. 1024, faer's kernels against nalgebra's, and a
    /// numpy script.
    #[value(alias = "W4")]
    W4,
    /// W1 cut into 1, 2 and 4 shards: slowest shard plus merge against one process
    /// (`--shard-runs` runs, default 10^5).
    Shards,
    /// The KF's RTS smoother on W1's model: library, hand-written loop and FilterPy.
    Smooth,
    /// Noise estimation: maximum likelihood against statsmodels' fit() and EM against
    /// pykalman, 10^4 steps of a 4-state model.
    Tune,
    /// Measures nothing: regenerates `README.md` in the output directory from its JSON files
    /// (after a merge of branches that each ran a workload).
    Table,
}

/// `cargo xtask bench` arguments.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Which workload to run.
    #[arg(value_enum, default_value = "all")]
    workloads: Workloads,
    /// Folder of the figures: each workload writes `<workload>.json` there and regenerates
    /// `README.md` from every JSON file in it (default: docs/benchmarks).
    #[arg(long, value_name = "DIR")]
    pub(crate) out: Option<PathBuf>,
    /// Monte Carlo runs per workload.
    #[arg(long, default_value_t = 1000, value_parser = positive, allow_negative_numbers = true)]
    pub(crate) runs: usize,
    /// Steps per run (W1 and eval; W2 has 51).
    #[arg(long, default_value_t = 1000, value_parser = positive, allow_negative_numbers = true)]
    pub(crate) steps: usize,
    /// Threads for the multi-thread comparison of W1 and W2, and for W4's within-step
    /// parallelism at n >= 512 (default: every core).
    #[arg(long, default_value_t = cores(), allow_negative_numbers = true)]
    pub(crate) threads: usize,
    /// Timed repeats; the best is reported.
    #[arg(long, default_value_t = 3, value_parser = positive, allow_negative_numbers = true)]
    pub(crate) repeats: usize,
    /// Seed of the eval workload's generated logs (W1 and W2 keep their fixed seeds).
    #[arg(long, default_value_t = 2012, allow_negative_numbers = true)]
    pub(crate) seed: u64,
    /// W4: the state dimensions measured (default 8, 16, ..., 1024).
    #[arg(long, value_delimiter = ',', default_values_t = w4::SIZES, allow_negative_numbers = true)]
    pub(crate) sizes: Vec<usize>,
    /// W4: also time the kernels of the step one by one, faer against nalgebra.
    #[arg(long)]
    pub(crate) kernels: bool,
    /// W4: also time a UKF on the same problems (n <= 256), faer against nalgebra.
    #[arg(long)]
    pub(crate) ukf: bool,
    /// W4: skip the numpy script (no Python, no PyPI).
    #[arg(long)]
    pub(crate) no_python: bool,
    /// Shards: the study's runs.
    #[arg(long, default_value_t = 100_000, value_parser = positive)]
    pub(crate) shard_runs: usize,
}

/// A count of at least one.
fn positive(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
    }
}

fn cores() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// The instruction set the batched paths run on: `KALIBRA_SIMD`'s, or the detected one.
pub(crate) fn isa() -> Result<Isa> {
    Ok(crate::simd_from_env()?.unwrap_or_else(Isa::detect))
}

pub fn main(args: &Args) -> Result<()> {
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| crate::workspace_root().join("docs").join("benchmarks"));
    if matches!(args.workloads, Workloads::Table) {
        let table = out.join(figures::TABLE);
        std::fs::write(&table, figures::render(&figures::read_all(&out)?))?;
        println!("figures: {} regenerated", table.display());
        return Ok(());
    }
    let workloads = match args.workloads {
        Workloads::All => vec![Workloads::W1, Workloads::W2, Workloads::W3],
        one => vec![one],
    };
    for (i, workload) in workloads.into_iter().enumerate() {
        if i > 0 {
            println!();
        }
        let figures = match workload {
            Workloads::W1 => w1::run(args)?,
            Workloads::W2 => w2::run(args)?,
            Workloads::W3 => w3::run(args)?,
            Workloads::W4 => w4::run(args)?,
            Workloads::Eval => eval::run(args)?,
            Workloads::Shards => shards::run(args)?,
            Workloads::Smooth => smooth::run(args)?,
            Workloads::Tune => tune::run(args)?,
            Workloads::All | Workloads::Table => {
                anyhow::bail!("`all` and `table` are handled above")
            }
        };
        let command = std::iter::once("cargo xtask".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" ");
        let record = figures.into_record(
            command,
            figures::Machine::this(),
            isa()?.to_string(),
            crate::reproduce::git_revision(),
            figures::utc_now(),
        );
        figures::write(&out, &record)?;
    }
    Ok(())
}
