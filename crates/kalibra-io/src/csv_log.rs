//! The CSV log: one row per run and step (see `input::FORMATS_HELP`), evaluated as it is
//! read. Each row goes to a `kalibra_eval::Evaluator` as soon as it is parsed, so memory holds
//! the statistics (per step, and the `n + 1` numbers per valid cell that NCI needs), never the
//! file; a large file shows a progress bar when stderr is a terminal.
//!
//! Rows go to the evaluator as they come, run after run in a file written so, not in the
//! strips of 32 steps across the runs that `kalibra_eval::Evaluation::evaluate` feeds: a strip
//! across all runs needs a row of every run, that is the whole file in memory; strips across
//! groups of whole runs would not, but their gain for one evaluator, which `cargo xtask bench
//! eval` times (the figures `npz: evaluate, run after run / ...`), did not hold from one run
//! to the next on a shared machine.
//!
//! Rows and columns in messages count from 1, the header being row 1, as a spreadsheet shows
//! them. Rows may come in any order (run after run is the usual one); every (run, step) of the
//! runs-by-steps rectangle needs exactly one row.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{IsTerminal, Read};
use std::path::Path;
use std::sync::{Mutex, mpsc};

use kalibra_eval::{Cell, Contents, EvalError, Evaluation, MatrixCell, Report};

use crate::csv_rows::Rows;
use crate::error::Error;

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
pub(crate) fn evaluate(file: &Path, evaluation: &Evaluation) -> Result<Report, Error> {
    let opened = File::open(file).map_err(|e| Error::read(file, e))?;
    // The size of a regular file bounds the rows it can hold (a pipe's is unknown).
    let known_size = opened
        .metadata()
        .ok()
        .filter(std::fs::Metadata::is_file)
        .map(|m| m.len());
    let size = known_size.unwrap_or(0);
    let progress = (size >= PROGRESS_FROM_BYTES && std::io::stderr().is_terminal()).then(|| {
        let bar = indicatif::ProgressBar::new(size);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg} {bar:40} {bytes}/{total_bytes} ({bytes_per_sec}, {eta} left)",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.set_message(format!("reading {}", file.display()));
        bar
    });
    let source: Box<dyn Read + Send> = match &progress {
        Some(bar) => Box::new(bar.wrap_read(opened)),
        None => Box::new(opened),
    };
    let result = stream(file, source, known_size, evaluation);
    if let Some(bar) = progress {
        bar.finish_and_clear();
    }
    result
}

/// Evaluates the CSV log held in `bytes` (the file `file`, as messages name it).
pub(crate) fn evaluate_bytes(
    file: &Path,
    bytes: &[u8],
    evaluation: &Evaluation,
) -> Result<Report, Error> {
    stream(file, bytes, Some(bytes.len() as u64), evaluation)
}

