//! The CSV log: one row per run and step (see `input::FORMATS_HELP`).
//!
//! Rows and columns in messages count from 1, the header being row 1, as a spreadsheet shows
//! them. The whole file is read before the log is built (streaming is a later step).

use std::path::Path;

use crate::csv_rows::Rows;
use crate::input::{MatrixArray, RawLog, VectorArray};

/// The per-cell arrays, vectors first.
const ARRAYS: [&str; 5] = [
    "truth",
    "estimate",
    "innovation",
    "covariance",
    "innovation_cov",
];
const FIRST_MATRIX: usize = 3;

/// What a header column holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Column {
    Run,
    Step,
    Time,
    /// Array (index into `ARRAYS`) and component.
    Vector(usize, usize),
    /// Array and entry `(i, j)`.
    Matrix(usize, usize, usize),
}

/// How one array's columns map to its cell values.
struct Layout {
    array: usize,
    dim: usize,
    diagonal: bool,
    /// For each value of a cell in order, its column (0-based).
    columns: Vec<usize>,
}

/// One data row, as read.
struct Row {
    line: u64,
    run: usize,
    step: usize,
    time: Option<f64>,
    cells: Vec<Option<Vec<f64>>>,
}

fn parse_column(name: &str) -> Option<Column> {
    match name {
        "run" => return Some(Column::Run),
        "step" => return Some(Column::Step),
        "time" => return Some(Column::Time),
        _ => {}
    }
    // Matrices first: `innovation_cov_0_1` also starts with `innovation_`.
    for (a, array) in ARRAYS.iter().enumerate().skip(FIRST_MATRIX) {
        if let Some(rest) = name.strip_prefix(array).and_then(|r| r.strip_prefix('_')) {
            let (i, j) = rest.split_once('_')?;
            return Some(Column::Matrix(a, i.parse().ok()?, j.parse().ok()?));
        }
    }
    for (a, array) in ARRAYS.iter().enumerate().take(FIRST_MATRIX) {
        if let Some(rest) = name.strip_prefix(array).and_then(|r| r.strip_prefix('_')) {
            return Some(Column::Vector(a, rest.parse().ok()?));
        }
    }
    None
}

