//! The evaluation fed cell by cell (`Evaluator`): the same report as `Evaluation::evaluate`
//! whatever the batching and the thread count, any order of the cells to rounding, and the
//! rectangle of runs and steps enforced (repeats, gaps, failed cells that leave no trace).

use kalibra_eval::{
    Cell, Contents, EvalError, Evaluation, FilterLog, Matrices, MatrixCell, ModelCell, Report,
    Vectors,
};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{Rng, SeedableRng};

const N: usize = 2;
const M: usize = 1;

/// A log of `runs x steps` cells with random errors, SPD covariances, and a few gaps.
struct Arrays {
    runs: usize,
    steps: usize,
    truth: Vec<f64>,
    estimate: Vec<f64>,
    cov: Vec<f64>,
    innovation: Vec<f64>,
    s: Vec<f64>,
    /// Cells whose innovation was not logged.
    gap: Vec<bool>,
}

/// A uniform draw in [0, 1) from the top 53 bits.
fn uniform(rng: &mut ChaCha8Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    // Box-Muller: enough for test data, and needs no distribution crate.
    let (u, v) = (uniform(rng).max(1e-300), uniform(rng));
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

fn arrays(seed: u64, runs: usize, steps: usize) -> Arrays {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cells = runs * steps;
    let mut a = Arrays {
        runs,
        steps,
        truth: Vec::new(),
        estimate: Vec::new(),
        cov: Vec::new(),
        innovation: Vec::new(),
        s: Vec::new(),
        gap: Vec::new(),
    };
    for _ in 0..cells {
        let (x0, x1) = (10.0 * normal(&mut rng), 10.0 * normal(&mut rng));
        let (v0, v1, c) = (1.0 + uniform(&mut rng), 1.0 + uniform(&mut rng), 0.3);
        a.truth.extend([x0, x1]);
        a.estimate.extend([
            x0 + v0.sqrt() * normal(&mut rng),
            x1 + v1.sqrt() * normal(&mut rng),
        ]);
        a.cov.extend([v0, c, c, v1]);
        a.innovation.push(2.0 * normal(&mut rng));
        a.s.push(4.0);
        a.gap.push(uniform(&mut rng) < 0.1);
    }
    a
}

impl Arrays {
    fn log(&self) -> FilterLog<'static> {
        let innovation = (0..self.runs * self.steps)
            .map(|i| (!self.gap[i]).then(|| vec![self.innovation[i]]))
            .collect();
        FilterLog::new(self.runs, self.steps)
            .unwrap()
            .with_truth(Vectors::dense(N, self.truth.clone()))
            .unwrap()
            .with_estimate(Vectors::dense(N, self.estimate.clone()))
            .unwrap()
            .with_covariance(Matrices::dense(N, N, self.cov.clone()))
            .unwrap()
            .with_innovation(Vectors::cells(M, innovation))
            .unwrap()
            .with_innovation_cov(Matrices::dense(M, M, self.s.clone()))
            .unwrap()
    }

    fn cell(&self, run: usize, step: usize) -> Cell<'_> {
        let i = run * self.steps + step;
        Cell {
            truth: Some(&self.truth[i * N..(i + 1) * N]),
            estimate: Some(&self.estimate[i * N..(i + 1) * N]),
            covariance: Some(MatrixCell::Full(&self.cov[i * N * N..(i + 1) * N * N])),
            innovation: (!self.gap[i]).then(|| &self.innovation[i..i + 1]),
            innovation_cov: Some(MatrixCell::Full(&self.s[i..i + 1])),
            model: None,
        }
    }
}

/// A constant model, for `J1`/`J2`.
const MODEL: ModelCell<'static> = ModelCell {
    f: &[1.0, 1.0, 0.0, 1.0],
    h: &[1.0, 0.0],
    q: &[0.25, 0.5, 0.5, 1.0],
    r: &[4.0],
};

impl Arrays {
    /// An evaluator of `evaluation` fed the whole runs `runs`, each cell with [`MODEL`].
    fn feed_with_model(
        &self,
        evaluation: &Evaluation,
        runs: std::ops::Range<usize>,
    ) -> kalibra_eval::Evaluator {
        let mut e = evaluation.evaluator(model_contents()).unwrap();
        for run in runs {
            for step in 0..self.steps {
                let cell = Cell {
                    model: Some(MODEL),
                    ..self.cell(run, step)
                };
                e.push(run, step, &cell).unwrap();
            }
        }
        e
    }
}

