//! A simulated linear Kalman filter Monte Carlo, logged as arrays and evaluated: the verdict
//! follows a deliberate scaling of the logged covariance, and J1/J2 equal the library's own
//! `j_step` on the filter's step records.

use kalibra_eval::{Evaluation, FilterLog, Matrices, Report, Vectors, VerdictKind};
use kalibra_filters::{Filter, Kf};
use kalibra_linalg::nalgebra::allocator::Allocator;
use kalibra_linalg::{DefaultAllocator, Dim, Matrix2, Matrix4, OMatrix, U2, U4, Vector4};
use kalibra_metrics::j_step;
use kalibra_models::{Kinematic, Simulator, sample_with_factor};
use kalibra_sim::MonteCarlo;

const RUNS: usize = 50;
const STEPS: usize = 40;

/// One run's arrays, flat per step.
#[derive(Default)]
struct RunLog {
    truth: Vec<f64>,
    estimate: Vec<f64>,
    cov: Vec<f64>,
    innovation: Vec<f64>,
    s: Vec<f64>,
    f: Vec<f64>,
    h: Vec<f64>,
    q: Vec<f64>,
    r: Vec<f64>,
    /// J1k of the records at steps 1.., by kalibra-metrics directly.
    j1: Vec<f64>,
}

/// Row by row (numpy's C order), as the log expects.
fn row_major<R: Dim, C: Dim>(m: &OMatrix<f64, R, C>) -> Vec<f64>
where
    DefaultAllocator: Allocator<R, C>,
{
    (0..m.nrows())
        .flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)]))
        .collect()
}

fn simulate() -> Vec<RunLog> {
    let cv = Kinematic::constant_velocity(2, 1.0).unwrap();
    let f = cv.dynamics(U4).unwrap();
    let h = cv
        .position_measurement(U4, U2, Matrix2::identity() * 100.0)
        .unwrap();
    let m0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let p0 = Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0));
    let l0 = p0.map(f64::sqrt);
    MonteCarlo::new(RUNS, 2024)
        .map(|_, rng| {
            let x0 = m0 + sample_with_factor(&l0, rng);
            let mut truth = Simulator::new(&f, &h, x0, 0).unwrap();
            let mut kf = Kf::new(&f, &h, m0, p0).unwrap();
            let mut log = RunLog::default();
            for k in 0..STEPS {
                let (x, z) = truth.step(rng).unwrap();
                if k > 0 {
                    kf.predict().unwrap();
                }
                let rec = kf.update(&z).unwrap();
                log.truth.extend(x.iter());
                log.estimate.extend(rec.posterior().mean.iter());
                log.cov.extend(row_major(&rec.posterior().cov));
                log.innovation.extend(rec.innovation().iter());
                log.s.extend(row_major(rec.s_matrix()));
                log.f.extend(row_major(rec.f()));
                log.h.extend(row_major(rec.h()));
                log.q.extend(row_major(rec.process_noise()));
                log.r.extend(row_major(rec.r()));
                if k > 0 {
                    let j = j_step(
                        &rec.compute_a(),
                        &rec.compute_b(),
                        rec.r(),
                        &rec.compute_c(),
                    )
                    .unwrap();
                    log.j1.push(j.j1);
                }
            }
            Ok::<_, std::fmt::Error>(log)
        })
        .unwrap()
}

fn concat(runs: &[RunLog], pick: fn(&RunLog) -> &Vec<f64>) -> Vec<f64> {
    runs.iter().flat_map(|r| pick(r).iter().copied()).collect()
}

