//! `cargo xtask reproduce`.

use std::ffi::OsString;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use kalibra_papers::w1;

struct Args {
    quick: bool,
    out: PathBuf,
    seed: Option<u64>,
    threads: usize,
}

fn parse(args: Vec<OsString>) -> Result<Args> {
    use lexopt::prelude::*;
    let mut parsed = Args {
        quick: false,
        out: crate::workspace_root().join("target/reproduce"),
        seed: None,
        threads: 0,
    };
    let mut parser = lexopt::Parser::from_args(args);
    while let Some(arg) = parser.next()? {
        match arg {
            Long("quick") => parsed.quick = true,
            Long("out") => parsed.out = parser.value()?.into(),
            Long("seed") => parsed.seed = Some(parser.value()?.parse()?),
            Long("threads") => parsed.threads = parser.value()?.parse()?,
            Value(v) => bail!("unknown study {v:?}; available: w1"),
            _ => return Err(arg.unexpected().into()),
        }
    }
    Ok(parsed)
}

fn git_revision() -> String {
    std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .current_dir(crate::workspace_root())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}

pub fn main(args: Vec<OsString>) -> Result<()> {
    let args = parse(args)?;
    let revision = git_revision();
    let mut config = if args.quick {
        w1::Config::quick()
    } else {
        w1::Config::paper()
    };
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    config.threads = args.threads;

    eprintln!(
        "w1: consistency study, {} runs x {} steps ...",
        config.runs, config.steps
    );
    let start = Instant::now();
    let report = w1::run(&config)?;
    let elapsed = start.elapsed().as_secs_f64();
    eprintln!("w1: done in {elapsed:.2} s");

    let dir = args.out.join("w1");
    std::fs::create_dir_all(&dir).with_context(|| format!("create {}", dir.display()))?;
    let json = serde_json::json!({
        "study": "w1",
        "git_revision": revision,
        "seed": config.seed,
        "threads": config.threads,
        "parameters": config,
        "results": report,
    });
    std::fs::write(
        dir.join("results.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    std::fs::write(dir.join("report.md"), report.to_markdown())?;

    let index = format!(
        "# kalibra reproduction report\n\nRevision `{revision}`, seed {}, {} size.\n\n\
         | study | summary | report |\n|---|---|---|\n\
         | W1 consistency | ANEES {:.3} ({:.1}% of steps in 95% band), NIS/2 {:.3} ({:.1}% in band) | [w1/report.md](w1/report.md) |\n\n\
         The paper studies (000-004) join this table as their issues land.\n",
        config.seed,
        if args.quick { "quick" } else { "full" },
        report.anees_time_average,
        100.0 * report.anees_inside,
        report.anis_time_average,
        100.0 * report.anis_inside,
    );
    std::fs::write(args.out.join("index.md"), &index)?;
    println!("{}", report.to_markdown());
    println!("wrote {}", args.out.join("index.md").display());
    Ok(())
}