/// `a` with every `every`-th cell's covariance made asymmetric (a finding, left out).
fn with_asymmetric_covariances(mut a: Arrays, every: usize) -> Arrays {
    for i in (0..a.runs * a.steps).step_by(every) {
        a.cov[i * N * N + 1] = 5.0;
        a.cov[i * N * N + 2] = 5.0;
    }
    a
}

/// [`contents`] with the model.
fn model_contents() -> Contents {
    Contents {
        model: Some((N, M)),
        ..contents()
    }
}

fn contents() -> Contents {
    Contents {
        truth: Some(N),
        estimate: Some(N),
        covariance: Some(N),
        innovation: Some(M),
        innovation_cov: Some(M),
        model: None,
    }
}

/// Every number of two reports, paired (serialised, so every field takes part).
fn assert_close(a: &Report, b: &Report, rel: f64) {
    fn walk(a: &serde_json::Value, b: &serde_json::Value, path: &str, rel: f64) {
        use serde_json::Value::*;
        match (a, b) {
            (Number(x), Number(y)) => {
                let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                assert!(
                    (x - y).abs() <= rel * x.abs().max(y.abs()).max(1.0),
                    "{path}: {x} vs {y}"
                );
            }
            (Array(x), Array(y)) => {
                assert_eq!(x.len(), y.len(), "{path}");
                for (i, (u, v)) in x.iter().zip(y).enumerate() {
                    walk(u, v, &format!("{path}[{i}]"), rel);
                }
            }
            (Object(x), Object(y)) => {
                for (k, u) in x {
                    walk(u, &y[k], &format!("{path}.{k}"), rel);
                }
            }
            // The verdict's evidence prints numbers; compare its kind, not its digits.
            (String(_), String(_)) if path.ends_with("evidence") => {}
            _ => assert_eq!(a, b, "{path}"),
        }
    }
    walk(
        &serde_json::to_value(a).unwrap(),
        &serde_json::to_value(b).unwrap(),
        "report",
        rel,
    );
}

#[test]
fn cell_by_cell_batched_and_whole_give_the_same_report_to_the_bit() {
    let a = arrays(1, 40, 30);
    let evaluation = Evaluation::new().window(5).unwrap();
    let whole = evaluation.evaluate(&a.log()).unwrap();

    let mut one_by_one = evaluation.evaluator(contents()).unwrap();
    for run in 0..a.runs {
        for step in 0..a.steps {
            one_by_one.push(run, step, &a.cell(run, step)).unwrap();
        }
    }
    assert_eq!(one_by_one.finish(None).unwrap(), whole);

    // One batch large enough to be factorised on several threads, on pools of 1 and 3.
    let cells: Vec<_> = (0..a.runs)
        .flat_map(|run| (0..a.steps).map(move |step| (run, step)))
        .map(|(run, step)| (run, step, a.cell(run, step)))
        .collect();
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let report = pool.install(|| {
            let mut batched = evaluation.evaluator(contents()).unwrap();
            batched.push_batch(&cells).unwrap();
            batched.finish(None).unwrap()
        });
        assert_eq!(report, whole, "{threads} threads");
    }
}

