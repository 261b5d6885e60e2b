//! The JSON log streamed: the per-cell arrays are read run after run, all in step, each from
//! its own handle on the file, and fed to a `kalibra_eval::Evaluator` as they come, so memory
//! holds the statistics and a few runs, never the file (`cargo xtask bench eval` prints the
//! peak). The cells go run after run, not in the strips of 32 steps across the runs that
//! `kalibra_eval::Evaluation::evaluate` feeds: a strip across all runs needs a part of every
//! run, that is the whole file; strips across groups of whole runs would not, but their gain
//! for one evaluator, which the same bench times (the figures `npz: evaluate, run after run /
//! ...`), did not hold from one run to the next on a shared machine.
//!
//! A JSON log stores its arrays one after another (all the truths, then all the estimates,
//! ...), so a first pass over the file finds where each array starts and counts its runs and
//! the first run's steps, and a second pass reads the arrays side by side. The small arrays
//! (`time`, `F`, `H`, `Q`, `R`) are read whole by `json_log`, with its rules.
//!
//! The streaming reader takes the layout `kalibra eval` documents with the runs axis: every
//! per-cell array a list of runs, each a list of the same number of steps, each step a cell
//! (a list of numbers, a list of rows for a matrix, or `null`) of one shape, the array's first
//! cell logged. Anything else (a single run without the runs axis, text that is not JSON, a
//! cell of another shape, a value the evaluation refuses) hands the file to the whole-file
//! reader (`json_log`), which then gives the error, with its line and column or the array and
//! index, or the report: the same as before for every file, with memory in proportion to the
//! file only for those. The report of a streamed log is the whole-file reader's to the bit:
//! the evaluator takes the cells run after run, which the in-memory evaluation reproduces
//! (`kalibra_eval::Evaluation::evaluate`), and every number is parsed correctly rounded, as
//! serde_json's `float_roundtrip` does (the test `numbers_read_as_serde_json_reads_them`).

use std::io::{Read, Seek, SeekFrom};
use std::sync::mpsc;

use kalibra_eval::{Cell, Contents, Evaluation, FilterLog, MatrixCell, ModelCell, Report};

use crate::raw::{ARRAY_NAMES, PER_CELL};

/// Why the streaming reader hands the file to the whole-file reader: the file leaves the
/// layout it reads, or something failed (whose message the whole-file reader gives).
#[derive(Debug)]
pub(crate) struct Fallback;

type Step<T> = Result<T, Fallback>;

impl From<std::io::Error> for Fallback {
    fn from(_: std::io::Error) -> Self {
        Fallback
    }
}

/// Bytes read from the file at a time.
const BUFFER_BYTES: usize = 1 << 20;

/// Cells handed from the reader thread to the evaluation at a time (whole runs).
const BATCH_CELLS: usize = 4096;

/// The longest number token read (longer ones go to the whole-file reader).
const LONGEST_NUMBER: usize = 4096;

/// A byte source with a window of look-ahead, and its position in the file.
struct Bytes<R> {
    reader: R,
    buf: Vec<u8>,
    pos: usize,
    len: usize,
    /// The file offset of `buf[0]`.
    offset: u64,
    eof: bool,
}

impl<R: Read> Bytes<R> {
    fn new(reader: R, offset: u64) -> Self {
        Self {
            reader,
            buf: vec![0; BUFFER_BYTES],
            pos: 0,
            len: 0,
            offset,
            eof: false,
        }
    }

    /// The file offset of the next byte.
    fn at(&self) -> u64 {
        self.offset + self.pos as u64
    }

