//! The NPZ log: numpy's `np.savez` (or `np.savez_compressed`) archive of arrays with the same
//! names and shapes as the JSON log (see `input::FORMATS_HELP`).
//!
//! A cell (one run and step) whose values are all NaN was not logged, since numpy arrays have
//! no `null`; a cell with only some NaN values is kept as logged, so a NaN covariance is a
//! finding about the filter under test, as in the other formats. Errors name the file and the
//! array, and the cell index where one is at fault.
//!
//! The per-cell arrays stream: each is read from its own handle on the archive, all in step,
//! run after run, by a reader thread that hands batches of cells to the evaluation; memory
//! holds the statistics and a few batches, never the arrays. The small arrays (`time`, `F`,
//! `H`, `Q`, `R`) are read whole.
//!
//! The cells go to the evaluator run after run, not in the strips of 32 steps across the runs
//! that `kalibra_eval::Evaluation::evaluate` feeds its blocks of steps: `cargo xtask bench
//! eval` times one evaluator fed each way (the figures `npz: evaluate, run after run / ...`),
//! and on a shared machine its gain did not hold from one run to the next; a strip across all
//! runs needs a seek per run and array, and a reader feeding groups of whole runs in strips
//! held more than a quarter of the bench's file and was no faster end to end.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek};
use std::path::Path;
use std::sync::mpsc;

use kalibra_eval::{
    Cell, Contents, EvalError, Evaluation, MatrixCell, ModelCell, PreparedBatch, Report,
};

use crate::error::Error;
use crate::raw::{
    ARRAY_NAMES, KNOWN, MODEL, ModelArray, PER_CELL, cell_shape, model_given, no_per_cell_array,
};

/// Cells per batch handed from the reader thread to the evaluation.
const BATCH_CELLS: usize = 4096;

/// The read buffer of each handle on the archive: at most a batch's bytes of the smallest
/// per-cell array of float64 (`BATCH_CELLS` values of a one-dimensional innovation).
const BUFFER_BYTES: usize = BATCH_CELLS * 8;

type Archive<R> = zip::ZipArchive<R>;

/// Opens the archive on a new handle from `source` (each per-cell array streams from its own).
fn open<R: Read + Seek>(
    file: &Path,
    source: &impl Fn() -> std::io::Result<R>,
) -> Result<Archive<R>, Error> {
    let handle = source().map_err(|e| Error::read(file, e))?;
    zip::ZipArchive::new(handle).map_err(|e| Error::File {
        file: file.to_path_buf(),
        message: format!("not an NPZ archive ({e}); write it with numpy's np.savez"),
    })
}

/// The bytes `shape` of `kind` takes, `None` beyond `u64`.
fn shape_bytes(shape: &[usize], kind: Kind) -> Option<u64> {
    shape
        .iter()
        .try_fold(kind.size() as u64, |acc, &d| acc.checked_mul(d as u64))
}

/// Refuses a header whose shape needs more bytes than its archive entry holds (`entry_size`,
/// the entry's uncompressed size), before anything is allocated for it: the shape is only
/// a claim, and a `.npy` header of a few bytes can claim terabytes.
fn check_fits(h: &Header, entry_size: u64) -> Result<(), String> {
    match shape_bytes(&h.shape, h.kind) {
        Some(bytes) if bytes <= entry_size => Ok(()),
        claimed => Err(format!(
            "shape {:?} needs {} bytes of values, but the entry holds {entry_size} \
             (truncated or corrupt?)",
            h.shape,
            claimed.map_or_else(|| "more than 2^64".to_string(), |b| b.to_string())
        )),
    }
}

/// An `.npy` file's reader after its header: the header's bytes, then the rest of the entry.
type AfterHeader<R> = std::io::Chain<std::io::Cursor<Vec<u8>>, R>;

