//! Writing the report: everything into a temporary directory beside DIR, renamed into place at
//! the end, so a failed run never leaves a report that looks complete.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use kalibra_plot::ToSvg;

use crate::document::Document;
use crate::error::Error;

/// Removes its directory when dropped, unless disarmed (also when a panic unwinds).
struct Guard(Option<PathBuf>);

impl Drop for Guard {
    fn drop(&mut self) {
        if let Some(dir) = self.0.take() {
            let _ = fs::remove_dir_all(dir);
        }
    }
}

/// A sibling of `out` named `.NAME.TAG-PID-N`, with `N` counted per process so that two threads
/// saving at once (Python's `Report.save` releases nothing, but a program may call it from
/// threads) never share a temporary directory.
fn sibling(out: &Path, tag: &str) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = out.file_name().map_or("kalibra-report".into(), |n| {
        n.to_string_lossy().into_owned()
    });
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    out.with_file_name(format!(".{name}.{tag}-{}-{n}", std::process::id()))
}

/// Whether a directory entry is one the writer produces: `report.json`, `report.md`,
/// `report.html` or a figure (`*.svg`). Only a directory holding nothing else is replaced, so a
/// user's folder that happens to contain a `report.json` is never deleted (the test
/// `refuses_a_folder_with_other_files` shows it).
fn is_report_file(entry: &fs::DirEntry) -> bool {
    let name = entry.file_name();
    let name = name.to_string_lossy();
    entry.file_type().is_ok_and(|t| t.is_file())
        && (matches!(name.as_ref(), "report.json" | "report.md" | "report.html")
            || name.ends_with(".svg"))
}

/// Writes `report.json`, `report.md`, `report.html` and the figures into `out` at once
/// ([`Target::prepare`] then [`Target::write`]), for a caller whose report is already computed
/// (the Python package's `save`).
///
/// `out` is replaced if it holds an earlier report and nothing else (`report.json`, and
/// `report.md`, `report.html`, figures); a directory holding anything else is left alone and
/// refused.
///
/// # Errors
/// As [`Target::prepare`] and [`Target::write`].
pub fn write_report(
    out: &Path,
    report: &impl serde::Serialize,
    doc: &Document,
) -> Result<(), Error> {
    Target::prepare(out)?.write(report, doc)
}

/// Where a report goes: checked and its temporary directory made before any work starts, so
/// that an unwritable `--out` fails at once, not after a long evaluation.
pub struct Target {
    out: PathBuf,
    /// As the user wrote it, for messages.
    shown: PathBuf,
    tmp: PathBuf,
    guard: Guard,
}

impl Target {
    /// Checks `out` and makes the temporary directory beside it.
    ///
    /// `out` will be replaced if it holds an earlier report and nothing else (`report.json`,
    /// and `report.md`, `report.html`, figures); a directory holding anything else is left
    /// alone and refused.
    ///
    /// # Errors
    /// [`Error::EmptyOutput`] for an empty path; [`Error::Output`] for a directory holding
    /// something other than an earlier report; [`Error::Io`] naming `out` for one that cannot
    /// be created or written beside.
    pub fn prepare(out: &Path) -> Result<Self, Error> {
        if out.as_os_str().is_empty() {
            // `Path::new("")` joins as the current directory: the report would land there.
            return Err(Error::EmptyOutput);
        }
        let shown = out.to_path_buf();
        let io = |what: &str, source: std::io::Error| Error::Io {
            file: shown.clone(),
            action: what.to_string(),
            source,
        };
        if out.exists() {
            if !out.is_dir() {
                return Err(Error::Output {
                    dir: shown,
                    message: "exists and is not a directory; choose another --out".to_string(),
                });
            }
            let mut has_json = false;
            let mut entries = 0usize;
            for entry in fs::read_dir(out).map_err(|e| io("read it", e))? {
                let entry = entry.map_err(|e| io("read it", e))?;
                if !is_report_file(&entry) {
                    return Err(Error::Output {
                        dir: shown,
                        message: format!(
                            "holds no earlier report ({} is not part of one); choose another \
                             --out or remove it",
                            entry.file_name().to_string_lossy()
                        ),
                    });
                }
                has_json |= entry.file_name() == "report.json";
                entries += 1;
            }
            if entries > 0 && !has_json {
                return Err(Error::Output {
                    dir: shown,
                    message: "exists and holds no earlier report; choose another --out or \
                              remove it"
                        .to_string(),
                });
            }
        }
        // `a/b` with no parent components is relative to the current directory.
        let out = if out.parent().is_none_or(|p| p.as_os_str().is_empty()) {
            Path::new(".").join(out)
        } else {
            out.to_path_buf()
        };
        if let Some(parent) = out.parent() {
            fs::create_dir_all(parent).map_err(|e| io("create its parent directory", e))?;
        }
        let tmp = sibling(&out, "tmp");
        let _ = fs::remove_dir_all(&tmp);
        fs::create_dir(&tmp).map_err(|e| io("create a temporary directory beside it", e))?;
        Ok(Self {
            out,
            shown,
            guard: Guard(Some(tmp.clone())),
            tmp,
        })
    }

