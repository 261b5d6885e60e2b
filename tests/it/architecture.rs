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

/// Architecture invariant: each crate depends on exactly the crates the design's table lists
/// (nothing more, and no entry the manifest has dropped); in particular metrics never depend
/// on filters, and nothing depends on the papers.
#[test]
fn crate_dependencies_follow_the_design() {
    let allowed: &[(&str, &[&str])] = &[
        ("kalibra-linalg", &[]),
        ("kalibra-models", &["kalibra-linalg"]),
        ("kalibra-filters", &["kalibra-linalg", "kalibra-models"]),
        ("kalibra-metrics", &["kalibra-linalg"]),
        ("kalibra-bounds", &["kalibra-linalg"]),
        // Figures are data and their SVG writer: nothing of the filters or the studies.
        ("kalibra-plot", &[]),
        // The log evaluation takes data, like the metrics, and uses the metrics' statistics;
        // it runs no filter. Never the studies.
        ("kalibra-eval", &["kalibra-linalg", "kalibra-metrics"]),
        // Choosing Q and R from measurements runs the library's filters on the models, with
        // the metrics' J1/J2 and the simulation's thread pools, and judges the tuned filter's
        // run with the log evaluation (which never depends on it). Never the studies.
        (
            "kalibra-tune",
            &[
                "kalibra-linalg",
                "kalibra-models",
                "kalibra-filters",
                "kalibra-metrics",
                "kalibra-eval",
                "kalibra-sim",
            ],
        ),
        // Reading logs and tuning inputs into kalibra-eval's types, and writing the report
        // (kalibra-eval's reports as documents, with kalibra-plot's figures). The one library
        // that touches files.
        (
            "kalibra-io",
            &["kalibra-eval", "kalibra-plot", "kalibra-tune"],
        ),
        // The `kalibra` executable: parses arguments, reads and writes through kalibra-io,
        // evaluates and tunes with kalibra-eval.
        (
            "kalibra-cli",
            &["kalibra-io", "kalibra-eval", "kalibra-tune"],
        ),
        // The Python package: a front end like the executable, reading arrays with the NPZ
        // rules and writing reports through kalibra-io, evaluating with kalibra-eval, plus the
        // filters, models, simulation and metrics it exposes on arrays.
        (
            "kalibra-py",
            &[
                "kalibra-eval",
                "kalibra-io",
                "kalibra-linalg",
                "kalibra-models",
                "kalibra-filters",
                "kalibra-metrics",
                "kalibra-sim",
                "kalibra-tune",
            ],
        ),
        (
            "kalibra-sim",
            &["kalibra-linalg", "kalibra-models", "kalibra-metrics"],
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
                "kalibra-plot",
                "kalibra-tune",
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
        let deps = kalibra_deps(krate);
        for dep in &deps {
            assert!(
                ok.contains(&dep.as_str()),
                "{krate} must not depend on {dep}"
            );
        }
        for listed in *ok {
            assert!(
                deps.iter().any(|d| d == listed),
                "the table lets {krate} use {listed}, which it does not: drop the entry"
            );
        }
    }
}

/// Architecture invariant: library crates do no I/O, read no environment and use no global
/// random generator (printing is caught by clippy's print lints). kalibra-io (the readers
/// and the report writer) and the executable crate kalibra-cli are exempt. The Python package
/// (kalibra-py) is checked like a library: its `Report.save` writes through kalibra-io's
/// writer, so it needs no file access of its own.
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
        // Tests may touch files, and so may examples (programs beside a crate, such as the
        // profiling drivers that read their instruction set from the command line); so may
        // kalibra-io, whose job is reading logs and writing reports, and the `kalibra`
        // executable, the one crate under crates/ that is not a library (like xtask).
        if file
            .components()
            .any(|c| c.as_os_str() == "tests" || c.as_os_str() == "examples")
            || file.starts_with(root().join("crates/kalibra-io"))
            || file.starts_with(root().join("crates/kalibra-cli"))
        {
            continue;
        }
        let text = fs::read_to_string(&file).unwrap();
        for word in banned {
            assert!(!uses(&text, word), "{} uses {word}", file.display());
        }
    }
}

/// Whether `text` names `word` as a path of its own: `File::open` does, a type whose name ends
/// in `File` (`NoiseReportFile::new`) does not.
fn uses(text: &str, word: &str) -> bool {
    text.match_indices(word).any(|(at, _)| {
        !text[..at]
            .chars()
            .next_back()
            .is_some_and(|c| c.is_alphanumeric() || c == '_')
    })
}

