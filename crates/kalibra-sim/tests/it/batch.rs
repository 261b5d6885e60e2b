//! The batched Monte Carlo path against the scalar one, run by run: the truth of
//! [`LinearTruthBatch`] against [`Simulator`], and [`KfBatch`] on it against [`Kf`], for every
//! instruction set this CPU has, forced in turn; and [`MonteCarlo::accumulate_batched`]'s
//! determinism and error reporting.

use kalibra_filters::batch::{BATCH, BatchModel, Isa, KfBatch};
use kalibra_filters::{Filter, Kf};
use kalibra_linalg::{Matrix2, Matrix4, PsdMatrix, U2, U4, Vector4};
use kalibra_metrics::{MetricsError, StepMean};
use kalibra_models::{
    Dynamics, Kinematic, LinearDynamics, LinearGaussian, LinearMeasurement, LinearObservation,
    Measurement, ModelError, ProcessNoise, Simulator, sample_with_factor,
};
use kalibra_sim::{ChaCha8Lanes, LinearTruthBatch, MonteCarlo, RunFailure, SimError};

/// W1's model (2-D constant velocity, position measured) with a larger process noise, so that
/// runs wander apart.
fn models() -> (LinearGaussian<U4>, LinearObservation<U4, U2>) {
    let cv = Kinematic::constant_velocity(2, 1.0)
        .unwrap()
        .noise(ProcessNoise::Discrete { q: 4.0 });
    (
        cv.dynamics(U4).unwrap(),
        cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)
            .unwrap(),
    )
}

fn prior() -> (Vector4<f64>, Matrix4<f64>) {
    (
        Vector4::new(0.0, 0.0, 10.0, -5.0),
        Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0)),
    )
}

/// Per-step NEES and NIS of one run, the scalar way (W1's `run_scalar` loop).
fn scalar_run(mc: &MonteCarlo, run: usize, steps: usize) -> Vec<(f64, f64, Vector4<f64>)> {
    let (f, h) = models();
    let (m0, p0) = prior();
    let l0 = *PsdMatrix::new(p0).unwrap().factor();
    let mut rng = mc.rng(run);
    let x0 = m0 + sample_with_factor(&l0, &mut rng);
    let mut truth = Simulator::new(&f, &h, x0, 0).unwrap();
    let mut kf = Kf::new(&f, &h, m0, p0).unwrap();
    (0..steps)
        .map(|k| {
            let (x, z) = truth.step(&mut rng).unwrap();
            if k > 0 {
                kf.predict().unwrap();
            }
            let rec = kf.update(&z).unwrap();
            let e = x - rec.posterior().mean;
            (rec.nees(&e).unwrap(), rec.nis(), x)
        })
        .collect()
}

fn batch_model() -> BatchModel<4, 2> {
    let (f, h) = models();
    let m0 = prior().0;
    BatchModel::new(
        f.matrix(0),
        f.noise_cov(0),
        h.matrix(0),
        h.noise_cov(0, &m0),
    )
    .unwrap()
}

/// Per-step NEES, NIS and truth of runs `runs`, batched on `isa`.
fn batched_runs(
    mc: &MonteCarlo,
    runs: std::ops::Range<usize>,
    steps: usize,
    isa: Isa,
) -> Vec<Vec<(f64, f64, Vector4<f64>)>> {
    let (f, h) = models();
    let (m0, p0) = prior();
    let l0 = *PsdMatrix::new(p0).unwrap().factor();
    let mut rngs: Vec<_> = runs.clone().map(|r| mc.rng(r)).collect();
    // The truth's arithmetic on `isa` too: every instruction set's is the scalar simulator's.
    let mut truth = LinearTruthBatch::new(&f, &h, runs.start, &mut rngs, |rng| {
        m0 + sample_with_factor(&l0, rng)
    })
    .unwrap()
    .with_isa(isa);
    let mut draws = ChaCha8Lanes::new(isa, &rngs).unwrap();
    let mut kf = KfBatch::new(isa, batch_model(), m0, p0).unwrap();
    let mut out = vec![Vec::new(); runs.len()];
    for k in 0..steps {
        truth.step(&mut draws).unwrap();
        let step = if k == 0 {
            kf.update(truth.measurement(), truth.state())
        } else {
            kf.predict_update(truth.measurement(), truth.state())
        };
        for (lane, run) in out.iter_mut().enumerate() {
            let x = Vector4::from_fn(|i, _| truth.state()[i][lane]);
            run.push((step.nees(lane).unwrap(), step.nis(lane).unwrap(), x));
        }
    }
    out
}

