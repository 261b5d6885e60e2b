//! Seeded, parallel Monte Carlo for kalibra, with results independent of the thread count.
//!
//! # What this crate is for
//! [`MonteCarlo`] runs `runs` independent replications of a study. Run `i` draws every random
//! number from its own generator, [`MonteCarlo::rng`]`(i)`: ChaCha8 seeded from the study's
//! seed, on stream `i`. Runs execute in parallel on rayon; each run writes into a streaming
//! accumulator (kalibra-metrics' [`Merge`] types), so a study holds one accumulator per block of
//! runs, never the runs themselves.
//!
//! # Determinism
//! The runs are cut into at most [`MAX_BLOCKS`] contiguous blocks whose boundaries depend only
//! on the number of runs. Each block feeds its runs, in order, into a fresh accumulator; the
//! block accumulators are then merged in block order on the calling thread. The sequence of
//! floating-point operations is therefore fixed, and results are bit-identical for 1, 2 or 64
//! threads (a test checks it). Errors are deterministic too: the error of the lowest-numbered
//! failing run is returned.
//!
//! # Lane-wise draws
//! Batched studies step [`BATCH`](kalibra_linalg::simd::BATCH) runs together
//! ([`MonteCarlo::accumulate_batched`]); [`ChaCha8Lanes`] draws for them together: the runs'
//! ChaCha8 blocks computed with SIMD, one block per vector lane, and each run reading only its
//! own stream's words, in order, so that every run draws exactly the numbers (and
//! [`ChaCha8Lanes::standard_normals`] exactly the ziggurat normals) its own [`ChaCha8Rng`]
//! would give, on every instruction set. Results stay those of the one-run studies.
//!
//! # Where each job lives
//! * `lib.rs`: [`MonteCarlo`], its blocks and the one-run loops ([`MonteCarlo::accumulate`],
//!   [`MonteCarlo::map`]), [`SimError`].
//! * `batch.rs`: the batched loops ([`MonteCarlo::accumulate_batched`]) and the lane-wise
//!   truths ([`LinearTruthBatch`], [`TruthBatch`]).
//! * `lanes.rs`: lane-wise ChaCha8 draws ([`ChaCha8Lanes`], [`LaneRng`]); `lanes/gather.rs`
//!   the AVX-512 ziggurat pass, the crate's one module with `unsafe` code;
//!   `ziggurat_tables.rs` rand_distr's tables.
//! * `shard.rs`: studies split across processes and merged ([`Shard`], [`Partial`],
//!   [`merge`]).
//!
//! The SIMD vocabulary (the instruction set, [`BATCH`](kalibra_linalg::simd::BATCH) and the
//! lane type) is kalibra-linalg's [`simd`](kalibra_linalg::simd) module.
//!
//! # Example
//! ```
//! use kalibra_sim::MonteCarlo;
//! use kalibra_metrics::StepMean;
//! use rand::RngExt;
//!
//! // The mean of 1000 uniform draws, one per run.
//! let mc = MonteCarlo::new(1000, 42);
//! let mean = mc.accumulate(|| StepMean::new(1), |_run, rng, acc| {
//!     acc.push(0, rng.random::<f64>())
//! })?;
//! assert!(mean.mean(0).is_some_and(|m| (m - 0.5).abs() < 0.05));
//! assert_eq!(mc.threads(1).accumulate(|| StepMean::new(1), |_, rng, acc| acc.push(0, rng.random::<f64>()))?, mean);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod batch;
mod lanes;
mod shard;
mod ziggurat_tables;

pub use batch::{LinearTruthBatch, RunFailure, TruthBatch};
pub use lanes::{ChaCha8Lanes, LaneRng, LanesError};
/// The generator of every Monte Carlo run (re-exported so callers can name it).
pub use rand_chacha::ChaCha8Rng;
pub use shard::{
    PARTIAL_FORMAT_VERSION, Partial, Shard, ShardError, StudyId, blocks_in_order, config_hash,
    merge,
};

use kalibra_metrics::Merge;
use rand_chacha::rand_core::SeedableRng;
use rayon::prelude::*;

/// The most blocks a study is cut into: enough to keep 64 threads busy, few enough that the
/// block accumulators stay small beside the runs they summarise.
pub const MAX_BLOCKS: usize = 64;

