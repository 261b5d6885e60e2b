//! `Tuning::tune`: the library behind `kalibra tune`, checked against a sweep built by hand
//! from the library's own pieces (Kf, j_step, JHorizon, crossover), for thread invariance,
//! gaps, typed errors, the RMSE against a truth, and the J1/J2 monotonicity and bounds.

use kalibra_filters::{Filter, Kf, Start};
use kalibra_linalg::{DMatrix, DVector, Dyn};
use kalibra_metrics::{JHorizon, SweepPoint, crossover, j_step};
use kalibra_models::{LinearGaussian, LinearObservation, simulate};
use kalibra_tune::{
    InitialCovariance, JDivisor, NoCrossover, TuneError, TuneProblem, TuneReport, Tuning,
};
use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};

const STEPS: usize = 120;

/// A 2-D constant-velocity model, state `[x, y, vx, vy]`, positions measured with `R = 4 I`,
/// nominal white-acceleration `Q` of intensity 1 (dt = 1).
struct Cv {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    q_nom: DMatrix<f64>,
    r: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    truth: Vec<DVector<f64>>,
    zs: Vec<DVector<f64>>,
}

fn cv() -> Cv {
    let f = DMatrix::from_row_slice(
        4,
        4,
        &[
            1.0, 0.0, 1.0, 0.0, //
            0.0, 1.0, 0.0, 1.0, //
            0.0, 0.0, 1.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        ],
    );
    let h = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    let q_nom = DMatrix::from_row_slice(
        4,
        4,
        &[
            0.25, 0.0, 0.5, 0.0, //
            0.0, 0.25, 0.0, 0.5, //
            0.5, 0.0, 1.0, 0.0, //
            0.0, 0.5, 0.0, 1.0,
        ],
    );
    let r = DMatrix::identity(2, 2) * 4.0;
    let x0 = DVector::from_row_slice(&[0.0, 0.0, 3.0, -1.0]);
    let p0 = DMatrix::identity(4, 4) * 10.0;
    // The truth's noise is 0.3 Q_nom (p = -0.52); the crossover is a compromise between
    // sensitivity and robustness, not the truth's Q.
    let truth_dyn = LinearGaussian::new(f.clone(), &q_nom * 0.3).unwrap();
    let sensor = LinearObservation::new(h.clone(), r.clone()).unwrap();
    let sim = simulate(
        &truth_dyn,
        &sensor,
        x0.clone(),
        STEPS + 1,
        &mut ChaCha8Rng::seed_from_u64(2024),
    )
    .unwrap();
    // x0 is step 0; the sequence is steps 1..=STEPS (predict first).
    Cv {
        f,
        h,
        q_nom,
        r,
        x0,
        p0,
        truth: sim.states[1..].to_vec(),
        zs: sim.measurements[1..].to_vec(),
    }
}

fn problem(cv: &Cv, zs: Vec<Option<DVector<f64>>>) -> Result<TuneProblem, TuneError> {
    TuneProblem::new(
        cv.f.clone(),
        cv.h.clone(),
        cv.q_nom.clone(),
        cv.r.clone(),
        cv.x0.clone(),
        cv.p0.clone(),
        zs,
    )
}

fn all_present(cv: &Cv) -> Vec<Option<DVector<f64>>> {
    cv.zs.iter().cloned().map(Some).collect()
}

fn tune(tuning: &Tuning, problem: &TuneProblem) -> TuneReport {
    tuning.tune(problem).unwrap()
}

