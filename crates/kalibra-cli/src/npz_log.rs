//! The NPZ log: numpy's `np.savez` (or `np.savez_compressed`) archive of arrays with the same
//! names and shapes as the JSON log (see `input::FORMATS_HELP`).
//!
//! A cell (one run and step) whose values are all NaN was not logged, since numpy arrays have
//! no `null`; a cell with only some NaN values is kept as logged, so a NaN covariance is a
//! finding about the filter under test, as in the other formats. Errors name the file and the
//! array, and the cell index where one is at fault.

use std::io::{Cursor, Read};
use std::path::Path;

use kalibra_eval::Scope;

use crate::input::{CellValues, ModelArray, PER_CELL, RawLog, model_given};

const KNOWN: &str = "truth, estimate, covariance, innovation, innovation_cov, time, F, H, Q, R";

/// One array as stored: its shape and its values in C order, as f64.
pub(crate) struct Array {
    pub(crate) shape: Vec<usize>,
    pub(crate) data: Vec<f64>,
}

/// Reads the NPZ log in `bytes` (from `file`, named in errors).
pub fn read(file: &Path, bytes: &[u8]) -> Result<RawLog, String> {
    let name = file.display();
    let fail = |msg: String| format!("{name}: {msg}");
    let mut archive = zip::ZipArchive::new(Cursor::new(bytes)).map_err(|e| {
        fail(format!(
            "not an NPZ archive ({e}); write it with numpy's np.savez"
        ))
    })?;
    let mut arrays = std::collections::BTreeMap::new();
    for index in 0..archive.len() {
        let mut entry = archive
            .by_index(index)
            .map_err(|e| fail(format!("entry {index} of the archive: {e} (truncated?)")))?;
        let entry_name = entry
            .name()
            .map_err(|e| {
                fail(format!(
                    "entry {index} of the archive has no readable name ({e})"
                ))
            })?
            .to_string();
        let Some(array) = entry_name.strip_suffix(".npy") else {
            return Err(fail(format!(
                "entry `{entry_name}` is not a .npy array; the arrays are {KNOWN}"
            )));
        };
        let array = array.to_string();
        let mut raw = Vec::new();
        entry
            .read_to_end(&mut raw)
            .map_err(|e| fail(format!("array {array}: cannot read it ({e}; truncated?)")))?;
        let parsed = parse(&raw).map_err(|e| fail(format!("array {array}: {e}")))?;
        arrays.insert(array, parsed);
    }
    build(arrays).map_err(fail)
}

/// One `.npy` payload as f64 values in C order.
fn parse(raw: &[u8]) -> Result<Array, String> {
    let npy = npyz::NpyFile::new(raw).map_err(|e| format!("not a .npy array ({e})"))?;
    if npy.order() == npyz::Order::Fortran {
        return Err(
            "stored in Fortran order; save a C-ordered array (np.ascontiguousarray)".to_string(),
        );
    }
    let shape: Vec<usize> = npy.shape().iter().map(|&d| d as usize).collect();
    let descr = npy.dtype().descr();
    // numpy's type string: byte order, kind, size (`<f8`, `<f4`, `<i8`, ...).
    let kind = descr
        .trim_matches('\'')
        .trim_start_matches(['<', '>', '|', '=']);
    let read_error = |e: std::io::Error| format!("cannot read its values ({e}; truncated?)");
    let data: Vec<f64> = match kind {
        "f8" => npy.into_vec::<f64>().map_err(read_error)?,
        "f4" => npy
            .into_vec::<f32>()
            .map_err(read_error)?
            .into_iter()
            .map(f64::from)
            .collect(),
        "i8" => npy
            .into_vec::<i64>()
            .map_err(read_error)?
            .into_iter()
            .map(|v| v as f64)
            .collect(),
        "i4" => npy
            .into_vec::<i32>()
            .map_err(read_error)?
            .into_iter()
            .map(f64::from)
            .collect(),
        other => {
            return Err(format!(
                "dtype `{other}` is not a number type kalibra reads (float64, float32, int64, \
                 int32)"
            ));
        }
    };
    if data.len() != shape.iter().product::<usize>() {
        return Err(format!(
            "holds {} values for shape {shape:?} (truncated?)",
            data.len()
        ));
    }
    Ok(Array { shape, data })
}

/// A per-cell array cut into its cells.
struct Cells {
    runs: usize,
    steps: usize,
    /// The shape of one cell (`[n]` or `[n, n]`).
    shape: Vec<usize>,
    /// Run-major cells, `None` where every value is NaN (not logged); kept as one buffer when
    /// every cell was logged.
    cells: CellValues,
}

/// The cells of a per-cell array with `cell_dims` trailing dimensions; a single run may drop
/// the leading R axis.
fn cells(array: &str, a: Array, cell_dims: usize) -> Result<Cells, String> {
    let (runs, rest) = match a.shape.len() - cell_dims.min(a.shape.len()) {
        2 => (a.shape[0], &a.shape[1..]),
        1 => (1, &a.shape[..]),
        _ => {
            let expected = if cell_dims == 1 {
                "(R, K, dim) or (K, dim)"
            } else {
                "(R, K, dim, dim) or (K, dim, dim)"
            };
            return Err(format!(
                "array {array} has shape {:?}; expected {expected}",
                a.shape
            ));
        }
    };
    let steps = rest[0];
    let cell_shape = rest[1..].to_vec();
    let size: usize = cell_shape.iter().product();
    let logged = |c: &[f64]| !c.iter().all(|v| v.is_nan());
    let cells = if size == 0 {
        CellValues::Sparse(vec![None; runs * steps])
    } else if a.data.chunks(size).all(logged) {
        CellValues::Dense(a.data)
    } else {
        CellValues::Sparse(
            a.data
                .chunks(size)
                .map(|c| logged(c).then(|| c.to_vec()))
                .collect(),
        )
    };
    Ok(Cells {
        runs,
        steps,
        shape: cell_shape,
        cells,
    })
}

/// The log from the named arrays.
pub(crate) fn build(
    mut arrays: std::collections::BTreeMap<String, Array>,
) -> Result<RawLog, String> {
    let known = [
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
    if let Some(unknown) = arrays.keys().find(|k| !known.contains(&k.as_str())) {
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
        log.time = Some(t.data);
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
                data: vec![],
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
                data: a.data,
            });
        }
        let [f, h, q, r]: [ModelArray; 4] = out
            .try_into()
            .map_err(|_| "arrays F, H, Q and R".to_string())?;
        log.model = Some([f, h, q, r]);
    }
    Ok(log)
}
