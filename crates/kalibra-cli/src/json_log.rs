//! The JSON log: an object of arrays with numpy's names and shapes (see `input::FORMATS_HELP`).
//!
//! Errors name the file and the array and index (`covariance[2][5][1]`), or the line and
//! column for text that is not JSON.

use std::path::Path;

use kalibra_eval::Scope;
use serde_json::Value;

use crate::input::{ModelArray, PER_CELL, RawLog, model_given};

const VECTORS: [&str; 3] = ["truth", "estimate", "innovation"];
const MATRICES: [&str; 2] = ["covariance", "innovation_cov"];
const MODEL: [&str; 4] = ["F", "H", "Q", "R"];
const KNOWN: &str = "truth, estimate, covariance, innovation, innovation_cov, time, F, H, Q, R";

/// An array's cells by run and step, each cell flat, with its shape.
struct Cells {
    runs: usize,
    steps: usize,
    rows: usize,
    /// 0 for vectors.
    cols: usize,
    cells: Vec<Option<Vec<f64>>>,
}

/// Reads the JSON log in `bytes` (from `file`, named in errors).
pub fn read(file: &Path, bytes: &[u8]) -> Result<RawLog, String> {
    let name = file.display();
    let value: Value = serde_json::from_slice(bytes).map_err(|e| {
        let what = match e.classify() {
            serde_json::error::Category::Eof => "the file ends early (truncated?)".to_string(),
            _ => format!("not valid JSON ({e})"),
        };
        format!("{name}: line {}, column {}: {what}", e.line(), e.column())
    })?;
    let Value::Object(map) = value else {
        return Err(format!(
            "{name}: expected an object of named arrays ({KNOWN}), found {}",
            kind(&value)
        ));
    };
    let known = |k: &str| {
        VECTORS.contains(&k) || MATRICES.contains(&k) || MODEL.contains(&k) || k == "time"
    };
    if let Some(unknown) = map.keys().find(|k| !known(k)) {
        return Err(format!(
            "{name}: unknown array `{unknown}`; the arrays are {KNOWN}"
        ));
    }
    let fail = |msg: String| format!("{name}: {msg}");

    let mut log = RawLog::default();
    for array in PER_CELL {
        let Some(v) = map.get(array) else { continue };
        let c = per_cell(array, v, MATRICES.contains(&array)).map_err(fail)?;
        log.put_cells(array, (c.runs, c.steps), (c.rows, c.cols), c.cells.into())
            .map_err(fail)?;
    }
    let (runs, steps) = log.require_cells().map_err(fail)?;
    if let Some(v) = map.get("time") {
        let times = numbers("time", v, &mut vec![]).map_err(fail)?;
        log.time = Some(times);
    }
    let present: Vec<&str> = MODEL
        .iter()
        .copied()
        .filter(|m| map.contains_key(*m))
        .collect();
    if model_given(&present).map_err(fail)? {
        let mut model = Vec::with_capacity(4);
        for array in MODEL {
            model.push(model_array(array, &map[array], runs, steps).map_err(fail)?);
        }
        let [f, h, q, r]: [ModelArray; 4] = model
            .try_into()
            .map_err(|_| fail("arrays F, H, Q and R".to_string()))?;
        log.model = Some([f, h, q, r]);
    }
    Ok(log)
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    }
}

/// `array[i][j]...` for error messages.
fn at(array: &str, index: &[usize]) -> String {
    let mut s = array.to_string();
    for i in index {
        s.push_str(&format!("[{i}]"));
    }
    s
}

fn list<'v>(array: &str, v: &'v Value, index: &[usize]) -> Result<&'v [Value], String> {
    match v {
        Value::Array(items) => Ok(items),
        other => Err(format!(
            "array {}: expected a list, found {}",
            at(array, index),
            kind(other)
        )),
    }
}

/// A list of numbers.
fn numbers(array: &str, v: &Value, index: &mut Vec<usize>) -> Result<Vec<f64>, String> {
    let items = list(array, v, index)?;
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        index.push(i);
        match item.as_f64() {
            Some(x) => out.push(x),
            None => {
                return Err(format!(
                    "array {}: expected a number, found {}",
                    at(array, index),
                    kind(item)
                ));
            }
        }
        index.pop();
    }
    Ok(out)
}

/// A vector (`cols == 0`) or a `rows x cols` matrix, flat; the size must match when given.
fn cell(
    array: &str,
    v: &Value,
    index: &mut Vec<usize>,
    size: Option<(usize, usize)>,
    matrix: bool,
) -> Result<(Vec<f64>, (usize, usize)), String> {
    let what = if matrix { "rows" } else { "values" };
    let check = |found: usize, expected: usize, index: &[usize], what: &str| {
        if found == expected {
            Ok(())
        } else {
            Err(format!(
                "array {}: expected {expected} {what}, found {found} (cells of one array have one \
                 shape)",
                at(array, index)
            ))
        }
    };
    if !matrix {
        let values = numbers(array, v, index)?;
        if let Some((rows, _)) = size {
            check(values.len(), rows, index, what)?;
        }
        let len = values.len();
        return Ok((values, (len, 0)));
    }
    let rows = list(array, v, index)?;
    if let Some((r, _)) = size {
        check(rows.len(), r, index, what)?;
    }
    let mut flat = Vec::new();
    let mut cols = size.map(|(_, c)| c);
    for (i, row) in rows.iter().enumerate() {
        index.push(i);
        let values = numbers(array, row, index)?;
        match cols {
            Some(c) => check(values.len(), c, index, "values")?,
            None => cols = Some(values.len()),
        }
        flat.extend(values);
        index.pop();
    }
    Ok((flat, (rows.len(), cols.unwrap_or(0))))
}

