//! `kalibra.Partial` and `kalibra.merge`: a Monte Carlo study run as shards (in Dask tasks,
//! job-array tasks, any processes) and merged into the report of the one-process run, bit for
//! bit.
//!
//! A shard evaluates its contiguous range of the study's blocks ([`kalibra_sim::Shard`]) and
//! keeps each block's evaluator apart, as data ([`kalibra_eval::EvaluatorState`]); the merge
//! resumes every block of every shard and folds them from the left in block order, the fold
//! of the one-process run ([`fold`], which both use). Folding a shard's blocks first would
//! change the association of the floating-point sums and the last bits of the report.
//!
//! The bytes of a partial (`Partial.to_bytes`, and what pickle carries) are one CBOR record,
//! followed by the record's 64-bit FNV-1a checksum ([`kalibra_sim::config_hash`]'s hash),
//! little-endian, so that a truncated or damaged partial is refused before it is read. The
//! record: `{"config": ..., "partial": ...}`, `partial` being kalibra-sim's
//! [`kalibra_sim::Partial`] (`format`, `study` = seed, runs, configuration hash and kalibra
//! version, `shard` = index and count, `blocks` = one evaluator state per block) and `config`
//! the study's configuration (model matrices row by row as little-endian byte strings,
//! steps, confidence, window, groups, lags), whose FNV-1a hash of its own CBOR is the
//! study's configuration hash.

use kalibra_eval::{Contents, Evaluator, EvaluatorState};
use kalibra_sim::{PARTIAL_FORMAT_VERSION, Partial, Shard, StudyId};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};
use serde::{Deserialize, Serialize};

use crate::error;
use crate::eval::{Report, evaluation_of};

/// What produced a partial: partials of other kalibra versions do not merge (their bits may
/// differ).
pub(crate) const VERSION: &str = concat!("kalibra ", env!("CARGO_PKG_VERSION"));

/// Everything but the seed, the runs and the thread count that decides a study's report:
/// what its configuration hash covers and what the merge rebuilds the evaluation from.
/// Matrices are row by row; floats keep their bits (byte strings, and CBOR floats, are exact).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct StudyConfig {
    /// The state and measurement dimensions.
    pub(crate) n: usize,
    pub(crate) m: usize,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) f: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) h: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) q: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) r: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) filter_q: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) filter_r: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) x0: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    pub(crate) p0: Vec<f64>,
    pub(crate) steps: usize,
    /// The evaluation's options, as `monte_carlo` took them.
    pub(crate) confidence: f64,
    pub(crate) window: Option<usize>,
    pub(crate) groups: Vec<(String, Vec<usize>)>,
    pub(crate) lags: usize,
}

impl StudyConfig {
    /// The FNV-1a hash of the configuration's CBOR: the same on every machine and build.
    pub(crate) fn hash(&self) -> Result<u64, String> {
        Ok(kalibra_sim::config_hash(&cbor(self)?))
    }

    /// What the evaluators of the study hold.
    pub(crate) fn contents(&self) -> Contents {
        study_contents(self.n, self.m)
    }
}

/// What a Monte Carlo study's evaluators hold: the whole log of a state of dimension `n`
/// measured in `m`, with the model.
pub(crate) fn study_contents(n: usize, m: usize) -> Contents {
    Contents {
        truth: Some(n),
        estimate: Some(n),
        covariance: Some(n),
        innovation: Some(m),
        innovation_cov: Some(m),
        model: Some((n, m)),
    }
}

/// A value's CBOR.
fn cbor<T: Serialize>(value: &T) -> Result<Vec<u8>, String> {
    let mut bytes = Vec::new();
    ciborium::into_writer(value, &mut bytes).map_err(|e| format!("write CBOR: {e}"))?;
    Ok(bytes)
}

/// A partial as written: the configuration beside kalibra-sim's partial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Record {
    config: StudyConfig,
    partial: Partial<EvaluatorState>,
}

/// Folds a study's block evaluators from the left, in block order: the one fold of the
/// one-process run and of [`merge`], so both add the same sums in the same order. Each block
/// comes with a label for its errors (its shard, in a merge).
pub(crate) fn fold(
    blocks: impl IntoIterator<Item = Result<(String, Evaluator), String>>,
) -> Result<Evaluator, String> {
    let mut blocks = blocks.into_iter();
    let (_, mut total) = blocks.next().ok_or_else(|| "no runs".to_string())??;
    for block in blocks {
        let (label, evaluator) = block?;
        total
            .merge(evaluator)
            .map_err(|e| format!("{label} does not merge: {e}"))?;
    }
    Ok(total)
}