/// The header's columns and the arrays' layouts, or the error naming the column at fault.
fn header<R: Read>(file: &Path, rows: &Rows<'_, R>) -> Result<(Vec<Column>, Vec<Layout>), Error> {
    let header = &rows.header;
    let columns = header
        .iter()
        .enumerate()
        .map(|(c, h)| {
            parse_column(h).ok_or_else(|| {
                rows.header_error(
                    c,
                    format!(
                        "unknown column `{h}`; the columns are run, step, time, truth_i, \
                         estimate_i, covariance_i_j, innovation_i, innovation_cov_i_j (i, j \
                         from 0)"
                    ),
                )
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    for (c, col) in columns.iter().enumerate() {
        if let Some(first) = columns[..c].iter().position(|x| x == col) {
            return Err(rows.header_error(
                c,
                format!("column `{}` repeats column {}", &header[c], first + 1),
            ));
        }
    }
    for (want, label) in [(Column::Run, "run"), (Column::Step, "step")] {
        if !columns.contains(&want) {
            return Err(Error::csv(
                file,
                Some(1),
                format!("missing column `{label}`"),
            ));
        }
    }
    let layouts = layouts(&columns).map_err(|e| Error::csv(file, Some(1), e))?;
    if layouts.is_empty() {
        return Err(Error::csv(
            file,
            Some(1),
            "no data columns (truth_i, estimate_i, covariance_i_j, innovation_i, \
             innovation_cov_i_j)",
        ));
    }
    Ok((columns, layouts))
}

/// A cell's text as a number; `None` for an empty cell.
fn number(text: &str) -> Result<Option<f64>, ()> {
    if text.is_empty() {
        return Ok(None);
    }
    text.parse::<f64>().map(Some).map_err(|_| ())
}

/// The fields of one data row as trimmed text. The row's bytes are checked as UTF-8 once,
/// not field by field (that check has a cost per call, which short numbers make large); a
/// row that is not UTF-8 is read field by field, lossily, so the message names the field at
/// fault.
struct Fields<'a> {
    record: &'a csv::ByteRecord,
    text: Option<&'a str>,
}

impl<'a> Fields<'a> {
    fn new(record: &'a csv::ByteRecord) -> Self {
        Self {
            record,
            text: std::str::from_utf8(record.as_slice()).ok(),
        }
    }

    /// Field `c`, trimmed; a field that is not UTF-8 is marked by U+FFFD, which no number
    /// holds.
    fn get(&self, c: usize) -> std::borrow::Cow<'a, str> {
        match (self.text, self.record.range(c)) {
            (Some(text), Some(range)) => text.get(range).unwrap_or("\u{fffd}").trim().into(),
            _ => String::from_utf8_lossy(self.record.get(c).unwrap_or(b""))
                .trim()
                .to_string()
                .into(),
        }
    }
}

/// Bytes of the file handed to a parsing thread at a time: large enough that the hand-over
/// costs nothing, small enough that the blocks in flight hold a few megabytes.
const BLOCK_BYTES: usize = 256 << 10;

/// What every parsing thread needs to know of the header.
struct Plan<'f> {
    file: &'f Path,
    header: csv::StringRecord,
    layouts: Vec<Layout>,
    run_col: usize,
    step_col: usize,
    time_col: Option<usize>,
    /// Per array, where its values start in a parsed row (`None` if not in the file).
    offsets: [Option<usize>; ARRAYS.len()],
    /// Per array, the range of its values in a parsed row and whether it is a diagonal
    /// matrix: [`Plan::cell`] runs once per row on the evaluating thread, so it looks up
    /// nothing in `layouts` (`cargo xtask bench eval`).
    spans: [Option<(std::ops::Range<usize>, bool)>; ARRAYS.len()],
    /// Values per parsed row: every array's cell side by side.
    width: usize,
    /// The most rows the file can hold, when its size is known: a row has at least one byte
    /// per column (a comma or the line's end, and the digits of its run and step). A row
    /// whose run and step need a larger rectangle of rows is refused as it is read, before
    /// the evaluation grows its per-run and per-step statistics to that size: a one-line
    /// file claiming step 10^15 must not allocate for 10^15 steps.
    max_rows: Option<u64>,
}

/// One parsed row of a block.
struct RowMeta {
    line: u64,
    run: usize,
    step: usize,
    time: Option<f64>,
    /// Per array, whether this row logs it.
    logged: [bool; ARRAYS.len()],
}

/// A parsed block: its rows, and their values `width` per row.
#[derive(Default)]
struct Parsed {
    rows: Vec<RowMeta>,
    values: Vec<f64>,
}

/// A block's place in the file and its parse.
type BlockResult = (usize, Result<Parsed, Error>);

impl Plan<'_> {
    /// Parses the rows of `block`, whose first line is row `first_row` of the file.
    fn parse(&self, block: &[u8], first_row: u64) -> Result<Parsed, Error> {
        let mut rows = Rows::continuing(self.file, block, self.header.clone(), first_row);
        let mut parsed = Parsed {
            rows: Vec::new(),
            values: Vec::new(),
        };
        let mut record = csv::ByteRecord::new();
        while let Some(line) = rows.next_byte_row(&mut record)? {
            let fields = Fields::new(&record);
            let not_number =
                |c: usize| rows.cell_error(line, c, format!("`{}` is not a number", fields.get(c)));
            let index = |c: usize| -> Result<usize, Error> {
                let text = fields.get(c);
                if text.is_empty() {
                    return Err(rows.cell_error(
                        line,
                        c,
                        "empty; every row names its run and step".into(),
                    ));
                }
                text.parse::<usize>().map_err(|_| {
                    rows.cell_error(
                        line,
                        c,
                        format!("`{text}` is not a whole number (0, 1, ...)"),
                    )
                })
            };
            let run = index(self.run_col)?;
            let step = index(self.step_col)?;
            if let Some(max) = self.max_rows {
                let needed = (run as u128 + 1) * (step as u128 + 1);
                if needed > u128::from(max) {
                    return Err(Error::csv(
                        self.file,
                        Some(line),
                        format!(
                            "run {run}, step {step}: a log holding it has at least {needed} \
                             rows (runs times steps), more than the file's {} columns per row \
                             leave room for (at most {max}); is the run or step wrong?",
                            self.header.len(),
                        ),
                    ));
                }
            }
            let time = match self.time_col {
                Some(c) => number(&fields.get(c)).map_err(|()| not_number(c))?,
                None => None,
            };
            let mut logged = [false; ARRAYS.len()];
            for layout in &self.layouts {
                let (mut present, mut empty) = (None, None);
                for &c in &layout.columns {
                    match number(&fields.get(c)) {
                        Ok(Some(v)) => {
                            parsed.values.push(v);
                            present.get_or_insert(c);
                        }
                        Ok(None) => {
                            parsed.values.push(f64::NAN);
                            empty.get_or_insert(c);
                        }
                        Err(()) => return Err(not_number(c)),
                    }
                }
                if let (Some(full), Some(empty)) = (present, empty) {
                    return Err(rows.cell_error(
                        line,
                        empty,
                        format!(
                            "empty, but column {} ({}) is not; {} is logged whole or not at all",
                            full + 1,
                            &self.header[full],
                            ARRAYS[layout.array]
                        ),
                    ));
                }
                logged[layout.array] = present.is_some();
            }
            parsed.rows.push(RowMeta {
                line,
                run,
                step,
                time,
                logged,
            });
        }
        Ok(parsed)
    }

    /// [`Plan::parse`] of a block of plain rows, without the csv crate and without an
    /// allocation per row: no quotes, no empty line, `\n` endings (no `\r`), the header's
    /// number of fields, numbers in decimal notation (the form every writer of a large log
    /// uses). Each row is read once from start to end, the numbers parsed where they stand
    /// (fast-float2 tells where each ends). `None` where the block is not plain or holds an
    /// error, which [`Plan::parse`] then reads and reports as it always did. The rows and
    /// values go into `parsed`'s storage, emptied first (a recycled parse, or
    /// `Parsed::default()`).
    fn parse_plain(&self, block: &[u8], first_row: u64, recycled: Parsed) -> Option<Parsed> {
        // A quote needs the csv crate's reading; so does a `\r`, after which the csv crate
        // numbers the rows its own way, and its numbers are the ones messages give.
        if memchr::memchr2(b'"', b'\r', block).is_some() {
            return None;
        }
        self.parse_plain_rows(block, first_row, recycled)
    }

    /// [`Plan::parse_plain`] of a block known to hold no quote and no `\r` (the reader
    /// thread, which scans each block for quotes anyway, looks for both in one pass).
    fn parse_plain_rows(&self, block: &[u8], first_row: u64, recycled: Parsed) -> Option<Parsed> {
        let columns = self.header.len();
        let mut slots = vec![Slot::Time; columns];
        slots[self.run_col] = Slot::Run;
        slots[self.step_col] = Slot::Step;
        for layout in &self.layouts {
            let offset = self.offsets[layout.array]?;
            for (k, &c) in layout.columns.iter().enumerate() {
                slots[c] = Slot::Value(offset + k, layout.array);
            }
        }
        // About 8 bytes a field in a log of floats; a guess, only for the first allocation.
        let rows_guess = block.len() / (8 * columns).max(1) + 1;
        let Parsed {
            mut rows,
            mut values,
        } = recycled;
        rows.clear();
        values.clear();
        rows.reserve(rows_guess);
        values.reserve(rows_guess * self.width);
        let mut parsed = Parsed { rows, values };
        let mut line_no = first_row;
        let mut start = 0;
        while start < block.len() {
            let end = memchr::memchr(b'\n', &block[start..]).map_or(block.len(), |e| start + e);
            let line = &block[start..end];
            let line_start = start;
            start = end + 1;
            if line.is_empty() {
                return None;
            }
            let at = parsed.values.len();
            parsed.values.resize(at + self.width, f64::NAN);
            let (mut run, mut step, mut time) = (0, 0, None);
            let (mut present, mut empty) = ([false; ARRAYS.len()], [false; ARRAYS.len()]);
            let mut i = 0;
            // Blanks around a field are skipped where they stand: a value read by
            // `quick_number` starts with a digit or `-`, so none precede it.
            for (c, slot) in slots.iter().enumerate() {
                if c > 0 {
                    if line.get(i) != Some(&b',') {
                        i = blanks(line, i);
                        if line.get(i) != Some(&b',') {
                            return None;
                        }
                    }
                    i += 1;
                }
                match *slot {
                    Slot::Value(k, array) => {
                        if let Some((v, end)) = crate::decimal::quick_number(block, line_start + i)
                        {
                            parsed.values[at + k] = v;
                            present[array] = true;
                            i = end - line_start;
                            continue;
                        }
                        let value;
                        (value, i) = plain_number(line, blanks(line, i))?;
                        match value {
                            Some(v) => {
                                parsed.values[at + k] = v;
                                present[array] = true;
                            }
                            None => empty[array] = true,
                        }
                    }
                    Slot::Run => (run, i) = plain_index(line, blanks(line, i))?,
                    Slot::Step => (step, i) = plain_index(line, blanks(line, i))?,
                    Slot::Time => (time, i) = number_at(block, line_start, line, blanks(line, i))?,
                }
            }
            i = blanks(line, i);
            if i != line.len() {
                return None;
            }
            if present.iter().zip(&empty).any(|(p, e)| *p && *e) {
                return None;
            }
            if let Some(max) = self.max_rows
                && (run as u128 + 1) * (step as u128 + 1) > u128::from(max)
            {
                return None;
            }
            parsed.rows.push(RowMeta {
                line: line_no,
                run,
                step,
                time,
                logged: present,
            });
            line_no += 1;
        }
        Some(parsed)
    }

    /// The cell of a parsed row whose values are `values`.
    fn cell<'a>(&self, row: &RowMeta, values: &'a [f64]) -> Cell<'a> {
        let slice = |a: usize| -> Option<&'a [f64]> {
            let (range, _) = self.spans[a].as_ref()?;
            row.logged[a].then(|| &values[range.clone()])
        };
        let matrix = |a: usize| {
            let diagonal = self.spans[a].as_ref().is_some_and(|(_, d)| *d);
            slice(a).map(|v| {
                if diagonal {
                    MatrixCell::Diagonal(v)
                } else {
                    MatrixCell::Full(v)
                }
            })
        };
        Cell {
            truth: slice(0),
            estimate: slice(1),
            innovation: slice(2),
            covariance: matrix(3),
            innovation_cov: matrix(4),
            model: None,
        }
    }
}

