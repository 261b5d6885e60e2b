//! Benchmark figures as data: each workload's figures, with where and how they were measured,
//! written as JSON, and the Markdown table generated from every JSON file of a folder.
//!
//! `cargo xtask bench WORKLOAD` writes `WORKLOAD.json` into `--out` (default
//! `docs/benchmarks/`) and then regenerates `README.md` there from all the JSON files, as
//! `cargo xtask reproduce` generates `docs/reproduction/`: a figure lives in the file its
//! benchmark wrote, and documents link to the table instead of copying numbers that would
//! drift from the code.

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

/// Version of the JSON layout below.
pub(crate) const SCHEMA: u32 = 1;

/// The name of the generated table in a figures folder.
pub(crate) const TABLE: &str = "README.md";

/// One measured figure.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Figure {
    /// What was measured, unique within its workload.
    pub name: String,
    /// The value (`null` in JSON when not finite).
    pub value: Option<f64>,
    /// Its unit (`steps/s`, `s`, `x` for a ratio, ...).
    pub unit: String,
}

/// The machine a workload ran on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Machine {
    /// The CPU model (`model name` of `/proc/cpuinfo`), or `unknown`.
    pub cpu: String,
    /// Logical cores available to the process.
    pub cores: usize,
    /// Operating system and architecture (`linux x86_64`).
    pub os: String,
}

impl Machine {
    /// This machine.
    pub(crate) fn this() -> Self {
        let cpu = fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|text| {
                text.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".into());
        Self {
            cpu,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            os: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
        }
    }
}

/// One workload's figures and their provenance: the content of `<workload>.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Record {
    /// [`SCHEMA`].
    pub schema: u32,
    /// The workload's name (`w1`, `w2`, `w3`, `w4`, `eval`, `shards`, `smooth`, `tune`).
    pub workload: String,
    /// What the workload runs, in one line.
    pub title: String,
    /// The command that produced the figures.
    pub command: String,
    /// Where.
    pub machine: Machine,
    /// The instruction set of the batched paths (detected, or `KALIBRA_SIMD`'s).
    pub isa: String,
    /// The commit measured (`git rev-parse --short=12 HEAD`).
    pub commit: String,
    /// When, in UTC (`YYYY-MM-DDTHH:MM:SSZ`).
    pub date: String,
    /// The figures, in the order the workload printed them.
    pub figures: Vec<Figure>,
}

/// A workload's figures as it measures them.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Figures {
    workload: &'static str,
    title: String,
    figures: Vec<Figure>,
}

impl Figures {
    /// No figures yet for `workload`, described by `title`.
    pub(crate) fn new(workload: &'static str, title: impl Into<String>) -> Self {
        Self {
            workload,
            title: title.into(),
            figures: Vec::new(),
        }
    }

    /// Records `value` in `unit` under `name`.
    pub(crate) fn push(&mut self, name: impl Into<String>, value: f64, unit: &str) {
        self.figures.push(Figure {
            name: name.into(),
            value: value.is_finite().then_some(value),
            unit: unit.into(),
        });
    }

    /// The figures with their provenance.
    pub(crate) fn into_record(
        self,
        command: String,
        machine: Machine,
        isa: String,
        commit: String,
        date: String,
    ) -> Record {
        Record {
            schema: SCHEMA,
            workload: self.workload.into(),
            title: self.title,
            command,
            machine,
            isa,
            commit,
            date,
            figures: self.figures,
        }
    }
}

/// Writes `record` as `<workload>.json` into `dir` (created if missing), then regenerates the
/// table [`TABLE`] there from every JSON file of `dir`.
pub(crate) fn write(dir: &Path, record: &Record) -> Result<()> {
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{}.json", record.workload));
    let text = serde_json::to_string_pretty(record)? + "\n";
    fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    let table = dir.join(TABLE);
    fs::write(&table, render(&read_all(dir)?))
        .with_context(|| format!("writing {}", table.display()))?;
    println!("figures: {} and {}", path.display(), table.display());
    Ok(())
}

/// Every `*.json` record of `dir`, in file-name order.
pub(crate) fn read_all(dir: &Path) -> Result<Vec<Record>> {
    let mut paths = Vec::new();
    for entry in fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "json") {
            paths.push(path);
        }
    }
    paths.sort();
    paths
        .iter()
        .map(|path| {
            let text =
                fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
        })
        .collect()
}

/// The Markdown table of `records`: a header saying how the figures are produced, then one
/// section per workload with its provenance and a table of its figures.
pub(crate) fn render(records: &[Record]) -> String {
    let mut out = String::from(
        "# Benchmark figures\n\n\
         Generated by `cargo xtask bench` (`xtask/src/bench/`) from the JSON files beside this one;\n\
         do not edit it by hand. Each run of `cargo xtask bench WORKLOAD` (a release build) writes\n\
         `WORKLOAD.json` here (or into `--out DIR`): the machine, the instruction set, the commit,\n\
         the date and every figure with its unit; then it regenerates this file from all of them.\n\
         The goals the figures are held against are in\n\
         [ARCHITECTURE.md](../ARCHITECTURE.md#performance); `cargo xtask bench --help` lists the\n\
         workloads.\n",
    );
    if records.is_empty() {
        out.push_str(
            "\nNo figures are committed yet. Figures measured on a shared or busy machine are noise:\n\
             run the benchmarks on quiet cores (`all`, then `w4`, `eval` and `shards`) and commit\n\
             the JSON files with this table.\n",
        );
    }
    for r in records {
        out.push_str(&format!(
            "\n## {}: {}\n\n`{}` at commit `{}`, {}; {} ({} cores, {}), instruction set {}.\n\n\
             | figure | value | unit |\n|---|---|---|\n",
            r.workload,
            r.title,
            r.command,
            r.commit,
            r.date,
            r.machine.cpu,
            r.machine.cores,
            r.machine.os,
            r.isa
        ));
        for f in &r.figures {
            out.push_str(&format!(
                "| {} | {} | {} |\n",
                f.name.replace('|', "\\|"),
                f.value.map_or_else(|| "not finite".into(), significant),
                f.unit
            ));
        }
    }
    out
}