/// The one module allowed `unsafe` code: the lane gathers of the batched simulation's normal
/// draws, which pulp exposes only as `unsafe` functions of raw pointers (see the module's
/// docs, "Why `unsafe`").
const UNSAFE_MODULE: &str = "crates/kalibra-sim/src/lanes/gather.rs";

/// Architecture invariant: `unsafe` is denied workspace-wide (`unsafe_code = "deny"` in the
/// root manifest, which every crate inherits through `[lints] workspace = true` and none
/// overrides) and allowed in exactly one module, [`UNSAFE_MODULE`]. A test's counting global
/// allocator (`no_alloc.rs`, which cannot be written without `unsafe`) is the one exception
/// outside library code.
#[test]
fn unsafe_code_is_allowed_in_one_module_only() {
    let root_manifest = fs::read_to_string(root().join("Cargo.toml")).unwrap();
    assert!(
        root_manifest.contains("unsafe_code = \"deny\""),
        "the workspace no longer denies unsafe code"
    );
    let mut manifests = vec![root().join("xtask/Cargo.toml")];
    for entry in fs::read_dir(root().join("crates")).unwrap() {
        manifests.push(entry.unwrap().path().join("Cargo.toml"));
    }
    for manifest in manifests {
        let text = fs::read_to_string(&manifest).unwrap();
        let lints = text.split("[lints]").nth(1).unwrap_or("");
        assert!(
            lints.trim_start().starts_with("workspace = true"),
            "{} does not take the workspace's lints",
            manifest.display()
        );
        assert!(
            !text.contains("unsafe_code"),
            "{} overrides the workspace's unsafe_code lint",
            manifest.display()
        );
    }
    let mut files = Vec::new();
    for dir in ["crates", "src", "tests", "examples", "xtask"] {
        rust_files(&root().join(dir), &mut files);
    }
    let mut allowing = Vec::new();
    for file in &files {
        let text = fs::read_to_string(file).unwrap();
        // An attribute line (`#![allow(unsafe_code)]`, `#[allow(..., unsafe_code)]`), not
        // text that names one.
        let allows = text.lines().any(|l| {
            let code = l.trim_start();
            code.starts_with('#') && code.contains("allow(") && code.contains("unsafe_code")
        });
        let test_allocator = file.file_name().is_some_and(|n| n == "no_alloc.rs")
            && file.components().any(|c| c.as_os_str() == "tests");
        if allows && !test_allocator {
            allowing.push(file.strip_prefix(root()).unwrap().to_path_buf());
        }
    }
    assert_eq!(
        allowing,
        vec![PathBuf::from(UNSAFE_MODULE)],
        "unsafe code is allowed in exactly one module"
    );
    let gather = fs::read_to_string(root().join(UNSAFE_MODULE)).unwrap();
    assert!(gather.contains("#![allow(unsafe_code)]"));
}

/// The `crate::` and `super::` modules the source `text` of module `module` (a top-level
/// module of its crate) imports: the first path segment after `crate::` or `super::` in its
/// `use` lines and paths.
fn imported_modules(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        let code = line.trim_start();
        if code.starts_with("//") {
            continue;
        }
        for prefix in ["crate::", "super::"] {
            let mut rest = code;
            while let Some(at) = rest.find(prefix) {
                rest = &rest[at + prefix.len()..];
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                // `crate::{a, b}`: each name in the braces.
                if name.is_empty() && rest.starts_with('{') {
                    let inside = rest[1..].split('}').next().unwrap_or("");
                    for part in inside.split(',') {
                        let part = part.trim().split("::").next().unwrap_or("").trim();
                        if !part.is_empty() {
                            out.push(part.to_string());
                        }
                    }
                } else if !name.is_empty() {
                    out.push(name);
                }
            }
        }
    }
    out
}

