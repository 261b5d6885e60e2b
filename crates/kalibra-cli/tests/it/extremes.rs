//! Extreme but finite inputs through the command line: each comes back promptly as an answer
//! or as the library's typed error in one clear message with exit code 1 (no panic, no hang).

use crate::common;
use std::time::{Duration, Instant};

use crate::common::{kalibra, scratch, text};

/// Runs `kalibra eval` on `csv` with `extra` options; returns the exit code and stderr, and
/// checks it ended within 30 s (a debug build on a loaded machine).
fn eval(test: &str, csv: &str, extra: &[&str]) -> (Option<i32>, String) {
    let dir = scratch(test);
    let log = dir.join("log.csv");
    std::fs::write(&log, csv).unwrap();
    let out = dir.join("report");
    let mut args = vec![
        "eval",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let start = Instant::now();
    let run = kalibra(&args);
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "took {:?}",
        start.elapsed()
    );
    (run.status.code(), text(&run.stderr))
}

/// A truth and an estimate of opposite signs near `f64::MAX` (each finite, their difference
/// not), and the largest counts the options take: typed errors, said plainly.
#[test]
fn extreme_values_and_counts_give_clear_errors() {
    let csv = "run,step,truth_0,estimate_0,covariance_0_0\n\
               0,0,1e308,-1.5e308,1\n\
               0,1,0,0.5,1\n\
               0,2,0,-0.5,1\n";
    let (code, err) = eval("opposite-signs", csv, &[]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("estimation error") && err.contains("beyond f64's range"),
        "{err}"
    );
    assert!(err.contains("run 0, step 0"), "{err}");
    assert!(!err.contains("panicked"), "{err}");

    // The same log within range, with the largest counts the options take: a window and
    // lags beyond the series are an answer (the report leaves them out), at once; a group
    // naming component `usize::MAX` is the library's typed refusal.
    let csv = csv.replace("1e308,-1.5e308", "0,0.1");
    let max = u64::MAX.to_string();
    for option in ["--window", "--lags"] {
        let (code, err) = eval("huge-counts", &csv, &[option, &max]);
        assert_eq!(code, Some(0), "{option}: {err}");
    }
    let group = format!("pos=0,{max}");
    let (code, err) = eval("huge-group", &csv, &["--group", &group]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains(&format!("component {max} is not in the state")),
        "{err}"
    );
    assert!(
        !err.contains("panicked") && !err.contains("capacity"),
        "{err}"
    );
}

/// `kalibra tune` on measurements of opposite signs near `f64::MAX` (each finite, the filter's
/// innovation between them not) and with the largest thread count: the library's typed
/// errors in one clear message, at once.
#[test]
fn tune_extremes_give_clear_errors() {
    let dir = scratch("tune-extremes");
    let meas = dir.join("measurements.csv");
    std::fs::write(&meas, "step,z_0\n0,1e308\n1,-1.5e308\n2,0\n3,0.5\n").unwrap();
    let out = dir.join("report");
    let model = common::fixture("tune_model.toml");
    let max = u64::MAX.to_string();
    let cases: [(&[&str], &str); 2] = [
        // The filter's own error, with the exponent and the step (it was cut to
        // "filter at p = -6" before the sweep's errors carried their source).
        (&[], "filter at p = -6: innovation is not finite at step 2"),
        (&["--threads", max.as_str()], "more than MAX_THREADS (4096)"),
    ];
    for (extra, needle) in cases {
        let mut args = vec![
            "tune",
            model.to_str().unwrap(),
            meas.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let start = Instant::now();
        let run = kalibra(&args);
        assert!(start.elapsed() < Duration::from_secs(30), "{extra:?}");
        let err = text(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{extra:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(
            !err.contains("panicked") && !err.contains("capacity"),
            "{err}"
        );
        assert!(err.contains(needle), "`{needle}` not in: {err}");
        assert!(!out.exists(), "no report after a failed run");
    }
}