/// Reads the `.npy` header at the start of `reader` with npyz, once the shape it claims has
/// been checked here: npyz multiplies the dimensions without checking for overflow, so a
/// header of a few bytes claiming `(2^40, 2^40)` panicked inside it in a debug build and
/// wrapped around in a release one (found by the readers' property test, `readers_fuzz.rs`).
fn npy_file<R: Read>(mut reader: R) -> Result<npyz::NpyFile<AfterHeader<R>>, String> {
    let not_npy = |why: String| format!("not a .npy array ({why})");
    // The magic string, the format version and the header's length (2 bytes in version 1,
    // 4 in versions 2 and 3).
    let mut prefix = vec![0u8; 10];
    reader
        .read_exact(&mut prefix)
        .map_err(|e| not_npy(e.to_string()))?;
    if &prefix[..6] != b"\x93NUMPY" {
        return Err(not_npy("no magic string".to_string()));
    }
    let len = match prefix[6] {
        1 => u64::from(u16::from_le_bytes([prefix[8], prefix[9]])),
        2 | 3 => {
            let mut more = [0u8; 2];
            reader
                .read_exact(&mut more)
                .map_err(|e| not_npy(e.to_string()))?;
            prefix.extend_from_slice(&more);
            u64::from(u32::from_le_bytes([prefix[8], prefix[9], more[0], more[1]]))
        }
        version => return Err(not_npy(format!("format version {version}"))),
    };
    // Read as it comes, not allocated up front: the length is only a claim.
    let mut header = Vec::new();
    (&mut reader)
        .take(len)
        .read_to_end(&mut header)
        .map_err(|e| not_npy(e.to_string()))?;
    if header.len() as u64 != len {
        return Err(not_npy("the header is cut short (truncated?)".to_string()));
    }
    check_shape_claim(&String::from_utf8_lossy(&header)).map_err(not_npy)?;
    prefix.extend_from_slice(&header);
    npyz::NpyFile::new(std::io::Cursor::new(prefix).chain(reader))
        .map_err(|e| not_npy(e.to_string()))
}

/// Checks the `'shape': (...)` of an `.npy` header's dictionary: whole numbers whose non-zero
/// ones multiply to at most `u64::MAX`, which bounds every product npyz forms of them (a
/// product with a zero is zero). A header without a shape is left to npyz to refuse.
fn check_shape_claim(dict: &str) -> Result<(), String> {
    let Some(key) = dict.find("'shape'").or_else(|| dict.find("\"shape\"")) else {
        return Ok(());
    };
    let rest = &dict[key + "'shape'".len()..];
    let tuple = rest
        .trim_start()
        .strip_prefix(':')
        .map(str::trim_start)
        .and_then(|t| t.strip_prefix('('))
        .and_then(|t| t.split_once(')'))
        .map(|(inside, _)| inside)
        .ok_or_else(|| "its shape is not a tuple".to_string())?;
    let mut product: u64 = 1;
    for piece in tuple.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let dim: u64 = piece
            .trim_end_matches(['L', 'l'])
            .parse()
            .map_err(|_| format!("shape ({tuple}) holds `{piece}`, not a whole number"))?;
        if dim != 0 {
            product = product
                .checked_mul(dim)
                .ok_or_else(|| format!("shape ({tuple}) holds more than 2^64 values"))?;
        }
    }
    Ok(())
}

/// How an array's values are stored.
#[derive(Clone, Copy, Debug)]
enum Kind {
    F8,
    F4,
    I8,
    I4,
}

/// An array's header: shape, value type, byte order.
struct Header {
    shape: Vec<usize>,
    kind: Kind,
    big_endian: bool,
}

/// Checks a `.npy` header: C order, a number type kalibra reads.
fn header<R: Read>(npy: &npyz::NpyFile<R>) -> Result<Header, String> {
    if npy.order() == npyz::Order::Fortran {
        return Err(
            "stored in Fortran order; save a C-ordered array (np.ascontiguousarray)".to_string(),
        );
    }
    let shape: Vec<usize> = npy.shape().iter().map(|&d| d as usize).collect();
    let descr = npy.dtype().descr();
    // numpy's type string: byte order, kind, size (`<f8`, `<f4`, `<i8`, ...).
    let descr = descr.trim_matches('\'');
    let big_endian = descr.starts_with('>');
    let kind = match descr.trim_start_matches(['<', '>', '|', '=']) {
        "f8" => Kind::F8,
        "f4" => Kind::F4,
        "i8" => Kind::I8,
        "i4" => Kind::I4,
        other => {
            return Err(format!(
                "dtype `{other}` is not a number type kalibra reads (float64, float32, int64, \
                 int32)"
            ));
        }
    };
    Ok(Header {
        shape,
        kind,
        big_endian,
    })
}

