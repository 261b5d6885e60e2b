//! The CSV log: one row per run and step (see `input::FORMATS_HELP`), evaluated as it is
//! read. Each row goes to a `kalibra_eval::Evaluator` as soon as it is parsed, so memory holds
//! the statistics (per step, and the `n + 1` numbers per valid cell that NCI needs), never the
//! file; a large file shows a progress bar when stderr is a terminal.
//!
//! Rows and columns in messages count from 1, the header being row 1, as a spreadsheet shows
//! them. Rows may come in any order (run after run is the usual one); every (run, step) of the
//! runs-by-steps rectangle needs exactly one row.

use std::fs::File;
use std::io::{IsTerminal, Read};
use std::path::Path;

use kalibra_eval::{Cell, Contents, EvalError, Evaluation, MatrixCell, Report};

use crate::csv_rows::Rows;
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

/// Files from this size on show a progress bar (when stderr is a terminal): about a second
/// of reading.
const PROGRESS_FROM_BYTES: u64 = 64 << 20;

/// Evaluates the CSV log `file` with `evaluation`, reading it once from start to end.
pub fn evaluate(file: &Path, evaluation: &Evaluation) -> Result<Report, String> {
    let name = file.display();
    let opened = File::open(file).map_err(|e| format!("{name}: cannot read the file: {e}"))?;
    let size = opened.metadata().map_or(0, |m| m.len());
    let progress = (size >= PROGRESS_FROM_BYTES && std::io::stderr().is_terminal()).then(|| {
        let bar = indicatif::ProgressBar::new(size);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg} {bar:40} {bytes}/{total_bytes} ({bytes_per_sec}, {eta} left)",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.set_message(format!("reading {name}"));
        bar
    });
    let source: Box<dyn Read> = match &progress {
        Some(bar) => Box::new(bar.wrap_read(opened)),
        None => Box::new(opened),
    };
    let result = stream(file, source, evaluation);
    if let Some(bar) = progress {
        bar.finish_and_clear();
    }
    result
}

/// The header's columns and the arrays' layouts, or the error naming the column at fault.
fn header<R: Read>(
    name: &impl std::fmt::Display,
    rows: &Rows<impl std::fmt::Display, R>,
) -> Result<(Vec<Column>, Vec<Layout>), String> {
    let header = &rows.header;
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
    for (want, label) in [(Column::Run, "run"), (Column::Step, "step")] {
        if !columns.contains(&want) {
            return Err(format!("{name}: row 1: missing column `{label}`"));
        }
    }
    let layouts = layouts(&columns).map_err(|e| format!("{name}: row 1: {e}"))?;
    if layouts.is_empty() {
        return Err(format!(
            "{name}: row 1: no data columns (truth_i, estimate_i, covariance_i_j, innovation_i, \
             innovation_cov_i_j)"
        ));
    }
    Ok((columns, layouts))
}

/// A cell's text as a number; `None` for an empty cell.
fn number(text: &[u8]) -> Result<Option<f64>, ()> {
    if text.is_empty() {
        return Ok(None);
    }
    std::str::from_utf8(text)
        .ok()
        .and_then(|t| t.parse::<f64>().ok())
        .map(Some)
        .ok_or(())
}