/// What a column of a plain row goes to ([`Plan::parse_plain`]).
#[derive(Clone, Copy)]
enum Slot {
    Run,
    Step,
    Time,
    /// The value's place in the parsed row, and its array.
    Value(usize, usize),
}

/// Skips spaces and tabs from `i` in `line`.
fn blanks(line: &[u8], mut i: usize) -> usize {
    while matches!(line.get(i), Some(b' ' | b'\t')) {
        i += 1;
    }
    i
}

/// The number at `i` in `line` (after blanks), and where it ends; `Some(None)` for an empty
/// field (the next byte ends it). `None` for anything but decimal notation (`inf`, `nan` and
/// what is not a number are left to the csv crate's reading): fast-float2 reads decimal
/// notation by Rust's grammar and rounds correctly, as `str::parse::<f64>` does, so a value
/// read here is the one [`number`] reads, bit for bit (the test
/// `plain_rows_are_read_as_the_csv_crate_reads_them`).
fn plain_number(line: &[u8], i: usize) -> Option<(Option<f64>, usize)> {
    match line.get(i) {
        None | Some(b',') => Some((None, i)),
        Some(b'0'..=b'9' | b'-' | b'+' | b'.') => {
            let (value, used) = fast_float2::parse_partial::<f64, _>(&line[i..]).ok()?;
            value.is_finite().then_some((Some(value), i + used))
        }
        Some(_) => None,
    }
}