/// One shard's partial result of `kalibra.monte_carlo(..., shard=(i, S))`: the evaluation
/// of its blocks of runs, kept apart so that `kalibra.merge` of every shard's partial gives
/// the one-process report to the bit.
///
/// Picklable (Dask, multiprocessing and joblib ship it as its bytes); ``to_bytes`` and
/// ``Partial.from_bytes`` write and read the bytes for files and queues. The bytes are a
/// CBOR record (format version, the study's identity: seed, runs, configuration hash and
/// kalibra version, the shard, the configuration, and one evaluator state per block)
/// followed by its 8-byte FNV-1a checksum; ``from_bytes`` refuses truncated, damaged or
/// foreign bytes with a ``KalibraError``.
///
/// Example:
///     >>> import pickle, numpy as np, kalibra
///     >>> args = (np.eye(1), np.eye(1), np.eye(1), np.eye(1), np.zeros(1), np.eye(1))
///     >>> part = kalibra.monte_carlo(*args, runs=10, steps=5, shard=(1, 2))
///     >>> (part.shard, part.shard_count, part.runs, part.seed)
///     (1, 2, 10, 0)
///     >>> pickle.loads(pickle.dumps(part)).to_bytes() == part.to_bytes()
///     True
#[pyclass(name = "Partial", module = "kalibra", frozen)]
pub struct PyPartial {
    record: Record,
}

impl PyPartial {
    /// The partial of shard `shard` of a study of `config` and `study`, its blocks' evaluators
    /// in block order.
    pub(crate) fn new(
        config: StudyConfig,
        study: StudyId,
        shard: Shard,
        blocks: Vec<Evaluator>,
    ) -> Self {
        let blocks = blocks.into_iter().map(Evaluator::into_state).collect();
        Self {
            record: Record {
                config,
                partial: Partial::new(study, shard, blocks),
            },
        }
    }

    /// The record's bytes and checksum.
    fn bytes(&self) -> Result<Vec<u8>, String> {
        let mut bytes = cbor(&self.record)?;
        let sum = kalibra_sim::config_hash(&bytes);
        bytes.extend_from_slice(&sum.to_le_bytes());
        Ok(bytes)
    }

    /// Reads what [`PyPartial::bytes`] writes.
    fn read(bytes: &[u8]) -> Result<Self, String> {
        let damaged = "the bytes are not a kalibra partial result, or were truncated or damaged";
        let split = bytes.len().checked_sub(8).ok_or(damaged)?;
        let (body, sum) = bytes.split_at(split);
        let mut le = [0u8; 8];
        le.copy_from_slice(sum);
        if kalibra_sim::config_hash(body) != u64::from_le_bytes(le) {
            return Err(format!("{damaged} (checksum mismatch)"));
        }
        match ciborium::from_reader::<Record, _>(body) {
            Ok(record) if record.partial.format == PARTIAL_FORMAT_VERSION => Ok(Self { record }),
            Ok(record) => Err(other_version(record.partial.format)),
            Err(e) => {
                // Another version's record may not parse as this one: name its version if
                // it has one (a second read only on this path, so a good partial is read once).
                #[derive(Deserialize)]
                struct Versioned {
                    partial: Format,
                }
                #[derive(Deserialize)]
                struct Format {
                    format: u32,
                }
                match ciborium::from_reader::<Versioned, _>(body) {
                    Ok(v) if v.partial.format != PARTIAL_FORMAT_VERSION => {
                        Err(other_version(v.partial.format))
                    }
                    _ => Err(format!("{damaged}: {e}")),
                }
            }
        }
    }
}

/// The refusal of a partial of another format version.
fn other_version(found: u32) -> String {
    format!(
        "a partial result of format version {found}; this kalibra ({VERSION}) reads version \
         {PARTIAL_FORMAT_VERSION}"
    )
}

#[pymethods]
impl PyPartial {
    /// The partial result of the bytes ``to_bytes`` wrote (in any process, on any machine
    /// with the same kalibra version).
    ///
    /// Raises:
    ///     KalibraError: for bytes that are not a partial result, truncated or damaged, or of
    ///     another format version.
    #[staticmethod]
    fn from_bytes(data: &[u8]) -> PyResult<Self> {
        Self::read(data).map_err(error)
    }

    /// The partial result as bytes (see the class docs for the format).
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        Ok(PyBytes::new(py, &self.bytes().map_err(error)?))
    }

    /// Pickles as its bytes: ``(Partial.from_bytes, (bytes,))``.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let from_bytes = slf.get_type().getattr("from_bytes")?;
        let bytes = slf.get().to_bytes(py)?;
        PyTuple::new(py, [from_bytes, PyTuple::new(py, [bytes])?.into_any()])
    }

    /// The shard's index ``i`` of ``shard=(i, S)``.
    #[getter]
    fn shard(&self) -> usize {
        self.record.partial.shard.index()
    }

    /// The number of shards ``S`` the study is cut into.
    #[getter]
    fn shard_count(&self) -> usize {
        self.record.partial.shard.count()
    }

    /// The study's number of runs (all shards').
    #[getter]
    fn runs(&self) -> usize {
        self.record.partial.study.runs
    }

    /// The study's seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.record.partial.study.seed
    }

    /// The study's configuration hash (FNV-1a, as 16 hexadecimal digits).
    #[getter]
    fn config_hash(&self) -> String {
        format!("{:016x}", self.record.partial.study.config_hash)
    }

    /// What produced the partial, for instance ``"kalibra 0.1.0"``.
    #[getter]
    fn version(&self) -> &str {
        &self.record.partial.study.version
    }

    /// The number of the study's blocks of runs this shard evaluated (0 when there are more
    /// shards than blocks).
    #[getter]
    fn blocks(&self) -> usize {
        self.record.partial.blocks.len()
    }

    fn __repr__(&self) -> String {
        let p = &self.record.partial;
        format!(
            "<kalibra.Partial shard {} of a Monte Carlo study ({})>",
            p.shard, p.study
        )
    }
}

