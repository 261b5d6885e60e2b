//! The seconds per stage of a reader ([`crate::stages`]), kept at the bottom of the crate so
//! that the readers can fill them in without importing the module that calls them.

/// Seconds per stage.
#[derive(Clone, Copy, Debug)]
pub struct Stages {
    /// Reading the file into memory (and, for a CSV, cutting it into blocks at record ends).
    pub read: f64,
    /// CSV: finding the rows and fields (the line ends and commas, counted with memchr);
    /// JSON: the first pass, finding where each array lies.
    pub tokenise: f64,
    /// CSV: reading the rows with their numbers, less the tokenising (the reader finds the
    /// fields as it parses the numbers); JSON: the second pass, the cells and their numbers on
    /// a reader thread with the evaluation on this one (so `evaluate` is NaN).
    pub parse: f64,
    /// CSV: feeding the parsed cells to the evaluator and finishing the report.
    pub evaluate: f64,
    /// CSV: the fields; JSON: the cells of the per-cell arrays.
    pub values: usize,
}
