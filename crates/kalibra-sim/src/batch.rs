//! Batched Monte Carlo: runs stepped [`BATCH`] at a time ([`MonteCarlo::accumulate_batched`])
//! and their true trajectories ([`LinearTruthBatch`] for linear models, [`TruthBatch`] for any).

use kalibra_linalg::simd::{BATCH, Isa, Lanes};
use kalibra_linalg::{Const, SMatrix, SVector};
use kalibra_metrics::Merge;
use kalibra_models::{
    Dynamics, LinearGaussian, LinearObservation, Measurement, ModelError, Simulator,
};
use pulp::{Simd, WithSimd};

use crate::{ChaCha8Lanes, ChaCha8Rng, MonteCarlo, Partial, Shard, SimError, StudyId};

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
        let blocks = self.blocks();
        let parts = self.block_accumulators(0..blocks, |b| {
            self.run_block_batched(b, blocks, &make, &group)
        })?;
        Ok(crate::fold_blocks(parts).unwrap_or_else(make))
    }

    /// Shard `shard` of [`MonteCarlo::accumulate_batched`]: its blocks, each into its own
    /// accumulator, as [`MonteCarlo::accumulate_shard`] does for the one-run path; [`merge`] of
    /// every shard's partial gives what [`MonteCarlo::accumulate_batched`] gives, to the bit.
    ///
    /// [`merge`]: crate::merge
    ///
    /// # Errors
    /// As [`MonteCarlo::accumulate_batched`]: the lowest failing run of the shard.
    pub fn accumulate_batched_shard<A, E, Make, Group>(
        &self,
        shard: Shard,
        study: &StudyId,
        make: Make,
        group: Group,
    ) -> Result<Partial<A>, SimError<E>>
    where
        A: Merge + Send,
        E: std::error::Error + Send + 'static,
        Make: Fn() -> A + Sync + Send,
        Group: Fn(std::ops::Range<usize>, &mut [ChaCha8Rng], &mut A) -> Result<(), RunFailure<E>>
            + Sync
            + Send,
    {
        let blocks = self.blocks();
        let accs = self.block_accumulators(shard.blocks(blocks), |b| {
            self.run_block_batched(b, blocks, &make, &group)
        })?;
        Ok(Partial::new(study.clone(), shard, accs))
    }

    /// Runs the study in groups of [`BATCH`] consecutive runs and returns each run's output,
    /// in run order: `group(runs, rngs)` simulates the runs `runs` (`rngs[i]` is the generator
    /// of run `runs.start + i`, [`MonteCarlo::rng`]) and returns one value per run, in order.
    /// The batched counterpart of [`MonteCarlo::map`]: a run's draws, and so its output, are
    /// the same whatever the thread count.
    ///
    /// ```
    /// use kalibra_sim::{MonteCarlo, RunFailure};
    /// use rand::RngExt;
    ///
    /// let mc = MonteCarlo::new(20, 3);
    /// let one = mc.map(|_, rng| Ok::<f64, std::fmt::Error>(rng.random::<f64>()))?;
    /// let batched = mc.map_batched(|_, rngs| {
    ///     Ok::<_, RunFailure<std::fmt::Error>>(rngs.iter_mut().map(|r| r.random::<f64>()).collect())
    /// })?;
    /// assert_eq!(one, batched);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::Run`] with the failing run a group reports (the lowest failing group's),
    /// [`SimError::ThreadPool`] if an explicit pool cannot be built.
    pub fn map_batched<T, E, Group>(&self, group: Group) -> Result<Vec<T>, SimError<E>>
    where
        T: Send,
        E: std::error::Error + Send + 'static,
        Group: Fn(std::ops::Range<usize>, &mut [ChaCha8Rng]) -> Result<Vec<T>, RunFailure<E>>
            + Sync
            + Send,
    {
        use rayon::prelude::*;
        let groups = self.runs().div_ceil(BATCH);
        self.in_pool(|| {
            let parts = (0..groups)
                .into_par_iter()
                .map(|g| {
                    let runs = g * BATCH..((g + 1) * BATCH).min(self.runs());
                    let mut rngs: Vec<ChaCha8Rng> = runs.clone().map(|r| self.rng(r)).collect();
                    group(runs, &mut rngs).map_err(|f| SimError::Run {
                        run: f.run,
                        source: f.source,
                    })
                })
                .collect::<Vec<_>>();
            // The lowest failing group, whatever thread finished first.
            let mut out = Vec::with_capacity(self.runs());
            for part in parts {
                out.extend(part?);
            }
            Ok(out)
        })
    }

    /// Block `b` of `blocks` into a fresh accumulator, in groups of [`BATCH`] runs from its
    /// start: the piece of work [`MonteCarlo::accumulate_batched`] and
    /// [`MonteCarlo::accumulate_batched_shard`] share.
    fn run_block_batched<A, E, Make, Group>(
        &self,
        b: usize,
        blocks: usize,
        make: &Make,
        group: &Group,
    ) -> Result<A, SimError<E>>
    where
        E: std::error::Error + Send + 'static,
        Make: Fn() -> A,
        Group: Fn(std::ops::Range<usize>, &mut [ChaCha8Rng], &mut A) -> Result<(), RunFailure<E>>,
    {
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
    }
}

