//! Shards: one study run as several independent pieces (on several machines), merged into the
//! result of the one-process run, bit for bit.
//!
//! A study of `R` runs is cut into `B = min(R, MAX_BLOCKS)` blocks whose boundaries depend only
//! on `R` (see [`MonteCarlo`]). Shard `i` of `S` runs a contiguous range of those blocks,
//! `i * B / S .. (i + 1) * B / S`, and keeps every block's accumulator apart: its
//! [`Partial`]. [`merge`] lays the blocks of all `S` partials end to end, in shard order, and
//! folds them from the left exactly as [`MonteCarlo::accumulate`] folds its blocks, so the
//! merged accumulator is the one-process accumulator to the bit, whatever `S` and whatever
//! thread count each shard used. (Merging already-merged shard totals would not be: floating
//! point addition is not associative, and `((b0 + b1) + (b2 + b3))` differs from
//! `(((b0 + b1) + b2) + b3)` in the last bits.)
//!
//! A partial carries the study's identity ([`StudyId`]: seed, runs, a hash of the
//! configuration and the kalibra version) and its shard; [`merge`] refuses partials of
//! different studies, a shard seen twice, a missing shard, and accumulators whose shapes do not
//! fit, each with its own [`ShardError`]. With serde, a partial serialises to a small
//! self-describing record (the format is documented on [`Partial`]).
//!
//! ```
//! use kalibra_metrics::StepMean;
//! use kalibra_sim::{MonteCarlo, Shard, StudyId, merge};
//! use rand::RngExt;
//!
//! let mc = MonteCarlo::new(1000, 42);
//! let id = StudyId::new(&mc, 0xfeed, "example");
//! let one = |_run: usize, rng: &mut kalibra_sim::ChaCha8Rng, acc: &mut StepMean| {
//!     acc.push(0, rng.random::<f64>())
//! };
//! // Three shards, as three machines would run them (here one after the other).
//! let mut parts = Vec::new();
//! for i in 0..3 {
//!     parts.push(mc.accumulate_shard(Shard::new(i, 3)?, &id, || StepMean::new(1), one)?);
//! }
//! let merged = merge(parts)?;
//! assert_eq!(merged, mc.accumulate(|| StepMean::new(1), one)?);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fmt;
use std::str::FromStr;

use kalibra_metrics::Merge;
use serde::{Deserialize, Serialize};

use crate::{MAX_BLOCKS, MonteCarlo, SimError};

/// The version of the [`Partial`] record; [`merge`] refuses any other.
pub const PARTIAL_FORMAT_VERSION: u32 = 1;

/// Why shards could not be made or merged.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ShardError {
    /// A shard index or count that does not describe a shard (`index >= count`, `count == 0`,
    /// or text that is not `i/S`).
    #[error("invalid shard {text:?}: expected i/S with 0 <= i < S (for instance 0/4)")]
    Invalid {
        /// What was given.
        text: String,
    },
    /// No partial results to merge.
    #[error("no partial results to merge")]
    Empty,
    /// A partial of a format version this build does not read.
    #[error("shard {index} has format version {found}; this kalibra reads version {expected}")]
    Version {
        /// The shard's index.
        index: usize,
        /// Its version.
        found: u32,
        /// [`PARTIAL_FORMAT_VERSION`].
        expected: u32,
    },
    /// Two partials of different studies (seed, runs, configuration or kalibra version).
    #[error("shard {index} belongs to another study: {found} (the first shard: {expected})")]
    OtherStudy {
        /// The shard's index.
        index: usize,
        /// Its study.
        found: StudyId,
        /// The first partial's study.
        expected: StudyId,
    },
    /// Two partials cut the study into different numbers of shards.
    #[error("shard {index}/{found} does not fit a study cut into {expected} shards")]
    OtherCount {
        /// The shard's index.
        index: usize,
        /// Its shard count.
        found: usize,
        /// The first partial's shard count.
        expected: usize,
    },
    /// The same shard twice.
    #[error("shard {index}/{count} is given twice")]
    Duplicate {
        /// The shard's index.
        index: usize,
        /// The shard count.
        count: usize,
    },
    /// Shards missing from `0..count`.
    #[error("missing shard(s) {missing:?} of {count}")]
    Missing {
        /// The missing indices.
        missing: Vec<usize>,
        /// The shard count.
        count: usize,
    },
    /// A partial whose number of block accumulators is not its shard's.
    #[error("shard {index} holds {found} block accumulators where its blocks number {expected}")]
    Blocks {
        /// The shard's index.
        index: usize,
        /// Accumulators found.
        found: usize,
        /// Blocks of the shard.
        expected: usize,
    },
    /// A block accumulator whose shape (steps, dimension) differs from the first one's.
    #[error("shard {index}: a block accumulator's shape differs from the first shard's")]
    Shape {
        /// The shard's index.
        index: usize,
    },
}