    /// Writes `report.json`, `report.md`, `report.html` and the figures, and moves them into
    /// place. `report` is the serialisable report (`kalibra eval`'s or `kalibra tune`'s).
    ///
    /// # Errors
    /// [`Error::Io`] naming the directory and what could not be written or moved;
    /// [`Error::Output`] for a report that cannot be serialised.
    pub fn write(mut self, report: &impl serde::Serialize, doc: &Document) -> Result<(), Error> {
        let (out, tmp, shown) = (&self.out, &self.tmp, &self.shown);
        let io = |what: &str, source: std::io::Error| Error::Io {
            file: shown.clone(),
            action: what.to_string(),
            source,
        };
        let json = serde_json::to_string_pretty(report).map_err(|e| Error::Output {
            dir: shown.clone(),
            message: format!("cannot serialise the report: {e}"),
        })?;
        let write = |name: &str, text: &str| {
            fs::write(tmp.join(name), text).map_err(|e| io(&format!("write {name}"), e))
        };
        write("report.json", &(json + "\n"))?;
        write("report.md", &doc.markdown())?;
        for (name, fig) in &doc.figures {
            write(name, &fig.to_svg())?;
        }
        write("report.html", &doc.html())?;

        // Move an earlier report aside, put the new one in place, then drop the old one.
        let old = sibling(out, "old");
        let had_old = out.exists();
        if had_old {
            let _ = fs::remove_dir_all(&old);
            fs::rename(out, &old).map_err(|e| io("move the earlier report aside", e))?;
        }
        if let Err(e) = fs::rename(tmp, out) {
            if had_old {
                let _ = fs::rename(&old, out);
            }
            return Err(io("move the new report into place", e));
        }
        self.guard.0 = None;
        if had_old {
            let _ = fs::remove_dir_all(&old);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("kalibra-io-output-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn accepts_an_earlier_report() {
        let out = scratch("earlier");
        for name in ["report.json", "report.md", "report.html", "nees.svg"] {
            fs::write(out.join(name), "old").unwrap();
        }
        let target = Target::prepare(&out);
        assert!(target.is_ok());
        drop(target);
        fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn refuses_a_folder_with_other_files() {
        let out = scratch("foreign");
        fs::write(out.join("report.json"), "{}").unwrap();
        fs::write(out.join("thesis.tex"), "keep me").unwrap();
        let err = Target::prepare(&out).err().unwrap();
        assert!(
            err.to_string().contains("thesis.tex is not part of one"),
            "{err}"
        );
        assert_eq!(
            fs::read_to_string(out.join("thesis.tex")).unwrap(),
            "keep me"
        );
        fs::remove_dir_all(&out).unwrap();
    }
}
