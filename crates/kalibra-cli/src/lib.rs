//! The front end's shared part: reading filter logs from files and arrays, and writing reports.
//!
//! The `kalibra` executable (`src/main.rs`, `kalibra eval` and `kalibra tune`) is built on this
//! library, and so is the Python package (`kalibra-py`), so that a log handed over as numpy
//! arrays is read with the NPZ reader's rules ([`input::log_from_arrays`]: a cell of all NaN was
//! not logged) and a report saved from Python is the same files, byte for byte, as the one
//! `kalibra eval` writes ([`output::write_report`] of a [`document::Document`]).
//!
//! This is the one crate under `crates/` that touches files (docs/ARCHITECTURE.md): reading
//! logs and models, and writing a report into a temporary directory renamed into place. Every
//! error is one message naming the file (or array) and where in it.

// Outside input must not reach an unwrap: every reader error is a message (issue 19).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

mod arrays;
mod csv_log;
mod csv_rows;
pub mod document;
pub mod finite;
pub mod input;
mod json_log;
mod npz_log;
pub mod output;
mod tune_document;
pub mod tune_input;

pub use arrays::ARRAY_NAMES;