#[test]
fn results_match_the_librarys_own_sweep_exactly() {
    let cv = cv();
    let zs = all_present(&cv);
    let report = tune(
        &Tuning::new().threads(2),
        &problem(&cv, zs.clone()).unwrap(),
    );
    let grid = kalibra_tune::grid(-6.0..=6.0, 0.5).unwrap();
    assert_eq!(
        report.points.iter().map(|p| p.p).collect::<Vec<_>>(),
        grid,
        "default grid"
    );
    let sensor = LinearObservation::new(cv.h.clone(), cv.r.clone()).unwrap();
    let mut by_hand = Vec::new();
    for (&p, got) in grid.iter().zip(&report.points) {
        let dynamics = LinearGaussian::new(cv.f.clone(), &cv.q_nom * 10f64.powf(p)).unwrap();
        let mut kf = Kf::new(&dynamics, &sensor, cv.x0.clone(), cv.p0.clone()).unwrap();
        let mut horizon = JHorizon::new();
        kf.run(zs.iter().map(Option::as_ref), Start::PredictFirst, |rec| {
            horizon.push(
                &j_step(
                    &rec.compute_a(),
                    &rec.compute_b(),
                    rec.r(),
                    &rec.compute_c(),
                )
                .unwrap(),
            );
        })
        .unwrap();
        let j = horizon.summary(horizon.updates()).unwrap();
        // Bit for bit: the same library calls in the same order.
        assert_eq!(got.j1.to_bits(), j.j1.to_bits(), "J1 at p = {p}");
        assert_eq!(got.j2.to_bits(), j.j2.to_bits(), "J2 at p = {p}");
        assert_eq!(
            got.nq_log10_mean,
            Some(j.nq_log10_mean),
            "nq (2014) at p = {p}"
        );
        assert_eq!(
            got.nq_mean_log10,
            Some(j.nq_mean_log10),
            "nq (2012) at p = {p}"
        );
        assert_eq!(got.updates, STEPS);
        assert_eq!(got.indefinite_updates, 0);
        assert_eq!(got.max_j2k.to_bits(), j.max_j2k.to_bits());
        by_hand.push((p, j));
    }
    for (nq_of, got) in [
        (
            (|j: &kalibra_metrics::JSummary| j.nq_log10_mean) as fn(&_) -> f64,
            report.crossover.unwrap().nq_log10_mean,
        ),
        (
            |j: &kalibra_metrics::JSummary| j.nq_mean_log10,
            report.crossover.unwrap().nq_mean_log10,
        ),
    ] {
        let pts: Vec<SweepPoint> = by_hand
            .iter()
            .map(|(p, j)| SweepPoint {
                p: *p,
                nq: nq_of(j),
                j1: j.j1,
                j2: j.j2,
            })
            .collect();
        let c = crossover(&pts).unwrap().expect("a crossing on -6..6");
        let ours = report.crossover.unwrap();
        assert_eq!(ours.p.to_bits(), c.p.to_bits());
        assert_eq!(ours.j.to_bits(), c.j.to_bits());
        assert_eq!(got, Some(c.nq));
    }
    let c = report.crossover.unwrap();
    let q = report.recommended_q.as_ref().unwrap();
    let expect = &cv.q_nom * 10f64.powf(c.p);
    for (i, row) in q.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            assert_eq!(v.to_bits(), expect[(i, j)].to_bits());
        }
    }
    // A compromise within a few decades of the truth's p = -0.52.
    assert!(c.p > -3.0 && c.p < 2.0, "p_c = {}", c.p);
    assert_eq!(report.schema_version, kalibra_tune::TUNE_SCHEMA_VERSION);
    assert_eq!(report.initial_covariance, InitialCovariance::Checked);
    assert!(report.findings.no_crossover.is_none());
    // The report serialises and reads back (serde_json's default float parsing may differ in
    // the last bit, so values are compared to rounding).
    let json = serde_json::to_string(&report).unwrap();
    let back: TuneReport = serde_json::from_str(&json).unwrap();
    assert_eq!(back.points.len(), report.points.len());
    assert!((back.crossover.unwrap().p - c.p).abs() < 1e-14);
    assert_eq!(back.findings, report.findings);
}

