//! Numpy-shaped arrays as a filter log: the rules of the NPZ format (see `input::FORMATS_HELP`)
//! for arrays handed over whole, which is how the Python package passes numpy arrays
//! (`input::log_from_arrays`). A cell (one run and step) whose values are all NaN was not
//! logged; a cell with only some NaN values is kept, so that a NaN covariance is a finding.
//!
//! `kalibra eval log.npz` streams the same arrays cell by cell instead (`npz_log`), with the
//! same shape rules.

use std::borrow::Cow;

use kalibra_eval::Scope;

use crate::input::{CellValues, ModelArray, PER_CELL, RawLog, model_given};

/// The arrays a log may hold, by name, in every format (CSV columns aside): the NPZ archive's
/// and the JSON object's entries, and the Python package's keyword arguments.
pub const ARRAY_NAMES: [&str; 10] = [
    "truth",
    "estimate",
    "covariance",
    "innovation",
    "innovation_cov",
    "time",
    "F",
    "H",
    "Q",
    "R",
];

/// [`ARRAY_NAMES`] as the error messages list them (a test keeps the two equal).
pub(crate) const KNOWN: &str =
    "truth, estimate, covariance, innovation, innovation_cov, time, F, H, Q, R";

/// One array as stored: its shape and its values in C order, as f64, owned or borrowed.
pub(crate) struct Array<'a> {
    pub(crate) shape: Vec<usize>,
    pub(crate) data: Cow<'a, [f64]>,
}

/// A per-cell array cut into its cells.
struct Cells<'a> {
    runs: usize,
    steps: usize,
    /// The shape of one cell (`[n]` or `[n, n]`).
    shape: Vec<usize>,
    /// Run-major cells in one buffer, a cell whose every value is NaN not logged.
    cells: CellValues<'a>,
}

/// The cells of a per-cell array with `cell_dims` trailing dimensions; a single run may drop
/// the leading R axis.
fn cells<'a>(array: &str, a: Array<'a>, cell_dims: usize) -> Result<Cells<'a>, String> {
    // The shape rules are the streaming NPZ reader's, so both read an array the same way.
    let (runs, steps, cell_shape) = crate::npz_log::cell_shape(array, &a.shape, cell_dims)?;
    let size: usize = cell_shape.iter().product();
    if size == 0 || runs == 0 || steps == 0 {
        // No values bound the other axes then: `(2^40, 2^40, 0)` holds nothing, and a cell
        // per run and step would not fit in memory.
        return Err(format!(
            "array {array} has shape {:?}; it holds no values",
            a.shape
        ));
    }
    // Which cells are all NaN is decided as the evaluation reads each cell, in its parallel
    // pass: a scan here, on one thread, read the whole array once more (a tenth of
    // `kalibra.evaluate`'s time on a 240 MB log).
    Ok(Cells {
        runs,
        steps,
        shape: cell_shape,
        cells: CellValues::NanUnlogged(a.data),
    })
}

/// The log from the named arrays.
pub(crate) fn build(
    mut arrays: std::collections::BTreeMap<String, Array<'_>>,
) -> Result<RawLog<'_>, String> {
    if let Some(unknown) = arrays.keys().find(|k| !ARRAY_NAMES.contains(&k.as_str())) {
        return Err(format!("unknown array `{unknown}`; the arrays are {KNOWN}"));
    }
    let mut log = RawLog::default();
    for array in PER_CELL {
        let Some(a) = arrays.remove(array) else {
            continue;
        };
        let matrix = array == "covariance" || array == "innovation_cov";
        let c = cells(array, a, if matrix { 2 } else { 1 })?;
        let cols = c.shape.get(1).copied().unwrap_or(0);
        log.put_cells(array, (c.runs, c.steps), (c.shape[0], cols), c.cells)?;
    }
    let (runs, steps) = log.require_cells()?;
    if let Some(t) = arrays.remove("time") {
        if t.shape.len() != 1 {
            return Err(format!("array time has shape {:?}; expected (K,)", t.shape));
        }
        log.time = Some(t.data.into_owned());
    }
    let model = ["F", "H", "Q", "R"];
    let present: Vec<&str> = model
        .iter()
        .copied()
        .filter(|m| arrays.contains_key(*m))
        .collect();
    if model_given(&present)? {
        let mut out = Vec::with_capacity(4);
        for name in model {
            let a = arrays.remove(name).unwrap_or(Array {
                shape: vec![],
                data: Cow::Borrowed(&[]),
            });
            let (scope, rows, cols) = match a.shape.as_slice() {
                [r, c] => (Scope::Constant, *r, *c),
                [k, r, c] if *k == steps => (Scope::PerStep, *r, *c),
                [rr, k, r, c] if (*rr, *k) == (runs, steps) => (Scope::PerRunStep, *r, *c),
                other => {
                    return Err(format!(
                        "array {name} has shape {other:?}; expected one matrix (rows, cols), \
                         one per step ({steps}, rows, cols) or one per run and step ({runs}, \
                         {steps}, rows, cols)"
                    ));
                }
            };
            out.push(ModelArray {
                rows,
                cols,
                scope,
                data: a.data.into_owned(),
            });
        }
        let [f, h, q, r]: [ModelArray; 4] = out
            .try_into()
            .map_err(|_| "arrays F, H, Q and R".to_string())?;
        log.model = Some([f, h, q, r]);
    }
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_listed_names_are_the_names() {
        assert_eq!(KNOWN, ARRAY_NAMES.join(", "));
    }
}
