//! Every dev-dependency of every manifest is used by the package's tests, examples, benches or
//! doc tests, so no manifest drags in a crate nothing uses. `cargo udeps` needs a nightly toolchain; this reads the
//! source instead: a dev-dependency `foo-bar` counts as used when some Rust file of the
//! package names the path `foo_bar::` (a `use`, a path or a macro's crate), not through a
//! re-export such as `kalibra::linalg::nalgebra::`.

use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The names in a manifest's `[dev-dependencies]` table.
fn dev_dependencies(manifest: &str) -> Vec<String> {
    let Some(table) = manifest.split("\n[dev-dependencies]").nth(1) else {
        return Vec::new();
    };
    let table = table.split("\n[").next().unwrap_or("");
    table
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split(['.', ' ', '=']).next())
        .map(String::from)
        .collect()
}

fn rust_sources(dir: &Path, out: &mut String) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push_str(&fs::read_to_string(&path).unwrap());
            out.push('\n');
        }
    }
}

/// Whether `source` names the crate `ident` as the first segment of a path.
fn names_crate(source: &str, ident: &str) -> bool {
    let needle = format!("{ident}::");
    source.match_indices(&needle).any(|(at, _)| {
        let before = source[..at].chars().next_back();
        !before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':')
    })
}

#[test]
fn names_crate_needs_a_first_path_segment() {
    assert!(names_crate("use rand::Rng;", "rand"));
    assert!(names_crate("proptest::prelude::*", "proptest"));
    assert!(!names_crate("use rand_chacha::ChaCha8Rng;", "rand"));
    assert!(!names_crate(
        "use kalibra::linalg::nalgebra::Matrix2;",
        "nalgebra"
    ));
    assert!(!names_crate("my_rand::x", "rand"));
}

#[test]
fn every_dev_dependency_is_used() {
    let mut packages = vec![(root(), vec!["src", "tests", "examples", "benches"])];
    for entry in fs::read_dir(root().join("crates")).unwrap() {
        packages.push((
            entry.unwrap().path(),
            vec!["src", "tests", "examples", "benches"],
        ));
    }
    packages.push((root().join("xtask"), vec!["src", "tests"]));
    let mut unused = Vec::new();
    for (dir, subdirs) in packages {
        let manifest = fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        let mut source = String::new();
        for sub in subdirs {
            rust_sources(&dir.join(sub), &mut source);
        }
        for dep in dev_dependencies(&manifest) {
            if !names_crate(&source, &dep.replace('-', "_")) {
                unused.push(format!("{}: {dep}", dir.display()));
            }
        }
    }
    assert!(unused.is_empty(), "unused dev-dependencies: {unused:#?}");
}
