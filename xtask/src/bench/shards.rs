//! `cargo xtask bench shards`: what cutting W1 into shards costs and buys (issue 20, point 5).
//!
//! The study (`--shard-runs` runs, default 10^5, of `--steps` steps) runs once in one process,
//! then as S = 1, 2 and 4 shards, one after the other on this machine, each with every core
//! (as each would run alone on its own machine). A shard's time includes writing its partial
//! result (CBOR); the merge reads the S encodings back, merges and builds the report. Printed per
//! S: the slowest shard, the merge, their sum beside the one-process time, and the merge as a
//! share of a shard; the merged report is checked equal to the one-process report, bit for bit.
//! Partials are encoded as the shard files hold them (CBOR, `study::write_partial`).
//! Last, a projection to 100 machines from the measured per-run cost and merge.

use std::time::Instant;

use anyhow::{Result, ensure};
use kalibra_sim::Shard;
use kalibra_studies::w1;

use crate::bench::Args;

/// Runs the benchmark and prints its table.
pub fn shards_bench(args: &Args) -> Result<()> {
    let config = w1::Config {
        runs: args.shard_runs,
        steps: args.steps,
        threads: 0,
        ..w1::Config::paper()
    };
    println!(
        "Shards: W1 (KF, NEES, NIS, RMSE), {} runs x {} steps; shards run one after the other, each on every core",
        config.runs, config.steps
    );
    let start = Instant::now();
    let whole = w1::run(&config)?;
    let one_process = start.elapsed().as_secs_f64();
    let whole_bits = serde_json::to_string(&whole)?;
    println!("one process: {one_process:.2} s");
    println!(
        "| S | slowest shard s | merge s | slowest + merge s | one process / (slowest + merge) | merge / shard | partial CBOR bytes | bit-identical |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut merge_costs = Vec::new();
    for count in [1usize, 2, 4] {
        let mut slowest = 0f64;
        let mut texts = Vec::with_capacity(count);
        for index in 0..count {
            let start = Instant::now();
            let part = w1::run_shard(&config, Shard::new(index, count)?)?;
            texts.push(kalibra_studies::study::write_partial(&part)?);
            slowest = slowest.max(start.elapsed().as_secs_f64());
        }
        let bytes: usize = texts.iter().map(Vec::len).sum();
        let start = Instant::now();
        let parts = kalibra_studies::study::read_partials("w1", texts)?;
        let merged = w1::merge(&config, parts)?;
        let merge = start.elapsed().as_secs_f64();
        let identical = serde_json::to_string(&merged)? == whole_bits;
        ensure!(
            identical,
            "the merged report of {count} shards differs from the one-process report"
        );
        merge_costs.push(merge);
        println!(
            "| {count} | {slowest:.2} | {merge:.3} | {:.2} | {:.2}x | {:.2}% | {} | yes |",
            slowest + merge,
            one_process / (slowest + merge),
            100.0 * merge / slowest,
            bytes,
        );
    }
    // The merge handles the study's blocks (at most 64) whatever S is, so its cost at S = 4
    // stands for any S; a shard's cost is the one-process cost divided by S.
    let merge = merge_costs.iter().copied().fold(0.0, f64::max);
    let per_machine = one_process / 100.0;
    println!(
        "projection, 100 machines like this one: a shard {per_machine:.3} s + merge {merge:.3} s = {:.3} s against {one_process:.2} s in one process ({:.0}x); at 10^7 runs a shard takes {:.1} s and the merge stays near {merge:.3} s",
        per_machine + merge,
        one_process / (per_machine + merge),
        one_process * 1e7 / config.runs as f64 / 100.0,
    );
    Ok(())
}
