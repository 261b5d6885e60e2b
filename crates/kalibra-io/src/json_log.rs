//! The JSON log: an object of arrays with numpy's names and shapes (see `input::FORMATS_HELP`).
//!
//! Python's `json.dump` writes NaN, Infinity and -Infinity as the bare tokens `NaN`,
//! `Infinity` and `-Infinity` (its default `allow_nan=True`), which are not JSON; they are read
//! wherever a value may stand, with the NPZ reader's meaning: a cell (one run and step) whose
//! values are all NaN was not logged, as `null`; a cell with only some NaN or infinite values
//! is kept, so that a NaN covariance is a finding about the filter under test.
//!
//! Errors name the file and the array and index (`covariance[2][5][1]`), or the line and
//! column for text that is not JSON.

use std::borrow::Cow;
use std::path::Path;

use kalibra_eval::Scope;
use serde_json::Value;

use crate::error::Error;
use crate::raw::{ARRAY_NAMES, KNOWN, MODEL, ModelArray, PER_CELL, RawLog, model_given};

const MATRICES: [&str; 2] = ["covariance", "innovation_cov"];

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
pub(crate) fn read(file: &Path, bytes: &[u8]) -> Result<RawLog<'static>, Error> {
    let text_error = |line, column, message| Error::Json {
        file: file.to_path_buf(),
        line: Some(line),
        column: Some(column),
        message,
    };
    let bytes = python_floats(bytes).map_err(|(line, column, literal)| {
        text_error(
            line,
            column,
            format!(
                "unexpected string {literal:?}; a log's only strings are the names of its \
                 arrays ({KNOWN})"
            ),
        )
    })?;
    let value: Value = serde_json::from_slice(&bytes).map_err(|e| {
        let what = match e.classify() {
            serde_json::error::Category::Eof => "the file ends early (truncated?)".to_string(),
            _ => format!("not valid JSON ({e})"),
        };
        text_error(e.line(), e.column(), what)
    })?;
    // A copy made for stand-ins is not needed past parsing: free it before the cells are built.
    drop(bytes);
    let Value::Object(map) = value else {
        return Err(Error::Json {
            file: file.to_path_buf(),
            line: None,
            column: None,
            message: format!(
                "expected an object of named arrays ({KNOWN}), found {}",
                kind(&value)
            ),
        });
    };
    if let Some(unknown) = map.keys().find(|k| !ARRAY_NAMES.contains(&k.as_str())) {
        return Err(Error::array(
            unknown.clone(),
            format!("unknown array `{unknown}`; the arrays are {KNOWN}"),
        )
        .in_file(file));
    }
    let fail = |e: Error| e.in_file(file);

    let mut log = RawLog::default();
    for array in PER_CELL {
        let Some(v) = map.get(array) else { continue };
        let c = per_cell(array, v, MATRICES.contains(&array)).map_err(fail)?;
        log.put_cells(array, (c.runs, c.steps), (c.rows, c.cols), c.cells.into())
            .map_err(fail)?;
    }
    let (runs, steps) = log.require_cells().map_err(fail)?;
    (log.time, log.model) = time_and_model(|name| map.get(name), runs, steps).map_err(fail)?;
    Ok(log)
}

/// The times and the model `F`, `H`, `Q`, `R` of a log, each if given.
pub(crate) type TimeAndModel = (Option<Vec<f64>>, Option<[ModelArray; 4]>);

/// The arrays read whole whatever the log's size, `time` and the model `F`, `H`, `Q`, `R`,
/// from the top-level object's values (`get` by name), for a log of `runs x steps` cells.
fn time_and_model<'v>(
    get: impl Fn(&str) -> Option<&'v Value>,
    runs: usize,
    steps: usize,
) -> Result<TimeAndModel, Error> {
    let time = match get("time") {
        Some(v) => Some(numbers("time", v, &mut vec![])?),
        None => None,
    };
    let present: Vec<&str> = MODEL.iter().copied().filter(|m| get(m).is_some()).collect();
    if !model_given(&present)? {
        return Ok((time, None));
    }
    let mut model = Vec::with_capacity(4);
    for array in MODEL {
        let v = get(array).ok_or_else(|| Error::log("arrays F, H, Q and R"))?;
        model.push(model_array(array, v, runs, steps)?);
    }
    let [f, h, q, r]: [ModelArray; 4] = model
        .try_into()
        .map_err(|_| Error::log("arrays F, H, Q and R"))?;
    Ok((time, Some([f, h, q, r])))
}