/// `Evaluation::evaluate` cuts a long log into blocks of steps evaluated in parallel: the
/// report of a log of several blocks (300 steps, gaps and all) is the same to the bit on
/// pools of 1, 2 and 3 threads, and equal to one evaluator fed run after run, cell by cell,
/// which is how `kalibra eval` streams an NPZ or CSV log.
#[test]
fn blocks_of_steps_give_one_pass_to_the_bit_for_any_thread_count() {
    let mut a = arrays(3, 12, 300);
    // Findings in several strips and blocks: covariances not positive definite (and the first
    // of them, run after run, in a later strip than another's), a non-finite estimate.
    for i in [5 * 300 + 40, 2 * 300 + 250, 11 * 300 + 3, 7 * 300 + 129] {
        a.cov[i * N * N + 1] = 5.0;
        a.cov[i * N * N + 2] = 5.0;
    }
    a.estimate[(4 * 300 + 77) * N] = f64::NAN;
    let evaluation = Evaluation::new();
    let mut one_pass = evaluation.evaluator(contents()).unwrap();
    for run in 0..a.runs {
        for step in 0..a.steps {
            one_pass.push(run, step, &a.cell(run, step)).unwrap();
        }
    }
    let one_pass = one_pass.finish(None).unwrap();
    let bits = |r: &Report| serde_json::to_string(r).unwrap();
    assert!(one_pass.summary.anees.is_some() && one_pass.summary.anis.is_some());
    let first = one_pass.findings.state.first.as_ref().unwrap();
    assert_eq!(
        (one_pass.findings.state.cells, first.run, first.step),
        (5, 2, 250)
    );
    assert!(one_pass.nci_per_step.iter().all(Option::is_some));
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let report = pool.install(|| evaluation.evaluate(&a.log()).unwrap());
        assert_eq!(bits(&report), bits(&one_pass), "{threads} threads");
    }
}

/// A block of steps is fed in strips of steps, each strip run after run, which meets the
/// cells in another order than one pass: an error is still that of the first failing cell
/// run after run. Here run 1 fails at step 10 (in the first strip) and run 0 at step 100 (a
/// later strip of the same block): the error names step 100, as one pass meets it first.
#[test]
fn a_failing_cell_is_the_first_run_after_run_whatever_the_feeding_order() {
    let mut a = arrays(5, 2, 300);
    // An error whose square is beyond f64's range: the squared errors cannot sum it.
    let huge = |a: &mut Arrays, run: usize, step: usize| {
        a.estimate[(run * a.steps + step) * N] = 1e200;
    };
    huge(&mut a, 1, 10);
    huge(&mut a, 0, 100);
    let failing_step = |e: EvalError| match e {
        EvalError::Metrics(kalibra_metrics::MetricsError::NonFiniteSample { index, .. }) => index,
        other => panic!("unexpected error {other:?}"),
    };
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let e = pool.install(|| Evaluation::new().evaluate(&a.log()).unwrap_err());
        assert_eq!(failing_step(e), 100, "{threads} threads");
    }
    // One pass run after run meets the same cell first.
    let mut one_pass = Evaluation::new().evaluator(contents()).unwrap();
    let first = (0..a.runs)
        .flat_map(|run| (0..a.steps).map(move |step| (run, step)))
        .find(|&(run, step)| one_pass.push(run, step, &a.cell(run, step)).is_err());
    assert_eq!(first, Some((0, 100)));
}

/// With model matrices, `J1`/`J2` come from consecutive steps of a run: a large batch
/// computes most of them on several threads, a run's first cell in a batch and single cells
/// on the calling thread. Batches cut mid-run, a model that changes every few steps, and
/// covariances that are not positive definite (no `J` across them) give the one-by-one
/// report to the bit, for 1 and 3 threads.
#[test]
fn j_from_batches_and_threads_equals_j_cell_by_cell_to_the_bit() {
    let mut a = arrays(7, 30, 40);
    // One covariance in 13 indefinite: NEES refuses it, and `J` skips the steps around it.
    for i in (0..a.runs * a.steps).step_by(13) {
        a.cov[i * N * N + 1] = 5.0;
        a.cov[i * N * N + 2] = 5.0;
    }
    let h = [1.0, 0.0];
    let r = [4.0];
    // F per step: the same for three steps, then another (the model's cache misses).
    let fs: Vec<[f64; 4]> = (0..a.steps)
        .map(|k| [1.0, 1.0 + (k / 3) as f64 * 0.01, 0.0, 1.0])
        .collect();
    let q = [0.25, 0.5, 0.5, 1.0];
    let cell = |run: usize, step: usize| Cell {
        model: Some(ModelCell {
            f: &fs[step],
            h: &h,
            q: &q,
            r: &r,
        }),
        ..a.cell(run, step)
    };
    let contents = Contents {
        model: Some((N, M)),
        ..contents()
    };
    let evaluation = Evaluation::new();
    let mut one_by_one = evaluation.evaluator(contents).unwrap();
    for run in 0..a.runs {
        for step in 0..a.steps {
            one_by_one.push(run, step, &cell(run, step)).unwrap();
        }
    }
    let want = one_by_one.finish(None).unwrap();
    let j = want.j.as_ref().expect("J1/J2 reported");
    assert!(j.updates > 0 && j.updates < a.runs * (a.steps - 1), "{j:?}");

    let cells: Vec<_> = (0..a.runs)
        .flat_map(|run| (0..a.steps).map(move |step| (run, step)))
        .map(|(run, step)| (run, step, cell(run, step)))
        .collect();
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for batch in [cells.len(), 700, 513] {
            let report = pool.install(|| {
                let mut e = evaluation.evaluator(contents).unwrap();
                for chunk in cells.chunks(batch) {
                    e.push_batch(chunk).unwrap();
                }
                e.finish(None).unwrap()
            });
            assert_eq!(report, want, "{threads} threads, batches of {batch}");
        }
    }
}