#[test]
fn thread_count_does_not_change_a_bit() {
    let cv = cv();
    let problem = problem(&cv, all_present(&cv))
        .unwrap()
        .with_truth(cv.truth.iter().cloned().map(Some).collect())
        .unwrap();
    let one = tune(&Tuning::new().threads(1).position(vec![0, 1]), &problem);
    let two = tune(&Tuning::new().threads(2).position(vec![0, 1]), &problem);
    // Compared through JSON text too, so a NaN or -0.0 could not hide behind PartialEq.
    assert_eq!(
        serde_json::to_string(&one).unwrap(),
        serde_json::to_string(&two).unwrap()
    );
    for (a, b) in one.points.iter().zip(&two.points) {
        assert_eq!(a.j1.to_bits(), b.j1.to_bits());
        assert_eq!(a.j2.to_bits(), b.j2.to_bits());
    }
}

/// `values` with the entries at indices `i % period == offset` left out (not logged).
fn with_gaps(values: &[DVector<f64>], period: usize, offset: usize) -> Vec<Option<DVector<f64>>> {
    values
        .iter()
        .enumerate()
        .map(|(i, v)| (i % period != offset).then(|| v.clone()))
        .collect()
}

#[test]
fn gaps_are_skipped_and_counted() {
    let cv = cv();
    // Every third measurement missing.
    let zs: Vec<Option<DVector<f64>>> = with_gaps(&cv.zs, 3, 1);
    let present = zs.iter().flatten().count();
    assert!(present < STEPS);
    let problem = problem(&cv, zs.clone()).unwrap();
    assert_eq!(problem.updates(), present);
    assert_eq!(problem.steps(), STEPS);
    let tuning = Tuning::new().exponents(-2.0, 2.0, 1.0).unwrap();
    let report = tune(&tuning, &problem);
    assert_eq!(report.updates, present);
    assert_eq!(report.divisor_value, present);
    for pt in &report.points {
        assert_eq!(pt.updates, present);
    }
    // The papers' divisor counts the missing steps as zeros: the same sums over STEPS.
    let papers = tune(&tuning.clone().divisor(JDivisor::Steps), &problem);
    assert_eq!(papers.divisor_value, STEPS);
    for (a, b) in report.points.iter().zip(&papers.points) {
        let ratio = present as f64 / STEPS as f64;
        assert!((b.j1 - a.j1 * ratio).abs() < 1e-12);
        assert!((b.j2 - a.j2 * ratio).abs() < 1e-12);
        assert_eq!(a.nq_log10_mean, b.nq_log10_mean);
    }
    // A hand-made run over the same gaps agrees with the first point exactly.
    let sensor = LinearObservation::new(cv.h.clone(), cv.r.clone()).unwrap();
    let dynamics = LinearGaussian::new(cv.f.clone(), &cv.q_nom * 10f64.powf(-2.0)).unwrap();
    let mut kf = Kf::new(&dynamics, &sensor, cv.x0.clone(), cv.p0.clone()).unwrap();
    let records = kf
        .run_collect(zs.iter().map(Option::as_ref), Start::PredictFirst)
        .unwrap();
    assert_eq!(records.len(), present);
    let steps: Vec<usize> = records.iter().map(|r| r.step()).collect();
    let expect: Vec<usize> = (0..STEPS).filter(|i| i % 3 != 1).map(|i| i + 1).collect();
    assert_eq!(steps, expect, "updates at the steps with a measurement");
}

