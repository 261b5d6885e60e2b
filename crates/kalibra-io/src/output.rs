//! Writing the report: everything into a temporary directory beside DIR, renamed into place at
//! the end, so a failed run never leaves a report that looks complete.

use std::fs;
use std::path::{Path, PathBuf};

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

/// A sibling of `out` named `.NAME.TAG-PID`.
fn sibling(out: &Path, tag: &str) -> PathBuf {
    let name = out.file_name().map_or("kalibra-report".into(), |n| {
        n.to_string_lossy().into_owned()
    });
    out.with_file_name(format!(".{name}.{tag}-{}", std::process::id()))
}

/// Writes `report.json`, `report.md`, `report.html` and the figures into `out` at once
/// ([`Target::prepare`] then [`Target::write`]), for a caller whose report is already computed
/// (the Python package's `save`).
///
/// `out` is replaced if it holds an earlier report (a `report.json`); a directory holding
/// anything else is left alone and refused.
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
    /// `out` will be replaced if it holds an earlier report (a `report.json`); a directory
    /// holding anything else is left alone and refused.
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
            let is_report = out.join("report.json").is_file();
            let is_empty = out.is_dir()
                && fs::read_dir(out)
                    .map_err(|e| io("read it", e))?
                    .next()
                    .is_none();
            if !(is_report || is_empty) {
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