    /// Moves the unread bytes to the front and reads more; false at the end of the source.
    fn refill(&mut self) -> Step<bool> {
        if self.eof {
            return Ok(false);
        }
        self.buf.copy_within(self.pos..self.len, 0);
        self.offset += self.pos as u64;
        self.len -= self.pos;
        self.pos = 0;
        loop {
            match self.reader.read(&mut self.buf[self.len..]) {
                Ok(0) => {
                    self.eof = true;
                    return Ok(false);
                }
                Ok(got) => {
                    self.len += got;
                    return Ok(true);
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// The next byte that is not JSON whitespace, not consumed; `None` at the end.
    fn peek(&mut self) -> Step<Option<u8>> {
        loop {
            while self.pos < self.len {
                let b = self.buf[self.pos];
                if !matches!(b, b' ' | b'\t' | b'\n' | b'\r') {
                    return Ok(Some(b));
                }
                self.pos += 1;
            }
            if !self.refill()? {
                return Ok(None);
            }
        }
    }

    /// Consumes the next non-whitespace byte, which must be `want`.
    fn expect(&mut self, want: u8) -> Step<()> {
        if self.peek()? == Some(want) {
            self.pos += 1;
            Ok(())
        } else {
            Err(Fallback)
        }
    }

    /// Consumes `word` (`null`, `NaN`, ...) at the next non-whitespace byte.
    fn word(&mut self, word: &[u8]) -> Step<()> {
        self.peek()?;
        self.ensure(word.len())?;
        if self.buf[self.pos..self.len].starts_with(word) {
            self.pos += word.len();
            Ok(())
        } else {
            Err(Fallback)
        }
    }

    /// Makes at least `want` bytes available unless the source ends first.
    fn ensure(&mut self, want: usize) -> Step<()> {
        while self.len - self.pos < want && self.refill()? {}
        Ok(())
    }

    /// The next number (JSON's grammar, or Python's `NaN`, `Infinity`, `-Infinity`).
    fn number(&mut self) -> Step<f64> {
        self.peek()?;
        self.ensure(64)?;
        loop {
            let rest = &self.buf[self.pos..self.len];
            match json_number(rest) {
                Some(Token::Number(end)) if end < rest.len() || self.eof => {
                    let value = parse_number(&rest[..end])?;
                    self.pos += end;
                    return Ok(value);
                }
                Some(Token::Python(value, end)) => {
                    self.pos += end;
                    return Ok(value);
                }
                // The token reaches the end of the window: read on, up to a limit.
                Some(Token::Number(end)) if end < LONGEST_NUMBER => {
                    let want = end + 64;
                    self.ensure(want)?;
                    if self.len - self.pos < want && !self.eof {
                        return Err(Fallback);
                    }
                }
                _ => return Err(Fallback),
            }
        }
    }
}

/// A number token at the start of some bytes.
enum Token {
    /// A JSON number of this many bytes.
    Number(usize),
    /// One of Python's tokens, its value and length.
    Python(f64, usize),
}

/// The JSON number (or Python token) at the start of `b`, by JSON's grammar:
/// `-? (0 | [1-9][0-9]*) (. [0-9]+)? ([eE] [+-]? [0-9]+)?`; `None` if there is none.
fn json_number(b: &[u8]) -> Option<Token> {
    let digits = |from: usize| b[from..].iter().take_while(|c| c.is_ascii_digit()).count();
    let mut i = 0;
    if b.first() == Some(&b'-') {
        i = 1;
    }
    match b.get(i) {
        Some(b'0') => i += 1,
        Some(b'1'..=b'9') => i += digits(i),
        Some(b'N') if i == 0 && b.starts_with(b"NaN") => return Some(Token::Python(f64::NAN, 3)),
        Some(b'I') if b[i..].starts_with(b"Infinity") => {
            let value = if i == 1 {
                f64::NEG_INFINITY
            } else {
                f64::INFINITY
            };
            return Some(Token::Python(value, i + 8));
        }
        _ => return None,
    }
    if b.get(i) == Some(&b'.') {
        let d = digits(i + 1);
        if d == 0 {
            return None;
        }
        i += 1 + d;
    }
    if matches!(b.get(i), Some(b'e' | b'E')) {
        i += 1;
        if matches!(b.get(i), Some(b'+' | b'-')) {
            i += 1;
        }
        let d = digits(i);
        if d == 0 {
            return None;
        }
        i += d;
    }
    // A number runs into a letter or a digit only in text that is not JSON (`01`, `1x`).
    match b.get(i) {
        Some(c) if c.is_ascii_alphanumeric() || *c == b'.' => None,
        _ => Some(Token::Number(i)),
    }
}

/// The value of a JSON number token, correctly rounded (fast-float2); one that overflows
/// `f64` is an error in serde_json, so it is not taken here.
fn parse_number(token: &[u8]) -> Step<f64> {
    match fast_float2::parse::<f64, _>(token) {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(Fallback),
    }
}

/// Where a top-level array's value lies in the file, and what the first pass counted.
struct Span {
    array: &'static str,
    start: u64,
    end: u64,
    /// Entries of the outer list (runs).
    runs: usize,
    /// Entries of the first run (steps).
    steps: usize,
}

/// The first pass: the top-level object's arrays, where each lies.
fn scan<R: Read>(bytes: &mut Bytes<R>) -> Step<Vec<Span>> {
    let mut spans: Vec<Span> = Vec::new();
    bytes.expect(b'{')?;
    if bytes.peek()? == Some(b'}') {
        return Err(Fallback);
    }
    loop {
        let array = key(bytes)?;
        if spans.iter().any(|s| s.array == array) {
            return Err(Fallback);
        }
        bytes.expect(b':')?;
        bytes.peek()?;
        let start = bytes.at();
        let (runs, steps) = if PER_CELL.contains(&array) {
            skip_cells(bytes)?
        } else {
            skip_value(bytes)?;
            (0, 0)
        };
        spans.push(Span {
            array,
            start,
            end: bytes.at(),
            runs,
            steps,
        });
        match bytes.peek()? {
            Some(b',') => bytes.pos += 1,
            Some(b'}') => {
                bytes.pos += 1;
                break;
            }
            _ => return Err(Fallback),
        }
    }
    match bytes.peek()? {
        None => Ok(spans),
        Some(_) => Err(Fallback),
    }
}

/// A key of the top-level object: one of the arrays' names, written plainly.
fn key<R: Read>(bytes: &mut Bytes<R>) -> Step<&'static str> {
    bytes.expect(b'"')?;
    bytes.ensure(32)?;
    let rest = &bytes.buf[bytes.pos..bytes.len];
    let close = rest.iter().take(32).position(|&b| b == b'"' || b == b'\\');
    match close {
        Some(end) if rest[end] == b'"' => {
            let name = ARRAY_NAMES
                .iter()
                .find(|n| n.as_bytes() == &rest[..end])
                .ok_or(Fallback)?;
            bytes.pos += end + 1;
            Ok(name)
        }
        _ => Err(Fallback),
    }
}

/// Skips any JSON value (a small array, read whole later), checking only its nesting.
fn skip_value<R: Read>(bytes: &mut Bytes<R>) -> Step<()> {
    let mut depth = 0usize;
    let mut in_string = false;
    loop {
        if bytes.pos == bytes.len && !bytes.refill()? {
            return Err(Fallback);
        }
        let b = bytes.buf[bytes.pos];
        if in_string {
            match b {
                b'\\' => {
                    bytes.ensure(2)?;
                    bytes.pos += 1;
                }
                b'"' => in_string = false,
                _ => {}
            }
        } else {
            match b {
                b'"' => in_string = true,
                b'[' | b'{' => depth += 1,
                b']' | b'}' if depth == 0 => return Ok(()),
                b']' | b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        bytes.pos += 1;
                        return Ok(());
                    }
                }
                b',' if depth == 0 => return Ok(()),
                _ => {}
            }
        }
        bytes.pos += 1;
    }
}

/// Skips a per-cell array, a list of runs of lists of cells, counting its runs and the first
/// run's steps. Only the brackets and commas are looked at (the second pass reads the rest);
/// a string or an object inside is not a log the streaming reader takes.
fn skip_cells<R: Read>(bytes: &mut Bytes<R>) -> Step<(usize, usize)> {
    bytes.expect(b'[')?;
    let (mut depth, mut runs, mut steps) = (1usize, 0usize, 0usize);
    // Whether a value has started at depth 1 (a run) and depth 2 of the first run (a step).
    let (mut run_open, mut first_run) = (false, true);
    loop {
        if bytes.pos == bytes.len && !bytes.refill()? {
            return Err(Fallback);
        }
        let chunk = &bytes.buf[bytes.pos..bytes.len];
        let mut used = chunk.len();
        for (i, &b) in chunk.iter().enumerate() {
            match b {
                b'[' => {
                    if depth == 1 {
                        run_open = true;
                        runs += 1;
                    } else if depth == 2 && first_run && steps == 0 {
                        steps = 1;
                    }
                    depth += 1;
                }
                b']' => {
                    depth -= 1;
                    if depth == 0 {
                        used = i + 1;
                        break;
                    }
                    if depth == 1 {
                        first_run = false;
                    }
                }
                b',' if depth == 2 && first_run => steps += 1,
                b'"' | b'{' | b'}' => return Err(Fallback),
                b'n' if depth == 2 && first_run && steps == 0 => steps = 1,
                // A run that is not a list (`null`, a number) is not this layout.
                b'n' | b'0'..=b'9' | b'-' | b'N' | b'I' if depth == 1 => return Err(Fallback),
                _ => {}
            }
        }
        bytes.pos += used;
        if depth == 0 {
            if !run_open || steps == 0 {
                return Err(Fallback);
            }
            return Ok((runs, steps));
        }
    }
}

/// One per-cell array read run by run in the second pass.
struct Cells<R> {
    array: &'static str,
    matrix: bool,
    bytes: Bytes<R>,
    /// Rows (the dimension) and columns (0 for a vector) of every cell, from the first.
    rows: usize,
    cols: usize,
    end: u64,
}

impl<R: Read> Cells<R> {
    fn width(&self) -> usize {
        if self.matrix {
            self.rows * self.cols
        } else {
            self.rows
        }
    }