fn rel(a: f64, b: f64) -> f64 {
    if a == b {
        0.0
    } else {
        (a - b).abs() / a.abs().max(b.abs())
    }
}

#[test]
fn every_run_agrees_with_the_scalar_path_on_every_instruction_set() {
    let mc = MonteCarlo::new(11, 2012);
    let steps = 300;
    let scalar: Vec<_> = (0..11).map(|run| scalar_run(&mc, run, steps)).collect();
    let isas = Isa::available();
    assert!(isas.contains(&Isa::Scalar));
    for isa in isas {
        // A full group and a partial one (lanes past the runs hold nothing).
        let mut batched = batched_runs(&mc, 0..BATCH, steps, isa);
        batched.extend(batched_runs(&mc, BATCH..11, steps, isa));
        let mut worst = 0.0f64;
        for (run, (b, s)) in batched.iter().zip(&scalar).enumerate() {
            for (k, ((nees_b, nis_b, x_b), (nees_s, nis_s, x_s))) in b.iter().zip(s).enumerate() {
                // The truth is the scalar simulator's, bit for bit.
                assert_eq!(x_b, x_s, "{isa}: truth of run {run} at step {k}");
                worst = worst.max(rel(*nees_b, *nees_s)).max(rel(*nis_b, *nis_s));
            }
        }
        assert!(
            worst <= 1e-12,
            "{isa}: largest relative difference in NEES or NIS {worst:e}"
        );
    }
}

/// W1-like accumulation of per-step NEES and NIS means through `accumulate_batched`.
fn batched_means(mc: MonteCarlo, steps: usize, isa: Isa) -> (StepMean, StepMean) {
    let (f, h) = models();
    let (m0, p0) = prior();
    let l0 = *PsdMatrix::new(p0).unwrap().factor();
    let model = batch_model();
    mc.accumulate_batched(
        || (StepMean::new(steps), StepMean::new(steps)),
        |runs, rngs, (nees, nis)| {
            let first = runs.start;
            let mut truth =
                LinearTruthBatch::new(&f, &h, first, rngs, |rng| m0 + sample_with_factor(&l0, rng))
                    .unwrap();
            let mut draws = ChaCha8Lanes::new(isa, rngs).unwrap();
            let mut kf = KfBatch::new(isa, model.clone(), m0, p0).unwrap();
            for k in 0..steps {
                truth.step(&mut draws).unwrap();
                let step = if k == 0 {
                    kf.update(truth.measurement(), truth.state())
                } else {
                    kf.predict_update(truth.measurement(), truth.state())
                };
                for lane in 0..runs.len() {
                    let fail = |source| RunFailure {
                        run: first + lane,
                        source,
                    };
                    nees.push(k, step.nees(lane).unwrap()).map_err(fail)?;
                    nis.push(k, step.nis(lane).unwrap()).map_err(fail)?;
                }
            }
            Ok::<(), RunFailure<MetricsError>>(())
        },
    )
    .unwrap()
}

#[test]
fn batched_results_are_bit_identical_for_any_thread_count() {
    // 150 runs: blocks of two or three runs (64 blocks), so groups are short and many.
    for isa in Isa::available() {
        let base = batched_means(MonteCarlo::new(150, 9).threads(1), 40, isa);
        for threads in [2, 3, 8] {
            let other = batched_means(MonteCarlo::new(150, 9).threads(threads), 40, isa);
            assert_eq!(base, other, "{isa}: {threads} threads");
        }
    }
}

