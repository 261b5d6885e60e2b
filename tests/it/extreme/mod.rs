//! The public functions of the library crates, found by scanning their sources, so that the
//! extreme-input property tests (`extreme_floats.rs`, `extreme_sizes.rs`) can check their own
//! lists against them: a new public function that takes floating-point data or a size fails
//! those tests until it is driven or listed with the reason it is not.
//!
//! The parser is deliberately small: comments and string and character literals are blanked,
//! `#[cfg(test)]` modules are dropped, and every `pub fn` (not `pub(crate)`) is taken with the
//! type of the `impl` block around it. Trait methods carry no `pub` and are reached through
//! their implementors' public constructors and the suites that run them.

// Each test binary uses a part of this module.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One public function: `key` is `Type::name` for a method, `name` for a free function.
#[derive(Clone, Debug)]
pub struct PublicFn {
    pub krate: String,
    pub file: String,
    pub key: String,
    pub params: String,
}

/// The library crates scanned: every `crates/kalibra-*` but the executable and the Python
/// bindings, which pass their inputs to these (their own tests cover them).
fn library_crates() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates");
    let mut out: Vec<PathBuf> = std::fs::read_dir(&root)
        .expect("crates/ is readable")
        .map(|e| e.expect("a directory entry").path())
        .filter(|p| {
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            name.starts_with("kalibra-")
                && name != "kalibra-cli"
                && name != "kalibra-py"
                && p.join("src").is_dir()
        })
        .collect();
    out.sort();
    out
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("a source directory is readable")
        .map(|e| e.expect("a directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The source with comments and the contents of string and character literals replaced by
/// spaces (lengths kept), so that braces and keywords can be matched on it.
fn blank(src: &str) -> Vec<u8> {
    let b = src.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    let fill = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                let end = b[i..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .map_or(b.len(), |p| i + p);
                fill(&mut out, i, end);
                i = end;
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let mut depth = 0;
                let start = i;
                while i < b.len() {
                    if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                        depth += 1;
                        i += 2;
                    } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                        depth -= 1;
                        i += 2;
                        if depth == 0 {
                            break;
                        }
                    } else {
                        i += 1;
                    }
                }
                fill(&mut out, start, i);
            }
            b'r' if matches!(b.get(i + 1), Some(b'"') | Some(b'#'))
                && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_')) =>
            {
                let mut j = i + 1;
                let mut hashes = 0;
                while b.get(j) == Some(&b'#') {
                    hashes += 1;
                    j += 1;
                }
                if b.get(j) != Some(&b'"') {
                    i += 1;
                    continue;
                }
                let start = j + 1;
                let mut k = start;
                loop {
                    if k >= b.len() {
                        break;
                    }
                    if b[k] == b'"'
                        && b[k + 1..]
                            .iter()
                            .take(hashes)
                            .filter(|&&c| c == b'#')
                            .count()
                            == hashes
                    {
                        break;
                    }
                    k += 1;
                }
                fill(&mut out, start, k);
                i = k + 1 + hashes;
            }
            b'"' => {
                let start = i + 1;
                let mut k = start;
                while k < b.len() && b[k] != b'"' {
                    if b[k] == b'\\' {
                        k += 1;
                    }
                    k += 1;
                }
                fill(&mut out, start, k.min(b.len()));
                i = k + 1;
            }
            b'\'' => {
                // A character literal ('x', '\n', '{'), or a lifetime ('a), which is left.
                if b.get(i + 1) == Some(&b'\\') {
                    let end = b[i + 2..]
                        .iter()
                        .position(|&c| c == b'\'')
                        .map_or(b.len(), |p| i + 2 + p);
                    fill(&mut out, i + 1, end);
                    i = end + 1;
                } else if b.get(i + 2) == Some(&b'\'') {
                    fill(&mut out, i + 1, i + 2);
                    i += 3;
                } else {
                    i += 1;
                }
            }
            _ => i += 1,
        }
    }
    out
}