/// The report of a sharded Monte Carlo study: merges the partial results of every shard
/// ``0 .. S-1`` of ``kalibra.monte_carlo(..., shard=(i, S))``, given in any order, into the
/// report ``monte_carlo`` without ``shard`` returns, to the bit (whatever ``S`` and the
/// thread counts the shards ran with).
///
/// Args:
///     parts: the ``Partial`` results (or their bytes), one per shard.
///
/// Returns:
///     Report.
///
/// Raises:
///     KalibraError: for no parts, parts of different studies (seed, runs, configuration or
///     kalibra version), of different shard counts, a shard given twice, missing shards,
///     bytes that are not a partial result, or a partial whose contents do not fit its study.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> args = (np.eye(1), np.eye(1), np.eye(1), np.eye(1), np.zeros(1), np.eye(1))
///     >>> parts = [kalibra.monte_carlo(*args, runs=50, steps=20, shard=(i, 3)) for i in range(3)]
///     >>> merged = kalibra.merge(parts)
///     >>> merged.to_json() == kalibra.monte_carlo(*args, runs=50, steps=20).to_json()
///     True
#[pyfunction]
fn merge<'py>(py: Python<'py>, parts: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let mut records = Vec::new();
    for (at, part) in parts.try_iter()?.enumerate() {
        let part = part?;
        if let Ok(p) = part.cast::<PyPartial>() {
            records.push(p.get().record.clone());
        } else if let Ok(bytes) = part.extract::<&[u8]>() {
            records.push(PyPartial::read(bytes).map_err(error)?.record);
        } else {
            return Err(error(format!(
                "argument parts: item {at} is a {}, not a kalibra.Partial or its bytes",
                part.get_type().name()?
            )));
        }
    }
    let report = py.detach(|| merge_records(records)).map_err(error)?;
    Ok(Bound::new(py, Report::new(report, "monte carlo"))?.into_any())
}

/// The merged report of `records`.
fn merge_records(records: Vec<Record>) -> Result<kalibra_eval::Report, String> {
    let config = records
        .first()
        .map(|r| r.config.clone())
        .ok_or_else(|| kalibra_sim::ShardError::Empty.to_string())?;
    let mut parts = Vec::with_capacity(records.len());
    let mut configs = Vec::with_capacity(records.len());
    for r in records {
        // A record whose configuration is not the one its identity's hash names was edited.
        if r.config.hash()? != r.partial.study.config_hash {
            return Err(format!(
                "shard {} carries a configuration that does not match its hash",
                r.partial.shard
            ));
        }
        configs.push((r.partial.shard, r.config));
        parts.push(r.partial);
    }
    let study = parts.first().map(|p| p.study.clone());
    let blocks = kalibra_sim::blocks_in_order(parts).map_err(|e| e.to_string())?;
    // Equal hashes, so equal configurations but for a forged collision.
    if let Some((shard, _)) = configs.iter().find(|(_, c)| *c != config) {
        return Err(format!(
            "shard {shard} has the study's configuration hash but another configuration"
        ));
    }
    let evaluation = evaluation_of(
        config.confidence,
        config.window,
        &config.groups,
        config.lags,
    )
    .map_err(|e| format!("the partials' configuration: {e}"))?;
    let contents = config.contents();
    let evaluator = fold(blocks.into_iter().map(|(index, state)| {
        let label = format!("a block of shard {index}");
        evaluation
            .resume(contents, state)
            .map(|e| (label.clone(), e))
            .map_err(|e| format!("{label}: {e}"))
    }))?;
    // Every run and step, and nothing else: states that claim other runs were not made by
    // this study (finish would name a missing cell, not the cause).
    if let Some(study) = study
        && (evaluator.runs() != study.runs || evaluator.steps() != config.steps)
    {
        return Err(format!(
            "the partials hold {} runs of {} steps, where the study has {} runs of {}",
            evaluator.runs(),
            evaluator.steps(),
            study.runs,
            config.steps
        ));
    }
    evaluator.finish(None).map_err(|e| e.to_string())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPartial>()?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    Ok(())
}
