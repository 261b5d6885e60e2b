//! `cargo xtask bench shards`: what cutting W1 into shards costs and buys.
//!
//! The study (`--shard-runs` runs, default 10^5, of `--steps` steps) runs once in one process,
//! then as S = 1, 2 and 4 shards, one after the other on this machine, each with every core
//! (as each would run alone on its own machine). A shard's time includes writing its partial
//! result (CBOR); the merge reads the S encodings back, merges and builds the report. Printed per
//! S: the slowest shard, the merge, their sum beside the one-process time, and the merge as a
//! share of a shard; the merged report is checked equal to the one-process report, bit for bit.
//! Partials are encoded as the shard files hold them (CBOR, `study::write_partial`).
//! Then the S = 4 merge once more from the same partials encoded as JSON (what the CBOR byte
//! strings save), and last a projection to 100 machines from the measured per-run cost and
//! merge. Every printed figure is also recorded for `docs/benchmarks/`.

use anyhow::{Result, ensure};
use kalibra_sim::Shard;
use kalibra_studies::w1;

use super::{Args, Figures, timed};

/// Runs the benchmark, prints its table and returns its figures.
pub(crate) fn run(args: &Args) -> Result<Figures> {
    let config = w1::Config {
        runs: args.shard_runs,
        steps: args.steps,
        threads: 0,
        ..w1::Config::paper()
    };
    let title = format!(
        "W1 (KF, NEES, NIS, RMSE), {} runs x {} steps; shards run one after the other, each on every core",
        config.runs, config.steps
    );
    println!("Shards: {title}");
    let mut figures = Figures::new("shards", title);
    let (one_process, whole) = timed(|| w1::run(&config));
    let whole = whole?;
    figures.push("one process", one_process, "s");
    let whole_bits = serde_json::to_string(&whole)?;
    println!("one process: {one_process:.2} s");
    println!(
        "| S | slowest shard s | merge s | slowest + merge s | one process / (slowest + merge) | merge / shard | partial CBOR bytes | bit-identical |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut merge_costs = Vec::new();
    // The last (S = 4) partials' encodings, merged once more from JSON below.
    let mut last_texts = Vec::new();
    for count in [1usize, 2, 4] {
        let mut slowest = 0f64;
        let mut texts = Vec::with_capacity(count);
        for index in 0..count {
            let (seconds, text) = timed(|| -> Result<Vec<u8>> {
                let part = w1::run_shard(&config, Shard::new(index, count)?)?;
                Ok(kalibra_studies::study::write_partial(&part)?)
            });
            texts.push(text?);
            slowest = slowest.max(seconds);
        }
        let bytes: usize = texts.iter().map(Vec::len).sum();
        let texts_copy = texts.clone();
        let (merge, merged) = timed(|| -> Result<_> {
            let parts = kalibra_studies::study::read_partials("w1", texts)?;
            Ok(w1::merge(&config, parts)?)
        });
        let merged = merged?;
        let identical = serde_json::to_string(&merged)? == whole_bits;
        ensure!(
            identical,
            "the merged report of {count} shards differs from the one-process report"
        );
        merge_costs.push(merge);
        figures.push(format!("{count} shards: slowest shard"), slowest, "s");
        figures.push(format!("{count} shards: merge"), merge, "s");
        figures.push(
            format!("{count} shards: one process / (slowest + merge)"),
            one_process / (slowest + merge),
            "x",
        );
        figures.push(
            format!("{count} shards: merge / shard"),
            100.0 * merge / slowest,
            "%",
        );
        figures.push(format!("{count} shards: partials"), bytes as f64, "bytes");
        println!(
            "| {count} | {slowest:.2} | {merge:.3} | {:.2} | {:.2}x | {:.2}% | {} | yes |",
            slowest + merge,
            one_process / (slowest + merge),
            100.0 * merge / slowest,
            bytes,
        );
        last_texts = texts_copy;
    }
    // The same merge from the partials encoded as JSON (the structures serialise to plain
    // arrays of decimal numbers there): what the CBOR byte strings save.
    let json: Vec<Vec<u8>> = kalibra_studies::study::read_partials::<w1::Acc>("w1", last_texts)?
        .iter()
        .map(serde_json::to_vec)
        .collect::<Result<_, _>>()?;
    let json_bytes: usize = json.iter().map(Vec::len).sum();
    let (json_merge, merged) = timed(|| -> Result<_> {
        let parts = json
            .iter()
            .map(|bytes| serde_json::from_slice::<kalibra_sim::Partial<w1::Acc>>(bytes))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(w1::merge(&config, parts)?)
    });
    ensure!(
        serde_json::to_string(&merged?)? == whole_bits,
        "the merge of JSON partials differs from the one-process report"
    );
    println!(
        "4 shards merged from JSON partials: {json_merge:.3} s ({json_bytes} bytes) against {:.3} s from CBOR",
        merge_costs.last().copied().unwrap_or(f64::NAN)
    );
    figures.push("4 shards: merge from JSON partials", json_merge, "s");
    figures.push("4 shards: JSON partials", json_bytes as f64, "bytes");
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
    figures.push("projection, 100 machines: a shard", per_machine, "s");
    figures.push(
        "projection, 100 machines: a shard + merge",
        per_machine + merge,
        "s",
    );
    figures.push(
        "projection, 100 machines: one process / (shard + merge)",
        one_process / (per_machine + merge),
        "x",
    );
    figures.push(
        "projection, 10^7 runs on 100 machines: a shard",
        one_process * 1e7 / config.runs as f64 / 100.0,
        "s",
    );
    Ok(figures)
}