/// Shard `index` of `count`: a contiguous range of a study's blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Shard {
    index: usize,
    count: usize,
}

impl Shard {
    /// The whole study as one shard.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Shard `index` of `count`.
    ///
    /// # Errors
    /// [`ShardError::Invalid`] unless `index < count`.
    pub fn new(index: usize, count: usize) -> Result<Self, ShardError> {
        if index < count {
            Ok(Self { index, count })
        } else {
            Err(ShardError::Invalid {
                text: format!("{index}/{count}"),
            })
        }
    }

    /// The shard's index, `0 <= index < count`.
    pub fn index(&self) -> usize {
        self.index
    }

    /// How many shards the study is cut into.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The blocks of a study of `blocks` blocks this shard runs. Shards differ by at most one
    /// block; with more shards than blocks some shards are empty (and still needed by
    /// [`merge`], which checks that none is missing).
    pub fn blocks(&self, blocks: usize) -> std::ops::Range<usize> {
        // u128 keeps `index * blocks` exact for any usize inputs.
        let at = |i: usize| (i as u128 * blocks as u128 / self.count as u128) as usize;
        at(self.index)..at(self.index + 1)
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    /// Parses `i/S` (as `--shard 2/8` gives it, or `$SLURM_ARRAY_TASK_ID/8`).
    fn from_str(text: &str) -> Result<Self, ShardError> {
        let invalid = || ShardError::Invalid {
            text: text.to_owned(),
        };
        let (i, s) = text.split_once('/').ok_or_else(invalid)?;
        let parse = |t: &str| t.trim().parse::<usize>().map_err(|_| invalid());
        Self::new(parse(i)?, parse(s)?).map_err(|_| invalid())
    }
}

/// What identifies a study across machines: partials merge only with partials of the same
/// identity.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct StudyId {
    /// The study's seed.
    pub seed: u64,
    /// Its number of runs.
    pub runs: usize,
    /// A hash of everything else that changes its results (the configuration without the thread
    /// count, which never does); the caller computes it, for instance with [`config_hash`].
    pub config_hash: u64,
    /// What produced the partial (for instance `"kalibra 0.1.0"`): builds that could compute
    /// different bits do not mix.
    pub version: String,
}

impl StudyId {
    /// The identity of `mc` with the caller's configuration hash and version label.
    pub fn new(mc: &MonteCarlo, config_hash: u64, version: impl Into<String>) -> Self {
        Self {
            seed: mc.seed(),
            runs: mc.runs(),
            config_hash,
            version: version.into(),
        }
    }
}

impl fmt::Display for StudyId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "seed {}, {} runs, configuration {:016x}, {}",
            self.seed, self.runs, self.config_hash, self.version
        )
    }
}