#[test]
fn any_order_of_the_cells_gives_the_report_to_rounding() {
    let a = arrays(2, 25, 20);
    let evaluation = Evaluation::new();
    let whole = evaluation.evaluate(&a.log()).unwrap();
    // Step after step, and runs backwards within a step.
    let mut e = evaluation.evaluator(contents()).unwrap();
    for step in 0..a.steps {
        for run in (0..a.runs).rev() {
            e.push(run, step, &a.cell(run, step)).unwrap();
        }
    }
    assert_eq!((e.runs(), e.steps()), (a.runs, a.steps));
    let shuffled = e.finish(None).unwrap();
    assert_close(&shuffled, &whole, 1e-12);
    // The findings' first cell is the lowest (run, step), whatever the order.
    assert_eq!(shuffled.findings, whole.findings);
}

#[test]
fn the_rectangle_is_enforced_and_a_failed_cell_leaves_no_trace() {
    let a = arrays(3, 2, 3);
    let evaluation = Evaluation::new();
    let mut e = evaluation.evaluator(contents()).unwrap();
    e.push(0, 0, &a.cell(0, 0)).unwrap();
    assert_eq!(
        e.push(0, 0, &a.cell(0, 0)),
        Err(EvalError::DuplicateCell { run: 0, step: 0 })
    );
    // A cell of the wrong length fails and is not marked: the right one goes in after it.
    let mut short = a.cell(0, 1);
    short.truth = Some(&a.truth[..1]);
    assert!(matches!(
        e.push(0, 1, &short),
        Err(EvalError::CellLength {
            array: "truth",
            run: 0,
            step: 1,
            ..
        })
    ));
    let mut nan_truth = a.cell(0, 1);
    let bad = [f64::NAN, 0.0];
    nan_truth.truth = Some(&bad);
    assert_eq!(
        e.push(0, 1, &nan_truth),
        Err(EvalError::NonFinite {
            array: "truth",
            run: 0,
            step: 1
        })
    );
    e.push(0, 1, &a.cell(0, 1)).unwrap();
    // Run 1 has only step 2 (and run 0 lacks it): the first gap is named.
    e.push(1, 2, &a.cell(1, 2)).unwrap();
    assert_eq!(
        e.finish(None),
        Err(EvalError::MissingCell {
            run: 0,
            step: 2,
            steps: 3
        })
    );
    // A batch stops at its first failing cell, and says which.
    let mut e = evaluation.evaluator(contents()).unwrap();
    let batch = [
        (0, 0, a.cell(0, 0)),
        (0, 1, a.cell(0, 1)),
        (0, 0, a.cell(0, 0)),
        (0, 2, a.cell(0, 2)),
    ];
    assert_eq!(
        e.push_batch(&batch),
        Err((2, EvalError::DuplicateCell { run: 0, step: 0 }))
    );
    assert_eq!((e.runs(), e.steps()), (1, 2));
    // Nothing fed at all.
    let e = evaluation.evaluator(contents()).unwrap();
    assert_eq!(e.finish(None), Err(EvalError::Empty { what: "runs" }));
    // Contents that disagree, or hold nothing to evaluate.
    let mut wrong = contents();
    wrong.estimate = Some(3);
    assert!(matches!(
        evaluation.evaluator(wrong),
        Err(EvalError::Mismatch {
            array: "estimate",
            ..
        })
    ));
    assert!(matches!(
        evaluation.evaluator(Contents::default()),
        Err(EvalError::NothingToEvaluate)
    ));
}