/// Architecture invariant: kalibra-io's modules import each other without cycles, leaf first
/// (the error and the cells at the bottom, one module per format above them, the dispatch on
/// top), so that each can be read, tested and changed from the bottom up.
#[test]
fn kalibra_io_modules_import_without_cycles() {
    let src = root().join("crates/kalibra-io/src");
    let mut modules = std::collections::BTreeMap::new();
    for entry in fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        let Some(name) = path.file_stem().map(|s| s.to_string_lossy().into_owned()) else {
            continue;
        };
        if name == "lib" {
            continue;
        }
        let mut files = Vec::new();
        if path.is_dir() {
            rust_files(&path, &mut files);
        } else {
            files.push(path.clone());
        }
        let mut imports = Vec::new();
        for file in files {
            let text = fs::read_to_string(&file).unwrap();
            // The unit tests inside a module may use anything of their parent.
            let text = text.split("#[cfg(test)]").next().unwrap_or("");
            imports.extend(imported_modules(text));
        }
        modules.insert(name, imports);
    }
    assert!(modules.len() > 5, "kalibra-io's modules were not found");
    // Imports of names the crate root re-exports (`crate::Error`) go to their module.
    let module_of = |name: &str| match name {
        "Error" => "error".to_string(),
        "ARRAY_NAMES" => "raw".to_string(),
        other => other.to_string(),
    };
    let graph: std::collections::BTreeMap<String, Vec<String>> = modules
        .iter()
        .map(|(m, imports)| {
            let mut to: Vec<String> = imports
                .iter()
                .map(|i| module_of(i))
                .filter(|i| i != m && modules.contains_key(i))
                .collect();
            to.sort();
            to.dedup();
            (m.clone(), to)
        })
        .collect();
    // Depth-first search for a cycle, reporting the path around it.
    fn visit(
        m: &str,
        graph: &std::collections::BTreeMap<String, Vec<String>>,
        path: &mut Vec<String>,
        done: &mut std::collections::BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == m) {
            let mut cycle = path[at..].to_vec();
            cycle.push(m.to_string());
            return Some(cycle);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_string());
        for next in &graph[m] {
            if let Some(cycle) = visit(next, graph, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = std::collections::BTreeSet::new();
    for m in graph.keys() {
        if let Some(cycle) = visit(m, &graph, &mut Vec::new(), &mut done) {
            panic!(
                "kalibra-io's modules import in a cycle: {}",
                cycle.join(" -> ")
            );
        }
    }
    // The bottom of the order imports nothing of the crate.
    assert!(
        graph["error"].is_empty(),
        "error imports {:?}",
        graph["error"]
    );
    assert!(
        graph["finite"].is_empty(),
        "finite imports {:?}",
        graph["finite"]
    );
}

/// The import scanner finds `crate::` and `super::` paths, braces included, and skips
/// comments, so the cycle check above can fail.
#[test]
fn imported_modules_reads_use_lines() {
    let text = "use crate::error::Error;\nuse crate::{raw::KNOWN, input};\n\
                // use crate::output;\nlet x = super::csv_rows::Rows::new();";
    assert_eq!(
        imported_modules(text),
        vec!["error", "raw", "input", "csv_rows"]
    );
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

/// Parts of names that name a paper, a paper's problem or a paper's reading of a typo, found
/// anywhere in a lower-cased name.
const PAPER_WORDS: [&str; 7] = [
    "paper",
    "saha",
    "minh",
    "spall",
    "problem_i",
    "table_i",
    "figures20",
];

/// Short words that name a paper's scenario only as a whole word of a name (`bot` in
/// `BotScenario` or `bot.rs`, not in `both`).
const PAPER_TOKENS: [&str; 2] = ["bot", "reading"];

/// The paper word or token `name` contains, if any. Tokens are the lower-cased parts of a
/// snake_case or CamelCase name.
fn paper_word(name: &str) -> Option<&'static str> {
    let lower = name.to_lowercase();
    if let Some(w) = PAPER_WORDS.iter().find(|w| lower.contains(*w)) {
        return Some(w);
    }
    let mut tokens = Vec::new();
    let mut current = String::new();
    for c in name.chars() {
        if c == '_' || c == '.' || (c.is_uppercase() && !current.is_empty()) {
            tokens.push(std::mem::take(&mut current));
        }
        if c != '_' && c != '.' {
            current.extend(c.to_lowercase());
        }
    }
    tokens.push(current);
    PAPER_TOKENS
        .iter()
        .find(|t| tokens.iter().any(|k| k == *t))
        .copied()
}

/// The identifier declared by a line such as `pub fn name(` or `struct Name<`, if any.
fn declared_item(line: &str) -> Option<&str> {
    let keywords = [
        "fn ",
        "struct ",
        "enum ",
        "const ",
        "static ",
        "type ",
        "mod ",
        "trait ",
        "macro_rules! ",
    ];
    let code = line.trim_start();
    if code.starts_with("//") {
        return None;
    }
    keywords.iter().find_map(|k| {
        let at = code.find(k)?;
        // The keyword must start the line or follow a visibility/qualifier and a space.
        if at > 0 && !code[..at].ends_with(' ') {
            return None;
        }
        let rest = &code[at + k.len()..];
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        (end > 0).then(|| &rest[..end])
    })
}

/// Architecture invariant: library crates carry no paper. Outside the studies crate, no file and no
/// declared item (function, type, constant, module, test) is named after a paper, one of its
/// problems or one of its readings; the library's models have neutral names and the papers'
/// numbers live with their studies.
#[test]
fn library_crates_carry_no_paper() {
    let mut files = Vec::new();
    for dir in ["crates", "src", "examples"] {
        rust_files(&root().join(dir), &mut files);
    }
    let mut found = Vec::new();
    for file in files
        .iter()
        .filter(|f| !f.starts_with(root().join("crates/kalibra-studies")))
    {
        let name = file.file_stem().unwrap().to_string_lossy().into_owned();
        if let Some(word) = paper_word(&name) {
            found.push(format!("file {} ({word})", file.display()));
        }
        let text = fs::read_to_string(file).unwrap();
        for (number, line) in text.lines().enumerate() {
            let Some(item) = declared_item(line) else {
                continue;
            };
            if let Some(word) = paper_word(item) {
                found.push(format!(
                    "{}:{}: {item} ({word})",
                    file.display(),
                    number + 1
                ));
            }
        }
    }
    assert!(
        found.is_empty(),
        "named after a paper outside kalibra-studies:\n{}",
        found.join("\n")
    );
}

/// The scanner finds the declarations it must find, and nothing in comments.
#[test]
fn declared_item_reads_declarations() {
    assert_eq!(declared_item("pub fn paper001(n: usize)"), Some("paper001"));
    assert_eq!(
        declared_item("    pub(crate) struct BotScenario<N>"),
        Some("BotScenario")
    );
    assert_eq!(
        declared_item("const TABLE_I: [f64; 3] = x;"),
        Some("TABLE_I")
    );
    assert_eq!(
        declared_item("    fn problem_ii_constants() {"),
        Some("problem_ii_constants")
    );
    assert_eq!(declared_item("/// the paper's fn paper001"), None);
    assert_eq!(declared_item("let reading = 3;"), None);
    assert_eq!(paper_word("BotScenario"), Some("bot"));
    assert_eq!(paper_word("bot"), Some("bot"));
    assert_eq!(paper_word("grid_hits_both_ends"), None);
    assert_eq!(paper_word("Target3dReading"), Some("reading"));
    assert_eq!(paper_word("read_positions"), None);
    assert_eq!(paper_word("KappaGrid_paper001"), Some("paper"));
}

/// Test files that must stay test binaries of their own, with the reason: process-wide state
/// a test binary can hold only once.
const OWN_TEST_BINARIES: [(&str, &str); 1] = [(
    "tests/no_alloc.rs",
    "installs a counting global allocator, which would count every other test's allocations",
)];

/// Architecture invariant: each package links at most one integration-test binary,
/// `tests/it/main.rs` with one module per file (plus [`OWN_TEST_BINARIES`]), because linking
/// a binary per test file dominated CI's build. Cargo makes a binary of every `tests/*.rs` and
/// every `tests/*/main.rs`, so a new file in `tests/` would silently add one.
#[test]
fn each_package_links_one_test_binary() {
    let mut packages = vec![root(), root().join("xtask")];
    for entry in fs::read_dir(root().join("crates")).unwrap() {
        packages.push(entry.unwrap().path());
    }
    let mut found = Vec::new();
    for package in &packages {
        let manifest = fs::read_to_string(package.join("Cargo.toml")).unwrap();
        assert!(
            !manifest.contains("[[test]]") && !manifest.contains("autotests"),
            "{} declares its own test targets",
            package.display()
        );
        let Ok(entries) = fs::read_dir(package.join("tests")) else {
            continue;
        };
        let mut binaries = Vec::new();
        for entry in entries {
            let path = entry.unwrap().path();
            let binary = if path.is_dir() {
                path.join("main.rs").exists()
            } else {
                path.extension().is_some_and(|e| e == "rs")
            };
            let relative = path.strip_prefix(root()).unwrap().to_path_buf();
            let own = OWN_TEST_BINARIES
                .iter()
                .any(|(file, _)| relative == Path::new(file));
            if binary && !own {
                binaries.push(relative.display().to_string());
            }
        }
        binaries.sort();
        if binaries.len() > 1 {
            found.push(binaries.join(", "));
        }
    }
    assert!(
        found.is_empty(),
        "more than one test binary in a package (move each file into tests/it/ as a module):\n{}",
        found.join("\n")
    );
    for (file, _) in OWN_TEST_BINARIES {
        assert!(root().join(file).exists(), "{file} is gone: drop its entry");
    }
}

/// The banned-word scan tells a path of its own from the end of a longer name.
#[test]
fn banned_words_match_whole_names() {
    assert!(uses("let f = File::open(p);", "File::"));
    assert!(uses("std::fs::read(p)", "std::fs"));
    assert!(!uses("NoiseReportFile::new(&p, &r)", "File::"));
    assert!(!uses("my_std::fs", "std::fs"));
}
