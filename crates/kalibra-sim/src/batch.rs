//! Batched Monte Carlo: runs stepped [`BATCH`] at a time ([`MonteCarlo::accumulate_batched`])
//! and their true trajectories ([`TruthBatch`]).

use kalibra_filters::batch::{BATCH, Lanes};
use kalibra_linalg::{Const, SVector};
use kalibra_metrics::Merge;
use kalibra_models::{Dynamics, Measurement, ModelError, Simulator};
use rayon::prelude::*;

use crate::{ChaCha8Rng, MAX_BLOCKS, MonteCarlo, SimError};

/// The failure of one run in a group of runs stepped together: the lowest-numbered failing
/// run of the group, with its error.
#[derive(Debug, thiserror::Error)]
#[error("run {run} failed")]
pub struct RunFailure<E: std::error::Error + 'static> {
    /// The run index (in the study, not in the group).
    pub run: usize,
    /// Its error.
    #[source]
    pub source: E,
}

impl MonteCarlo {
    /// Runs the study into accumulators in groups of at most [`BATCH`] consecutive runs:
    /// `group(runs, rngs, acc)` simulates the runs `runs` (`rngs[i]` is the generator of run
    /// `runs.start + i`, [`MonteCarlo::rng`]) and pushes their results into `acc`.
    ///
    /// The runs are cut into the blocks [`MonteCarlo::accumulate`] uses, each block into groups
    /// of [`BATCH`] runs from its start (the last group of a block may be shorter), and a block
    /// feeds its groups in order into a fresh accumulator; blocks merge in order. So the results
    /// are bit-identical for any thread count, and a group that pushes its runs' values step by
    /// step, run by run within a step, adds them to each step's sums in the order the one-run
    /// closure of [`MonteCarlo::accumulate`] does.
    ///
    /// ```
    /// use kalibra_sim::{MonteCarlo, RunFailure};
    /// use kalibra_metrics::{MetricsError, StepMean};
    /// use rand::RngExt;
    ///
    /// let mc = MonteCarlo::new(100, 7);
    /// let one = mc.accumulate(|| StepMean::new(1), |_, rng, acc| acc.push(0, rng.random::<f64>()))?;
    /// let batched = mc.accumulate_batched(|| StepMean::new(1), |runs, rngs, acc| {
    ///     for (run, rng) in runs.zip(rngs.iter_mut()) {
    ///         acc.push(0, rng.random::<f64>())
    ///             .map_err(|source| RunFailure { run, source })?;
    ///     }
    ///     Ok::<(), RunFailure<MetricsError>>(())
    /// })?;
    /// assert_eq!(one, batched);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::Run`] with the lowest failing run (groups report their lowest failing run),
    /// [`SimError::ThreadPool`] if an explicit pool cannot be built.
    pub fn accumulate_batched<A, E, Make, Group>(
        &self,
        make: Make,
        group: Group,
    ) -> Result<A, SimError<E>>
    where
        A: Merge + Send,
        E: std::error::Error + Send + 'static,
        Make: Fn() -> A + Sync + Send,
        Group: Fn(std::ops::Range<usize>, &mut [ChaCha8Rng], &mut A) -> Result<(), RunFailure<E>>
            + Sync
            + Send,
    {
        let blocks = self.runs.clamp(1, MAX_BLOCKS);
        self.in_pool(|| {
            let parts: Vec<Result<A, SimError<E>>> = (0..blocks)
                .into_par_iter()
                .map(|b| {
                    let mut acc = make();
                    let block = self.block(b, blocks);
                    let mut start = block.start;
                    while start < block.end {
                        let runs = start..(start + BATCH).min(block.end);
                        let mut rngs: Vec<ChaCha8Rng> = runs.clone().map(|r| self.rng(r)).collect();
                        group(runs.clone(), &mut rngs, &mut acc).map_err(|f| SimError::Run {
                            run: f.run,
                            source: f.source,
                        })?;
                        start = runs.end;
                    }
                    Ok(acc)
                })
                .collect();
            let mut parts = parts.into_iter();
            let mut total = parts.next().unwrap_or_else(|| Ok(make()))?;
            for part in parts {
                total.merge(&part?);
            }
            Ok(total)
        })
    }
}