/// The true trajectories of up to [`BATCH`] runs, in the lane layout of
/// `kalibra_filters::batch::KfBatch`: lane `i` is a [`Simulator`] of its own, drawing
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

/// The true trajectories of up to [`BATCH`] runs of a time-invariant linear model
/// ([`LinearGaussian`] dynamics, [`LinearObservation`] sensor), in the lane layout of
/// `kalibra_filters::batch::KfBatch`.
///
/// Lane `i` draws from run `i`'s stream exactly the normals its scalar [`Simulator`] draws,
/// in the same order (per step: the measurement noise, then the process noise), and applies
/// them as the models do (`z = H x + L_R n_v`, `x' = F x + L_Q n_w` with the models' own
/// factors, each product summed in column order as nalgebra's), so a lane's truth is the
/// scalar run's, bit for bit where the compiler keeps the operation order. Unlike
/// [`TruthBatch`], the arithmetic runs across the lanes (the compiler vectorises the loops, for
/// the instruction set of [`LinearTruthBatch::with_isa`]) and skips the per-lane model calls,
/// and the steps draw through [`ChaCha8Lanes`], which computes
/// the lanes' ChaCha8 blocks together and gives each lane its own stream's normals, bit for bit.
///
/// ```
/// use kalibra_linalg::simd::Isa;
/// use kalibra_linalg::{Matrix1, Vector1};
/// use kalibra_models::{LinearGaussian, LinearObservation};
/// use kalibra_sim::{ChaCha8Lanes, LinearTruthBatch, MonteCarlo};
///
/// let f = LinearGaussian::new(Matrix1::new(1.0), Matrix1::new(1.0))?;
/// let h = LinearObservation::new(Matrix1::new(1.0), Matrix1::new(4.0))?;
/// let mc = MonteCarlo::new(3, 1);
/// let mut rngs: Vec<_> = (0..3).map(|run| mc.rng(run)).collect();
/// // The initial states from the scalar generators, then the steps lane-wise.
/// let mut truth = LinearTruthBatch::new(&f, &h, 0, &mut rngs, |_| Vector1::new(0.0))?;
/// let mut draws = ChaCha8Lanes::new(Isa::detect(), &rngs)?;
/// for _ in 0..10 {
///     truth.step(&mut draws)?;
/// }
/// // The scalar generators continue after the steps' draws.
/// draws.write_back(&mut rngs)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct LinearTruthBatch<const N: usize, const M: usize> {
    f: [[f64; N]; N],
    lq: [[f64; N]; N],
    h: [[f64; N]; M],
    lr: [[f64; M]; M],
    // The instruction set the arithmetic runs on (the draws are per lane).
    isa: Isa,
    lanes: usize,
    first_run: usize,
    k: usize,
    x: [Lanes; N],
    current: [Lanes; N],
    z: [Lanes; M],
}

/// `z = H x + L_R n_v` and `x' = F x + L_Q n_w` for every lane, compiled inside the
/// dispatched function for its instruction set. Products and sums are separate operations
/// (Rust never fuses them), so every instruction set gives the same numbers.
struct Affine<'a, const N: usize, const M: usize> {
    truth: &'a mut LinearTruthBatch<N, M>,
    /// `M` rows of measurement noise.
    nv: &'a [Lanes],
    /// `N` rows of process noise.
    nw: &'a [Lanes],
}

/// Rows of normals a step draws in one call when its `M + N` fit (W1: 6): one pass over the
/// lanes' buffers instead of two.
const JOINT_ROWS: usize = 8;