/// The small arrays of a streamed log (`json_stream`): each array's name and the text of its
/// value, read with the rules of [`read`].
pub(crate) fn small_arrays(
    texts: &[(&'static str, Vec<u8>)],
    runs: usize,
    steps: usize,
) -> Result<TimeAndModel, Error> {
    let mut values = Vec::with_capacity(texts.len());
    for (name, text) in texts {
        let text = python_floats(text).map_err(|(_, _, s)| Error::log(s))?;
        let value: Value = serde_json::from_slice(&text).map_err(|e| Error::log(e.to_string()))?;
        values.push((*name, value));
    }
    time_and_model(
        |name| values.iter().find(|(n, _)| *n == name).map(|(_, v)| v),
        runs,
        steps,
    )
}

/// One of Python's tokens for a float JSON has no word for, and the stand-in it is read as.
struct PythonFloat {
    /// As `json.dump` writes it.
    token: &'static str,
    /// The JSON that replaces it before serde_json reads the file: a string of one character
    /// that no valid log holds, exactly as long as the token, so that serde_json's line and
    /// column of a later syntax error are still those of the file as written.
    stand_in: &'static [u8],
    /// The stand-in as serde_json reads it.
    read_as: &'static str,
    value: f64,
}

const PYTHON_FLOATS: [PythonFloat; 3] = [
    PythonFloat {
        token: "NaN",
        stand_in: b"\"\x7f\"",
        read_as: "\u{7f}",
        value: f64::NAN,
    },
    PythonFloat {
        token: "Infinity",
        stand_in: br#""\u0001""#,
        read_as: "\u{1}",
        value: f64::INFINITY,
    },
    PythonFloat {
        token: "-Infinity",
        stand_in: br#""\u0002" "#,
        read_as: "\u{2}",
        value: f64::NEG_INFINITY,
    },
];

/// The Python token a string read by serde_json stands in for.
fn python_float(s: &str) -> Option<&'static PythonFloat> {
    PYTHON_FLOATS.iter().find(|p| p.read_as == s)
}

/// `bytes` with each of Python's `NaN`, `Infinity` and `-Infinity` that stands where a value
/// may (the start of the file, after `[`, `:`, or a list's `,`) replaced by its stand-in
/// ([`PYTHON_FLOATS`]), in one pass; a copy only if there is one. Text inside strings is
/// left as it is. A string in the file that reads as a stand-in would be taken for a number,
/// so it is refused, with its line, column and text: no valid log holds one, since its only
/// strings are array names. A file that is not JSON is left for serde_json to locate.
fn python_floats(bytes: &[u8]) -> Result<Cow<'_, [u8]>, (usize, usize, String)> {
    // The longest spelling of a one-character stand-in: `"\u0001"`.
    const LONGEST_STAND_IN: usize = 8;
    let mut out = Cow::Borrowed(bytes);
    // The lists and objects open at `i`, innermost last: after a comma, a list takes a value
    // and an object a key.
    let mut open = Vec::new();
    // The last byte before `i` outside strings and whitespace (`"` for a string).
    let mut last = None;
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        match b {
            b' ' | b'\t' | b'\n' | b'\r' => {
                i += 1;
                continue;
            }
            b'"' => {
                let end = string_end(bytes, i);
                let literal = &bytes[i..end];
                if literal.len() <= LONGEST_STAND_IN
                    && let Ok(s) = serde_json::from_slice::<String>(literal)
                    && python_float(&s).is_some()
                {
                    let line_start = bytes[..i]
                        .iter()
                        .rposition(|&c| c == b'\n')
                        .map_or(0, |p| p + 1);
                    let line = bytes[..i].iter().filter(|&&c| c == b'\n').count() + 1;
                    return Err((line, i - line_start + 1, s));
                }
                last = Some(b'"');
                i = end;
                continue;
            }
            // The first bytes of the tokens: the only place a token can start.
            b'N' | b'I' | b'-' => {
                let value_here = match last {
                    None | Some(b'[' | b':') => true,
                    Some(b',') => open.last() == Some(&b'['),
                    Some(_) => false,
                };
                if value_here
                    && let Some(p) = PYTHON_FLOATS
                        .iter()
                        .find(|p| bytes[i..].starts_with(p.token.as_bytes()))
                {
                    let end = i + p.token.len();
                    out.to_mut()[i..end].copy_from_slice(p.stand_in);
                    last = Some(b'"');
                    i = end;
                    continue;
                }
            }
            b'[' | b'{' => open.push(b),
            b']' | b'}' => {
                open.pop();
            }
            _ => {}
        }
        last = Some(b);
        i += 1;
    }
    Ok(out)
}

