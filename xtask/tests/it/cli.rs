//! `cargo xtask`'s command line: `--help` on every command and
//! subcommand (`bench` had none), every option named in its parse error, and an empty or
//! unwritable `reproduce --out` refused before any study runs. The binary is the one cargo
//! built for these tests; nothing here runs a study or a benchmark.

use std::process::{Command, Output};

fn xtask(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn every_command_answers_help() {
    for args in [
        vec!["--help"],
        vec!["help"],
        vec!["reproduce", "--help"],
        vec!["reproduce", "-h"],
        vec!["help", "reproduce"],
        vec!["bench", "--help"],
        vec!["bench", "-h"],
        vec!["bench", "eval", "--help"],
        vec!["bench", "w4", "--help"],
        vec!["help", "bench"],
        vec!["merge", "--help"],
        vec!["help", "merge"],
    ] {
        let run = xtask(&args);
        let out = text(&run.stdout);
        assert_eq!(
            run.status.code(),
            Some(0),
            "{args:?}: {}",
            text(&run.stderr)
        );
        assert!(out.contains("Usage: cargo xtask"), "{args:?}: {out}");
    }
    // The workloads and the studies are listed where they are chosen.
    assert!(text(&xtask(&["bench", "--help"]).stdout).contains("w4"));
    assert!(text(&xtask(&["reproduce", "--help"]).stdout).contains("Studies:"));
}

#[test]
fn every_option_is_named_in_its_parse_error() {
    for (args, option) in [
        (vec!["reproduce", "--seed", "x"], "--seed"),
        (vec!["reproduce", "--threads", "-1"], "--threads"),
        (vec!["reproduce", "--out", ""], "--out"),
        (vec!["reproduce", "no-such-study"], "[STUDY]"),
        (vec!["reproduce", "--fast"], "--fast"),
        (vec!["bench", "--runs", "0"], "--runs"),
        (vec!["bench", "--steps", "many"], "--steps"),
        (vec!["bench", "--repeats", "0"], "--repeats"),
        (vec!["bench", "--threads", "x"], "--threads"),
        (vec!["bench", "--seed", "-3"], "--seed"),
        (vec!["bench", "--sizes", "8,x"], "--sizes"),
        (vec!["bench", "w9"], "[WORKLOADS]"),
        (vec!["bench", "shards", "--shard-runs", "0"], "--shard-runs"),
        (vec!["reproduce", "w1", "--shard", "3/3"], "--shard"),
        (vec!["reproduce", "--shard", "0/2"], "--shard"),
        (vec!["merge"], "<DIR>"),
        (vec!["merge", ""], "<DIR>"),
        (vec!["merge", "d", "--out", ""], "--out"),
    ] {
        let run = xtask(&args);
        let err = text(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains(option),
            "{args:?}: the error does not name {option}: {err}"
        );
    }
}

/// An `--out` under a plain file fails at once with a message about `--out`: no study starts
/// (each prints `ID: ...` to stderr as it begins), and nothing is created.
#[test]
fn an_unwritable_out_fails_before_any_study() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("xtask-unwritable-out");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let blocker = dir.join("plain-file");
    std::fs::write(&blocker, "not a directory").unwrap();
    let out = blocker.join("reports");
    let run = xtask(&["reproduce", "--quick", "--out", out.to_str().unwrap()]);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(
        err.contains("--out") && err.contains("cannot write there"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "a study started: {err}");
}