/// Reads the CSV log in `bytes` (from `file`, named in errors).
pub fn read(file: &Path, bytes: &[u8]) -> Result<RawLog, String> {
    let name = file.display();
    let mut rows_in = Rows::new(&name, bytes)?;
    let header = rows_in.header.clone();
    let columns = header
        .iter()
        .enumerate()
        .map(|(c, h)| {
            parse_column(h).ok_or_else(|| {
                format!(
                    "{name}: row 1, column {}: unknown column `{h}`; the columns are run, step, \
                     time, truth_i, estimate_i, covariance_i_j, innovation_i, \
                     innovation_cov_i_j (i, j from 0)",
                    c + 1
                )
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    for (c, col) in columns.iter().enumerate() {
        if let Some(first) = columns[..c].iter().position(|x| x == col) {
            return Err(format!(
                "{name}: row 1, column {}: column `{}` repeats column {}",
                c + 1,
                &header[c],
                first + 1
            ));
        }
    }
    let find = |want: Column| columns.iter().position(|c| *c == want);
    let run_col =
        find(Column::Run).ok_or_else(|| format!("{name}: row 1: missing column `run`"))?;
    let step_col =
        find(Column::Step).ok_or_else(|| format!("{name}: row 1: missing column `step`"))?;
    let time_col = find(Column::Time);
    let layouts = layouts(&columns).map_err(|e| format!("{name}: row 1: {e}"))?;
    if layouts.is_empty() {
        return Err(format!(
            "{name}: row 1: no data columns (truth_i, estimate_i, covariance_i_j, innovation_i, \
             innovation_cov_i_j)"
        ));
    }

    let mut rows = Vec::new();
    let mut record = csv::StringRecord::new();
    while let Some(line) = rows_in.next_row(&mut record)? {
        let cell_error = |c: usize, msg: String| rows_in.cell_error(line, c, msg);
        let number = |c: usize| -> Result<Option<f64>, String> {
            let text = &record[c];
            if text.is_empty() {
                return Ok(None);
            }
            text.parse::<f64>()
                .map(Some)
                .map_err(|_| cell_error(c, format!("`{text}` is not a number")))
        };
        let index = |c: usize| -> Result<usize, String> {
            let text = &record[c];
            if text.is_empty() {
                return Err(cell_error(
                    c,
                    "empty; every row names its run and step".into(),
                ));
            }
            text.parse::<usize>()
                .map_err(|_| cell_error(c, format!("`{text}` is not a whole number (0, 1, ...)")))
        };
        let run = index(run_col)?;
        let step = index(step_col)?;
        let time = time_col.map(number).transpose()?.flatten();
        let mut cells = vec![None; ARRAYS.len()];
        for layout in &layouts {
            let values = layout
                .columns
                .iter()
                .map(|&c| number(c))
                .collect::<Result<Vec<_>, _>>()?;
            let logged = values.iter().filter(|v| v.is_some()).count();
            if logged == 0 {
                continue;
            }
            if let Some(k) = values.iter().position(Option::is_none) {
                let full = layout.columns[values.iter().position(Option::is_some).unwrap_or(0)];
                return Err(cell_error(
                    layout.columns[k],
                    format!(
                        "empty, but column {} ({}) is not; {} is logged whole or not at all",
                        full + 1,
                        &header[full],
                        ARRAYS[layout.array]
                    ),
                ));
            }
            cells[layout.array] = Some(values.into_iter().flatten().collect());
        }
        rows.push(Row {
            line,
            run,
            step,
            time,
            cells,
        });
    }
    assemble(&name.to_string(), rows, &layouts, time_col.is_some())
}

/// The arrays' layouts from the header: every component of a vector, every entry of a full
/// matrix or every diagonal entry.
fn layouts(columns: &[Column]) -> Result<Vec<Layout>, String> {
    let mut out = Vec::new();
    for (a, array) in ARRAYS.iter().enumerate() {
        let mut entries: Vec<(usize, usize, usize)> = columns
            .iter()
            .enumerate()
            .filter_map(|(c, col)| match *col {
                Column::Vector(x, i) if x == a => Some((i, 0, c)),
                Column::Matrix(x, i, j) if x == a => Some((i, j, c)),
                _ => None,
            })
            .collect();
        if entries.is_empty() {
            continue;
        }
        entries.sort_unstable();
        let dim = entries.iter().map(|&(i, j, _)| i.max(j)).max().unwrap_or(0) + 1;
        let column = |i: usize, j: usize| {
            entries
                .iter()
                .find(|&&(x, y, _)| (x, y) == (i, j))
                .map(|&(_, _, c)| c)
        };
        let matrix = a >= FIRST_MATRIX;
        let diagonal = matrix && entries.iter().all(|&(i, j, _)| i == j);
        let wanted: Vec<(usize, usize)> = if !matrix {
            (0..dim).map(|i| (i, 0)).collect()
        } else if diagonal {
            (0..dim).map(|i| (i, i)).collect()
        } else {
            (0..dim)
                .flat_map(|i| (0..dim).map(move |j| (i, j)))
                .collect()
        };
        let mut cols = Vec::with_capacity(wanted.len());
        for (i, j) in wanted {
            let c = column(i, j).ok_or_else(|| {
                if !matrix {
                    format!(
                        "missing column `{array}_{i}` ({array}_0 to {array}_{} expected)",
                        dim - 1
                    )
                } else {
                    format!(
                        "missing column `{array}_{i}_{j}` ({array} columns are every \
                         {array}_i_j for i, j below {dim}, or the diagonal {array}_i_i alone)"
                    )
                }
            })?;
            cols.push(c);
        }
        out.push(Layout {
            array: a,
            dim,
            diagonal,
            columns: cols,
        });
    }
    // The state arrays share n, the innovation arrays m: a smaller one lacks columns.
    for group in [[0, 1, 3], [2, 4, 4]] {
        let in_group = || out.iter().filter(|l| group.contains(&l.array));
        let Some(widest) = in_group().max_by_key(|l| l.dim) else {
            continue;
        };
        if let Some(short) = in_group().find(|l| l.dim < widest.dim) {
            let array = ARRAYS[short.array];
            let missing = if short.array >= FIRST_MATRIX {
                format!("{array}_{0}_{0}", short.dim)
            } else {
                format!("{array}_{}", short.dim)
            };
            return Err(format!(
                "missing column `{missing}` ({} has {} components, {array} {})",
                ARRAYS[widest.array], widest.dim, short.dim
            ));
        }
    }
    Ok(out)
}

/// Orders the rows by run and step, checks that every (run, step) appears exactly once and
/// that the times agree across runs, and builds the arrays.
fn assemble(
    name: &str,
    mut rows: Vec<Row>,
    layouts: &[Layout],
    has_time: bool,
) -> Result<RawLog, String> {
    if rows.is_empty() {
        return Err(format!("{name}: no data rows after the header"));
    }
    rows.sort_by_key(|r| (r.run, r.step, r.line));
    for pair in rows.windows(2) {
        if (pair[0].run, pair[0].step) == (pair[1].run, pair[1].step) {
            let (first, second) = if pair[0].line < pair[1].line {
                (&pair[0], &pair[1])
            } else {
                (&pair[1], &pair[0])
            };
            return Err(format!(
                "{name}: row {}: run {}, step {} already given in row {}",
                second.line, second.run, second.step, first.line
            ));
        }
    }
    let runs = rows.iter().map(|r| r.run).max().unwrap_or(0) + 1;
    let steps = rows.iter().map(|r| r.step).max().unwrap_or(0) + 1;
    if runs.checked_mul(steps) != Some(rows.len()) {
        let missing = (0..)
            .map(|i| (i / steps, i % steps))
            .zip(&rows)
            .find(|((r, k), row)| (row.run, row.step) != (*r, *k))
            .map(|(rk, _)| rk)
            .unwrap_or((rows.len() / steps, rows.len() % steps));
        return Err(format!(
            "{name}: no row for run {}, step {} (every run needs a row for every step 0..{}; \
             is the file truncated?)",
            missing.0,
            missing.1,
            steps - 1
        ));
    }
    let mut log = RawLog {
        runs,
        steps,
        ..RawLog::default()
    };
    if has_time {
        let mut times: Vec<Option<(f64, u64)>> = vec![None; steps];
        for row in &rows {
            let Some(t) = row.time else { continue };
            match times[row.step] {
                None => times[row.step] = Some((t, row.line)),
                Some((first, line)) if first.to_bits() != t.to_bits() => {
                    return Err(format!(
                        "{name}: row {}, column time: {t} differs from row {line}'s time {first} \
                         for step {} (the times are per step, the same in every run)",
                        row.line, row.step
                    ));
                }
                Some(_) => {}
            }
        }
        let mut out = Vec::with_capacity(steps);
        for (k, t) in times.into_iter().enumerate() {
            out.push(
                t.map(|(t, _)| t)
                    .ok_or_else(|| format!("{name}: column time: no time for step {k}"))?,
            );
        }
        log.time = Some(out);
    }
    for layout in layouts {
        let cells: Vec<Option<Vec<f64>>> = rows
            .iter_mut()
            .map(|r| r.cells[layout.array].take())
            .collect();
        if layout.array >= FIRST_MATRIX {
            let m = MatrixArray {
                dim: layout.dim,
                diagonal: layout.diagonal,
                cells: cells.into(),
            };
            if ARRAYS[layout.array] == "covariance" {
                log.covariance = Some(m);
            } else {
                log.innovation_cov = Some(m);
            }
        } else {
            let v = VectorArray {
                dim: layout.dim,
                cells: cells.into(),
            };
            match ARRAYS[layout.array] {
                "truth" => log.truth = Some(v),
                "estimate" => log.estimate = Some(v),
                _ => log.innovation = Some(v),
            }
        }
    }
    Ok(log)
}