    /// Appends the numbers of a list to `out`, returning how many.
    fn list(&mut self, out: &mut Vec<f64>) -> Step<usize> {
        self.bytes.expect(b'[')?;
        let before = out.len();
        if self.bytes.peek()? == Some(b']') {
            self.bytes.pos += 1;
            return Ok(0);
        }
        loop {
            out.push(self.bytes.number()?);
            match self.bytes.peek()? {
                Some(b',') => self.bytes.pos += 1,
                Some(b']') => {
                    self.bytes.pos += 1;
                    return Ok(out.len() - before);
                }
                _ => return Err(Fallback),
            }
        }
    }

    /// Appends one cell's values to `out` (NaN for `null`); returns whether it is logged.
    fn cell(&mut self, out: &mut Vec<f64>) -> Step<bool> {
        if self.bytes.peek()? == Some(b'n') {
            if self.rows == 0 {
                // The first cell fixes the shape; a first cell not logged leaves it unknown.
                return Err(Fallback);
            }
            self.bytes.word(b"null")?;
            out.resize(out.len() + self.width(), f64::NAN);
            return Ok(false);
        }
        let start = out.len();
        if !self.matrix {
            let len = self.list(out)?;
            if self.rows == 0 && len > 0 {
                self.rows = len;
            }
            if len != self.rows {
                return Err(Fallback);
            }
        } else {
            self.bytes.expect(b'[')?;
            let mut rows = 0;
            loop {
                let len = self.list(out)?;
                if self.cols == 0 && len > 0 {
                    self.cols = len;
                }
                if len != self.cols {
                    return Err(Fallback);
                }
                rows += 1;
                match self.bytes.peek()? {
                    Some(b',') => self.bytes.pos += 1,
                    Some(b']') => {
                        self.bytes.pos += 1;
                        break;
                    }
                    _ => return Err(Fallback),
                }
            }
            if self.rows == 0 {
                self.rows = rows;
            }
            // Square matrices only: another shape is the whole-file reader's error.
            if rows != self.rows || self.rows != self.cols {
                return Err(Fallback);
            }
        }
        // A cell of all NaN was not logged (as numpy's arrays mark it).
        Ok(!out[start..].iter().all(|v| v.is_nan()))
    }