impl Kind {
    fn size(self) -> usize {
        match self {
            Kind::F8 | Kind::I8 => 8,
            Kind::F4 | Kind::I4 => 4,
        }
    }

    /// Appends the values of `bytes` to `out` as f64.
    fn decode(self, big_endian: bool, bytes: &[u8], out: &mut Vec<f64>) {
        macro_rules! each {
            ($t:ty, $n:literal) => {
                out.extend(bytes.chunks_exact($n).map(|c| {
                    let b: [u8; $n] = c.try_into().unwrap_or([0; $n]);
                    let v = if big_endian {
                        <$t>::from_be_bytes(b)
                    } else {
                        <$t>::from_le_bytes(b)
                    };
                    v as f64
                }))
            };
        }
        match self {
            Kind::F8 => each!(f64, 8),
            Kind::F4 => each!(f32, 4),
            Kind::I8 => each!(i64, 8),
            Kind::I4 => each!(i32, 4),
        }
    }
}

/// An array read whole (`time`, `F`, `H`, `Q`, `R`): its shape and its values in C order.
struct Array {
    shape: Vec<usize>,
    data: Vec<f64>,
}

/// Reads the array in `entry` whole.
fn read_whole<R: Read + Seek>(archive: &mut Archive<R>, entry: &str) -> Result<Array, String> {
    let file = archive
        .by_name(entry)
        .map_err(|e| format!("cannot read it ({e}; truncated?)"))?;
    let entry_size = file.size();
    let npy = npy_file(file)?;
    let h = header(&npy)?;
    check_fits(&h, entry_size)?;
    let mut bytes = Vec::new();
    npy.into_inner()
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read its values ({e}; truncated?)"))?;
    // Fits in usize: the values' bytes fit in the entry, whose bytes were just read.
    let count: usize = h.shape.iter().product();
    if bytes.len() != count * h.kind.size() {
        return Err(format!(
            "holds {} values for shape {:?} (truncated?)",
            bytes.len() / h.kind.size(),
            h.shape
        ));
    }
    let mut data = Vec::with_capacity(count);
    h.kind.decode(h.big_endian, &bytes, &mut data);
    Ok(Array {
        shape: h.shape,
        data,
    })
}

/// A per-cell array, read cell by cell from its own handle on the archive.
struct Stream<R: Read> {
    array: &'static str,
    /// Values per cell.
    width: usize,
    kind: Kind,
    big_endian: bool,
    reader: R,
    bytes: Vec<u8>,
}

impl<R: Read> Stream<R> {
    /// Sets `out` to the next `cells` cells' values (a recycled `out` of that length is
    /// overwritten as it stands, not cleared and filled again).
    fn read(&mut self, cells: usize, out: &mut Vec<f64>) -> Result<(), (&'static str, String)> {
        let array = self.array;
        let cut_short = |e: std::io::Error| {
            (
                array,
                format!("array {array}: cannot read its values ({e}; truncated?)"),
            )
        };
        let count = cells * self.width;
        // float64 in this machine's byte order (numpy's `<f8` on x86 and ARM) is read
        // straight into `out`: the copy through `self.bytes` and its decoding cost as much as
        // the evaluation's own per-cell sums (`cargo xtask bench eval`, NPZ), and the bits
        // are the same as `f64::from_le_bytes` gives.
        if matches!(self.kind, Kind::F8) && self.big_endian == cfg!(target_endian = "big") {
            out.resize(count, 0.0);
            return self
                .reader
                .read_exact(bytemuck::cast_slice_mut(out.as_mut_slice()))
                .map_err(cut_short);
        }
        self.bytes.resize(count * self.kind.size(), 0);
        self.reader.read_exact(&mut self.bytes).map_err(cut_short)?;
        out.clear();
        self.kind.decode(self.big_endian, &self.bytes, out);
        Ok(())
    }

