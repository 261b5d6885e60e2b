//! `cargo xtask reproduce`: the registry loop. Each study computes and renders in
//! `kalibra-studies`; this module picks the studies, writes their files and the index.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use kalibra_sim::Shard;
use kalibra_studies::REGISTRY;
use kalibra_studies::claims::{Claim, Verdict};
use kalibra_studies::study::{Options, Outcome, Reproduce, Size};

use kalibra_plot::ToSvg;

/// `cargo xtask reproduce` arguments.
#[derive(Debug, clap::Args)]
#[command(after_help = studies_help())]
pub struct Args {
    /// Studies to run, by identifier (default: all of them, in registry order).
    #[arg(value_name = "STUDY", value_parser = known_study)]
    studies: Vec<String>,
    /// Run the reduced sizes the tests use instead of the published ones.
    #[arg(long)]
    quick: bool,
    /// Output directory (default: target/reproduce in the workspace).
    #[arg(long, value_name = "DIR", value_parser = non_empty_dir)]
    out: Option<PathBuf>,
    /// Seed for every study, replacing each study's own.
    // Negative numbers are taken as values, so that their error names the option
    // (`xtask/tests/cli.rs`).
    #[arg(long, allow_negative_numbers = true)]
    seed: Option<u64>,
    /// Worker threads (0: every core); the results do not depend on it.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    threads: usize,
    /// Run only shard I of S of each named study's Monte Carlo (0 <= I < S) and write its
    /// partial result to `DIR/<study>/shard-I-of-S.cbor`; `cargo xtask merge` turns the S
    /// partials into the report the unsharded run writes, to the bit.
    #[arg(long, value_name = "I/S", value_parser = parse_shard, requires = "studies")]
    shard: Option<Shard>,
}

/// `cargo xtask merge` arguments.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// Directories holding shard files (`<study>/shard-I-of-S.cbor`, as `reproduce --shard`
    /// writes them), for instance one per machine; every shard of a study must be present.
    #[arg(value_name = "DIR", required = true, value_parser = non_empty_dir)]
    dirs: Vec<PathBuf>,
    /// Output directory for the merged reports (default: the first DIR).
    #[arg(long, value_name = "DIR", value_parser = non_empty_dir)]
    out: Option<PathBuf>,
    /// The thread count the reports record (the unsharded run's, 0 by default); results do
    /// not depend on it.
    #[arg(long, default_value_t = 0)]
    threads: usize,
}

/// The version of the shard file around a study's partial result.
const SHARD_FILE_VERSION: u64 = 1;

fn parse_shard(text: &str) -> Result<Shard, String> {
    text.parse::<Shard>().map_err(|e| e.to_string())
}

/// The list of studies shown by `--help`.
fn studies_help() -> String {
    let mut text = String::from("Studies:\n");
    for study in REGISTRY {
        text.push_str(&format!("  {:<5} {}\n", study.id(), study.title()));
    }
    text
}

/// A directory path that is not empty: `--out ''` would write into the current directory.
fn non_empty_dir(s: &str) -> Result<PathBuf, String> {
    if s.trim().is_empty() {
        Err("empty; name the directory the reports are written to".to_string())
    } else {
        Ok(PathBuf::from(s))
    }
}

/// Accepts a registered study identifier; the error lists the known ones.
fn known_study(id: &str) -> Result<String, String> {
    kalibra_studies::find(id)
        .map(|s| s.id().to_string())
        .map_err(|e| e.to_string())
}

pub(crate) fn git_revision() -> String {
    std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .current_dir(crate::workspace_root())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}

/// Checks that `out` can be created and written, before any work starts.
fn check_out(out: &Path, option: &str) -> Result<()> {
    if out.as_os_str().is_empty() {
        anyhow::bail!("{option} is empty: give a directory");
    }
    std::fs::create_dir_all(out)
        .and_then(|()| {
            let probe = out.join(format!(".write-check-{}", std::process::id()));
            std::fs::write(&probe, b"")?;
            std::fs::remove_file(probe)
        })
        .with_context(|| format!("{option} {}: cannot write there", out.display()))
}