/// Why a Monte Carlo study failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError<E: std::error::Error + 'static> {
    /// A run failed; the lowest-numbered failing run is reported.
    #[error("run {run} failed")]
    Run {
        /// The run index.
        run: usize,
        /// Its error.
        #[source]
        source: E,
    },
    /// The thread pool for an explicit thread count could not be built.
    #[error("build a thread pool of {threads} threads: {message}")]
    ThreadPool {
        /// Threads asked for.
        threads: usize,
        /// rayon's message, or the limit ([`MAX_THREADS`]) exceeded.
        message: String,
    },
}

/// A Monte Carlo study: number of runs, seed, and optionally a thread count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MonteCarlo {
    runs: usize,
    seed: u64,
    threads: Option<usize>,
}

impl MonteCarlo {
    /// A study of `runs` runs from `seed`, on rayon's global pool.
    pub fn new(runs: usize, seed: u64) -> Self {
        Self {
            runs,
            seed,
            threads: None,
        }
    }

    /// The same study on a dedicated pool of `threads` threads (`0` means rayon's global
    /// pool). The results do not change; only the wall time does. A count above
    /// [`MAX_THREADS`] makes the study's run a [`SimError::ThreadPool`] error.
    pub fn threads(mut self, threads: usize) -> Self {
        self.threads = (threads > 0).then_some(threads);
        self
    }

    /// Number of runs.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// The seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The generator of run `run`: ChaCha8 from the seed, on stream `run`. Streams are
    /// independent 2^64-block sequences, so runs never share random numbers.
    pub fn rng(&self, run: usize) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(run as u64);
        rng
    }

    /// Block `b`'s run range: contiguous, sizes differing by at most one, fixed by `runs`.
    fn block(&self, b: usize, blocks: usize) -> std::ops::Range<usize> {
        (b * self.runs / blocks)..((b + 1) * self.runs / blocks)
    }

    fn in_pool<T: Send, E: std::error::Error + Send + 'static>(
        &self,
        work: impl FnOnce() -> Result<T, SimError<E>> + Send,
    ) -> Result<T, SimError<E>> {
        in_pool(self.threads, work)
    }

    /// Runs the study into accumulators: `one(run, rng, acc)` simulates run `run` with its own
    /// generator and pushes its results into `acc`; `make()` builds an empty accumulator.
    ///
    /// # Errors
    /// [`SimError::Run`] with the lowest failing run, [`SimError::ThreadPool`] if an explicit
    /// pool cannot be built.
    pub fn accumulate<A, E, Make, One>(&self, make: Make, one: One) -> Result<A, SimError<E>>
    where
        A: Merge + Send,
        E: std::error::Error + Send + 'static,
        Make: Fn() -> A + Sync + Send,
        One: Fn(usize, &mut ChaCha8Rng, &mut A) -> Result<(), E> + Sync + Send,
    {
        let blocks = self.blocks();
        let parts =
            self.block_accumulators(0..blocks, |b| self.run_block(b, blocks, &make, &one))?;
        Ok(fold_blocks(parts).unwrap_or_else(make))
    }

    /// The accumulators of the blocks `range`, computed in parallel on the study's pool and
    /// returned in block order; an error is the lowest failing block's (so its lowest failing
    /// run), whatever the thread count. Every accumulating entry point (one run at a time or
    /// batched, whole or one shard) goes through here.
    pub(crate) fn block_accumulators<A, E>(
        &self,
        range: std::ops::Range<usize>,
        block: impl Fn(usize) -> Result<A, SimError<E>> + Sync + Send,
    ) -> Result<Vec<A>, SimError<E>>
    where
        A: Send,
        E: std::error::Error + Send + 'static,
    {
        self.in_pool(|| {
            // Collected whole before the errors are looked at: rayon's own collect into a
            // Result would return whichever error a thread met first.
            let parts: Vec<Result<A, SimError<E>>> = range.into_par_iter().map(block).collect();
            parts.into_iter().collect()
        })
    }

    /// Block `b` of `blocks` into a fresh accumulator, its runs in order: the one piece of
    /// work that [`MonteCarlo::accumulate`] and [`MonteCarlo::accumulate_shard`] share, so a
    /// shard's blocks are the one-process blocks to the bit.
    fn run_block<A, E, Make, One>(
        &self,
        b: usize,
        blocks: usize,
        make: &Make,
        one: &One,
    ) -> Result<A, SimError<E>>
    where
        E: std::error::Error + Send + 'static,
        Make: Fn() -> A,
        One: Fn(usize, &mut ChaCha8Rng, &mut A) -> Result<(), E>,
    {
        let mut acc = make();
        for run in self.block(b, blocks) {
            let mut rng = self.rng(run);
            one(run, &mut rng, &mut acc).map_err(|source| SimError::Run { run, source })?;
        }
        Ok(acc)
    }

    /// Runs the study and returns each run's output, in run order.
    ///
    /// # Errors
    /// As [`MonteCarlo::accumulate`].
    pub fn map<T, E, One>(&self, one: One) -> Result<Vec<T>, SimError<E>>
    where
        T: Send,
        E: std::error::Error + Send + 'static,
        One: Fn(usize, &mut ChaCha8Rng) -> Result<T, E> + Sync + Send,
    {
        self.in_pool(|| {
            (0..self.runs)
                .into_par_iter()
                .map(|run| {
                    one(run, &mut self.rng(run)).map_err(|source| SimError::Run { run, source })
                })
                .collect()
        })
    }
}