#[test]
fn every_bad_input_is_a_typed_error() {
    let cv = cv();
    let zs = all_present(&cv);
    let build = |f: DMatrix<f64>,
                 h: DMatrix<f64>,
                 q: DMatrix<f64>,
                 r: DMatrix<f64>,
                 x0: DVector<f64>,
                 p0: DMatrix<f64>,
                 zs: Vec<Option<DVector<f64>>>| {
        TuneProblem::new(f, h, q, r, x0, p0, zs).unwrap_err()
    };
    let (f, h, q, r, x0, p0) = (
        cv.f.clone(),
        cv.h.clone(),
        cv.q_nom.clone(),
        cv.r.clone(),
        cv.x0.clone(),
        cv.p0.clone(),
    );
    // F not square.
    assert_eq!(
        build(
            DMatrix::zeros(4, 3),
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::NotSquare {
            matrix: "F",
            rows: 4,
            cols: 3
        }
    );
    // H's columns differ from n.
    assert_eq!(
        build(
            f.clone(),
            DMatrix::zeros(2, 3),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::Shape {
            matrix: "H",
            expected_rows: 2,
            expected_cols: 4,
            found_rows: 2,
            found_cols: 3
        }
    );
    // Q of the wrong size; R of the wrong size; P0 not square; x0 of the wrong length.
    assert!(matches!(
        build(
            f.clone(),
            h.clone(),
            DMatrix::identity(3, 3),
            r.clone(),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::Shape {
            matrix: "Q_nom",
            ..
        }
    ));
    assert!(matches!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            DMatrix::identity(3, 3),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::Shape { matrix: "R", .. }
    ));
    assert!(matches!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            DMatrix::zeros(4, 2),
            zs.clone()
        ),
        TuneError::NotSquare { matrix: "P0", .. }
    ));
    assert!(matches!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            r.clone(),
            DVector::zeros(3),
            p0.clone(),
            zs.clone()
        ),
        TuneError::Shape {
            matrix: "x0",
            expected_rows: 4,
            found_rows: 3,
            ..
        }
    ));
    // n = 0 and m = 0.
    assert!(matches!(
        build(
            DMatrix::zeros(0, 0),
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::Empty { .. }
    ));
    assert!(matches!(
        build(
            f.clone(),
            DMatrix::zeros(0, 4),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::Empty { .. }
    ));
    // Non-finite model values.
    let mut f_nan = f.clone();
    f_nan[(1, 2)] = f64::NAN;
    assert_eq!(
        build(
            f_nan,
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::NonFinite {
            what: "F",
            step: None
        }
    );
    // Asymmetric Q, indefinite R, indefinite P0.
    let mut q_asym = q.clone();
    q_asym[(0, 2)] += 0.1;
    assert!(matches!(
        build(
            f.clone(),
            h.clone(),
            q_asym,
            r.clone(),
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::NotSymmetric {
            matrix: "Q_nom",
            ..
        }
    ));
    let r_neg = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
    assert!(matches!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            r_neg,
            x0.clone(),
            p0.clone(),
            zs.clone()
        ),
        TuneError::NotPositiveSemiDefinite { matrix: "R", .. }
    ));
    let mut p0_bad = p0.clone();
    p0_bad[(3, 3)] = -5.0;
    assert!(matches!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0_bad.clone(),
            zs.clone()
        ),
        TuneError::NotPositiveSemiDefinite { matrix: "P0", .. }
    ));
    // ... which the as-given opt-in accepts.
    let given = TuneProblem::as_given(
        f.clone(),
        h.clone(),
        q.clone(),
        r.clone(),
        x0.clone(),
        p0_bad,
        zs.clone(),
    )
    .unwrap();
    assert_eq!(given.initial_covariance(), InitialCovariance::AsGiven);
    // Measurement of the wrong length, non-finite measurement, no measurement at all.
    let mut short = zs.clone();
    short[7] = Some(DVector::zeros(3));
    assert_eq!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            short
        ),
        TuneError::MeasurementLength {
            step: 7,
            expected: 2,
            found: 3
        }
    );
    let mut nan = zs.clone();
    nan[9] = Some(DVector::from_element(2, f64::INFINITY));
    assert_eq!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            nan
        ),
        TuneError::NonFinite {
            what: "measurement",
            step: Some(9)
        }
    );
    assert_eq!(
        build(
            f.clone(),
            h.clone(),
            q.clone(),
            r.clone(),
            x0.clone(),
            p0.clone(),
            vec![None; 5]
        ),
        TuneError::NoMeasurements
    );
    // Truth of the wrong length or size.
    let ok = problem(&cv, zs.clone()).unwrap();
    assert_eq!(
        ok.clone().with_truth(vec![None; 3]).unwrap_err(),
        TuneError::TruthSteps {
            expected: STEPS,
            found: 3
        }
    );
    let mut truth: Vec<Option<DVector<f64>>> = vec![None; STEPS];
    truth[4] = Some(DVector::zeros(2));
    assert_eq!(
        ok.clone().with_truth(truth).unwrap_err(),
        TuneError::TruthLength {
            step: 4,
            expected: 4,
            found: 2
        }
    );
    // Bad options: grid step, a decreasing grid, an empty grid, a scale that underflows, a
    // position beyond the state.
    assert!(matches!(
        Tuning::new().exponents(0.0, 1.0, 0.0).unwrap_err(),
        TuneError::InvalidOption { .. }
    ));
    assert!(matches!(
        Tuning::new()
            .grid(vec![0.0, 1.0, 1.0])
            .tune(&ok)
            .unwrap_err(),
        TuneError::InvalidGrid { index: 2, .. }
    ));
    assert!(matches!(
        Tuning::new().grid(vec![]).tune(&ok).unwrap_err(),
        TuneError::InvalidGrid { index: 0, .. }
    ));
    assert!(matches!(
        Tuning::new().grid(vec![-400.0, 0.0]).tune(&ok).unwrap_err(),
        TuneError::InvalidGrid { index: 0, .. }
    ));
    assert_eq!(
        Tuning::new().position(vec![0, 4]).tune(&ok).unwrap_err(),
        TuneError::PositionIndex { index: 4, dim: 4 }
    );
    // Ragged rows from a file.
    assert_eq!(
        kalibra_tune::matrix_from_rows("Q_nom", &[vec![1.0, 0.0], vec![0.0]]).unwrap_err(),
        TuneError::Ragged {
            matrix: "Q_nom",
            row: 1,
            expected: 2,
            found: 1
        }
    );
    // Messages name the matrix.
    let msg = TuneError::NotSquare {
        matrix: "F",
        rows: 4,
        cols: 3,
    }
    .to_string();
    assert_eq!(msg, "matrix F is 4x3, not square");
}

