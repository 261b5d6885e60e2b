//! The architecture invariants of docs/ARCHITECTURE.md, checked on the source tree.

use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The kalibra crates a library crate depends on (normal dependencies only).
fn kalibra_deps(krate: &str) -> Vec<String> {
    let manifest =
        fs::read_to_string(root().join("crates").join(krate).join("Cargo.toml")).unwrap();
    let deps = manifest.split("[dependencies]").nth(1).unwrap_or("");
    let deps = deps.split("\n[").next().unwrap_or("");
    deps.lines()
        .filter_map(|l| l.split(['.', ' ', '=']).next())
        .filter(|n| n.starts_with("kalibra-"))
        .map(String::from)
        .collect()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Architecture invariant: each crate depends only on the crates the design allows; in
/// particular metrics never depend on filters, and nothing depends on the papers.
#[test]
fn crate_dependencies_follow_the_design() {
    let allowed: &[(&str, &[&str])] = &[
        ("kalibra-linalg", &[]),
        ("kalibra-models", &["kalibra-linalg"]),
        ("kalibra-filters", &["kalibra-linalg", "kalibra-models"]),
        ("kalibra-metrics", &["kalibra-linalg"]),
        ("kalibra-bounds", &["kalibra-linalg"]),
        (
            "kalibra-sim",
            &[
                "kalibra-linalg",
                "kalibra-models",
                "kalibra-filters",
                "kalibra-metrics",
            ],
        ),
        (
            "kalibra-studies",
            &[
                "kalibra-linalg",
                "kalibra-models",
                "kalibra-filters",
                "kalibra-metrics",
                "kalibra-bounds",
                "kalibra-sim",
            ],
        ),
    ];
    let present: Vec<String> = fs::read_dir(root().join("crates"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    for krate in &present {
        let rule = allowed.iter().find(|(name, _)| name == krate);
        let Some((_, ok)) = rule else {
            panic!("crate {krate} is not in the design's table")
        };
        for dep in kalibra_deps(krate) {
            assert!(
                ok.contains(&dep.as_str()),
                "{krate} must not depend on {dep}"
            );
        }
    }
}

/// Architecture invariant: library crates do no I/O, read no environment and use no global
/// random generator (printing is caught by clippy's print lints).
#[test]
fn library_crates_do_no_io() {
    let mut files = Vec::new();
    rust_files(&root().join("crates"), &mut files);
    let banned = [
        "std::fs",
        "std::io::stdout",
        "std::env",
        "File::",
        "thread_rng",
        "rand::rng()",
        "OsRng",
    ];
    for file in files {
        if file.components().any(|c| c.as_os_str() == "tests") {
            continue;
        }
        let text = fs::read_to_string(&file).unwrap();
        for word in banned {
            assert!(!text.contains(word), "{} uses {word}", file.display());
        }
    }
}

/// Architecture invariant: the copy of the design kept in docs/ lists every crate present.
#[test]
fn architecture_doc_names_every_crate() {
    let doc = fs::read_to_string(root().join("docs/ARCHITECTURE.md")).unwrap();
    for entry in fs::read_dir(root().join("crates")).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        assert!(
            doc.contains(&format!("`{name}`")),
            "docs/ARCHITECTURE.md does not describe {name}"
        );
    }
}