/// The end (one past the closing quote) of the string literal opening at `start`, or the end
/// of `bytes` for an unterminated one.
fn string_end(bytes: &[u8], start: usize) -> usize {
    let mut i = start + 1;
    while i < bytes.len() {
        match bytes[i] {
            b'\\' => i += 2,
            b'"' => return i + 1,
            _ => i += 1,
        }
    }
    bytes.len()
}

/// The number `v` stands for: a JSON number, or one of Python's tokens.
fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => python_float(s).map(|p| p.value),
        _ => None,
    }
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(s) => python_float(s).map_or("a string", |p| p.token),
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

/// The error `array {array[i][j]...}: {what}` at `index` of `array`.
fn at_error(array: &str, index: &[usize], what: String) -> Error {
    Error::Array {
        file: None,
        array: array.to_string(),
        index: index.to_vec(),
        message: format!("array {}: {what}", at(array, index)),
    }
}

fn list<'v>(array: &str, v: &'v Value, index: &[usize]) -> Result<&'v [Value], Error> {
    match v {
        Value::Array(items) => Ok(items),
        other => Err(at_error(
            array,
            index,
            format!("expected a list, found {}", kind(other)),
        )),
    }
}

/// A list of numbers.
fn numbers(array: &str, v: &Value, index: &mut Vec<usize>) -> Result<Vec<f64>, Error> {
    let items = list(array, v, index)?;
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        index.push(i);
        match number(item) {
            Some(x) => out.push(x),
            None => {
                return Err(at_error(
                    array,
                    index,
                    format!("expected a number, found {}", kind(item)),
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
) -> Result<(Vec<f64>, (usize, usize)), Error> {
    let what = if matrix { "rows" } else { "values" };
    let check = |found: usize, expected: usize, index: &[usize], what: &str| {
        if found == expected {
            Ok(())
        } else {
            Err(at_error(
                array,
                index,
                format!(
                    "expected {expected} {what}, found {found} (cells of one array have one shape)"
                ),
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
        v if number(v).is_some() => Some(0),
        _ => None,
    }
}

/// A per-cell array: `(R, K, ...)`, or `(K, ...)` for a single run; `null` cells.
fn per_cell(array: &'static str, v: &Value, matrix: bool) -> Result<Cells, Error> {
    let cell_depth = if matrix { 2 } else { 1 };
    let d = depth(v).ok_or_else(|| {
        Error::array(
            array,
            format!(
                "array {array} holds no numbers (expected shape {})",
                if matrix { "(R, K, n, n)" } else { "(R, K, n)" }
            ),
        )
    })?;
    let runs_axis = if d == cell_depth + 2 {
        true
    } else if d == cell_depth + 1 {
        false
    } else {
        return Err(Error::array(
            array,
            format!(
                "array {array} has {d} axes, expected {} (runs, steps, {}) or {} for a single run",
                cell_depth + 2,
                if matrix { "rows, columns" } else { "values" },
                cell_depth + 1
            ),
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
                return Err(at_error(
                    array,
                    &index,
                    format!("expected {k} steps (as run 0), found {}", items.len()),
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
                // All NaN is how a numpy array (and Python's json.dump of its list) marks a
                // value not logged, as in the NPZ reader; some NaN is a finding, kept.
                let logged = values.is_empty() || !values.iter().all(|v| v.is_nan());
                cells.push(logged.then_some(values));
            }
            index.pop();
        }
    }
    let (rows, cols) = size.unwrap_or((0, 0));
    let steps = steps.unwrap_or(0);
    if runs == 0 || steps == 0 {
        return Err(Error::array(array, format!("array {array} is empty")));
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
) -> Result<ModelArray, Error> {
    let d =
        depth(v).ok_or_else(|| Error::array(array, format!("array {array} holds no numbers")))?;
    let (scope, shape): (Scope, &[usize]) = match d {
        2 => (Scope::Constant, &[]),
        3 => (Scope::PerStep, &[steps]),
        4 => (Scope::PerRunStep, &[runs, steps]),
        _ => {
            return Err(Error::array(
                array,
                format!(
                    "array {array} has {d} axes, expected 2 (one matrix), 3 (one per step) or 4 \
                     (one per run and step)"
                ),
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
) -> Result<(), Error> {
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
        return Err(at_error(
            array,
            index,
            format!(
                "expected {len} entries ({axis} of the log), found {}",
                items.len()
            ),
        ));
    }
    for (i, item) in items.iter().enumerate() {
        index.push(i);
        walk_model(array, item, rest, index, size, data)?;
        index.pop();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rewritten(text: &str) -> Vec<u8> {
        python_floats(text.as_bytes()).unwrap().into_owned()
    }

    #[test]
    fn stand_ins_are_as_long_as_their_tokens_and_read_as_said() {
        for p in &PYTHON_FLOATS {
            assert_eq!(p.stand_in.len(), p.token.len(), "{}", p.token);
            let read: String = serde_json::from_slice(p.stand_in.trim_ascii_end()).unwrap();
            assert_eq!(read, p.read_as);
        }
    }

    #[test]
    fn tokens_become_stand_ins_of_their_length_where_values_stand() {
        let text = r#"{"a": [NaN, -Infinity, [Infinity, 1e3]], "b": NaN}"#;
        let out = rewritten(text);
        assert_eq!(out.len(), text.len());
        let value: Value = serde_json::from_slice(&out).unwrap();
        let numbers: Vec<f64> = [&value["a"][0], &value["a"][1], &value["a"][2][0]]
            .into_iter()
            .map(|v| number(v).unwrap())
            .collect();
        assert!(numbers[0].is_nan());
        assert_eq!(numbers[1..], [f64::NEG_INFINITY, f64::INFINITY]);
        assert_eq!(number(&value["a"][2][1]), Some(1e3));
        assert!(number(&value["b"]).unwrap().is_nan());
    }

    #[test]
    fn text_without_tokens_is_borrowed_and_strings_are_untouched() {
        let text = r#"{"NaN": ["Infinity", "x\"NaN", "-Infinity\\"], "k": [1, -2.5e-3]}"#;
        assert!(matches!(
            python_floats(text.as_bytes()),
            Ok(Cow::Borrowed(_))
        ));
    }

    #[test]
    fn tokens_where_no_value_stands_are_left_for_serde_json_to_refuse() {
        for text in [
            r#"{NaN: 1}"#,
            r#"{"a": 1, Infinity: 2}"#,
            "[1 -Infinity]",
            "[1]NaN",
        ] {
            assert_eq!(rewritten(text), text.as_bytes());
        }
        assert_eq!(rewritten("[NaN NaN]"), b"[\"\x7f\" NaN]");
    }

    #[test]
    fn every_spelling_of_a_stand_in_is_refused_with_its_place() {
        for literal in [
            "\"\x7f\"",
            r#""\u007f""#,
            r#""\u007F""#,
            r#""\u0001""#,
            r#""\u0002""#,
        ] {
            let text = format!("{{\"a\":\n  [{literal}]}}");
            let (line, column, s) = python_floats(text.as_bytes()).unwrap_err();
            assert_eq!((line, column), (2, 4), "{literal}");
            assert!(python_float(&s).is_some());
        }
        // Longer strings holding those characters are only text.
        assert!(python_floats(br#"["\u0001\u0001", "a\u007f"]"#).is_ok());
    }
}
