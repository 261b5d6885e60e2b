//! The command line's options: every option is named in its parse error,
//! an empty `--out` (or an empty file argument) is a usage error before any work starts, a
//! `--group` the log's state cannot hold names the option, and every command and subcommand
//! answers `--help`.

use crate::common::{fixture, kalibra, scratch, text};

/// Runs `kalibra` in `dir` (so that anything written to the current directory shows there).
fn kalibra_in(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_kalibra"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

#[test]
fn every_option_is_named_in_its_parse_error() {
    let log = fixture("kf.json");
    let log = log.to_str().unwrap();
    let model = fixture("tune_model.toml");
    let model = model.to_str().unwrap();
    let z = fixture("tune_measurements.csv");
    let z = z.to_str().unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["eval", log, "--confidence", "2"], "--confidence"),
        (vec!["eval", log, "--confidence", "most"], "--confidence"),
        (vec!["eval", log, "--window", "1"], "--window"),
        (vec!["eval", log, "--window", "wide"], "--window"),
        (vec!["eval", log, "--lags", "0"], "--lags"),
        (vec!["eval", log, "--lags", "-3"], "--lags"),
        (vec!["eval", log, "--window", "-2"], "--window"),
        (vec!["eval", log, "--confidence", "-0.5"], "--confidence"),
        (vec!["eval", log, "--group", "position"], "--group"),
        (vec!["eval", log, "--group", "=0,1"], "--group"),
        (vec!["eval", log, "--group", "p=0,x"], "--group"),
        (vec!["eval", log, "--out", ""], "--out"),
        (vec!["eval", ""], "<LOG>"),
        (vec!["eval", log, "--colour"], "--colour"),
        (vec!["tune", model, z, "--p", "1:2"], "--p"),
        (vec!["tune", model, z, "--p", "3:1:1"], "--p"),
        (vec!["tune", model, z, "--p", "0:1:0"], "--p"),
        (vec!["tune", model, z, "--threads", "many"], "--threads"),
        (vec!["tune", model, z, "--threads", "-1"], "--threads"),
        (vec!["tune", model, z, "--out", " "], "--out"),
        (vec!["tune", model, z, "--truth", ""], "--truth"),
        (vec!["tune", "", z], "<MODEL>"),
        (vec!["tune", model, ""], "<MEASUREMENTS>"),
    ];
    for (args, option) in cases {
        let run = kalibra(&args);
        let err = text(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains(option),
            "{args:?}: the error does not name {option}: {err}"
        );
    }
}

/// A group naming a component beyond the log's state is the option's fault: the message
/// names `--group` (before, it blamed the log).
#[test]
fn a_group_beyond_the_state_names_the_option() {
    let dir = scratch("group-beyond");
    for name in ["kf.json", "kf.csv", "kf.npz"] {
        let log = fixture(name);
        let out = dir.join(name);
        let run = kalibra(&[
            "eval",
            log.to_str().unwrap(),
            "--group",
            "far=0,7",
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = text(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains("--group far: component 7"), "{name}: {err}");
        assert!(!out.exists(), "{name}");
    }
}

/// `--out ''` was read as the current directory: now it is refused before the log is read,
/// and nothing is written where the command ran.
#[test]
fn an_empty_out_is_refused_before_any_work() {
    let dir = scratch("empty-out");
    let log = fixture("kf.json");
    let model = fixture("tune_model.toml");
    let z = fixture("tune_measurements.csv");
    for args in [
        vec!["eval", log.to_str().unwrap(), "--out", ""],
        vec!["eval", log.to_str().unwrap(), "-o", ""],
        vec![
            "tune",
            model.to_str().unwrap(),
            z.to_str().unwrap(),
            "--out",
            "",
        ],
    ] {
        let run = kalibra_in(&dir, &args);
        let err = text(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("--out"), "{args:?}: {err}");
        assert!(
            std::fs::read_dir(&dir).unwrap().next().is_none(),
            "{args:?} wrote into the cwd"
        );
    }
}

/// The library's own check, for callers other than the command line (the Python package's
/// `save`): an empty path is an error, not the current directory.
#[test]
fn the_report_target_refuses_an_empty_path() {
    let Err(error) = kalibra_io::output::Target::prepare(std::path::Path::new("")) else {
        panic!("an empty path was accepted");
    };
    assert!(matches!(error, kalibra_io::Error::EmptyOutput), "{error}");
    assert!(error.to_string().contains("empty path"), "{error}");
}

#[test]
fn every_command_answers_help() {
    for args in [
        vec!["--help"],
        vec!["-h"],
        vec!["help"],
        vec!["eval", "--help"],
        vec!["eval", "-h"],
        vec!["help", "eval"],
        vec!["tune", "--help"],
        vec!["tune", "-h"],
        vec!["help", "tune"],
    ] {
        let run = kalibra(&args);
        let out = text(&run.stdout);
        assert_eq!(
            run.status.code(),
            Some(0),
            "{args:?}: {}",
            text(&run.stderr)
        );
        assert!(out.contains("Usage: kalibra"), "{args:?}: {out}");
    }
    let version = kalibra(&["--version"]);
    assert_eq!(version.status.code(), Some(0));
    assert!(text(&version.stdout).starts_with("kalibra "));
}