/// [`plain_number`] at `i` of `line`, which starts at `line_start` of `block`: the common
/// forms read by [`crate::decimal::quick_number`] (the same value and end), the others by
/// fast-float2. The quick reading never passes the line's end (a newline is no digit).
#[inline(always)]
fn number_at(
    block: &[u8],
    line_start: usize,
    line: &[u8],
    i: usize,
) -> Option<(Option<f64>, usize)> {
    match crate::decimal::quick_number(block, line_start + i) {
        Some((value, end)) => Some((Some(value), end - line_start)),
        None => plain_number(line, i),
    }
}

/// The whole number (digits only) at `i` in `line`, and where it ends.
fn plain_index(line: &[u8], i: usize) -> Option<(usize, usize)> {
    let digits = line[i.min(line.len())..]
        .iter()
        .take_while(|b| b.is_ascii_digit())
        .count();
    if digits == 0 || digits > 18 {
        return None;
    }
    let value = line[i..i + digits]
        .iter()
        .fold(0usize, |acc, &b| acc * 10 + usize::from(b - b'0'));
    Some((value, i + digits))
}

/// Where `buf` (starting at a record) can be cut after a whole record: just after its last
/// newline outside quotes, `None` if it has none.
fn last_record_end(buf: &[u8]) -> Option<usize> {
    // The memchr crate's vectorised search, faster than `<[u8]>::contains` (`cargo xtask bench eval`).
    record_end_before(buf, memchr::memchr(b'"', buf).is_some())
}

/// [`last_record_end`] of `buf`, which holds a quote if `quoted`.
fn record_end_before(buf: &[u8], quoted: bool) -> Option<usize> {
    if !quoted {
        return memchr::memrchr(b'\n', buf).map(|i| i + 1);
    }
    // A quoted field may hold a newline; quotes toggle (an escaped "" toggles twice).
    let mut inside = false;
    let mut end = None;
    for (i, &b) in buf.iter().enumerate() {
        match b {
            b'"' => inside = !inside,
            b'\n' if !inside => end = Some(i + 1),
            _ => {}
        }
    }
    end
}

/// Reads `source` until `buf` holds at least `want` bytes or the end; returns whether the end
/// was reached. `read_to_end` reads into the spare capacity without zeroing it first: the
/// blocks come back to be filled again, so zeroing them is work for nothing (`cargo xtask bench
/// eval`).
fn fill(source: &mut impl Read, buf: &mut Vec<u8>, want: usize) -> std::io::Result<bool> {
    let missing = want.saturating_sub(buf.len());
    if missing == 0 {
        return Ok(false);
    }
    buf.reserve(missing);
    source.by_ref().take(missing as u64).read_to_end(buf)?;
    Ok(buf.len() < want)
}

/// The plan of a CSV log whose header is `header` (the file's first record) and whose size is
/// `size` if known, and what the log holds.
fn plan<'f>(
    file: &'f Path,
    header_bytes: &[u8],
    size: Option<u64>,
) -> Result<(Plan<'f>, Contents), Error> {
    let rows = Rows::new(file, header_bytes)?;
    let (columns, layouts) = header(file, &rows)?;
    let find = |want: Column| columns.iter().position(|c| *c == want);
    let (Some(run_col), Some(step_col)) = (find(Column::Run), find(Column::Step)) else {
        return Err(Error::csv(file, Some(1), "missing column `run` or `step`"));
    };
    let mut contents = Contents::default();
    let mut offsets = [None; ARRAYS.len()];
    let mut spans = [const { None }; ARRAYS.len()];
    let mut width = 0;
    for l in &layouts {
        *match ARRAYS[l.array] {
            "truth" => &mut contents.truth,
            "estimate" => &mut contents.estimate,
            "covariance" => &mut contents.covariance,
            "innovation" => &mut contents.innovation,
            _ => &mut contents.innovation_cov,
        } = Some(l.dim);
        offsets[l.array] = Some(width);
        spans[l.array] = Some((width..width + l.columns.len(), l.diagonal));
        width += l.columns.len();
    }
    let plan = Plan {
        file,
        header: rows.header.clone(),
        layouts,
        run_col,
        step_col,
        time_col: find(Column::Time),
        offsets,
        spans,
        width,
        max_rows: size.map(|s| s / (rows.header.len().max(1) as u64)),
    };
    Ok((plan, contents))
}