/// A run or step index at the limit is refused before anything grows, so that an index of
/// usize::MAX cannot size the evaluator's per-run and per-step state. The cell just below
/// the limit is taken.
#[test]
fn indices_beyond_the_limits_are_refused_before_anything_grows() {
    use kalibra_eval::{EvalError, MAX_RUNS, MAX_STEPS};
    let contents = Contents {
        innovation: Some(1),
        innovation_cov: Some(1),
        ..Contents::default()
    };
    let cell = Cell {
        innovation: Some(&[0.5]),
        innovation_cov: Some(MatrixCell::Full(&[1.0])),
        ..Cell::default()
    };
    let mut evaluator = Evaluation::new().evaluator(contents).unwrap();
    for (run, step, what) in [
        (MAX_RUNS, 0, "run"),
        (usize::MAX, 0, "run"),
        (0, MAX_STEPS, "step"),
        (0, usize::MAX, "step"),
    ] {
        match evaluator.push(run, step, &cell) {
            Err(EvalError::IndexLimit { what: w, .. }) => assert_eq!(w, what),
            other => panic!("({run}, {step}): {other:?}"),
        }
        match evaluator.push_batch(&[(run, step, cell)]) {
            Err((0, EvalError::IndexLimit { what: w, .. })) => assert_eq!(w, what),
            other => panic!("batch ({run}, {step}): {other:?}"),
        }
    }
    evaluator.push(0, 0, &cell).unwrap();
    let report = evaluator.finish(None).unwrap();
    assert_eq!(report.anis_per_step.len(), 1);
}

/// Evaluators fed blocks of whole runs, merged in block order, give the one-evaluator report
/// to rounding (the per-step sums are re-associated; NCI, medians, findings and counts, which
/// come from stored values and counts, are the same), with `J1`/`J2` from a model, windows and
/// findings; merging the same blocks in the same order on any threads gives the same bits.
#[test]
fn merged_evaluators_of_run_blocks_give_the_report_to_rounding() {
    let a = with_asymmetric_covariances(arrays(11, 23, 17), 11);
    let contents = model_contents();
    let evaluation = Evaluation::new().window(4).unwrap().diagnostic_run(9);
    let feed = |runs| a.feed_with_model(&evaluation, runs);
    let want = feed(0..a.runs).finish(None).unwrap();
    assert!(want.j.is_some());
    let blocked = |cuts: &[usize]| {
        let mut blocks = cuts.windows(2).map(|w| feed(w[0]..w[1]));
        let mut total = blocks.next().unwrap();
        for b in blocks {
            total.merge(b).unwrap();
        }
        total.finish(None).unwrap()
    };
    let merged = blocked(&[0, 5, 6, 14, 23]);
    assert_close(&merged, &want, 1e-12);
    assert_eq!(merged.findings, want.findings);
    assert_eq!(blocked(&[0, 5, 6, 14, 23]), merged);
    // One block is the one evaluator, to the bit.
    assert_eq!(blocked(&[0, 23]), want);

    // Cells given to both, and evaluators of other options, are refused.
    let mut e = feed(0..3);
    let err = e.merge(feed(2..4)).unwrap_err();
    assert_eq!(
        err,
        kalibra_eval::EvalError::DuplicateCell { run: 2, step: 0 }
    );
    let other = Evaluation::new().evaluator(contents).unwrap();
    assert_eq!(
        e.merge(other).unwrap_err(),
        kalibra_eval::EvalError::MergeMismatch
    );
}