/// Depth of nested lists down to the first number, following the first non-null entry.
fn depth(v: &Value) -> Option<usize> {
    match v {
        Value::Array(items) => items
            .iter()
            .find(|i| !i.is_null())
            .and_then(depth)
            .map(|d| d + 1),
        Value::Number(_) => Some(0),
        _ => None,
    }
}

/// A per-cell array: `(R, K, ...)`, or `(K, ...)` for a single run; `null` cells.
fn per_cell(array: &'static str, v: &Value, matrix: bool) -> Result<Cells, String> {
    let cell_depth = if matrix { 2 } else { 1 };
    let d = depth(v).ok_or_else(|| {
        format!(
            "array {array} holds no numbers (expected shape {})",
            if matrix { "(R, K, n, n)" } else { "(R, K, n)" }
        )
    })?;
    let runs_axis = if d == cell_depth + 2 {
        true
    } else if d == cell_depth + 1 {
        false
    } else {
        return Err(format!(
            "array {array} has {d} axes, expected {} (runs, steps, {}) or {} for a single run",
            cell_depth + 2,
            if matrix { "rows, columns" } else { "values" },
            cell_depth + 1
        ));
    };
    let run_values: Vec<&Value> = if runs_axis {
        list(array, v, &[])?.iter().collect()
    } else {
        vec![v]
    };
    let runs = run_values.len();
    let mut steps = None;
    let mut size = None;
    let mut cells = Vec::new();
    for (r, run) in run_values.into_iter().enumerate() {
        let mut index = if runs_axis { vec![r] } else { vec![] };
        let items = list(array, run, &index)?;
        match steps {
            None => steps = Some(items.len()),
            Some(k) if k != items.len() => {
                return Err(format!(
                    "array {}: expected {k} steps (as run 0), found {}",
                    at(array, &index),
                    items.len()
                ));
            }
            Some(_) => {}
        }
        for (k, item) in items.iter().enumerate() {
            index.push(k);
            if item.is_null() {
                cells.push(None);
            } else {
                let (values, s) = cell(array, item, &mut index, size, matrix)?;
                size = Some(s);
                cells.push(Some(values));
            }
            index.pop();
        }
    }
    let (rows, cols) = size.unwrap_or((0, 0));
    let steps = steps.unwrap_or(0);
    if runs == 0 || steps == 0 {
        return Err(format!("array {array} is empty"));
    }
    Ok(Cells {
        runs,
        steps,
        rows,
        cols,
        cells,
    })
}

/// A model matrix: one `(rows, cols)` matrix, one per step `(K, ..)`, or one per run and step
/// `(R, K, ..)`; no null cells.
fn model_array(
    array: &'static str,
    v: &Value,
    runs: usize,
    steps: usize,
) -> Result<ModelArray, String> {
    let d = depth(v).ok_or_else(|| format!("array {array} holds no numbers"))?;
    let (scope, shape): (Scope, &[usize]) = match d {
        2 => (Scope::Constant, &[]),
        3 => (Scope::PerStep, &[steps]),
        4 => (Scope::PerRunStep, &[runs, steps]),
        _ => {
            return Err(format!(
                "array {array} has {d} axes, expected 2 (one matrix), 3 (one per step) or 4 \
                 (one per run and step)"
            ));
        }
    };
    let mut data = Vec::new();
    let mut size = None;
    walk_model(array, v, shape, &mut vec![], &mut size, &mut data)?;
    let (rows, cols) = size.unwrap_or((0, 0));
    Ok(ModelArray {
        rows,
        cols,
        scope,
        data,
    })
}

fn walk_model(
    array: &str,
    v: &Value,
    shape: &[usize],
    index: &mut Vec<usize>,
    size: &mut Option<(usize, usize)>,
    data: &mut Vec<f64>,
) -> Result<(), String> {
    let Some((&len, rest)) = shape.split_first() else {
        let (values, s) = cell(array, v, index, *size, true)?;
        *size = Some(s);
        data.extend(values);
        return Ok(());
    };
    let items = list(array, v, index)?;
    if items.len() != len {
        let axis = if rest.len() + 1 == shape.len() && shape.len() == 2 {
            "runs"
        } else {
            "steps"
        };
        return Err(format!(
            "array {}: expected {len} entries ({axis} of the log), found {}",
            at(array, index),
            items.len()
        ));
    }
    for (i, item) in items.iter().enumerate() {
        index.push(i);
        walk_model(array, item, rest, index, size, data)?;
        index.pop();
    }
    Ok(())
}