/// The stages of reading the CSV log `file`, each run alone on this thread, one after another
/// (`stages`): reading the file and cutting it into blocks at record ends, finding the
/// rows and fields of every block, reading them with their numbers, and evaluating the cells.
/// Holds the file and its numbers in memory: for the bench's stage split, not for use.
pub(crate) fn stages(
    file: &Path,
    evaluation: &Evaluation,
) -> Result<(crate::stage_times::Stages, Report), Error> {
    let clock = std::time::Instant::now();
    let bytes = std::fs::read(file).map_err(|e| Error::read(file, e))?;
    let header_end = first_record_end(&bytes).unwrap_or(bytes.len());
    let mut blocks = Vec::new();
    let mut rest = &bytes[header_end..];
    let mut row = 2;
    while !rest.is_empty() {
        let cut = if rest.len() <= BLOCK_BYTES {
            rest.len()
        } else {
            last_record_end(&rest[..BLOCK_BYTES]).unwrap_or(rest.len())
        };
        blocks.push((row, &rest[..cut]));
        row += memchr::memchr_iter(b'\n', &rest[..cut]).count() as u64;
        rest = &rest[cut..];
    }
    let read = clock.elapsed().as_secs_f64();
    let (plan, contents) = plan(file, &bytes[..header_end], Some(bytes.len() as u64))?;
    let clock = std::time::Instant::now();
    let fields: usize = blocks.iter().map(|(_, b)| plain_fields(b)).sum();
    let tokenise = clock.elapsed().as_secs_f64();
    let clock = std::time::Instant::now();
    let parsed = blocks
        .iter()
        .map(
            |&(row, b)| match plan.parse_plain(b, row, Parsed::default()) {
                Some(parsed) => Ok(parsed),
                None => plan.parse(b, row),
            },
        )
        .collect::<Result<Vec<_>, _>>()?;
    let parse = clock.elapsed().as_secs_f64() - tokenise;
    let clock = std::time::Instant::now();
    let fail = |e: EvalError| Error::evaluate(file, e);
    let mut evaluator = evaluation.evaluator(contents).map_err(fail)?;
    for p in &parsed {
        let cells: Vec<_> = p
            .rows
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let values = &p.values[i * plan.width..(i + 1) * plan.width];
                (r.run, r.step, plan.cell(r, values))
            })
            .collect();
        evaluator.push_batch(&cells).map_err(|(_, e)| fail(e))?;
    }
    let report = evaluator.finish(None).map_err(fail)?;
    let evaluate = clock.elapsed().as_secs_f64();
    let stages = crate::stage_times::Stages {
        read,
        tokenise,
        parse,
        evaluate,
        values: fields,
    };
    Ok((stages, report))
}

/// The fields of a block's rows, found as [`Plan::parse_plain`] finds rows and fields but
/// without reading the numbers: the tokenising part of its work, timed apart.
fn plain_fields(block: &[u8]) -> usize {
    memchr::memchr_iter(b'\n', block).count() + memchr::memchr_iter(b',', block).count()
}