/// The blocks' evaluators shipped as states (CBOR, as a Python shard ships them) and resumed
/// merge into the report of the evaluators themselves, to the bit (with findings, `J1`/`J2`,
/// windows and a diagnostic run in a later block); states that do not fit their contents, or
/// contradict themselves, are refused.
#[test]
fn evaluator_states_resume_to_the_same_bits() {
    // 300 steps: the per-run sums span three blocks of steps.
    let a = with_asymmetric_covariances(arrays(12, 19, 300), 13);
    let contents = model_contents();
    let evaluation = Evaluation::new().window(5).unwrap().diagnostic_run(7);
    let feed = |runs| a.feed_with_model(&evaluation, runs);
    let cbor = |state: &kalibra_eval::EvaluatorState| {
        let mut bytes = Vec::new();
        ciborium::into_writer(state, &mut bytes).unwrap();
        bytes
    };
    let cuts = [0, 4, 5, 12, 19];
    let fold = |blocks: Vec<kalibra_eval::Evaluator>| {
        let mut blocks = blocks.into_iter();
        let mut total = blocks.next().unwrap();
        for b in blocks {
            total.merge(b).unwrap();
        }
        format!("{:?}", total.finish(None).unwrap())
    };
    let want = fold(cuts.windows(2).map(|w| feed(w[0]..w[1])).collect());
    let states: Vec<Vec<u8>> = cuts
        .windows(2)
        .map(|w| cbor(&feed(w[0]..w[1]).into_state()))
        .collect();
    let resumed = states
        .iter()
        .map(|bytes| {
            let state = ciborium::from_reader(bytes.as_slice()).unwrap();
            evaluation.resume(contents, state).unwrap()
        })
        .collect();
    assert_eq!(fold(resumed), want);
    assert!(want.contains("j: Some"), "{want}");

    // A block's state starts at its first run: its size does not grow with the runs before.
    assert!(
        states[3].len() < states[2].len() + 64,
        "{} {}",
        states[3].len(),
        states[2].len()
    );

    let state = || feed(5..12).into_state();
    let refused = |contents: Contents, state| match evaluation.resume(contents, state) {
        Err(EvalError::State(message)) => message,
        other => panic!("{:?}", other.map(|e| e.runs())),
    };
    // Contents with another side, or another dimension.
    let innovation_only = Contents {
        truth: None,
        estimate: None,
        covariance: None,
        model: None,
        ..contents
    };
    assert!(refused(innovation_only, state()).contains("sides"));
    let wider = Contents {
        innovation: Some(2),
        innovation_cov: Some(2),
        model: Some((N, 2)),
        ..contents
    };
    assert!(refused(wider, state()).contains("dimension"));
    // A state edited to claim more steps than its accumulators hold, or fewer runs than it saw.
    let mut value: ciborium::Value = ciborium::from_reader(cbor(&state()).as_slice()).unwrap();
    let set = |value: &mut ciborium::Value, key: &str, to: u64| {
        for (k, v) in value.as_map_mut().unwrap() {
            if k.as_text() == Some(key) {
                *v = ciborium::Value::Integer(to.into());
            }
        }
    };
    let resume_value = |value: &ciborium::Value| {
        let mut bytes = Vec::new();
        ciborium::into_writer(value, &mut bytes).unwrap();
        evaluation.resume(contents, ciborium::from_reader(bytes.as_slice()).unwrap())
    };
    assert!(resume_value(&value).is_ok());
    set(&mut value, "steps", 301);
    assert!(matches!(resume_value(&value), Err(EvalError::State(_))));
    set(&mut value, "steps", 300);
    set(&mut value, "runs", 11);
    assert!(matches!(resume_value(&value), Err(EvalError::State(_))));
    set(&mut value, "runs", 12);
    // A count no state of its runs and steps can hold (a merge of it could overflow).
    let j = |value: &mut ciborium::Value| -> ciborium::Value {
        let map = value.as_map_mut().unwrap();
        map.iter()
            .find(|(k, _)| k.as_text() == Some("j"))
            .unwrap()
            .1
            .clone()
    };
    let mut side = j(&mut value);
    set(&mut side, "failed", 12 * 300 + 1);
    for (k, v) in value.as_map_mut().unwrap() {
        if k.as_text() == Some("j") {
            *v = side.clone();
        }
    }
    match resume_value(&value) {
        Err(EvalError::State(message)) => assert!(message.contains("failed J steps"), "{message}"),
        other => panic!("{:?}", other.map(|e| e.runs())),
    }
}
