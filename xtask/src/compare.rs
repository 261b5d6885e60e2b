//! `cargo xtask compare BEFORE AFTER`: are two `reproduce --out` trees the same numbers?
//!
//! A refactor must keep the reproduction's results. This walks every `STUDY/results.json` of
//! `BEFORE`, parses it and its twin in `AFTER` as JSON, and compares them value by value: numbers
//! as the `f64` (or integer) the text parses to (the studies write shortest round-trip text, so
//! equal values are equal bits, up to the sign of zero), strings and booleans exactly. The commit (`git_revision`) is skipped, and so are the values the
//! studies measure with a clock ([`MEASURED`]), which differ between any two runs; they are
//! counted and named, never silently dropped.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde_json::Value;

/// Arguments of `cargo xtask compare`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The reference tree (`cargo xtask reproduce --out BEFORE` at the earlier commit).
    #[arg(value_name = "BEFORE")]
    before: PathBuf,
    /// The tree to check against it.
    #[arg(value_name = "AFTER")]
    after: PathBuf,
}

/// Values that are wall-clock measurements, as `(study, JSON path prefix)`: paper 001 times its
/// filters in the same process (the cost columns of its Table II and the ordering claim quoting
/// them).
const MEASURED: &[(&str, &str)] = &[
    ("001", "/results/cost_ns_per_step"),
    ("001", "/results/cost_relative_to_srf"),
    ("001", "/results/claims/61/ours"),
    ("001", "/results/claims/61/verdict"),
];

/// What one comparison found.
#[derive(Default)]
struct Tally {
    compared: usize,
    skipped: usize,
    differences: Vec<String>,
}

/// Runs the comparison and fails when any compared value differs or a study is missing.
pub fn main(args: &Args) -> Result<()> {
    let mut studies: Vec<PathBuf> = std::fs::read_dir(&args.before)
        .with_context(|| format!("read {}", args.before.display()))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|path| path.join("results.json").is_file())
        .collect();
    studies.sort();
    if studies.is_empty() {
        bail!("{}: no STUDY/results.json found", args.before.display());
    }
    let mut total = Tally::default();
    let mut differing = 0;
    for dir in &studies {
        let study = dir.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let before = read(&dir.join("results.json"))?;
        let after = read(&args.after.join(study).join("results.json"))?;
        let mut tally = Tally::default();
        walk(study, "", &before, &after, &mut tally);
        println!(
            "{study}: {} values compared, {} measured values skipped, {} differ",
            tally.compared,
            tally.skipped,
            tally.differences.len()
        );
        for line in tally.differences.iter().take(10) {
            println!("  {line}");
        }
        if !tally.differences.is_empty() {
            differing += 1;
        }
        total.compared += tally.compared;
        total.skipped += tally.skipped;
    }
    println!(
        "{} studies, {} values compared, {} measured values skipped, {differing} studies differ",
        studies.len(),
        total.compared,
        total.skipped
    );
    if differing > 0 {
        bail!("{differing} studies differ");
    }
    Ok(())
}

fn read(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path).with_context(|| format!("read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parse {}", path.display()))
}

/// Compares `a` and `b` at `path`, recording leaves compared, skipped and different.
fn walk(study: &str, path: &str, a: &Value, b: &Value, tally: &mut Tally) {
    if path == "/git_revision"
        || MEASURED
            .iter()
            .any(|(s, prefix)| *s == study && path.starts_with(prefix))
    {
        tally.skipped += leaves(a);
        return;
    }
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for (key, va) in x {
                match y.get(key) {
                    Some(vb) => walk(study, &format!("{path}/{key}"), va, vb, tally),
                    None => tally
                        .differences
                        .push(format!("{path}/{key}: missing after")),
                }
            }
            for key in y.keys().filter(|k| !x.contains_key(*k)) {
                tally.differences.push(format!("{path}/{key}: new after"));
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (va, vb)) in x.iter().zip(y).enumerate() {
                walk(study, &format!("{path}/{i}"), va, vb, tally);
            }
        }
        _ => {
            tally.compared += leaves(a);
            if a != b {
                tally.differences.push(format!("{path}: {a} -> {b}"));
            }
        }
    }
}

/// The number of scalar values in `v`.
fn leaves(v: &Value) -> usize {
    match v {
        Value::Object(m) => m.values().map(leaves).sum(),
        Value::Array(a) => a.iter().map(leaves).sum(),
        _ => 1,
    }
}