impl<const N: usize, const M: usize> WithSimd for Affine<'_, N, M> {
    /// Whether every lane's measurement and state are finite.
    type Output = bool;

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) -> bool {
        let t = self.truth;
        // Here rather than before the dispatch: compiled for the baseline, the copy of the
        // state is a call to memcpy every step (`cargo xtask bench w1`).
        t.current = t.x;
        affine(simd, &t.h, &t.current, &t.lr, self.nv, &mut t.z);
        affine(simd, &t.f, &t.current, &t.lq, self.nw, &mut t.x);
        // `v * 0` is 0 for a finite `v` and NaN otherwise: one sum per vector of lanes over
        // the rows, then one comparison tells whether any lane needs its own test.
        let zero = simd.splat_f64s(0.0);
        let mut finite = true;
        for c in 0..BATCH / S::F64_LANES {
            let mut sum = zero;
            for row in t.z.iter().chain(t.x.iter()) {
                sum = simd.add_f64s(sum, simd.mul_f64s(S::as_simd_f64s(row).0[c], zero));
            }
            let bad = simd.xor_m64s(simd.equal_f64s(sum, zero), simd.equal_f64s(zero, zero));
            finite &= simd.first_true_m64s(bad) == S::F64_LANES;
        }
        finite
    }
}

fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> [[f64; C]; R] {
    let mut out = [[0.0; C]; R];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = m[(i, j)];
        }
    }
    out
}

/// `out = a v + l n`, lane by lane, each product summed over columns in order, one vector of
/// lanes at a time with the matrices' entries broadcast. Written with pulp's vectors rather
/// than as loops over `[f64; 8]`, which the compiler vectorised with transposes that made
/// these two products a large part of the scheduled study (`cargo xtask bench w1`).
#[inline(always)]
fn affine<S: Simd, const R: usize, const C: usize, const D: usize>(
    simd: S,
    a: &[[f64; C]; R],
    v: &[Lanes; C],
    l: &[[f64; D]; R],
    n: &[Lanes],
    out: &mut [Lanes; R],
) {
    for c in 0..BATCH / S::F64_LANES {
        // (Index expressions, not closures: a closure not inlined would be compiled for the
        // baseline instruction set.)
        for i in 0..R {
            let mut av = simd.mul_f64s(simd.splat_f64s(a[i][0]), S::as_simd_f64s(&v[0]).0[c]);
            for j in 1..C {
                let term = simd.mul_f64s(simd.splat_f64s(a[i][j]), S::as_simd_f64s(&v[j]).0[c]);
                av = simd.add_f64s(av, term);
            }
            let mut ln = simd.mul_f64s(simd.splat_f64s(l[i][0]), S::as_simd_f64s(&n[0]).0[c]);
            for j in 1..D {
                let term = simd.mul_f64s(simd.splat_f64s(l[i][j]), S::as_simd_f64s(&n[j]).0[c]);
                ln = simd.add_f64s(ln, term);
            }
            S::as_mut_simd_f64s(&mut out[i]).0[c] = simd.add_f64s(av, ln);
        }
    }
}

/// Whether every entry of lane `lane` is finite.
fn lane_finite<const D: usize>(v: &[Lanes; D], lane: usize) -> bool {
    v.iter().all(|row| row[lane].is_finite())
}

impl<const N: usize, const M: usize> LinearTruthBatch<N, M> {
    /// One lane per generator (at most [`BATCH`]), lane `i` (run `first_run + i`) starting at
    /// step 0 from the state `x0(rng_i)` it draws (`m0 + L0 n` for a Gaussian prior, as the
    /// scalar study draws it). Lanes past `rngs.len()` hold zeros and draw nothing.
    ///
    /// # Errors
    /// [`ModelError::NonFinite`] for the lowest lane whose initial state is not finite, as
    /// that lane's run's failure.
    ///
    /// # Panics
    /// If more than [`BATCH`] generators are given.
    pub fn new(
        dynamics: &LinearGaussian<Const<N>>,
        measurement: &LinearObservation<Const<N>, Const<M>>,
        first_run: usize,
        rngs: &mut [ChaCha8Rng],
        mut x0: impl FnMut(&mut ChaCha8Rng) -> SVector<f64, N>,
    ) -> Result<Self, RunFailure<ModelError>> {
        assert!(rngs.len() <= BATCH, "at most {BATCH} lanes");
        let mut x = [[0.0; BATCH]; N];
        for (lane, rng) in rngs.iter_mut().enumerate() {
            let x0 = x0(rng);
            if !x0.iter().all(|v| v.is_finite()) {
                return Err(RunFailure {
                    run: first_run + lane,
                    source: ModelError::NonFinite {
                        what: "initial state",
                        step: 0,
                    },
                });
            }
            for i in 0..N {
                x[i][lane] = x0[i];
            }
        }
        Ok(Self {
            f: rows(dynamics.f()),
            lq: rows(dynamics.q().factor()),
            h: rows(measurement.h()),
            lr: rows(measurement.r().factor()),
            isa: Isa::detect(),
            lanes: rngs.len(),
            first_run,
            k: 0,
            x,
            current: [[0.0; BATCH]; N],
            z: [[0.0; BATCH]; M],
        })
    }

