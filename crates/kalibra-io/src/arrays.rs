//! Numpy-shaped arrays as a filter log: the rules of the NPZ format (see `input::FORMATS_HELP`)
//! for arrays handed over whole, which is how the Python package passes numpy arrays
//! (`input::log_from_arrays`). A cell (one run and step) whose values are all NaN was not
//! logged; a cell with only some NaN values is kept, so that a NaN covariance is a finding.
//!
//! `kalibra eval log.npz` streams the same arrays cell by cell instead (`npz_log`), with the
//! same shape rules (`raw::cell_shape`).

use std::borrow::Cow;
use std::collections::BTreeMap;

use crate::error::Error;
use crate::raw::{
    ARRAY_NAMES, CellValues, KNOWN, MODEL, ModelArray, PER_CELL, RawLog, cell_shape, model_given,
};

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
fn cells<'a>(array: &str, a: Array<'a>, cell_dims: usize) -> Result<Cells<'a>, Error> {
    let (runs, steps, cell_shape) = cell_shape(array, &a.shape, cell_dims)?;
    let size: usize = cell_shape.iter().product();
    if size == 0 || runs == 0 || steps == 0 {
        // No values bound the other axes then: `(2^40, 2^40, 0)` holds nothing, and a cell
        // per run and step would not fit in memory.
        return Err(Error::array(
            array,
            format!("array {array} has shape {:?}; it holds no values", a.shape),
        ));
    }
    // Which cells are all NaN is decided as the evaluation reads each cell, in its parallel
    // pass, not by a scan here on one thread, which would read the whole array once more.
    Ok(Cells {
        runs,
        steps,
        shape: cell_shape,
        cells: CellValues::NanUnlogged(a.data),
    })
}

/// The log from the named arrays.
pub(crate) fn build(mut arrays: BTreeMap<String, Array<'_>>) -> Result<RawLog<'_>, Error> {
    if let Some(unknown) = arrays.keys().find(|k| !ARRAY_NAMES.contains(&k.as_str())) {
        return Err(Error::array(
            unknown.clone(),
            format!("unknown array `{unknown}`; the arrays are {KNOWN}"),
        ));
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
            return Err(Error::array(
                "time",
                format!("array time has shape {:?}; expected (K,)", t.shape),
            ));
        }
        log.time = Some(t.data.into_owned());
    }
    let present: Vec<&str> = MODEL
        .iter()
        .copied()
        .filter(|m| arrays.contains_key(*m))
        .collect();
    if model_given(&present)? {
        let mut take = |name: &str| {
            let a = arrays.remove(name).unwrap_or(Array {
                shape: vec![],
                data: Cow::Borrowed(&[]),
            });
            ModelArray::of_shape(name, &a.shape, a.data.into_owned(), (runs, steps))
        };
        log.model = Some([take("F")?, take("H")?, take("Q")?, take("R")?]);
    }
    Ok(log)
}