fn evaluate(runs: &[RunLog], scale: f64) -> Report {
    let cov: Vec<f64> = concat(runs, |r| &r.cov).iter().map(|v| v * scale).collect();
    let log = FilterLog::new(runs.len(), STEPS)
        .unwrap()
        .with_truth(Vectors::dense(4, concat(runs, |r| &r.truth)))
        .unwrap()
        .with_estimate(Vectors::dense(4, concat(runs, |r| &r.estimate)))
        .unwrap()
        .with_covariance(Matrices::dense(4, 4, cov))
        .unwrap()
        .with_innovation(Vectors::dense(2, concat(runs, |r| &r.innovation)))
        .unwrap()
        .with_innovation_cov(Matrices::dense(2, 2, concat(runs, |r| &r.s)))
        .unwrap()
        .with_model(
            Matrices::dense(4, 4, concat(runs, |r| &r.f)),
            Matrices::dense(2, 4, concat(runs, |r| &r.h)),
            Matrices::dense(4, 4, concat(runs, |r| &r.q)),
            Matrices::dense(2, 2, concat(runs, |r| &r.r)),
        )
        .unwrap();
    Evaluation::new()
        .group("position", vec![0, 1])
        .unwrap()
        .window(10)
        .unwrap()
        .evaluate(&log)
        .unwrap()
}

#[test]
fn verdict_follows_the_scale_of_the_covariance() {
    let runs = simulate();
    let consistent = evaluate(&runs, 1.0);
    let s = &consistent.summary;
    assert_eq!(
        s.verdict.kind,
        VerdictKind::Consistent,
        "{}",
        s.verdict.evidence
    );
    assert!(s.anees_fraction_inside.unwrap() > 0.8, "{s:?}");
    assert!(s.nci.unwrap().abs() < 1.0, "{s:?}");

    // P x 0.25: NEES x 4, NCI + 6 dB.
    let optimistic = evaluate(&runs, 0.25);
    let o = &optimistic.summary;
    assert_eq!(
        o.verdict.kind,
        VerdictKind::Optimistic,
        "{}",
        o.verdict.evidence
    );
    assert!((o.anees.unwrap() / s.anees.unwrap() - 4.0).abs() < 1e-9);
    assert!((o.nci.unwrap() - s.nci.unwrap() - 10.0 * 4f64.log10()).abs() < 1e-9);

    let pessimistic = evaluate(&runs, 4.0);
    let p = &pessimistic.summary;
    assert_eq!(
        p.verdict.kind,
        VerdictKind::Pessimistic,
        "{}",
        p.verdict.evidence
    );
    assert!(p.anees_fraction_inside.unwrap() < 0.1);

    // The innovations were not scaled: ANIS is the same in all three.
    assert_eq!(o.anis, s.anis);
    assert_eq!(
        s.anis_test.as_ref().unwrap().outcome,
        VerdictKind::Consistent
    );
}

#[test]
fn j1_equals_the_library_on_the_step_records_and_the_report_serialises() {
    let runs = simulate();
    let report = evaluate(&runs, 1.0);
    let j = report.j.as_ref().unwrap();
    assert_eq!(j.updates, RUNS * (STEPS - 1));
    assert_eq!(j.failed_updates, 0);
    let direct = runs.iter().flat_map(|r| r.j1.iter()).sum::<f64>() / j.updates as f64;
    assert!(
        (j.j1 - direct).abs() < 1e-12 * direct,
        "{} vs {direct}",
        j.j1
    );
    assert!(j.j1 > 0.0 && j.j1 < 2.0 && j.j2 > 0.0 && j.j2 < 2.0);
    assert_eq!(j.j1_per_step[0], None);

    let w = report.window.as_ref().unwrap();
    assert_eq!((w.window, w.start_steps.len()), (10, STEPS - 9));
    assert!(report.whiteness.is_some());
    assert_eq!(report.rmse_per_step.len(), 5);
    assert_eq!(report.rmse_per_step[4].name, "position");

    let json = serde_json::to_string(&report).unwrap();
    assert!(json.contains("\"schema_version\":1"));
    assert!(json.contains("\"verdict\":{\"kind\":\"consistent\""));
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back.summary.verdict, report.summary.verdict);
    // serde_json's default float parser may be one ulp off: compare to a relative 1e-15.
    for (a, b) in back.anees_band.iter().zip(&report.anees_band) {
        let (a, b) = (a.unwrap(), b.unwrap());
        assert!((a.upper - b.upper).abs() <= 1e-15 * b.upper);
    }
}