    /// Reads to the entry's end, which checks its checksum.
    fn finish(&mut self) -> Result<(), (&'static str, String)> {
        std::io::copy(&mut self.reader, &mut std::io::sink())
            .map(|_| ())
            .map_err(|e| {
                (
                    self.array,
                    format!("array {}: cannot read it ({e}; truncated?)", self.array),
                )
            })
    }
}

/// Consecutive cells, run-major, of every per-cell array.
struct Batch {
    first: usize,
    cells: usize,
    /// Per array, `cells * width` values.
    values: Vec<Vec<f64>>,
}

/// Evaluates the NPZ log `file` with `evaluation`.
pub(crate) fn evaluate(file: &Path, evaluation: &Evaluation) -> Result<Report, Error> {
    // No larger than a batch's read of one array, so that those reads bypass the buffer
    // (`BufReader` hands a read at least its capacity straight to the file) instead of
    // being copied through it.
    let source = || File::open(file).map(|f| BufReader::with_capacity(BUFFER_BYTES, f));
    evaluate_from(file, &source, evaluation)
}

/// Evaluates the NPZ log held in `bytes` (the file `file`, as messages name it).
pub(crate) fn evaluate_bytes(
    file: &Path,
    bytes: &[u8],
    evaluation: &Evaluation,
) -> Result<Report, Error> {
    let source = || Ok(std::io::Cursor::new(bytes));
    evaluate_from(file, &source, evaluation)
}