/// Writes one study's `results.json` (with the provenance every study records), `report.md`
/// and its figures under `out/<id>`.
fn write_study(
    out: &Path,
    study: &dyn Reproduce,
    provenance: serde_json::Value,
    outcome: &Outcome,
) -> Result<()> {
    let dir = out.join(study.id());
    std::fs::create_dir_all(&dir).with_context(|| format!("create {}", dir.display()))?;
    let mut json = provenance;
    json["results"] = outcome.results.clone();
    std::fs::write(
        dir.join("results.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    std::fs::write(dir.join("report.md"), &outcome.markdown)?;
    for figure in &outcome.figures {
        std::fs::write(dir.join(&figure.file), figure.figure.to_svg())?;
    }
    Ok(())
}

pub fn main(args: &Args) -> Result<()> {
    let revision = git_revision();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| crate::workspace_root().join("target/reproduce"));
    let options = Options {
        size: if args.quick { Size::Quick } else { Size::Paper },
        seed: args.seed,
        threads: args.threads,
        simd: crate::simd_from_env()?,
    };
    // The output directory first: a bad --out fails before minutes of studies, not after.
    check_out(&out, "--out")?;
    if let Some(shard) = args.shard {
        return run_shards(args, &options, shard, &out, &revision);
    }
    let mut rows = Vec::new();
    let mut claims: Vec<(&dyn Reproduce, Vec<Claim>)> = Vec::new();
    let total = Instant::now();
    let wanted = |id: &str| args.studies.is_empty() || args.studies.iter().any(|s| s == id);
    for &study in REGISTRY.iter().filter(|s| wanted(s.id())) {
        let id = study.id();
        eprintln!("{id}: {} ...", study.describe(&options));
        let start = Instant::now();
        let outcome = with_progress(id, || study.reproduce(&options))
            .with_context(|| format!("study {id}"))?;
        eprintln!("{id}: done in {:.2} s", start.elapsed().as_secs_f64());
        record(
            &out,
            study,
            &options,
            &revision,
            outcome,
            &mut rows,
            &mut claims,
        )?;
    }

    let index = index_markdown(
        &revision,
        options.size.label(),
        args.seed,
        args.threads,
        &rows,
        &claims,
    );
    std::fs::create_dir_all(&out)?;
    std::fs::write(out.join("index.md"), &index)?;
    println!("{index}");
    println!(
        "wrote {} in {:.2} s",
        out.join("index.md").display(),
        total.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Writes one study's files and adds its row and claims to the index's.
fn record<'a>(
    out: &Path,
    study: &'a dyn Reproduce,
    options: &Options,
    revision: &str,
    outcome: Outcome,
    rows: &mut Vec<String>,
    claims: &mut Vec<(&'a dyn Reproduce, Vec<Claim>)>,
) -> Result<()> {
    let id = study.id();
    let provenance = serde_json::json!({
        "study": id,
        "git_revision": revision,
        "size": options.size.label(),
        "seed": outcome.seed,
        "threads": options.threads,
        "parameters": outcome.config,
    });
    write_study(out, study, provenance, &outcome)?;
    rows.push(format!(
        "| {} | {} | [{id}/report.md]({id}/report.md) |",
        study.title(),
        outcome.highlight
    ));
    if study.paper().is_some() {
        claims.push((study, outcome.claims));
    }
    Ok(())
}

/// `reproduce --shard I/S`: each named study's shard, written as a partial result.
fn run_shards(
    args: &Args,
    options: &Options,
    shard: Shard,
    out: &Path,
    revision: &str,
) -> Result<()> {
    let studies: Vec<&dyn Reproduce> = args
        .studies
        .iter()
        .filter_map(|id| REGISTRY.iter().copied().find(|s| s.id() == id))
        .collect();
    // Every study is checked before any runs: a typo in the list fails at once.
    if let Some(study) = studies.iter().find(|s| !s.sharded()) {
        let sharded: Vec<&str> = REGISTRY
            .iter()
            .filter(|s| s.sharded())
            .map(|s| s.id())
            .collect();
        anyhow::bail!(
            "--shard: study {} does not run as shards; the studies that do: {}",
            study.id(),
            sharded.join(", ")
        );
    }
    for study in studies {
        let id = study.id();
        eprintln!("{id}: shard {shard} of {} ...", study.describe(options));
        let start = Instant::now();
        let partial = with_progress(id, || study.reproduce_shard(options, shard))
            .with_context(|| format!("study {id}, shard {shard}"))?;
        let file = ShardFile {
            kalibra_shard: SHARD_FILE_VERSION,
            study: id.to_string(),
            git_revision: revision.to_string(),
            size: options.size.label().to_string(),
            seed: options.seed,
            partial: ciborium::Value::Bytes(partial),
        };
        let dir = out.join(id);
        std::fs::create_dir_all(&dir).with_context(|| format!("create {}", dir.display()))?;
        let path = dir.join(format!("shard-{}-of-{}.cbor", shard.index(), shard.count()));
        let mut bytes = Vec::new();
        ciborium::into_writer(&file, &mut bytes)?;
        std::fs::write(&path, bytes).with_context(|| format!("write {}", path.display()))?;
        eprintln!(
            "{id}: shard {shard} done in {:.2} s, wrote {}",
            start.elapsed().as_secs_f64(),
            path.display()
        );
    }
    Ok(())
}

/// A shard file (CBOR, RFC 8949): which study, size and seed it belongs to, where it was
/// built, and the study's partial result (`Study::run_shard`'s bytes).
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ShardFile {
    kalibra_shard: u64,
    study: String,
    git_revision: String,
    size: String,
    seed: Option<u64>,
    partial: ciborium::Value,
}

/// A shard file read back, with its path for messages and its partial result's bytes.
struct ReadShard {
    path: PathBuf,
    study: String,
    size: String,
    seed: Option<u64>,
    partial: Vec<u8>,
}

fn read_shard_file(path: &Path) -> Result<ReadShard> {
    let bytes = std::fs::read(path).with_context(|| format!("read {}", path.display()))?;
    let file: ShardFile = ciborium::from_reader(bytes.as_slice())
        .with_context(|| format!("{}: not a kalibra shard file", path.display()))?;
    if file.kalibra_shard != SHARD_FILE_VERSION {
        anyhow::bail!(
            "{}: a shard file of version {}; this xtask reads version {SHARD_FILE_VERSION}",
            path.display(),
            file.kalibra_shard
        );
    }
    let ciborium::Value::Bytes(partial) = file.partial else {
        anyhow::bail!(
            "{}: its partial result is not a byte string",
            path.display()
        );
    };
    Ok(ReadShard {
        path: path.to_path_buf(),
        study: file.study,
        size: file.size,
        seed: file.seed,
        partial,
    })
}

/// `cargo xtask merge DIR...`: every study's shard files merged into the reports and index
/// that the unsharded `reproduce` writes.
pub fn merge(args: &MergeArgs) -> Result<()> {
    let out = args.out.clone().unwrap_or_else(|| args.dirs[0].clone());
    check_out(&out, "--out")?;
    let total = Instant::now();
    // Shard files by study, in registry order.
    let mut files: std::collections::BTreeMap<String, Vec<ReadShard>> = Default::default();
    for dir in &args.dirs {
        let entries = std::fs::read_dir(dir).with_context(|| format!("read {}", dir.display()))?;
        for study_dir in entries {
            let study_dir = study_dir?.path();
            if !study_dir.is_dir() {
                continue;
            }
            for entry in std::fs::read_dir(&study_dir)? {
                let path = entry?.path();
                let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
                if name.starts_with("shard-") && name.ends_with(".cbor") {
                    let file = read_shard_file(&path)?;
                    files.entry(file.study.clone()).or_default().push(file);
                }
            }
        }
    }
    if files.is_empty() {
        anyhow::bail!(
            "no shard files (<study>/shard-I-of-S.cbor) under {}",
            args.dirs
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let revision = git_revision();
    let (mut rows, mut claims) = (Vec::new(), Vec::new());
    let mut seeds = std::collections::BTreeSet::new();
    let mut sizes = std::collections::BTreeSet::new();
    for study in REGISTRY.iter().copied() {
        let Some(parts) = files.remove(study.id()) else {
            continue;
        };
        let first = &parts[0];
        if let Some(other) = parts
            .iter()
            .find(|p| (&p.size, p.seed) != (&first.size, first.seed))
        {
            anyhow::bail!(
                "{} and {} are shards of different runs (size {} seed {:?} vs size {} seed {:?})",
                first.path.display(),
                other.path.display(),
                first.size,
                first.seed,
                other.size,
                other.seed
            );
        }
        let size = match first.size.as_str() {
            "full" => Size::Paper,
            "quick" => Size::Quick,
            other => anyhow::bail!("{}: unknown size {other:?}", first.path.display()),
        };
        let options = Options {
            size,
            seed: first.seed,
            threads: args.threads,
            // The merge runs nothing batched; the shards' arithmetic is in their identity.
            simd: None,
        };
        seeds.insert(first.seed);
        sizes.insert(size.label());
        let id = study.id();
        let start = Instant::now();
        let outcome = study
            .reproduce_merged(&options, parts.into_iter().map(|p| p.partial).collect())
            .with_context(|| format!("merge the shards of study {id}"))?;
        eprintln!("{id}: merged in {:.3} s", start.elapsed().as_secs_f64());
        record(
            &out,
            study,
            &options,
            &revision,
            outcome,
            &mut rows,
            &mut claims,
        )?;
    }
    if let Some(unknown) = files.keys().next() {
        anyhow::bail!("shard files of an unknown study {unknown:?}");
    }
    // The index records one size and seed, as an unsharded run does.
    let (Some(size), Some(seed), true) = (
        sizes.first(),
        seeds.first(),
        sizes.len() == 1 && seeds.len() == 1,
    ) else {
        anyhow::bail!(
            "the shard files mix sizes {sizes:?} or seeds {seeds:?}: merge them separately"
        );
    };
    let index = index_markdown(&revision, size, *seed, args.threads, &rows, &claims);
    std::fs::write(out.join("index.md"), &index)?;
    println!(
        "wrote {} in {:.2} s",
        out.join("index.md").display(),
        total.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `index.md`: the per-paper verdict counts, the per-study highlights, then every published
/// claim with its verdict and a link to the section of the paper's report that explains it.
fn index_markdown(
    revision: &str,
    size: &str,
    seed: Option<u64>,
    threads: usize,
    highlights: &[String],
    claims: &[(&dyn Reproduce, Vec<Claim>)],
) -> String {
    let count = |c: &[Claim], v: Verdict| c.iter().filter(|c| c.verdict == v).count();
    let mut summary = String::from(
        "| paper | claims | reproduced | not reproduced | not testable | report |\n|---|---|---|---|---|---|\n",
    );
    let mut table = String::from(
        "| paper | claim | published | ours | tolerance | verdict |\n|---|---|---|---|---|---|\n",
    );
    for (study, list) in claims {
        let paper = study.id();
        summary.push_str(&format!(
            "| {paper}: {} | {} | {} | {} | {} | [{paper}/report.md]({paper}/report.md) |\n",
            study.title(),
            list.len(),
            count(list, Verdict::Reproduced),
            count(list, Verdict::NotReproduced),
            count(list, Verdict::NotTestable),
        ));
        for c in list {
            table.push_str(&format!(
                "| {paper} | {} | {} | {} | {} | {} ([why]({paper}/report.md#{})) |\n",
                c.claim.replace('|', "\\|"),
                c.published.replace('|', "\\|"),
                c.ours.replace('|', "\\|"),
                c.tolerance.replace('|', "\\|"),
                c.verdict.label(),
                c.section
            ));
        }
    }
    format!(
        "# kalibra reproduction report\n\nRevision `{revision}`, {size} size, seed {}, threads {}.\n\n\
         ## Summary\n\n{summary}\n\
         A claim is reproduced when ours is within the stated tolerance of the published value \
         (or the claimed property holds), not reproduced otherwise, and not testable when the \
         paper gives too little or the seed-to-seed spread exceeds the tolerance. Each paper's \
         report explains every gap.\n\n\
         ## Studies\n\n| study | summary | report |\n|---|---|---|\n{}\n\n\
         ## Every published claim\n\n{table}",
        seed.map_or("default per study".to_string(), |s| s.to_string()),
        threads,
        highlights.join("\n"),
    )
}

/// Runs a stage, printing its elapsed time every 5 s while it runs (stderr), so a long stage
/// shows it is alive.
fn with_progress<T>(stage: &str, work: impl FnOnce() -> T) -> T {
    let (done, wait) = std::sync::mpsc::channel::<()>();
    let start = Instant::now();
    let stage_name = stage.to_string();
    let ticker = std::thread::spawn(move || {
        while wait
            .recv_timeout(std::time::Duration::from_secs(5))
            .is_err_and(|e| e == std::sync::mpsc::RecvTimeoutError::Timeout)
        {
            eprintln!(
                "{stage_name}: running, {:.0} s",
                start.elapsed().as_secs_f64()
            );
        }
    });
    let out = work();
    let _ = done.send(());
    let _ = ticker.join();
    out
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// Drops what legitimately differs between two runs: the recorded thread count, and the
    /// wall times of paper 001's Table II (with the claim and the report section built on
    /// them).
    fn strip(value: &mut serde_json::Value) {
        match value {
            serde_json::Value::Object(map) => {
                for key in ["threads", "cost_relative_to_srf", "cost_ns_per_step"] {
                    map.remove(key);
                }
                map.values_mut().for_each(strip);
            }
            serde_json::Value::Array(items) => {
                items.retain(|v| v["id"] != "table2_ordering");
                items.iter_mut().for_each(strip);
            }
            _ => {}
        }
    }

    fn text_without_timing(text: &str) -> String {
        let body = text.split("## Table II").next().unwrap_or(text);
        // Paper 001's summary row counts the timed Table II claim, whose verdict can flip when
        // other tests load the machine (it did in a CI run: 17 reproduced instead of 18).
        body.lines()
            .filter(|l| {
                !l.contains("threads") && !l.contains("Table II") && !l.starts_with("| 001: ")
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// Every file of `dir`, relative path to contents, normalised for comparison.
    fn outputs(dir: &Path) -> std::collections::BTreeMap<String, String> {
        let mut out = std::collections::BTreeMap::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                    continue;
                }
                let text = std::fs::read_to_string(&path).unwrap();
                let norm = if path.extension().is_some_and(|e| e == "json") {
                    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
                    strip(&mut v);
                    v.to_string()
                } else if path.extension().is_some_and(|e| e == "md") {
                    text_without_timing(&text)
                } else {
                    text
                };
                let rel = path.strip_prefix(dir).unwrap().display().to_string();
                out.insert(rel, norm);
            }
        }
        out
    }

    /// `cargo xtask reproduce --quick` writes the same reports, results and figures with 1
    /// and 2 threads (apart from the recorded thread count and the timed Table II).
    #[test]
    fn quick_reproduction_is_the_same_for_1_and_2_threads() {
        let base = std::env::temp_dir().join(format!("kalibra-reproduce-{}", std::process::id()));
        let run = |threads: &str| {
            let out = base.join(threads);
            let args = super::Args {
                studies: Vec::new(),
                quick: true,
                out: Some(out.clone()),
                seed: None,
                threads: threads.parse().unwrap(),
                shard: None,
            };
            super::main(&args).unwrap();
            outputs(&out)
        };
        let one = run("1");
        let two = run("2");
        let _ = std::fs::remove_dir_all(&base);
        assert!(one.len() > 40, "only {} files", one.len());
        assert_eq!(
            one.keys().collect::<Vec<_>>(),
            two.keys().collect::<Vec<_>>()
        );
        for (file, text) in &one {
            assert!(text == &two[file], "{file} differs between 1 and 2 threads");
        }
    }
}
