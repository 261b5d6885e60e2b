//! `cargo xtask bench` writes its figures as data: a small W1 run with `--out DIR` leaves
//! `DIR/w1.json` (the provenance and every figure with its unit) and regenerates
//! `DIR/README.md` from the JSON files there, keeping the figures of other workloads.

use std::fs;
use std::process::Command;

#[test]
fn bench_writes_json_and_regenerates_the_table() {
    let dir = std::env::temp_dir().join(format!("xtask-bench-figures-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    // Another workload's figures, written earlier: the table must keep them.
    let other = r#"{"schema": 1, "workload": "w2", "title": "earlier", "command": "cargo xtask bench w2",
        "machine": {"cpu": "c", "cores": 1, "os": "linux x86_64"}, "isa": "scalar",
        "commit": "0", "date": "2026-01-01T00:00:00Z",
        "figures": [{"name": "EKF library, 1 thread", "value": 1.0, "unit": "steps/s"}]}"#;
    fs::write(dir.join("w2.json"), other).unwrap();

    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args([
            "bench",
            "w1",
            "--runs",
            "16",
            "--steps",
            "50",
            "--repeats",
            "1",
        ])
        .args(["--threads", "2", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let json: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(dir.join("w1.json")).unwrap()).unwrap();
    assert_eq!(json["schema"], 1);
    assert_eq!(json["workload"], "w1");
    for key in ["title", "command", "isa", "commit", "date"] {
        assert!(
            json[key].as_str().is_some_and(|s| !s.is_empty()),
            "{key}: {json}"
        );
    }
    assert!(json["machine"]["cpu"].is_string() && json["machine"]["cores"].is_u64());
    let figures = json["figures"].as_array().unwrap();
    let rate = figures
        .iter()
        .find(|f| f["name"] == "library, 1 thread")
        .expect("the scalar library's rate");
    assert_eq!(rate["unit"], "steps/s");
    assert!(rate["value"].as_f64().is_some_and(|v| v > 0.0));
    assert!(figures.iter().all(|f| f["unit"].is_string()));

    let table = fs::read_to_string(dir.join("README.md")).unwrap();
    assert!(table.contains("\n## w1: "), "{table}");
    assert!(table.contains("\n## w2: earlier"), "{table}");
    assert!(table.contains("| library, 1 thread |"), "{table}");
    fs::remove_dir_all(&dir).unwrap();
}