#[test]
fn rmse_per_p_equals_a_direct_computation() {
    let cv = cv();
    // Gaps in both the measurements and the truth.
    let zs: Vec<Option<DVector<f64>>> = with_gaps(&cv.zs, 5, 2);
    let truth: Vec<Option<DVector<f64>>> = with_gaps(&cv.truth, 7, 0);
    let problem = problem(&cv, zs.clone())
        .unwrap()
        .with_truth(truth.clone())
        .unwrap();
    let report = tune(
        &Tuning::new()
            .exponents(-3.0, 3.0, 1.5)
            .unwrap()
            .position(vec![0, 1]),
        &problem,
    );
    let sensor = LinearObservation::new(cv.h.clone(), cv.r.clone()).unwrap();
    let mut best = (f64::NAN, f64::INFINITY);
    for pt in &report.points {
        let dynamics = LinearGaussian::new(cv.f.clone(), &cv.q_nom * 10f64.powf(pt.p)).unwrap();
        let mut kf = Kf::new(&dynamics, &sensor, cv.x0.clone(), cv.p0.clone()).unwrap();
        // Step by step: predict, update where measured, compare with the truth where known.
        let (mut sq, mut sq_pos, mut per, mut count) = (0.0, 0.0, [0.0; 4], 0usize);
        for (z, x) in zs.iter().zip(&truth) {
            Filter::<Dyn, Dyn>::predict(&mut kf).unwrap();
            if let Some(z) = z {
                kf.update(z).unwrap();
            }
            if let Some(x) = x {
                let e = kf.mean() - x;
                sq += e.norm_squared();
                sq_pos += e[0] * e[0] + e[1] * e[1];
                for (sum, ei) in per.iter_mut().zip(e.iter()) {
                    *sum += ei * ei;
                }
                count += 1;
            }
        }
        let k = count as f64;
        let rmse = pt.rmse.as_ref().expect("truth given");
        assert_eq!(rmse.steps, count);
        assert!((rmse.state - (sq / k).sqrt()).abs() < 1e-12 * rmse.state.max(1.0));
        assert!((rmse.position.unwrap() - (sq_pos / k).sqrt()).abs() < 1e-12 * rmse.state.max(1.0));
        for (got, sum) in rmse.per_component.iter().zip(per) {
            assert!((got - (sum / k).sqrt()).abs() < 1e-12 * rmse.state.max(1.0));
        }
        if rmse.state < best.1 {
            best = (pt.p, rmse.state);
        }
    }
    let min = report.rmse_minimum.unwrap();
    assert_eq!((min.p_state, min.state), best);
    assert!(min.p_position.is_some());
}