/// Evaluates the NPZ log that `source` opens a handle on (each call a new handle at its start).
fn evaluate_from<R: Read + Seek + Send>(
    file: &Path,
    source: &impl Fn() -> std::io::Result<R>,
    evaluation: &Evaluation,
) -> Result<Report, Error> {
    let fail = |e: Error| e.in_file(file);
    let file_error = |message: String| Error::File {
        file: file.to_path_buf(),
        message,
    };
    // An error of the array `array` as a whole (`array {array}: {message}`).
    let array_error = |array: &str, message: String| {
        Error::array(array, format!("array {array}: {message}")).in_file(file)
    };
    let mut archive = open(file, source)?;
    // Array name -> entry name.
    let mut entries = BTreeMap::new();
    for index in 0..archive.len() {
        let entry = match archive.name_for_index(index) {
            Some(Ok(entry)) => entry.to_string(),
            Some(Err(e)) => {
                return Err(file_error(format!(
                    "entry {index} of the archive has no readable name ({e})"
                )));
            }
            None => {
                return Err(file_error(format!(
                    "entry {index} of the archive (truncated?)"
                )));
            }
        };
        let Some(array) = entry.strip_suffix(".npy") else {
            return Err(file_error(format!(
                "entry `{entry}` is not a .npy array; the arrays are {KNOWN}"
            )));
        };
        if !ARRAY_NAMES.contains(&array) {
            return Err(fail(Error::array(
                array,
                format!("unknown array `{array}`; the arrays are {KNOWN}"),
            )));
        }
        entries.insert(array.to_string(), entry.clone());
    }
    let mut whole = |array: &str| -> Result<Option<Array>, Error> {
        match entries.get(array) {
            None => Ok(None),
            Some(entry) => read_whole(&mut archive, entry)
                .map(Some)
                .map_err(|e| array_error(array, e)),
        }
    };
    let time = whole("time")?;
    let model_arrays = [whole("F")?, whole("H")?, whole("Q")?, whole("R")?];

    // The per-cell arrays' headers, each on its own handle so that all stream together.
    let present: Vec<&'static str> = PER_CELL
        .into_iter()
        .filter(|a| entries.contains_key(*a))
        .collect();
    if present.is_empty() {
        return Err(fail(no_per_cell_array()));
    }
    let mut archives = present
        .iter()
        .map(|_| open(file, source))
        .collect::<Result<Vec<_>, _>>()?;
    let mut streams = Vec::new();
    let mut contents = Contents::default();
    let mut shape_from: Option<(&str, usize, usize)> = None;
    for (archive, &array) in archives.iter_mut().zip(&present) {
        let entry = archive
            .by_name(&entries[array])
            .map_err(|e| array_error(array, format!("cannot read it ({e}; truncated?)")))?;
        let entry_size = entry.size();
        let npy = npy_file(entry).map_err(|e| array_error(array, e))?;
        let h = header(&npy).map_err(|e| array_error(array, e))?;
        check_fits(&h, entry_size).map_err(|e| array_error(array, e))?;
        let matrix = array == "covariance" || array == "innovation_cov";
        let (runs, steps, cell) =
            cell_shape(array, &h.shape, if matrix { 2 } else { 1 }).map_err(fail)?;
        if runs == 0 || steps == 0 {
            // Nothing to evaluate; refused before the evaluation sizes itself by the cells'
            // dimensions, which no value then bounds.
            return Err(fail(Error::array(
                array,
                format!("array {array} is empty (shape {:?})", h.shape),
            )));
        }
        match shape_from {
            None => shape_from = Some((array, runs, steps)),
            Some((first, r, k)) if (r, k) != (runs, steps) => {
                return Err(fail(Error::array(
                    array,
                    format!(
                        "array {array} has {runs} runs of {steps} steps, but array {first} has \
                         {r} runs of {k} steps"
                    ),
                )));
            }
            Some(_) => {}
        }
        if matrix && cell[0] != cell[1] {
            return Err(fail(Error::array(
                array,
                format!(
                    "array {array} holds {}x{} matrices; a covariance is square",
                    cell[0], cell[1]
                ),
            )));
        }
        *match array {
            "truth" => &mut contents.truth,
            "estimate" => &mut contents.estimate,
            "covariance" => &mut contents.covariance,
            "innovation" => &mut contents.innovation,
            _ => &mut contents.innovation_cov,
        } = Some(cell[0]);
        streams.push(Stream {
            array,
            width: cell.iter().product(),
            kind: h.kind,
            big_endian: h.big_endian,
            reader: npy.into_inner(),
            bytes: Vec::new(),
        });
    }
    let (_, runs, steps) = shape_from.unwrap_or(("", 0, 0));
    let times = match time {
        None => None,
        Some(t) if t.shape.len() == 1 => Some(t.data),
        Some(t) => {
            return Err(fail(Error::array(
                "time",
                format!("array time has shape {:?}; expected (K,)", t.shape),
            )));
        }
    };
    let model = model(model_arrays, runs, steps).map_err(fail)?;
    if let Some([f, h, ..]) = &model {
        contents.model = Some((f.rows, h.rows));
    }
    let evaluate_error = |e: EvalError| Error::evaluate(file, e);
    let mut evaluator = evaluation.evaluator(contents).map_err(evaluate_error)?;
    // The pure part of each batch (checks and factorisations) is computed on the reader's
    // thread by a second evaluator of the same contents, while this thread adds the sums of
    // the batch before: the two halves overlap.
    let preparer = evaluation.evaluator(contents).map_err(evaluate_error)?;

    // Every array's values fit in its entry (`check_fits`) and the evaluation refused cells of
    // no values, so this product is at most the archive's size.
    let total = runs.saturating_mul(steps);
    let (present, model) = (&present, model.as_ref());
    let fed: Result<(), Error> = std::thread::scope(|scope| {
        // The reader: batches of cells, run-major, each with its pure part, while this thread
        // adds the sums of the last.
        let (tx, rx) =
            mpsc::sync_channel::<Result<(Batch, PreparedBatch), (&'static str, String)>>(4);
        // The values of evaluated batches come back to be filled again: a fresh allocation
        // per batch and array was paid again in page faults (`cargo xtask bench eval`, NPZ).
        let (back_tx, back_rx) = mpsc::channel::<Vec<Vec<f64>>>();
        scope.spawn(move || {
            let mut first = 0;
            while first < total {
                let cells = BATCH_CELLS.min(total - first);
                let mut values = back_rx
                    .try_recv()
                    .unwrap_or_else(|_| vec![Vec::new(); streams.len()]);
                for (s, out) in streams.iter_mut().zip(&mut values) {
                    if let Err(e) = s.read(cells, out) {
                        let _ = tx.send(Err(e));
                        return;
                    }
                }
                let batch = Batch {
                    first,
                    cells,
                    values,
                };
                let prepared = preparer.prepare_batch(&cells_of(&batch, present, model, steps));
                if tx.send(Ok((batch, prepared))).is_err() {
                    return;
                }
                first += cells;
            }
            for s in &mut streams {
                if let Err(e) = s.finish() {
                    let _ = tx.send(Err(e));
                    return;
                }
            }
        });
        while let Ok(batch) = rx.recv() {
            let (batch, prepared) =
                batch.map_err(|(array, message)| Error::array(array, message).in_file(file))?;
            let cells = cells_of(&batch, present, model, steps);
            evaluator
                .push_prepared(&cells, prepared)
                .map_err(|(_, source)| Error::Refused {
                    file: Some(file.to_path_buf()),
                    source,
                })?;
            drop(cells);
            // The reader may have finished; then the values are dropped here.
            let _ = back_tx.send(batch.values);
        }
        Ok(())
    });
    fed?;
    evaluator.finish(times).map_err(|e| match e {
        EvalError::Empty { .. } => Error::Refused {
            file: Some(file.to_path_buf()),
            source: e,
        },
        other => evaluate_error(other),
    })
}

/// The cells of `batch` (of a log of `steps` steps whose per-cell arrays are `present`, in
/// the batch's order, and whose model is `model`), each with its run and step.
fn cells_of<'a>(
    batch: &'a Batch,
    present: &[&str],
    model: Option<&'a [ModelArray; 4]>,
    steps: usize,
) -> Vec<(usize, usize, Cell<'a>)> {
    (0..batch.cells)
        .map(|i| {
            let (run, step) = ((batch.first + i) / steps, (batch.first + i) % steps);
            let mut cell = Cell::default();
            for (a, &array) in present.iter().enumerate() {
                let width = batch.values[a].len() / batch.cells;
                let v = &batch.values[a][i * width..(i + 1) * width];
                // A cell of all NaN was not logged (numpy has no null).
                if v.iter().all(|x| x.is_nan()) {
                    continue;
                }
                match array {
                    "truth" => cell.truth = Some(v),
                    "estimate" => cell.estimate = Some(v),
                    "innovation" => cell.innovation = Some(v),
                    "covariance" => cell.covariance = Some(MatrixCell::Full(v)),
                    _ => cell.innovation_cov = Some(MatrixCell::Full(v)),
                }
            }
            cell.model = model.map(|[f, h, q, r]| ModelCell {
                f: f.cell(run, step, steps),
                h: h.cell(run, step, steps),
                q: q.cell(run, step, steps),
                r: r.cell(run, step, steps),
            });
            (run, step, cell)
        })
        .collect()
}