    /// Reads run `run` of `steps` cells into `out` and `logged`.
    fn run(
        &mut self,
        run: usize,
        steps: usize,
        out: &mut Vec<f64>,
        logged: &mut Vec<bool>,
    ) -> Step<()> {
        self.bytes.expect(if run == 0 { b'[' } else { b',' })?;
        self.bytes.expect(b'[')?;
        for step in 0..steps {
            if step > 0 {
                self.bytes.expect(b',')?;
            }
            logged.push(self.cell(out)?);
        }
        self.bytes.expect(b']')
    }

    /// After the last run: the list's end, where the first pass found it.
    fn close(&mut self) -> Step<()> {
        self.bytes.expect(b']')?;
        if self.bytes.at() == self.end {
            Ok(())
        } else {
            Err(Fallback)
        }
    }
}

/// Runs of every per-cell array, from `first_run` on.
struct Batch {
    first_run: usize,
    runs: usize,
    /// Per array: the values, and whether each cell is logged.
    values: Vec<(Vec<f64>, Vec<bool>)>,
}

/// Evaluates the JSON log that `source` opens handles on (each call a new handle at its
/// start), streamed; `Fallback` where the whole-file reader must take it.
pub(crate) fn evaluate<R: Read + Seek + Send>(
    source: &impl Fn() -> std::io::Result<R>,
    evaluation: &Evaluation,
) -> Result<Report, Fallback> {
    let spans = scan(&mut Bytes::new(source()?, 0))?;
    let cell_spans: Vec<&Span> = spans
        .iter()
        .filter(|s| PER_CELL.contains(&s.array))
        .collect();
    let (runs, steps) = match cell_spans.first() {
        Some(s) => (s.runs, s.steps),
        None => return Err(Fallback),
    };
    if cell_spans
        .iter()
        .any(|s| (s.runs, s.steps) != (runs, steps))
    {
        return Err(Fallback);
    }
    // The small arrays, read whole with the whole-file reader's rules.
    let mut small = Vec::new();
    for span in spans.iter().filter(|s| !PER_CELL.contains(&s.array)) {
        let mut handle = source()?;
        handle.seek(SeekFrom::Start(span.start))?;
        let len = usize::try_from(span.end - span.start).map_err(|_| Fallback)?;
        let mut text = vec![0; len];
        handle.read_exact(&mut text)?;
        small.push((span.array, text));
    }
    let (times, model) =
        crate::json_log::small_arrays(&small, runs, steps).map_err(|_| Fallback)?;
    // The checks `FilterLog` makes of the times and the model, before any cell is read.
    let mut check = FilterLog::new(runs, steps).map_err(|_| Fallback)?;
    if let Some(t) = &times {
        check = check.with_times(t.clone()).map_err(|_| Fallback)?;
    }
    if let Some([f, h, q, r]) = &model {
        check
            .with_model(
                f.clone().matrices(),
                h.clone().matrices(),
                q.clone().matrices(),
                r.clone().matrices(),
            )
            .map_err(|_| Fallback)?;
    }

    let mut readers = Vec::new();
    for span in &cell_spans {
        let mut handle = source()?;
        handle.seek(SeekFrom::Start(span.start))?;
        readers.push(Cells {
            array: span.array,
            matrix: span.array == "covariance" || span.array == "innovation_cov",
            bytes: Bytes::new(handle, span.start),
            rows: 0,
            cols: 0,
            end: span.end,
        });
    }
    // Run 0 first: its cells fix every array's shape, which the evaluator needs.
    let first = read_runs(&mut readers, 0, 1, steps)?;
    let mut contents = Contents::default();
    for r in &readers {
        *match r.array {
            "truth" => &mut contents.truth,
            "estimate" => &mut contents.estimate,
            "covariance" => &mut contents.covariance,
            "innovation" => &mut contents.innovation,
            _ => &mut contents.innovation_cov,
        } = Some(r.rows);
    }
    if let Some([f, h, ..]) = &model {
        contents.model = Some((f.rows, h.rows));
    }
    let mut evaluator = evaluation.evaluator(contents).map_err(|_| Fallback)?;
    let arrays: Vec<&'static str> = readers.iter().map(|r| r.array).collect();
    let mut feed = |batch: &Batch| -> Step<()> {
        let cells: Vec<(usize, usize, Cell<'_>)> = (0..batch.runs * steps)
            .map(|i| {
                let (run, step) = (batch.first_run + i / steps, i % steps);
                let mut cell = Cell::default();
                for (array, (values, logged)) in arrays.iter().zip(&batch.values) {
                    if !logged[i] {
                        continue;
                    }
                    let width = values.len() / logged.len();
                    let v = &values[i * width..(i + 1) * width];
                    match *array {
                        "truth" => cell.truth = Some(v),
                        "estimate" => cell.estimate = Some(v),
                        "innovation" => cell.innovation = Some(v),
                        "covariance" => cell.covariance = Some(MatrixCell::Full(v)),
                        _ => cell.innovation_cov = Some(MatrixCell::Full(v)),
                    }
                }
                cell.model = model.as_ref().map(|[f, h, q, r]| ModelCell {
                    f: f.cell(run, step, steps),
                    h: h.cell(run, step, steps),
                    q: q.cell(run, step, steps),
                    r: r.cell(run, step, steps),
                });
                (run, step, cell)
            })
            .collect();
        evaluator.push_batch(&cells).map_err(|_| Fallback)
    };
    feed(&first)?;
    let per_batch = (BATCH_CELLS / steps).max(1);
    let fed: Step<()> = std::thread::scope(|scope| {
        // The reader: batches of runs, while this thread evaluates the last.
        let (tx, rx) = mpsc::sync_channel::<Step<Batch>>(2);
        scope.spawn(move || {
            let mut run = 1;
            while run < runs {
                let count = per_batch.min(runs - run);
                let batch = read_runs(&mut readers, run, count, steps);
                let failed = batch.is_err();
                if tx.send(batch).is_err() || failed {
                    return;
                }
                run += count;
            }
            let closed = readers.iter_mut().try_for_each(Cells::close);
            if let Err(e) = closed {
                let _ = tx.send(Err(e));
            }
        });
        while let Ok(batch) = rx.recv() {
            feed(&batch?)?;
        }
        Ok(())
    });
    fed?;
    evaluator.finish(times).map_err(|_| Fallback)
}

/// Reads `count` runs from `first_run` on of every array.
fn read_runs<R: Read>(
    readers: &mut [Cells<R>],
    first_run: usize,
    count: usize,
    steps: usize,
) -> Step<Batch> {
    let mut values = Vec::with_capacity(readers.len());
    for r in readers.iter_mut() {
        let mut out = Vec::with_capacity(count * steps * r.width().max(1));
        let mut logged = Vec::with_capacity(count * steps);
        for run in first_run..first_run + count {
            r.run(run, steps, &mut out, &mut logged)?;
        }
        values.push((out, logged));
    }
    Ok(Batch {
        first_run,
        runs: count,
        values,
    })
}

/// The stages of the streamed JSON log `file` (`stages`): reading the file, the first
/// pass (finding the arrays), and the second pass with the evaluation (reading the cells and
/// their numbers on the reader thread while this one evaluates), timed apart, with the file
/// held in memory; `None` for a log the streaming reader hands over.
pub(crate) fn stages(
    file: &std::path::Path,
    evaluation: &Evaluation,
) -> Result<Option<(crate::stage_times::Stages, Report)>, crate::Error> {
    let clock = std::time::Instant::now();
    let bytes = std::fs::read(file).map_err(|e| crate::Error::read(file, e))?;
    let read = clock.elapsed().as_secs_f64();
    let clock = std::time::Instant::now();
    let Ok(spans) = scan(&mut Bytes::new(std::io::Cursor::new(&bytes[..]), 0)) else {
        return Ok(None);
    };
    let tokenise = clock.elapsed().as_secs_f64();
    let values = spans.iter().map(|s| s.runs * s.steps).sum();
    let clock = std::time::Instant::now();
    let source = || Ok(std::io::Cursor::new(&bytes[..]));
    let Ok(report) = evaluate(&source, evaluation) else {
        return Ok(None);
    };
    // The streaming evaluation makes the first pass again; it is the time above.
    let rest = clock.elapsed().as_secs_f64() - tokenise;
    let stages = crate::stage_times::Stages {
        read,
        tokenise,
        parse: rest,
        evaluate: f64::NAN,
        values,
    };
    Ok(Some((stages, report)))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    fn fixture(name: &str) -> Vec<u8> {
        std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../kalibra-cli/tests/fixtures")
                .join(name),
        )
        .unwrap()
    }

    /// The streaming reader's answer on `text` against the whole-file reader's: a report it
    /// gives must be the whole-file reader's, byte for byte as JSON; returns whether it
    /// streamed.
    fn agrees(text: &[u8]) -> bool {
        let evaluation = Evaluation::new();
        let source = || Ok(std::io::Cursor::new(text));
        let streamed = evaluate(&source, &evaluation);
        let whole = crate::input::evaluate_json(Path::new("log.json"), text, &evaluation);
        match (streamed, whole) {
            (Ok(a), Ok(b)) => {
                assert_eq!(
                    serde_json::to_string(&a).unwrap(),
                    serde_json::to_string(&b).unwrap(),
                    "{}",
                    String::from_utf8_lossy(text)
                );
                true
            }
            (Ok(_), Err(e)) => panic!(
                "streamed a log the whole-file reader refuses ({e}): {}",
                String::from_utf8_lossy(text)
            ),
            (Err(Fallback), _) => false,
        }
    }

    /// A small log: 3 runs of 4 steps, n = 2, m = 1, with `edit` applied to its text.
    fn small_log(extra: &str) -> String {
        let cell = |r: usize, k: usize, i: usize| ((r * 7 + k * 3 + i) % 5) as f64 * 0.37 - 0.5;
        let per_run = |f: &dyn Fn(usize, usize) -> String| {
            let runs: Vec<String> = (0..3)
                .map(|r| {
                    let steps: Vec<String> = (0..4).map(|k| f(r, k)).collect();
                    format!("[{}]", steps.join(", "))
                })
                .collect();
            format!("[{}]", runs.join(",\n "))
        };
        let truth = per_run(&|r, k| format!("[{}, {}]", cell(r, k, 0), cell(r, k, 1)));
        let estimate = per_run(&|r, k| format!("[{}, {:e}]", cell(r, k, 1), cell(r, k, 2)));
        let cov = per_run(&|r, k| {
            let d = 1.0 + cell(r, k, 3).abs();
            format!("[[{d}, 0.1], [0.1, {}]]", d + 0.5)
        });
        let nu = per_run(&|r, k| format!("[{}]", cell(r, k, 4)));
        let s = per_run(&|r, k| format!("[[{}]]", 1.5 + cell(r, k, 5).abs()));
        format!(
            "{{\"truth\": {truth}, \"estimate\": {estimate}, \"covariance\": {cov}, \
             \"innovation\": {nu}, \"innovation_cov\": {s}{extra}}}\n"
        )
    }

    #[test]
    fn streamed_logs_give_the_whole_file_readers_report() {
        for name in ["kf.json", "kf_python.json"] {
            assert!(agrees(&fixture(name)), "{name} streams");
        }
        let plain = small_log("");
        assert!(agrees(plain.as_bytes()));
        // Valid variations that stream: null, NaN and all-NaN cells after the first, Python's
        // tokens, times, a model of each scope, other whitespace and key order.
        let streaming = [
            small_log(", \"time\": [0, 1, 2.5, 4]"),
            small_log(
                ", \"F\": [[1, 0], [0, 1]], \"H\": [[1, 0]], \"Q\": [[0.1, 0], [0, 0.1]], \
                 \"R\": [[1]]",
            ),
            small_log(
                ", \"F\": [[[1, 0], [0, 1]], [[1, 0], [0, 1]], [[1, 0], [0, 1]], [[1, 0], [0, 1]]], \
                 \"H\": [[1, 0]], \"Q\": [[0.1, 0], [0, 0.1]], \"R\": [[1]]",
            ),
            plain.replace(", ", ",").replace(": ", ":\t"),
        ];
        for text in &streaming {
            assert!(agrees(text.as_bytes()), "{text}");
        }
        let second_cell = |text: &str, by: &str| {
            let at = text.find("], [").unwrap() + 3;
            let end = at + text[at..].find(']').unwrap() + 1;
            format!("{}{by}{}", &text[..at], &text[end..])
        };
        assert!(agrees(second_cell(&plain, "null").as_bytes()));
        assert!(agrees(second_cell(&plain, "[NaN, NaN]").as_bytes()));
        // A non-finite truth is refused, by both.
        assert!(!agrees(second_cell(&plain, "[NaN, -Infinity]").as_bytes()));
        // Logs the whole-file reader takes or refuses, which must not stream differently.
        let others = [
            plain.replacen("0.13", "\"x\"", 1),
            plain.replacen("]]", "]]]", 1),
            plain.replacen("-0.5", "1e400", 1),
            plain.replacen("-0.5", "01", 1),
            plain.replacen("[[", "[null, [", 1),
            format!("{plain} x"),
            plain.replacen("\"truth\"", "\"truths\"", 1),
            plain.replacen("\"estimate\"", "\"truth\"", 1),
            small_log(", \"time\": [0, 1, 1, 4]"),
            small_log(", \"F\": [[1, 0], [0, 1]]"),
            second_cell(&plain, "[1, 2, 3]"),
            second_cell(&plain, "[1]"),
            plain.replacen("[[1.", "[[1, 2], [3, 4], [1.", 1),
            plain[..plain.len() - 10].to_string(),
        ];
        for text in &others {
            agrees(text.as_bytes());
        }
        // Every byte of a small log deleted in turn, and a bracket put there instead.
        let bytes = plain.as_bytes();
        for i in (0..bytes.len()).step_by(7) {
            let mut cut = bytes.to_vec();
            cut.remove(i);
            agrees(&cut);
            let mut swapped = bytes.to_vec();
            swapped[i] = b']';
            agrees(&swapped);
        }
    }

    /// Every literal either parses to serde_json's value, bit for bit, or goes to the
    /// whole-file reader, which then gives serde_json's answer.
    #[test]
    fn numbers_read_as_serde_json_reads_them() {
        let literals = [
            "0",
            "-0",
            "1",
            "-1",
            "0.1",
            "-0.0",
            "1e5",
            "1E5",
            "1e+5",
            "1e-5",
            "2.5e-3",
            "1.7976931348623157e308",
            "2.2250738585072014e-308",
            "4.9e-324",
            "5e-325",
            "1e-400",
            "1e400",
            "-1e400",
            "18446744073709551615",
            "18446744073709551616",
            "-9223372036854775808",
            "-9223372036854775809",
            "123456789012345678901234567890",
            "0.30000000000000004",
            "9007199254740993",
            "2.4703282292062328e-324",
            "0.1000000000000000055511151231257827021181583404541015625",
            "01",
            "1.",
            ".5",
            "+1",
            "1e",
            "1e+",
            "-",
            "1x",
            "0x10",
            "inf",
            "nan",
        ];
        for text in literals {
            let ours = match json_number(text.as_bytes()) {
                Some(Token::Number(end)) if end == text.len() => parse_number(text.as_bytes()).ok(),
                _ => None,
            };
            let theirs = serde_json::from_str::<serde_json::Value>(text)
                .ok()
                .and_then(|v| v.as_f64());
            match (ours, theirs) {
                (Some(a), Some(b)) => assert_eq!(a.to_bits(), b.to_bits(), "{text}"),
                (Some(a), None) => panic!("{text}: read as {a}, serde_json refuses it"),
                // Refused here: the whole-file reader decides.
                (None, _) => {}
            }
        }
        // The plain forms of a log are read here, not handed over.
        for text in ["0", "-0", "1e5", "0.1", "-2.5e-3", "4.9e-324"] {
            assert!(matches!(
                json_number(text.as_bytes()),
                Some(Token::Number(_))
            ));
        }
        assert!(matches!(
            json_number(b"-Infinity,"),
            Some(Token::Python(v, 9)) if v == f64::NEG_INFINITY
        ));
        assert!(matches!(json_number(b"NaN]"), Some(Token::Python(v, 3)) if v.is_nan()));
    }
}