/// `value` with four significant digits (scientific notation outside 1e-3 ..= 1e6).
fn significant(value: f64) -> String {
    if value == 0.0 {
        return "0".into();
    }
    let magnitude = value.abs().log10().floor();
    if !(-3.0..6.0).contains(&magnitude) {
        return format!("{value:.3e}");
    }
    // At most 6 digits before the point, so the cast cannot wrap.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let decimals = (3.0 - magnitude).max(0.0) as usize;
    format!("{value:.decimals$}")
}

/// The UTC time now, as `YYYY-MM-DDTHH:MM:SSZ`.
pub(crate) fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    utc(secs)
}

/// `secs` since the Unix epoch as `YYYY-MM-DDTHH:MM:SSZ` (Howard Hinnant's `civil_from_days`).
fn utc(secs: u64) -> String {
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(workload: &str, figures: Vec<(&str, f64, &str)>) -> Record {
        let mut f = Figures::new("w1", "a title");
        for (name, value, unit) in figures {
            f.push(name, value, unit);
        }
        let mut r = f.into_record(
            "cargo xtask bench w1 --runs 16".into(),
            Machine {
                cpu: "Some CPU".into(),
                cores: 2,
                os: "linux x86_64".into(),
            },
            "avx2".into(),
            "0123456789ab".into(),
            "2026-11-27T21:00:00Z".into(),
        );
        r.workload = workload.into();
        r
    }

    /// The committed table is generated from the committed JSON (`cargo xtask bench table`
    /// regenerates it), so the two never disagree.
    #[test]
    fn the_committed_table_is_generated_from_its_json() {
        let dir = crate::workspace_root().join("docs").join("benchmarks");
        let committed = std::fs::read_to_string(dir.join(TABLE)).unwrap();
        assert!(
            committed == render(&read_all(&dir).unwrap()),
            "docs/benchmarks/README.md is stale: run `cargo xtask bench table`"
        );
    }

    #[test]
    fn records_round_trip_through_json_with_non_finite_values_as_null() {
        let r = record(
            "w1",
            vec![("rate", 1.5e6, "steps/s"), ("ratio", f64::NAN, "x")],
        );
        let text = serde_json::to_string_pretty(&r).unwrap();
        assert!(text.contains("\"value\": null"), "{text}");
        let back: Record = serde_json::from_str(&text).unwrap();
        assert_eq!(back, r);
    }

    #[test]
    fn the_table_has_a_section_per_record_with_its_provenance() {
        let md = render(&[
            record("w1", vec![("library, 1 thread", 4_560_000.0, "steps/s")]),
            record("w2", vec![("EKF | batched", 2.4449, "x")]),
        ]);
        assert!(md.contains("\n## w1: a title\n"), "{md}");
        assert!(md.contains("\n## w2: a title\n"), "{md}");
        assert!(md.contains("`cargo xtask bench w1 --runs 16` at commit `0123456789ab`"));
        assert!(md.contains("Some CPU (2 cores, linux x86_64), instruction set avx2."));
        assert!(
            md.contains("| library, 1 thread | 4.560e6 | steps/s |"),
            "{md}"
        );
        assert!(md.contains("| EKF \\| batched | 2.445 | x |"), "{md}");
        assert!(!md.contains("No figures are committed yet"));
    }

    #[test]
    fn an_empty_folder_says_how_figures_are_produced() {
        let md = render(&[]);
        assert!(md.contains("No figures are committed yet"));
        assert!(md.contains("cargo xtask bench WORKLOAD"));
    }

    #[test]
    fn significant_digits() {
        assert_eq!(significant(0.0), "0");
        assert_eq!(significant(2.44491), "2.445");
        assert_eq!(significant(0.0531), "0.05310");
        assert_eq!(significant(33_940_000.0), "3.394e7");
        assert_eq!(significant(123_456.7), "123457");
        assert_eq!(significant(-1.5), "-1.500");
    }

    #[test]
    fn dates_are_utc_civil_dates() {
        assert_eq!(utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc(1_795_813_200), "2026-11-27T21:00:00Z");
    }

    #[test]
    fn write_adds_a_file_and_regenerates_the_table_from_all() {
        let dir = std::env::temp_dir().join(format!("xtask-figures-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        write(&dir, &record("w2", vec![("b", 2.0, "s")])).unwrap();
        write(&dir, &record("w1", vec![("a", 1.0, "s")])).unwrap();
        let all = read_all(&dir).unwrap();
        assert_eq!(
            all.iter().map(|r| r.workload.as_str()).collect::<Vec<_>>(),
            ["w1", "w2"]
        );
        let table = fs::read_to_string(dir.join(TABLE)).unwrap();
        assert_eq!(table, render(&all));
        fs::remove_dir_all(&dir).unwrap();
    }

    /// The committed table is the one the committed JSON files generate, so the two cannot
    /// drift apart.
    #[test]
    fn committed_table_matches_committed_figures() {
        let dir = crate::workspace_root().join("docs").join("benchmarks");
        let committed = fs::read_to_string(dir.join(TABLE)).unwrap();
        assert_eq!(committed, render(&read_all(&dir).unwrap()));
    }
}
