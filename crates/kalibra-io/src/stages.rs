//! Where the time of `kalibra eval` goes, stage by stage, for `cargo xtask bench eval`: each
//! stage of a reader run alone on one thread, one after another, with the file held in
//! memory. Nothing here runs when a log is evaluated: the readers carry no timing code. Not
//! part of the stable API.

use std::path::Path;

use kalibra_eval::{Evaluation, Report};

use crate::error::Error;
use crate::input::LogFormat;

pub use crate::stage_times::Stages;

/// The stages of evaluating the log `path` (CSV or JSON; `None` for an NPZ log, whose values
/// need no tokenising or parsing, or a JSON log the streaming reader does not take), and the
/// report.
///
/// # Errors
/// As [`crate::input::evaluate_log`].
pub fn stages(path: &Path, evaluation: &Evaluation) -> Result<Option<(Stages, Report)>, Error> {
    match LogFormat::of(path)? {
        LogFormat::Csv => crate::csv_log::stages(path, evaluation).map(Some),
        LogFormat::Json => crate::json_stream::stages(path, evaluation),
        LogFormat::Npz => Ok(None),
    }
}
