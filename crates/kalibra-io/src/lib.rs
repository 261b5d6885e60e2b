//! Reading filter logs and tuning inputs from files and arrays, and writing kalibra's reports.
//!
//! The `kalibra` executable (`kalibra-cli`: `kalibra eval`, `kalibra tune`) and the Python
//! package (`kalibra-py`) both read and write through this crate, so a log handed over as
//! numpy arrays is read with the NPZ reader's rules ([`input::log_from_arrays`]: a cell of
//! all NaN was not logged) and a report saved from Python is the same files, byte for byte,
//! as the one `kalibra eval` writes ([`output::write_report`] of a [`document::Document`]).
//! It is the one library crate under `crates/` that touches files (docs/ARCHITECTURE.md):
//! reading logs and models, and writing a report into a temporary directory renamed into
//! place.
//!
//! # Notation
//! A log holds R runs of K steps of a filter with n states and m measurements; its arrays
//! carry numpy's names and shapes: `truth`, `estimate` (R, K, n), `covariance` (R, K, n, n),
//! `innovation` (R, K, m), `innovation_cov` (R, K, m, m), `time` (K) and the model `F`, `H`,
//! `Q`, `R` (see [`input::FORMATS_HELP`]). A cell is one run and step. Rows and columns of a
//! CSV file count from 1, the header being row 1 (as a spreadsheet shows them); indices of
//! arrays count from 0.
//!
//! # Where each job lives
//! The modules are ordered from the bottom up, and none imports a module above it
//! (`tests/architecture.rs` checks that they import each other without cycles):
//!
//! * [`error`]: the one error type, [`Error`], whose variants carry the file, the CSV row
//!   and column, the array and index, or the MODEL.toml key, and display as one message.
//! * [`finite`]: finding a non-finite number inside a report.
//! * `raw`: the arrays' names, cells and shapes as the readers produce them, and the rules
//!   all array formats share; `csv_rows`: the CSV header and rows both commands read.
//! * One module per format: `arrays` (numpy-shaped arrays in memory), `json_log` (read
//!   whole) and `json_stream` (streamed, handing `json_log` what it does not take), `npz_log`
//!   (streamed), `csv_log` (streamed), and [`tune_input`] (MODEL.toml and the measurement
//!   and truth CSVs of `kalibra tune`).
//! * [`input`]: the format by extension, dispatching to the readers.
//! * [`document`] (with `tune_document` and `noise_document`): the human-readable report as
//!   blocks and figures; [`noise_report`]: `report.json` of a noise estimate
//!   (`kalibra tune --method`) and its writer; [`output`]: the writer of a report directory.
//!
//! Every reader error is an [`Error`]; nothing panics on data and nothing prints (a CSV log
//! larger than 64 MiB draws a progress bar on stderr when stderr is a terminal).

// Outside input must not reach an unwrap: every reader error is an `Error`.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

mod arrays;
mod csv_log;
mod csv_rows;
mod decimal;
pub mod document;
pub mod error;
pub mod finite;
#[doc(hidden)]
pub mod fuzzing;
pub mod input;
mod json_log;
mod json_stream;
mod noise_document;
pub mod noise_report;
mod npz_log;
pub mod output;
mod raw;
mod stage_times;
#[doc(hidden)]
pub mod stages;
mod tune_document;
pub mod tune_input;

pub use error::Error;
pub use raw::ARRAY_NAMES;