/// The true trajectories of up to [`BATCH`] runs, in the lane layout of
/// [`KfBatch`](kalibra_filters::batch::KfBatch): lane `i` is a [`Simulator`] of its own, drawing
/// from run `i`'s generator exactly what the scalar study's simulator draws (the initial state,
/// then per step the measurement noise and the process noise), through the same model calls,
/// so a lane's truth is bit-identical to its scalar run's.
///
/// The simulation is per lane on purpose: the draws (ChaCha8 and the ziggurat normal) are
/// sequential per generator and are most of its cost; the model arithmetic beside them is a
/// few matrix-vector products.
#[derive(Clone, Debug)]
pub struct TruthBatch<const N: usize, const M: usize, D, H> {
    lanes: Vec<Simulator<Const<N>, D, H>>,
    x: [Lanes; N],
    z: [Lanes; M],
}

impl<const N: usize, const M: usize, D, H> TruthBatch<N, M, D, H>
where
    D: Dynamics<Const<N>> + Clone,
    H: Measurement<Const<N>, Const<M>> + Clone,
{
    /// One lane per generator (at most [`BATCH`]), lane `i` (run `first_run + i`) starting at
    /// step 0 from the state `x0(rng_i)` it draws (`m0 + L0 n` for a Gaussian prior, as the
    /// scalar study draws it). Lanes past `rngs.len()` hold zeros.
    ///
    /// # Errors
    /// What [`Simulator::new`] returns for the lowest lane whose initial state it refuses, as
    /// that lane's run's failure.
    ///
    /// # Panics
    /// If more than [`BATCH`] generators are given.
    pub fn new(
        dynamics: &D,
        measurement: &H,
        first_run: usize,
        rngs: &mut [ChaCha8Rng],
        mut x0: impl FnMut(&mut ChaCha8Rng) -> SVector<f64, N>,
    ) -> Result<Self, RunFailure<ModelError>> {
        assert!(rngs.len() <= BATCH, "at most {BATCH} lanes");
        let lanes = rngs
            .iter_mut()
            .enumerate()
            .map(|(lane, rng)| {
                Simulator::new(dynamics.clone(), measurement.clone(), x0(rng), 0).map_err(
                    |source| RunFailure {
                        run: first_run + lane,
                        source,
                    },
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            lanes,
            x: [[0.0; BATCH]; N],
            z: [[0.0; BATCH]; M],
        })
    }

    /// Number of live lanes.
    pub fn len(&self) -> usize {
        self.lanes.len()
    }

    /// Whether there are no lanes.
    pub fn is_empty(&self) -> bool {
        self.lanes.is_empty()
    }

    /// Steps every lane once ([`Simulator::step`]: measures `x_k`, then advances): afterwards
    /// [`TruthBatch::state`] holds the `x_k` and [`TruthBatch::measurement`] the `z_k` of every
    /// lane. A failing lane (a diverging truth) reports its error in its slot of the result and
    /// keeps its last values; the other lanes step on.
    ///
    /// # Panics
    /// If `rngs` has fewer generators than there are lanes.
    pub fn step(&mut self, rngs: &mut [ChaCha8Rng]) -> [Option<ModelError>; BATCH] {
        let mut failures: [Option<ModelError>; BATCH] = std::array::from_fn(|_| None);
        for (lane, (sim, rng)) in self.lanes.iter_mut().zip(rngs.iter_mut()).enumerate() {
            match sim.step::<Const<M>, _>(rng) {
                Ok((x, z)) => {
                    write_lane(&mut self.x, lane, &x);
                    write_lane(&mut self.z, lane, &z);
                }
                Err(e) => failures[lane] = Some(e),
            }
        }
        failures
    }

    /// The true states `x_k` of the last [`TruthBatch::step`], lane by lane.
    pub fn state(&self) -> &[Lanes; N] {
        &self.x
    }

    /// The measurements `z_k` of the last [`TruthBatch::step`], lane by lane.
    pub fn measurement(&self) -> &[Lanes; M] {
        &self.z
    }
}

fn write_lane<const D: usize>(out: &mut [Lanes; D], lane: usize, v: &SVector<f64, D>) {
    for (row, value) in out.iter_mut().zip(v.iter()) {
        row[lane] = *value;
    }
}
