//! A study run as three shards in three separate processes (as three
//! machines would), merged by a fourth, writes the files of the one-process run byte for byte.

use std::path::{Path, PathBuf};
use std::process::Command;

fn xtask(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .expect("run the xtask binary");
    assert!(
        out.status.success(),
        "xtask {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Every file under `dir` but the shard files, relative path to bytes.
fn files(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if !path
                .file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("shard-")
            {
                let rel = path.strip_prefix(dir).unwrap().display().to_string();
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    out
}

#[test]
fn three_shard_processes_merge_into_the_one_process_files_byte_for_byte() {
    let base: PathBuf = std::env::temp_dir().join(format!("kalibra-shards-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let path = |p: &str| base.join(p).display().to_string();
    // Each shard on its own thread count and in its own directory, as on separate machines.
    for (i, threads) in [(0, "1"), (1, "2"), (2, "1")] {
        let log = xtask(&[
            "reproduce",
            "w1",
            "--quick",
            "--threads",
            threads,
            "--shard",
            &format!("{i}/3"),
            "--out",
            &path(&format!("machine{i}")),
        ]);
        assert!(log.contains(&format!("shard {i}/3 done")), "{log}");
    }
    xtask(&[
        "merge",
        &path("machine0"),
        &path("machine1"),
        &path("machine2"),
        "--out",
        &path("merged"),
    ]);
    xtask(&["reproduce", "w1", "--quick", "--out", &path("whole")]);
    let merged = files(&base.join("merged"));
    let whole = files(&base.join("whole"));
    assert!(merged.contains_key("w1/results.json") && merged.contains_key("index.md"));
    assert_eq!(
        merged.keys().collect::<Vec<_>>(),
        whole.keys().collect::<Vec<_>>()
    );
    for (file, bytes) in &whole {
        assert!(
            &merged[file] == bytes,
            "{file} differs from the one-process run"
        );
    }

    // A missing shard is refused by name, and nothing is written.
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args([
            "merge",
            &path("machine0"),
            &path("machine2"),
            "--out",
            &path("gap"),
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("missing shard(s) [1] of 3"), "{err}");
    assert!(!base.join("gap/w1/results.json").exists());

    // A shard of another seed is refused.
    xtask(&[
        "reproduce",
        "w1",
        "--quick",
        "--seed",
        "9",
        "--shard",
        "1/3",
        "--out",
        &path("other"),
    ]);
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args([
            "merge",
            &path("machine0"),
            &path("other"),
            &path("machine2"),
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("shards of different runs"), "{err}");

    // A study without shards says so before running anything.
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["reproduce", "004", "--shard", "0/2", "--out", &path("none")])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("does not run as shards; the studies that do: w1"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&base);
}