#[test]
fn batched_sums_add_the_runs_in_the_scalar_order() {
    // The same values pushed one run at a time and a group at a time give the same bits.
    let mc = MonteCarlo::new(37, 4).threads(2);
    let one = mc
        .accumulate(
            || StepMean::new(3),
            |run, _, acc| (0..3).try_for_each(|k| acc.push(k, 1.0 / (1.0 + run as f64 + k as f64))),
        )
        .unwrap();
    let batched = mc
        .accumulate_batched(
            || StepMean::new(3),
            |runs, rngs, acc| {
                assert_eq!(rngs.len(), runs.len());
                assert!(runs.len() <= BATCH);
                for k in 0..3 {
                    for run in runs.clone() {
                        acc.push(k, 1.0 / (1.0 + run as f64 + k as f64))
                            .map_err(|source| RunFailure { run, source })?;
                    }
                }
                Ok(())
            },
        )
        .unwrap();
    assert_eq!(one, batched);
}

#[test]
fn the_lowest_failing_run_is_reported_for_any_thread_count() {
    for threads in [1, 2, 5] {
        let err = MonteCarlo::new(200, 1)
            .threads(threads)
            .accumulate_batched(
                || StepMean::new(1),
                |runs, _, acc| {
                    // Runs 37, 38 and 137 fail; a group names its lowest.
                    for run in runs.clone() {
                        if [37, 38, 137].contains(&run) {
                            return Err(RunFailure {
                                run,
                                source: MetricsError::Empty { what: "test" },
                            });
                        }
                        acc.push(0, 1.0)
                            .map_err(|source| RunFailure { run, source })?;
                    }
                    Ok(())
                },
            )
            .unwrap_err();
        assert!(matches!(err, SimError::Run { run: 37, .. }), "{err}");
    }
}

#[test]
fn a_diverging_truth_lane_is_its_runs_failure() {
    let (f, h) = models();
    let mc = MonteCarlo::new(8, 3);
    let mut rngs: Vec<_> = (0..8).map(|r| mc.rng(r)).collect();
    // A lane starting beyond f64's range: its first measurement is not finite.
    let mut truth = LinearTruthBatch::new(&f, &h, 16, &mut rngs, {
        let mut lane = 0;
        move |_| {
            lane += 1;
            if lane == 6 {
                Vector4::new(f64::MAX, 0.0, f64::MAX, 0.0)
            } else {
                Vector4::zeros()
            }
        }
    })
    .unwrap();
    let mut draws = ChaCha8Lanes::new(Isa::detect(), &rngs).unwrap();
    let failure = truth.step(&mut draws).unwrap_err();
    assert_eq!(failure.run, 16 + 5);
    assert!(
        matches!(failure.source, ModelError::NonFinite { step: 1, .. }),
        "{:?}",
        failure.source
    );
}

#[test]
fn map_batched_gives_map_s_outputs_in_run_order_for_any_thread_count() {
    use rand::RngExt;
    // 29 runs: three full groups and a short one.
    let mc = MonteCarlo::new(29, 4);
    let one = mc
        .map(|run, rng| Ok::<_, MetricsError>((run, rng.random::<u64>())))
        .unwrap();
    for threads in [1, 2, 3] {
        let batched = mc
            .threads(threads)
            .map_batched(|runs, rngs| {
                assert!(runs.len() <= BATCH && runs.start % BATCH == 0);
                Ok::<_, RunFailure<MetricsError>>(
                    runs.zip(rngs.iter_mut())
                        .map(|(run, rng)| (run, rng.random::<u64>()))
                        .collect(),
                )
            })
            .unwrap();
        assert_eq!(batched, one, "{threads} threads");
    }
}

#[test]
fn map_batched_reports_the_lowest_failing_group_for_any_thread_count() {
    for threads in [1, 2, 5] {
        let err = MonteCarlo::new(100, 1)
            .threads(threads)
            .map_batched(|runs, _| {
                // Runs 21 and 90 fail; each group names its lowest failing run.
                match runs.clone().find(|r| [21, 90].contains(r)) {
                    Some(run) => Err(RunFailure {
                        run,
                        source: MetricsError::Empty { what: "test" },
                    }),
                    None => Ok(runs.collect::<Vec<_>>()),
                }
            })
            .unwrap_err();
        assert!(matches!(err, SimError::Run { run: 21, .. }), "{err}");
    }
}