/// Folds block accumulators from the left, in block order: the one fold of a study, shared by
/// [`MonteCarlo::accumulate`], [`MonteCarlo::accumulate_batched`] and the shards' [`merge`], so
/// that all three add the same sums in the same order. `None` for no blocks.
pub(crate) fn fold_blocks<A: Merge>(blocks: impl IntoIterator<Item = A>) -> Option<A> {
    let mut blocks = blocks.into_iter();
    let mut total = blocks.next()?;
    for b in blocks {
        total.merge(&b);
    }
    Some(total)
}

/// The most threads a dedicated pool ([`MonteCarlo::threads`], `kalibra_tune::sweep`) is built
/// with: far beyond any machine's cores. rayon reserves its per-thread state before it spawns, so
/// `usize::MAX` threads would be a "capacity overflow" panic (`tests/extreme_sizes.rs`).
pub const MAX_THREADS: usize = 4096;

/// Runs `work` on a pool of `threads` threads, or on rayon's global pool for `None`.
///
/// Public so that other crates' parallel loops (kalibra-tune's `sweep`) build their explicit
/// pool the way the studies do, with the same [`SimError::ThreadPool`].
///
/// ```
/// let sum = kalibra_sim::in_pool(Some(2), || Ok::<_, kalibra_sim::SimError<std::fmt::Error>>(1 + 1))?;
/// assert_eq!(sum, 2);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`SimError::ThreadPool`] if the pool cannot be built; otherwise `work`'s result.
pub fn in_pool<T: Send, E: std::error::Error + Send + 'static>(
    threads: Option<usize>,
    work: impl FnOnce() -> Result<T, SimError<E>> + Send,
) -> Result<T, SimError<E>> {
    if let Some(threads) = threads.filter(|&t| t > MAX_THREADS) {
        return Err(SimError::ThreadPool {
            threads,
            message: format!("more than MAX_THREADS ({MAX_THREADS})"),
        });
    }
    match threads {
        None => work(),
        Some(threads) => rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| SimError::ThreadPool {
                threads,
                message: e.to_string(),
            })?
            .install(work),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_metrics::{MetricsError, StepMean};
    use rand::RngExt;

    #[test]
    fn blocks_cover_every_run_once() {
        for runs in [1, 7, 64, 65, 1000] {
            let mc = MonteCarlo::new(runs, 0);
            let blocks = runs.clamp(1, MAX_BLOCKS);
            let covered: Vec<usize> = (0..blocks).flat_map(|b| mc.block(b, blocks)).collect();
            assert_eq!(covered, (0..runs).collect::<Vec<_>>());
        }
    }

    #[test]
    fn streams_differ_between_runs_and_repeat_for_a_run() {
        let mc = MonteCarlo::new(2, 5);
        let a: u64 = mc.rng(0).random();
        let b: u64 = mc.rng(1).random();
        assert_ne!(a, b);
        assert_eq!(a, mc.rng(0).random::<u64>());
    }

    #[test]
    fn reports_the_lowest_failing_run() {
        let mc = MonteCarlo::new(200, 1).threads(4);
        let err = mc
            .accumulate(
                || StepMean::new(1),
                |run, _, acc| {
                    if run % 50 == 37 {
                        acc.push(5, 0.0)
                    } else {
                        acc.push(0, 1.0)
                    }
                },
            )
            .unwrap_err();
        assert!(
            matches!(
                err,
                SimError::Run {
                    run: 37,
                    source: MetricsError::StepOutOfRange { .. }
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn map_keeps_run_order() {
        let out = MonteCarlo::new(100, 3)
            .threads(3)
            .map(|run, _| Ok::<_, MetricsError>(run * 2))
            .unwrap();
        assert_eq!(out, (0..100).map(|r| r * 2).collect::<Vec<_>>());
    }
}