/// Reads the rows of `source` (the file `file`) into an evaluator and finishes it.
///
/// The file is cut into blocks at record boundaries; parsing threads turn blocks into numbers
/// while this thread feeds the rows to the evaluator in file order, so the report is the one a
/// single thread would give, bit for bit, whatever the number of threads.
fn stream(
    file: &Path,
    mut source: impl Read + Send,
    size: Option<u64>,
    evaluation: &Evaluation,
) -> Result<Report, Error> {
    let read_error = |e: std::io::Error| Error::read(file, e);
    // The header: everything up to the first record end.
    let mut buf = Vec::new();
    let mut at_end = false;
    let header_end = loop {
        if let Some(end) = first_record_end(&buf) {
            break end;
        }
        if at_end {
            break buf.len();
        }
        let want = buf.len() + 64 * 1024;
        at_end = fill(&mut source, &mut buf, want).map_err(read_error)?;
    };
    let (plan, contents) = plan(file, &buf[..header_end], size)?;
    let fail = |e: EvalError| Error::evaluate(file, e);
    let mut evaluator = evaluation.evaluator(contents).map_err(fail)?;
    let first_data_row = 1 + buf[..header_end].iter().filter(|&&b| b == b'\n').count() as u64;
    buf.drain(..header_end);

    let workers = std::thread::available_parallelism().map_or(1, |n| n.get().clamp(1, 4));
    let (work_tx, work_rx) = mpsc::sync_channel::<(usize, u64, Vec<u8>, bool)>(workers);
    let work_rx = Mutex::new(work_rx);
    let (done_tx, done_rx) = mpsc::sync_channel::<BlockResult>(workers + 1);
    // Blocks parsed and parses evaluated come back to be filled again: a fresh allocation per
    // block was paid again in page faults (`cargo xtask bench eval`, CSV). As many are in
    // circulation as were in flight before.
    let (blocks_back, blocks_back_rx) = mpsc::channel::<Vec<u8>>();
    let (parses_back, parses_back_rx) = mpsc::channel::<Parsed>();
    let parses_back_rx = Mutex::new(parses_back_rx);
    let mut times: Vec<Option<(f64, u64)>> = Vec::new();
    let mut any = false;
    let fed: Result<(), Error> = std::thread::scope(|scope| {
        // The reader: cuts the file into blocks of whole records, in order.
        let reader_done = done_tx.clone();
        scope.spawn(move || {
            let (mut row, mut index, mut want) = (first_data_row, 0, BLOCK_BYTES);
            loop {
                let end = match fill(&mut source, &mut buf, want) {
                    Ok(end) => end,
                    Err(e) => {
                        let _ = reader_done.send((index, Err(read_error(e))));
                        return;
                    }
                };
                // One scan tells whether a quote may hide a newline (then the cut needs a
                // closer look) and whether the rows can be read plain (no quote, no `\r`).
                let odd = memchr::memchr2(b'"', b'\r', &buf).is_some();
                let quoted = odd && memchr::memchr(b'"', &buf).is_some();
                let cut = match (end, record_end_before(&buf, quoted)) {
                    (true, _) => buf.len(),
                    (false, Some(cut)) => cut,
                    // A record longer than the block: read on.
                    (false, None) => {
                        want = buf.len() + BLOCK_BYTES;
                        continue;
                    }
                };
                want = BLOCK_BYTES;
                let mut rest = blocks_back_rx.try_recv().unwrap_or_default();
                rest.clear();
                rest.extend_from_slice(&buf[cut..]);
                buf.truncate(cut);
                let block = std::mem::replace(&mut buf, rest);
                let lines = memchr::memchr_iter(b'\n', &block).count() as u64;
                if block.is_empty() || work_tx.send((index, row, block, !odd)).is_err() {
                    return;
                }
                row += lines;
                index += 1;
                if end && buf.is_empty() {
                    return;
                }
            }
        });
        for _ in 0..workers {
            let (done, blocks_back) = (done_tx.clone(), blocks_back.clone());
            let (work_rx, plan, parses_back_rx) = (&work_rx, &plan, &parses_back_rx);
            scope.spawn(move || {
                loop {
                    let next = work_rx
                        .lock()
                        .map_err(|_| ())
                        .and_then(|rx| rx.recv().map_err(|_| ()));
                    let Ok((index, row, block, plain)) = next else {
                        return;
                    };
                    let recycled = parses_back_rx
                        .lock()
                        .ok()
                        .and_then(|rx| rx.try_recv().ok())
                        .unwrap_or_default();
                    let parsed = match if plain {
                        plan.parse_plain_rows(&block, row, recycled)
                    } else {
                        plan.parse_plain(&block, row, recycled)
                    } {
                        Some(parsed) => Ok(parsed),
                        None => plan.parse(&block, row),
                    };
                    // The reader may have finished; then the block is dropped here.
                    let _ = blocks_back.send(block);
                    if done.send((index, parsed)).is_err() {
                        return;
                    }
                }
            });
        }
        drop(done_tx);
        // This thread: the blocks in file order, each row to the evaluator.
        let mut pending = BTreeMap::new();
        let mut next = 0;
        while let Ok((index, parsed)) = done_rx.recv() {
            pending.insert(index, parsed);
            while let Some(parsed) = pending.remove(&next) {
                next += 1;
                let parsed = parsed?;
                any |= !parsed.rows.is_empty();
                // The times first, up to the first row whose time disagrees: the rows before
                // it go to the evaluator, so that the first error in file order is reported.
                let mut time_error = None;
                if let Some(c) = plan.time_col {
                    for (i, row) in parsed.rows.iter().enumerate() {
                        let Some(t) = row.time else { continue };
                        if let Err(msg) = check_time(&mut times, row, t) {
                            time_error = Some((
                                i,
                                Error::Csv {
                                    file: file.to_path_buf(),
                                    row: Some(row.line),
                                    column: Some(c + 1),
                                    column_name: Some(plan.header[c].to_string()),
                                    message: msg,
                                },
                            ));
                            break;
                        }
                    }
                }
                let upto = time_error.as_ref().map_or(parsed.rows.len(), |e| e.0);
                let cells: Vec<_> = parsed.rows[..upto]
                    .iter()
                    .enumerate()
                    .map(|(i, row)| {
                        let values = &parsed.values[i * plan.width..(i + 1) * plan.width];
                        (row.run, row.step, plan.cell(row, values))
                    })
                    .collect();
                evaluator.push_batch(&cells).map_err(|(i, e)| {
                    let line = parsed.rows[i].line;
                    match e {
                        EvalError::DuplicateCell { run, step } => Error::csv(
                            file,
                            Some(line),
                            format!("run {run}, step {step} already given in an earlier row"),
                        ),
                        other => Error::Evaluate {
                            file: file.to_path_buf(),
                            row: Some(line),
                            source: other,
                        },
                    }
                })?;
                if let Some((_, message)) = time_error {
                    return Err(message);
                }
                drop(cells);
                let _ = parses_back.send(parsed);
            }
        }
        Ok(())
    });
    fed?;
    if !any {
        return Err(Error::csv(file, None, "no data rows after the header"));
    }
    let times = match plan.time_col {
        None => None,
        Some(_) => Some(
            (0..evaluator.steps())
                .map(|k| {
                    times
                        .get(k)
                        .copied()
                        .flatten()
                        .map(|(t, _)| t)
                        .ok_or_else(|| {
                            Error::csv(file, None, format!("column time: no time for step {k}"))
                        })
                })
                .collect::<Result<Vec<_>, _>>()?,
        ),
    };
    evaluator.finish(times).map_err(|e| match e {
        EvalError::MissingCell { run, step, steps } => Error::csv(
            file,
            None,
            format!(
                "no row for run {run}, step {step} (every run needs a row for every step \
                 0..{}; is the file truncated?)",
                steps - 1
            ),
        ),
        other => fail(other),
    })
}