    /// Runs the arithmetic on instruction set `isa` (the CPU's widest by default, the
    /// scalar fallback if the CPU does not run `isa`): a study pins its batch's instruction
    /// set with it, so that a forced one runs everywhere. The numbers do not depend on it.
    pub fn with_isa(mut self, isa: Isa) -> Self {
        self.isa = isa;
        self
    }

    /// Number of live lanes.
    pub fn len(&self) -> usize {
        self.lanes
    }

    /// Whether there are no lanes.
    pub fn is_empty(&self) -> bool {
        self.lanes == 0
    }

    /// Steps every lane once, as [`Simulator::step`] does (measures `x_k`, then advances):
    /// afterwards [`LinearTruthBatch::state`] holds the `x_k` and
    /// [`LinearTruthBatch::measurement`] the `z_k` of every lane.
    ///
    /// Lane `i` draws from lane `i` of `draws` (run `first_run + i`'s stream, taken from its
    /// generator after the initial state's draws: [`ChaCha8Lanes::new`]): per lane, first the
    /// `M` measurement-noise normals, then the `N` process-noise normals, as the scalar
    /// simulator draws them.
    ///
    /// # Errors
    /// [`ModelError::NonFinite`] for the lowest lane whose measurement or next state is not
    /// finite (a diverging truth), as [`Simulator::step`] reports it, as its run's failure;
    /// the other lanes have stepped.
    ///
    /// # Panics
    /// If `draws` does not have one lane per truth lane.
    pub fn step(&mut self, draws: &mut ChaCha8Lanes) -> Result<(), RunFailure<ModelError>> {
        assert_eq!(draws.len(), self.lanes, "one generator lane per truth lane");
        // Per lane the same order as the scalar simulator: measurement noise, process noise
        // (row `r` of a call is each lane's `r`-th draw, so one call of `M + N` rows draws
        // what two calls of `M` and `N` do).
        let mut joint = [[0.0; BATCH]; JOINT_ROWS];
        let mut nv = [[0.0; BATCH]; M];
        let mut nw = [[0.0; BATCH]; N];
        let (nv, nw): (&[Lanes], &[Lanes]) = if M + N <= JOINT_ROWS {
            draws.standard_normals(&mut joint[..M + N]);
            let (v, w) = joint.split_at(M);
            (v, w)
        } else {
            draws.standard_normals(&mut nv);
            draws.standard_normals(&mut nw);
            (&nv, &nw)
        };
        let isa = self.isa;
        let finite = isa.dispatch(Affine {
            truth: self,
            nv,
            nw,
        });
        let k = self.k;
        self.k += 1;
        if finite {
            return Ok(());
        }
        for lane in 0..self.lanes {
            let what = if !lane_finite(&self.z, lane) {
                ("simulated measurement", k)
            } else if !lane_finite(&self.x, lane) {
                ("simulated state", k + 1)
            } else {
                continue;
            };
            return Err(RunFailure {
                run: self.first_run + lane,
                source: ModelError::NonFinite {
                    what: what.0,
                    step: what.1,
                },
            });
        }
        Ok(())
    }

    /// The true states `x_k` of the last [`LinearTruthBatch::step`], lane by lane.
    pub fn state(&self) -> &[Lanes; N] {
        &self.current
    }

    /// The measurements `z_k` of the last [`LinearTruthBatch::step`], lane by lane.
    pub fn measurement(&self) -> &[Lanes; M] {
        &self.z
    }
}