/// The model arrays `F`, `H`, `Q`, `R`, all or none, with their shapes checked.
fn model(
    arrays: [Option<Array>; 4],
    runs: usize,
    steps: usize,
) -> Result<Option<[ModelArray; 4]>, Error> {
    let present: Vec<&str> = MODEL
        .iter()
        .zip(&arrays)
        .filter(|(_, a)| a.is_some())
        .map(|(n, _)| *n)
        .collect();
    if !model_given(&present)? {
        return Ok(None);
    }
    let [f, h, q, r] = arrays;
    let take = |name: &str, a: Option<Array>| {
        let a = a.unwrap_or(Array {
            shape: vec![],
            data: vec![],
        });
        ModelArray::of_shape(name, &a.shape, a.data, (runs, steps))
    };
    let [f, h, q, r] = [take("F", f)?, take("H", h)?, take("Q", q)?, take("R", r)?];
    let n = f.rows;
    let m = h.rows;
    for (array, a, want) in [
        ("F", &f, (n, n)),
        ("H", &h, (m, n)),
        ("Q", &q, (n, n)),
        ("R", &r, (m, m)),
    ] {
        if (a.rows, a.cols) != want {
            return Err(Error::array(
                array,
                format!(
                    "array {array} holds {}x{} matrices; with F of {n}x{n} and H of {m} rows it \
                     must be {}x{}",
                    a.rows, a.cols, want.0, want.1
                ),
            ));
        }
    }
    Ok(Some([f, h, q, r]))
}