/// Where the first record of `buf` ends (just after its newline outside quotes).
fn first_record_end(buf: &[u8]) -> Option<usize> {
    let mut quoted = false;
    for (i, &b) in buf.iter().enumerate() {
        match b {
            b'"' => quoted = !quoted,
            b'\n' if !quoted => return Some(i + 1),
            _ => {}
        }
    }
    None
}

/// Records the time of a row's step: the first row of a step gives it, the others must agree.
fn check_time(times: &mut Vec<Option<(f64, u64)>>, row: &RowMeta, t: f64) -> Result<(), String> {
    if row.step >= times.len() {
        times.resize(row.step + 1, None);
    }
    match times[row.step] {
        None => times[row.step] = Some((t, row.line)),
        Some((first, line)) if first.to_bits() != t.to_bits() => {
            return Err(format!(
                "{t} differs from row {line}'s time {first} for step {} (the times are per \
                 step, the same in every run)",
                row.step
            ));
        }
        Some(_) => {}
    }
    Ok(())
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
        let matrix = a >= FIRST_MATRIX;
        let diagonal = matrix && entries.iter().all(|&(i, j, _)| i == j);
        // The largest index names the dimension. It can be absurd (`truth_99999999999`): the
        // array is then incomplete, and the search below finds its first missing column
        // without making room for the columns it would need (a header of a few bytes once
        // asked for terabytes here).
        let dim = entries
            .iter()
            .map(|&(i, j, _)| i.max(j))
            .max()
            .unwrap_or(0)
            .saturating_add(1);
        // The p-th entry of a complete cell, in the sorted order of `entries`.
        let position = |p: usize| {
            if !matrix {
                (p, 0)
            } else if diagonal {
                (p, p)
            } else {
                (p / dim, p % dim)
            }
        };
        let needed = if matrix && !diagonal {
            dim.saturating_mul(dim)
        } else {
            dim
        };
        // Entries are unique (a repeated column was refused) and lie inside the cell, so the
        // cell is complete when every entry sits at its own position; otherwise the first
        // one out of place marks the first missing column. At most `entries.len() + 1` steps.
        if let Some((i, j)) = (0..needed)
            .find(|&p| entries.get(p).map(|&(i, j, _)| (i, j)) != Some(position(p)))
            .map(position)
        {
            return Err(if !matrix {
                format!(
                    "missing column `{array}_{i}` ({array}_0 to {array}_{} expected)",
                    dim - 1
                )
            } else {
                format!(
                    "missing column `{array}_{i}_{j}` ({array} columns are every {array}_i_j \
                     for i, j below {dim}, or the diagonal {array}_i_i alone)"
                )
            });
        }
        let cols: Vec<usize> = entries.iter().map(|&(_, _, c)| c).collect();
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

#[cfg(test)]
mod tests {
    use super::*;

    fn plan_of(header: &str) -> Plan<'static> {
        plan(Path::new("log.csv"), header.as_bytes(), None)
            .unwrap()
            .0
    }

    /// The rows and values of a parse, with every number as its bits.
    type Bits = (u64, usize, usize, Option<u64>, [bool; 5], Vec<u64>);

    fn bits(p: &Parsed) -> Vec<Bits> {
        let width = p.values.len() / p.rows.len().max(1);
        p.rows
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let values = p.values[i * width..(i + 1) * width]
                    .iter()
                    .map(|v| v.to_bits())
                    .collect();
                (
                    r.line,
                    r.run,
                    r.step,
                    r.time.map(f64::to_bits),
                    r.logged,
                    values,
                )
            })
            .collect()
    }

    #[test]
    fn plain_rows_are_read_as_the_csv_crate_reads_them() {
        let header =
            "run,step,time,truth_0,truth_1,estimate_0,estimate_1,covariance_0_0,covariance_1_1\n";
        let plan = plan_of(header);
        let plain = [
            "0,0,0.5,1,2,3,4,5,6\n",
            "0, 1 ,1.5,\t-0, +1.5 ,.5,5.,1e5,1E-300\n",
            "0,2,2.5,0.30000000000000004,123456789012345678901234,,,4.9e-324,2.2250738585072014e-308\n",
            "1,0,,1.7976931348623157e308,-2.5e-3,0.1000000000000000055511151231257827021181583404541015625,7,8,9",
        ];
        let block = plain.concat();
        let fast = plan
            .parse_plain(block.as_bytes(), 2, Parsed::default())
            .expect("a plain block");
        let slow = plan.parse(block.as_bytes(), 2).unwrap();
        assert_eq!(bits(&fast), bits(&slow));
        assert_eq!(fast.rows.len(), 4);
        assert!(!fast.rows[2].logged[1] && fast.rows[2].logged[0]);
        // Blocks left to the csv crate: it reads them, or reports their error.
        for odd in [
            "0,0,\"0.5\",1,2,3,4,5,6\n",
            "0,0,0.5,1,2,3,4,5,6\r\n",
            "0,0,0.5,1,2,3,4,5,6\n\n0,1,0.5,1,2,3,4,5,6\n",
            "0,0,0.5,inf,2,3,4,5,6\n",
            "0,0,0.5,NaN,2,3,4,5,6\n",
            "0,0,0.5,1e400,2,3,4,5,6\n",
            "0,0,0.5,1.5x,2,3,4,5,6\n",
            "0,0,0.5,1 2,2,3,4,5,6\n",
            "0,0,0.5,1,2,3,4,5\n",
            "0,0,0.5,1,2,3,4,5,6,7\n",
            "0,0,0.5,1,2,3,,5,6\n",
            "+0,0,0.5,1,2,3,4,5,6\n",
            "0,,0.5,1,2,3,4,5,6\n",
            "0,0,0.5,1,2,3,4,5,6\r0,1,0.5,1,2,3,4,5,6\n",
            "0,0,0.5,1,2,3,4,5,\u{a0}6\n",
        ] {
            assert!(
                plan.parse_plain(odd.as_bytes(), 2, Parsed::default())
                    .is_none(),
                "{odd:?}"
            );
        }
    }

    /// As `plain_rows_are_read_as_the_csv_crate_reads_them`, with the rows in the middle of
    /// a long block, where `decimal::quick_number` reads the numbers (it needs 40 bytes from
    /// a number's start): blanks around fields, empty cells, every form of number.
    #[test]
    fn plain_rows_mid_block_are_read_as_the_csv_crate_reads_them() {
        let header =
            "run,step,time,truth_0,truth_1,estimate_0,estimate_1,covariance_0_0,covariance_1_1\n";
        let plan = plan_of(header);
        let filler = "9,9,9.5,1,2,3,4,5,6\n".repeat(4);
        let rows = [
            "0,0,0.5,1,2,3,4,5,6\n",
            "0,1,1.5,-7.399621529173474,26.541660839191493,0,-0,49.99999999999999,25\n",
            "0, 1 ,1.5,\t-0, +1.5 ,.5,5.,1e5,1E-300\n",
            " 0 ,\t2\t, 2.5 ,0.30000000000000004 , 123456789012345678901234,,, 4.9e-324,2.2\n",
            "1,0,,1.7976931348623157e308,-2.5e-3,0.1000000000000000055511151231257827021181583404541015625,7,8,9\n",
            "1,1,3,1234567.1234567891,12345678.5,9007199254740993,9007199254740992,0.000001,-0.5\n",
            "1,2,3,1 ,2\t,3 , 4,5\t,\t6 \n",
        ];
        let block = format!("{}{}", rows.concat(), filler);
        let fast = plan
            .parse_plain(block.as_bytes(), 2, Parsed::default())
            .expect("a plain block");
        let slow = plan.parse(block.as_bytes(), 2).unwrap();
        assert_eq!(bits(&fast), bits(&slow));
        assert_eq!(fast.rows.len(), rows.len() + 4);
        for odd in [
            "0,0,0.5,1,2,3,4,5,6 7\n",
            "0,0,0.5,1,2,3,4,5,6,\n",
            "0,0,0.5,1,2,3,4,5\n",
            "0,0,0.5,1.5x,2,3,4,5,6\n",
            "0,0,0.5,1.5e,2,3,4,5,6\n",
            "0,0,0.5,1,2,3,,5,6\n",
            "0,0,0.5,1;2,3,4,5,6,7\n",
            "0,0,0.5,--1,2,3,4,5,6\n",
            "0,0,0.5,1,2,3,4,5,6\t\u{a0}\n",
        ] {
            let block = format!("{odd}{filler}");
            assert!(
                plan.parse_plain(block.as_bytes(), 2, Parsed::default())
                    .is_none(),
                "{odd:?}"
            );
        }
    }
}