/// The index just past the bracket that closes the one at `open` (`(`, `{`, `<`), on blanked
/// source; `->` and `=>` do not count as closing `<`.
fn close(b: &[u8], open: usize) -> usize {
    let (o, c) = match b[open] {
        b'(' => (b'(', b')'),
        b'{' => (b'{', b'}'),
        _ => (b'<', b'>'),
    };
    let mut depth = 0i32;
    let mut i = open;
    while i < b.len() {
        let ch = b[i];
        if ch == o {
            depth += 1;
        } else if ch == c && !(c == b'>' && i > 0 && matches!(b[i - 1], b'-' | b'=')) {
            depth -= 1;
            if depth == 0 {
                return i + 1;
            }
        }
        i += 1;
    }
    b.len()
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// Positions where the keyword `word` starts as a whole word.
fn words(b: &[u8], word: &str) -> Vec<usize> {
    let w = word.as_bytes();
    (0..b.len().saturating_sub(w.len() - 1))
        .filter(|&i| {
            &b[i..i + w.len()] == w
                && (i == 0 || !is_ident(b[i - 1]))
                && b.get(i + w.len()).is_none_or(|&c| !is_ident(c))
        })
        .collect()
}

fn skip_ws(b: &[u8], mut i: usize) -> usize {
    while i < b.len() && b[i].is_ascii_whitespace() {
        i += 1;
    }
    i
}

fn ident_at(b: &[u8], i: usize) -> (String, usize) {
    let mut j = i;
    while j < b.len() && is_ident(b[j]) {
        j += 1;
    }
    (String::from_utf8_lossy(&b[i..j]).into_owned(), j)
}

/// The public functions of one file's source.
fn scan_source(src: &str, krate: &str, file: &str, out: &mut Vec<PublicFn>) {
    let mut b = blank(src);
    // Drop `#[cfg(test)] mod name { ... }`.
    let marker = b"#[cfg(test)]";
    let mut i = 0;
    while let Some(p) = b[i..].windows(marker.len()).position(|w| w == marker) {
        let at = i + p;
        let j = skip_ws(&b, at + marker.len());
        if b[j..].starts_with(b"mod ")
            && let Some(brace) = b[j..].iter().position(|&c| c == b'{' || c == b';')
            && b[j + brace] == b'{'
        {
            let end = close(&b, j + brace);
            for c in &mut b[at..end] {
                if *c != b'\n' {
                    *c = b' ';
                }
            }
        }
        i = at + marker.len();
    }
    // `impl` blocks: (start, end, type name).
    let mut impls = Vec::new();
    for at in words(&b, "impl") {
        let mut j = skip_ws(&b, at + 4);
        if b.get(j) == Some(&b'<') {
            j = close(&b, j);
        }
        let Some(brace) = b[j..].iter().position(|&c| c == b'{' || c == b';') else {
            continue;
        };
        let brace = j + brace;
        if b[brace] != b'{' {
            continue;
        }
        let header = String::from_utf8_lossy(&b[j..brace]).into_owned();
        let header = header.split(" where").next().unwrap_or("").to_string();
        let ty = match header.rfind(" for ") {
            Some(f) => header[f + 5..].to_string(),
            None => header,
        };
        let ty = ty.trim().trim_start_matches('&');
        let name = ty
            .split('<')
            .next()
            .unwrap_or("")
            .rsplit("::")
            .next()
            .unwrap_or("");
        impls.push((brace, close(&b, brace), name.trim().to_string()));
    }
    for at in words(&b, "pub") {
        let mut j = skip_ws(&b, at + 3);
        for qualifier in ["const", "unsafe", "async"] {
            if b[j..].starts_with(qualifier.as_bytes()) && !is_ident(b[j + qualifier.len()]) {
                j = skip_ws(&b, j + qualifier.len());
            }
        }
        if !(b[j..].starts_with(b"fn") && b.get(j + 2).is_some_and(|c| c.is_ascii_whitespace())) {
            continue;
        }
        let j = skip_ws(&b, j + 2);
        let (name, mut k) = ident_at(&b, j);
        if name.is_empty() {
            continue; // a macro's `pub fn $name`
        }
        k = skip_ws(&b, k);
        if b.get(k) == Some(&b'<') {
            k = close(&b, k);
        }
        k = skip_ws(&b, k);
        if b.get(k) != Some(&b'(') {
            continue;
        }
        let end = close(&b, k);
        let params = String::from_utf8_lossy(&b[k + 1..end - 1]);
        let params = params.split_whitespace().collect::<Vec<_>>().join(" ");
        let owner = impls
            .iter()
            .filter(|(s, e, _)| *s < at && at < *e)
            .max_by_key(|(s, _, _)| *s)
            .map(|(_, _, t)| t.clone());
        let key = match owner {
            Some(t) => format!("{t}::{name}"),
            None => name,
        };
        out.push(PublicFn {
            krate: krate.to_string(),
            file: file.to_string(),
            key,
            params,
        });
    }
}

/// Every public function of the library crates.
pub fn public_fns() -> Vec<PublicFn> {
    let mut out = Vec::new();
    for dir in library_crates() {
        let krate = dir
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("")
            .to_string();
        let mut files = Vec::new();
        rust_files(&dir.join("src"), &mut files);
        for f in files {
            let src = std::fs::read_to_string(&f).expect("a source file is readable");
            let rel = f
                .strip_prefix(dir.join("src"))
                .unwrap_or(&f)
                .display()
                .to_string();
            scan_source(&src, &krate, &rel, &mut out);
        }
    }
    out
}

/// How a function is covered: driven by the property test, or not, with the reason.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cover {
    /// Called by the property test (its source holds `name(`).
    Driven,
    /// Not called here, for the reason given.
    Reason(&'static str),
}

/// Checks `listed` against the scanned functions `wanted` selects: the same keys with the same
/// multiplicity, and every `Driven` entry's name called in `test_source`. Returns the
/// problems, one a line, with the lines to add or remove.
pub fn check_list(
    listed: &[(&str, Cover)],
    wanted: impl Fn(&PublicFn) -> bool,
    test_source: &str,
) -> Vec<String> {
    let mut scanned: BTreeMap<String, (usize, String)> = BTreeMap::new();
    for f in public_fns().into_iter().filter(|f| wanted(f)) {
        let e = scanned
            .entry(f.key.clone())
            .or_insert((0, format!("{}/{}: ({})", f.krate, f.file, f.params)));
        e.0 += 1;
    }
    let mut list: BTreeMap<String, usize> = BTreeMap::new();
    let mut problems = Vec::new();
    for (key, cover) in listed {
        *list.entry(key.to_string()).or_default() += 1;
        if *cover == Cover::Driven {
            let name = key.rsplit("::").next().unwrap_or(key);
            if !(test_source.contains(&format!("{name}("))
                || test_source.contains(&format!("{name}::<")))
            {
                problems.push(format!(
                    "{key} is listed as driven but the test never calls {name}("
                ));
            }
        }
    }
    for (key, (n, at)) in &scanned {
        let have = list.get(key).copied().unwrap_or(0);
        if have != *n {
            problems.push(format!(
                "{key}: {n} public fn(s) in the sources, {have} in the list (add or remove; {at})"
            ));
        }
    }
    for (key, n) in &list {
        if !scanned.contains_key(key) {
            problems.push(format!(
                "{key}: listed {n} time(s), no such public fn takes it"
            ));
        }
    }
    problems
}

// ----- the "no non-finite Ok" check, shared by both property tests -----------------------------

/// Values whose numbers must all be finite when they come back inside `Ok`.
pub trait Finite {
    fn finite(&self) -> bool;
}

impl Finite for f64 {
    fn finite(&self) -> bool {
        self.is_finite()
    }
}
impl Finite for bool {
    fn finite(&self) -> bool {
        true
    }
}
impl Finite for usize {
    fn finite(&self) -> bool {
        true
    }
}
impl Finite for () {
    fn finite(&self) -> bool {
        true
    }
}
impl<T: Finite> Finite for Vec<T> {
    fn finite(&self) -> bool {
        self.iter().all(Finite::finite)
    }
}
impl<T: Finite> Finite for Option<T> {
    fn finite(&self) -> bool {
        self.as_ref().is_none_or(Finite::finite)
    }
}
impl<A: Finite, B: Finite> Finite for (A, B) {
    fn finite(&self) -> bool {
        self.0.finite() && self.1.finite()
    }
}
impl<R: kalibra::linalg::Dim, C: kalibra::linalg::Dim> Finite
    for kalibra::linalg::OMatrix<f64, R, C>
where
    kalibra::linalg::DefaultAllocator: kalibra::linalg::nalgebra::allocator::Allocator<R, C>,
{
    fn finite(&self) -> bool {
        self.iter().all(|v| v.is_finite())
    }
}