/// Reads the rows of `source` (the file `file`) into an evaluator and finishes it.
fn stream(file: &Path, source: impl Read, evaluation: &Evaluation) -> Result<Report, String> {
    let name = file.display();
    let mut rows = Rows::new(&name, source)?;
    let (columns, layouts) = header(&name, &rows)?;
    let find = |want: Column| columns.iter().position(|c| *c == want);
    let (run_col, step_col) = match (find(Column::Run), find(Column::Step)) {
        (Some(r), Some(s)) => (r, s),
        _ => return Err(format!("{name}: row 1: missing column `run` or `step`")),
    };
    let time_col = find(Column::Time);
    let mut contents = Contents::default();
    for l in &layouts {
        *match ARRAYS[l.array] {
            "truth" => &mut contents.truth,
            "estimate" => &mut contents.estimate,
            "covariance" => &mut contents.covariance,
            "innovation" => &mut contents.innovation,
            _ => &mut contents.innovation_cov,
        } = Some(l.dim);
    }
    let fail = |e: EvalError| format!("{name}: cannot evaluate the log: {e}");
    let mut evaluator = evaluation.evaluator(contents).map_err(fail)?;
    // Per array, the current row's values (reused from row to row) and whether logged.
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); ARRAYS.len()];
    let mut logged = [false; ARRAYS.len()];
    // Per step, the time and the row that gave it first.
    let mut times: Vec<Option<(f64, u64)>> = Vec::new();
    let mut record = csv::ByteRecord::new();
    let mut any = false;
    while let Some(line) = rows.next_byte_row(&mut record)? {
        any = true;
        let text = |c: usize| String::from_utf8_lossy(&record[c]).into_owned();
        let not_number =
            |c: usize| rows.cell_error(line, c, format!("`{}` is not a number", text(c)));
        let index = |c: usize| -> Result<usize, String> {
            if record[c].is_empty() {
                return Err(rows.cell_error(
                    line,
                    c,
                    "empty; every row names its run and step".into(),
                ));
            }
            std::str::from_utf8(&record[c])
                .ok()
                .and_then(|t| t.parse::<usize>().ok())
                .ok_or_else(|| {
                    rows.cell_error(
                        line,
                        c,
                        format!("`{}` is not a whole number (0, 1, ...)", text(c)),
                    )
                })
        };
        let run = index(run_col)?;
        let step = index(step_col)?;
        for layout in &layouts {
            let out = &mut values[layout.array];
            out.clear();
            let mut first_empty = None;
            for &c in &layout.columns {
                match number(&record[c]) {
                    Ok(Some(v)) => out.push(v),
                    Ok(None) => {
                        first_empty.get_or_insert(c);
                    }
                    Err(()) => return Err(not_number(c)),
                }
            }
            logged[layout.array] = !out.is_empty();
            if let (Some(empty), false) = (first_empty, out.is_empty()) {
                let full = layout
                    .columns
                    .iter()
                    .copied()
                    .find(|&c| !record[c].is_empty())
                    .unwrap_or(empty);
                return Err(rows.cell_error(
                    line,
                    empty,
                    format!(
                        "empty, but column {} ({}) is not; {} is logged whole or not at all",
                        full + 1,
                        &rows.header[full],
                        ARRAYS[layout.array]
                    ),
                ));
            }
        }
        if let Some(c) = time_col {
            let t = number(&record[c]).map_err(|()| not_number(c))?;
            if let Some(t) = t {
                if step >= times.len() {
                    times.resize(step + 1, None);
                }
                match times[step] {
                    None => times[step] = Some((t, line)),
                    Some((first, first_line)) if first.to_bits() != t.to_bits() => {
                        return Err(rows.cell_error(
                            line,
                            c,
                            format!(
                                "{t} differs from row {first_line}'s time {first} for step \
                                 {step} (the times are per step, the same in every run)"
                            ),
                        ));
                    }
                    Some(_) => {}
                }
            }
        }
        let vector = |a: usize| logged[a].then(|| values[a].as_slice());
        let matrix = |a: usize, diagonal: bool| {
            logged[a].then(|| {
                if diagonal {
                    MatrixCell::Diagonal(values[a].as_slice())
                } else {
                    MatrixCell::Full(values[a].as_slice())
                }
            })
        };
        let diagonal = |a: usize| layouts.iter().any(|l| l.array == a && l.diagonal);
        let cell = Cell {
            truth: vector(0),
            estimate: vector(1),
            innovation: vector(2),
            covariance: matrix(3, diagonal(3)),
            innovation_cov: matrix(4, diagonal(4)),
            model: None,
        };
        evaluator.push(run, step, &cell).map_err(|e| match e {
            EvalError::DuplicateCell { run, step } => rows.row_error(
                line,
                format!("run {run}, step {step} already given in an earlier row"),
            ),
            other => rows.row_error(line, format!("cannot evaluate the log: {other}")),
        })?;
    }
    if !any {
        return Err(format!("{name}: no data rows after the header"));
    }
    let times = match time_col {
        None => None,
        Some(_) => {
            let steps = evaluator.steps();
            Some(
                (0..steps)
                    .map(|k| {
                        times
                            .get(k)
                            .copied()
                            .flatten()
                            .map(|(t, _)| t)
                            .ok_or_else(|| format!("{name}: column time: no time for step {k}"))
                    })
                    .collect::<Result<Vec<_>, _>>()?,
            )
        }
    };
    evaluator.finish(times).map_err(|e| match e {
        EvalError::MissingCell { run, step, steps } => format!(
            "{name}: no row for run {run}, step {step} (every run needs a row for every step \
             0..{}; is the file truncated?)",
            steps - 1
        ),
        other => fail(other),
    })
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