/// FNV-1a, 64 bits, of `bytes`: a stable hash (the same on every machine and build, unlike
/// std's `DefaultHasher`) for [`StudyId::config_hash`], taken of a canonical serialisation of
/// the configuration.
pub fn config_hash(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// One shard's result: its block accumulators, in block order, with the study's identity.
///
/// Serialised (serde) it is a record of these fields:
/// - `format`: [`PARTIAL_FORMAT_VERSION`];
/// - `study`: the [`StudyId`] (`seed`, `runs`, `config_hash`, `version`);
/// - `shard`: `index` and `count`;
/// - `blocks`: the accumulators of the shard's blocks, in order, in the accumulator's own
///   serde form.
///
/// Floating-point sums must survive the round trip exactly for the merge to be bit-identical:
/// use a format that writes `f64` exactly (serde_json with its `float_roundtrip` feature,
/// which the `kalibra` tools enable, or any binary format).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Partial<A> {
    /// [`PARTIAL_FORMAT_VERSION`] when written.
    pub format: u32,
    /// The study.
    pub study: StudyId,
    /// Which shard.
    pub shard: Shard,
    /// The accumulators of the shard's blocks, in block order.
    pub blocks: Vec<A>,
}

impl<A> Partial<A> {
    /// A partial of the current format version, for a study that runs its shard's blocks
    /// itself ([`MonteCarlo::accumulate_shard`] makes it for the others): `blocks` are the
    /// accumulators of [`Shard::blocks`], in order.
    pub fn new(study: StudyId, shard: Shard, blocks: Vec<A>) -> Self {
        Self {
            format: PARTIAL_FORMAT_VERSION,
            study,
            shard,
            blocks,
        }
    }
}

impl MonteCarlo {
    /// The number of blocks this study is cut into (see the crate docs); shards divide them.
    pub fn blocks(&self) -> usize {
        self.runs().clamp(1, MAX_BLOCKS)
    }

    /// The runs of block `b` (of [`MonteCarlo::blocks`]): contiguous, sizes differing by at
    /// most one, fixed by the number of runs alone. For a study that accumulates its blocks
    /// itself (the Python package's Monte Carlo evaluates each block on its own evaluator and
    /// merges them in block order, as [`MonteCarlo::accumulate`] does); empty for `b` beyond
    /// the last block.
    pub fn block_runs(&self, b: usize) -> std::ops::Range<usize> {
        let blocks = self.blocks();
        if b >= blocks {
            return self.runs()..self.runs();
        }
        self.block(b, blocks)
    }

    /// Runs shard `shard` of the study: its blocks, each into its own fresh accumulator, in
    /// parallel as [`MonteCarlo::accumulate`] runs them. [`merge`] of every shard's partial
    /// gives what [`MonteCarlo::accumulate`] gives, to the bit.
    ///
    /// # Errors
    /// As [`MonteCarlo::accumulate`]: the lowest failing run of the shard.
    pub fn accumulate_shard<A, E, Make, One>(
        &self,
        shard: Shard,
        study: &StudyId,
        make: Make,
        one: One,
    ) -> Result<Partial<A>, SimError<E>>
    where
        A: Merge + Send,
        E: std::error::Error + Send + 'static,
        Make: Fn() -> A + Sync + Send,
        One: Fn(usize, &mut crate::ChaCha8Rng, &mut A) -> Result<(), E> + Sync + Send,
    {
        let blocks = self.blocks();
        let accs = self.block_accumulators(shard.blocks(blocks), |b| {
            self.run_block(b, blocks, &make, &one)
        })?;
        Ok(Partial::new(study.clone(), shard, accs))
    }
}

