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
        // Figures are data and their SVG writer: nothing of the filters or the studies.
        ("kalibra-plot", &[]),
        // The log evaluation takes data, like the metrics: never filters, models or studies.
        (
            "kalibra-eval",
            &[
                "kalibra-linalg",
                "kalibra-models",
                "kalibra-filters",
                "kalibra-metrics",
                "kalibra-sim",
            ],
        ),
        // The `kalibra` executable: reads logs, evaluates them, draws and writes the report.
        ("kalibra-cli", &["kalibra-eval", "kalibra-plot"]),
        // The Python package: a front end like the executable, whose log reading (the NPZ
        // rules) and report writing it calls, plus the filters and metrics it exposes on arrays.
        (
            "kalibra-py",
            &[
                "kalibra-eval",
                "kalibra-cli",
                "kalibra-linalg",
                "kalibra-models",
                "kalibra-filters",
                "kalibra-metrics",
                "kalibra-sim",
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
/// random generator (printing is caught by clippy's print lints). The executable crate
/// kalibra-cli is exempt. The Python package (kalibra-py) is checked like a library: its
/// `Report.save` writes through kalibra-cli's writer, so it needs no file access of its own.
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
        // the `kalibra` executable, the one crate under crates/ that is not a library (it
        // reads logs and writes reports, like xtask).
        if file
            .components()
            .any(|c| c.as_os_str() == "tests" || c.as_os_str() == "examples")
            || file.starts_with(root().join("crates/kalibra-cli"))
        {
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