#[test]
fn j1_falls_and_j2_rises_along_p_within_the_bounds() {
    let cv = cv();
    let report = tune(
        &Tuning::new().exponents(-6.0, 6.0, 0.25).unwrap(),
        &problem(&cv, all_present(&cv)).unwrap(),
    );
    let m = 2.0;
    for pt in &report.points {
        assert!(0.0 <= pt.j1 && pt.j1 <= m, "J1 = {} at p = {}", pt.j1, pt.p);
        assert!(0.0 <= pt.j2 && pt.j2 <= m, "J2 = {} at p = {}", pt.j2, pt.p);
    }
    for pair in report.points.windows(2) {
        assert!(pair[1].j1 < pair[0].j1, "J1 falls at p = {}", pair[1].p);
        assert!(pair[1].j2 > pair[0].j2, "J2 rises at p = {}", pair[1].p);
        let (a, b) = (
            pair[0].nq_log10_mean.unwrap(),
            pair[1].nq_log10_mean.unwrap(),
        );
        assert!(b > a, "nq rises with p");
    }
    assert_eq!(report.findings.points_outside_bounds, 0);
    assert_eq!(report.findings.points_with_indefinite_updates, 0);
    // A grid entirely below the crossing says which way to move.
    let c = report.crossover.unwrap();
    let low = tune(
        &Tuning::new().grid(vec![c.p - 3.0, c.p - 2.0]),
        &problem(&cv, all_present(&cv)).unwrap(),
    );
    assert!(low.crossover.is_none() && low.recommended_q.is_none());
    assert_eq!(low.findings.no_crossover, Some(NoCrossover::J1AboveJ2));
}

#[test]
fn an_indefinite_initial_covariance_as_given_runs_and_is_reported() {
    let cv = cv();
    // Symmetric but indefinite P0 (a negative position variance, which leaves the first
    // A + B indefinite while S stays positive), and an asymmetric one.
    let mut indefinite = cv.p0.clone();
    indefinite[(0, 0)] = -12.0;
    let mut asymmetric = cv.p0.clone();
    asymmetric[(0, 2)] = 3.0;
    for p0 in [indefinite, asymmetric] {
        let problem = TuneProblem::as_given(
            cv.f.clone(),
            cv.h.clone(),
            cv.q_nom.clone(),
            cv.r.clone(),
            cv.x0.clone(),
            p0,
            all_present(&cv),
        )
        .unwrap();
        let report = tune(&Tuning::new().threads(1), &problem);
        assert_eq!(report.initial_covariance, InitialCovariance::AsGiven);
        assert_eq!(report.points.len(), 25);
        assert!(
            report
                .points
                .iter()
                .all(|p| p.j1.is_finite() && p.j2.is_finite())
        );
        if problem.p0()[(0, 0)] < 0.0 {
            assert!(report.findings.points_with_indefinite_updates > 0);
            assert_eq!(report.findings.first_indefinite_p, Some(-6.0));
        }
    }
    // A checked P0 run as given gives the same J to rounding: LU and Cholesky solves agree.
    let checked = tune(&Tuning::new(), &problem(&cv, all_present(&cv)).unwrap());
    let given = tune(
        &Tuning::new(),
        &TuneProblem::as_given(
            cv.f.clone(),
            cv.h.clone(),
            cv.q_nom.clone(),
            cv.r.clone(),
            cv.x0.clone(),
            cv.p0.clone(),
            all_present(&cv),
        )
        .unwrap(),
    );
    for (a, b) in checked.points.iter().zip(&given.points) {
        assert!(
            (a.j1 - b.j1).abs() < 1e-9 && (a.j2 - b.j2).abs() < 1e-9,
            "p = {}",
            a.p
        );
    }
}