/// Merges the partials of every shard of one study into the study's accumulator: the blocks
/// of all shards, in shard order (the order `parts` comes in does not matter), folded from the
/// left as [`MonteCarlo::accumulate`] folds them.
///
/// # Errors
/// [`ShardError::Empty`] for no partials; [`ShardError::Version`], [`ShardError::OtherStudy`],
/// [`ShardError::OtherCount`], [`ShardError::Duplicate`] and [`ShardError::Missing`] for
/// partials that are not exactly the shards `0..S` of one study; [`ShardError::Blocks`] for a
/// partial with the wrong number of blocks; [`ShardError::Shape`] for accumulators that do not
/// fit together ([`Merge::fits`]).
pub fn merge<A: Merge>(parts: Vec<Partial<A>>) -> Result<A, ShardError> {
    let parts = blocks_in_order(parts)?;
    // Shapes first, against the first block, so that the fold cannot panic.
    if let Some((_, first)) = parts.first() {
        for (index, block) in &parts {
            if !first.fits(block) {
                return Err(ShardError::Shape { index: *index });
            }
        }
    }
    crate::fold_blocks(parts.into_iter().map(|(_, b)| b)).ok_or(ShardError::Empty)
}

/// The blocks of every shard of one study, in the study's block order, each with its shard's
/// index, after the checks [`merge`] makes of the partials themselves: for accumulators that
/// merge their own way (the Python package's evaluators, whose merge can fail and is not
/// [`Merge`]), which the caller then folds from the left as [`merge`] does.
///
/// # Errors
/// As [`merge`], but for [`ShardError::Shape`], which only the caller's merge can tell.
pub fn blocks_in_order<A>(mut parts: Vec<Partial<A>>) -> Result<Vec<(usize, A)>, ShardError> {
    let first = parts.first().ok_or(ShardError::Empty)?;
    let (study, count) = (first.study.clone(), first.shard.count);
    for part in &parts {
        let index = part.shard.index;
        if part.format != PARTIAL_FORMAT_VERSION {
            return Err(ShardError::Version {
                index,
                found: part.format,
                expected: PARTIAL_FORMAT_VERSION,
            });
        }
        if part.study != study {
            return Err(ShardError::OtherStudy {
                index,
                found: part.study.clone(),
                expected: study,
            });
        }
        // A deserialised shard was never checked by Shard::new.
        if part.shard.count != count || index >= count {
            return Err(ShardError::OtherCount {
                index,
                found: part.shard.count,
                expected: count,
            });
        }
    }
    parts.sort_by_key(|p| p.shard.index);
    if let Some(w) = parts.windows(2).find(|w| w[0].shard == w[1].shard) {
        return Err(ShardError::Duplicate {
            index: w[0].shard.index,
            count,
        });
    }
    if parts.len() != count {
        let have: Vec<usize> = parts.iter().map(|p| p.shard.index).collect();
        return Err(ShardError::Missing {
            missing: (0..count)
                .filter(|i| have.binary_search(i).is_err())
                .collect(),
            count,
        });
    }
    let blocks = study.runs.clamp(1, MAX_BLOCKS);
    for part in &parts {
        let expected = part.shard.blocks(blocks).len();
        if part.blocks.len() != expected {
            return Err(ShardError::Blocks {
                index: part.shard.index,
                found: part.blocks.len(),
                expected,
            });
        }
    }
    Ok(parts
        .into_iter()
        .flat_map(|p| {
            let index = p.shard.index;
            p.blocks.into_iter().map(move |b| (index, b))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_cover_every_block_once_in_order() {
        for blocks in [1, 2, 7, 64] {
            for count in 1..=70 {
                let covered: Vec<usize> = (0..count)
                    .flat_map(|i| Shard::new(i, count).unwrap().blocks(blocks))
                    .collect();
                assert_eq!(covered, (0..blocks).collect::<Vec<_>>());
            }
        }
    }

    #[test]
    fn shard_text_parses_and_refuses() {
        assert_eq!("2/8".parse::<Shard>(), Shard::new(2, 8));
        assert_eq!(Shard::new(2, 8).unwrap().to_string(), "2/8");
        for bad in ["8/8", "1", "a/2", "1/0", "-1/2", "", "1/2/3"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }

    #[test]
    fn config_hash_is_fnv1a() {
        // The FNV-1a test vectors.
        assert_eq!(config_hash(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(config_hash(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
