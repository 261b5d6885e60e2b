//! Paper 002 (angle tracking): exact replay of an independent implementation's trace, EKF = KF
//! on the linear angle model, and the claims of the reproduction at quick size.
//!
//! `tests/data/angle-ekf-trace.json` is a copy of `shared/data/angle-ekf-trace.json`: outputs
//! of an independent Python implementation (numpy, float64) from explicit noise draws, so the
//! replay needs no random numbers. Two independent implementations agreed on it to about
//! 1e-11; we compare to 1e-9 relative.

use kalibra_filters::{Ekf, Filter, FilterOptions, Kf, Start, UpdateForm};
use kalibra_linalg::{Matrix3, Vector1, Vector3};
use kalibra_metrics::{instantaneous_errors, rmse_per_state, sliding_window};
use kalibra_models::{AngularTarget, ManoeuvringTarget, ManoeuvringTargetParams};
use kalibra_studies::claims::Verdict;
use kalibra_studies::paper002::{self, Config, Q_SETS, R};
use kalibra_studies::study::Study;
use serde_json::Value;

fn trace() -> Value {
    let text = include_str!("../data/angle-ekf-trace.json");
    serde_json::from_str(text).expect("the trace parses")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

fn rows(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("an array").iter().map(floats).collect()
}

/// `|a - b| <= tol max(|a|, |b|, floor)`: relative, with an absolute floor for values near
/// zero (errors and biases cross zero).
fn close(a: f64, b: f64, tol: f64, floor: f64, what: &str) {
    let scale = a.abs().max(b.abs()).max(floor);
    assert!(
        (a - b).abs() <= tol * scale,
        "{what}: ours {a:e}, trace {b:e}"
    );
}

const TOL: f64 = 1e-9;

#[test]
fn replays_the_independent_trace() {
    let data = trace();
    let n = data["n_steps"].as_u64().unwrap() as usize;
    let dt = data["dt"].as_f64().unwrap();
    assert_eq!(data["W"].as_u64(), Some(50));
    assert_eq!(data["R"].as_f64(), Some(R));
    // The trace's truth configuration is our default profile, run for n samples.
    let cfg = &data["truth_config"];
    assert_eq!(cfg["step"].as_f64(), Some(3.0));
    assert_eq!(cfg["osc_amp"].as_f64(), Some(10.0));
    let target = ManoeuvringTarget::new(ManoeuvringTargetParams {
        dt,
        duration: (n - 1) as f64 * dt,
        profile: paper002::manoeuvre(),
        sigma_input: data["sigma_input"].as_f64().unwrap(),
        x0: Vector3::zeros(),
    })
    .unwrap();
    let truth = target
        .truth_from_noise(&floats(&data["accel_noise"]))
        .unwrap();
    assert_eq!(truth.len(), n);
    for (k, (x, want)) in truth.iter().zip(rows(&data["x_true"])).enumerate() {
        for i in 0..3 {
            close(x[i], want[i], TOL, 1e-6, &format!("truth k={k} i={i}"));
        }
    }
    let z = ManoeuvringTarget::measurements_from_noise(&truth, R, &floats(&data["meas_noise"]))
        .unwrap();
    for (k, (ours, want)) in z.iter().zip(floats(&data["z"])).enumerate() {
        close(ours[0], want, TOL, 1e-6, &format!("z k={}", k + 1));
    }

    for set in &Q_SETS {
        let expected = &data["filters"][set.name];
        assert_eq!(floats(&data["Q"][set.name]), set.diag.to_vec());
        let model = AngularTarget::diagonal(dt, set.diag).unwrap();
        let h = AngularTarget::angle_measurement(R).unwrap();
        // The trace uses the printed update (I - K H) P-.
        let options = FilterOptions {
            update: UpdateForm::Standard,
            ..FilterOptions::default()
        };
        let mut ekf =
            Ekf::with_options(&model, &h, Vector3::zeros(), Matrix3::identity(), options).unwrap();
        let records = ekf
            .run_collect(z.iter().map(Some), Start::PredictFirst)
            .unwrap();
        let xh = rows(&expected["xh"]);
        let p_diag = rows(&expected["P_diag"]);
        let gains = rows(&expected["K"]);
        for (j, rec) in records.iter().enumerate() {
            let k = j + 1;
            let post = rec.posterior();
            for i in 0..3 {
                let what = |s: &str| format!("{} {s} k={k} i={i}", set.name);
                close(post.mean[i], xh[k][i], TOL, 1e-6, &what("xh"));
                close(post.cov[(i, i)], p_diag[k][i], TOL, 0.0, &what("P"));
                close(rec.gain()[(i, 0)], gains[k][i], TOL, 1e-9, &what("K"));
            }
        }
        let p_final = rows(&expected["P_final"]);
        let last = &records.last().unwrap().posterior().cov;
        for i in 0..3 {
            for j in 0..3 {
                close(last[(i, j)], p_final[i][j], TOL, 1e-6, "P_final");
            }
        }

        // Metrics on our own estimates: e = xh - x, RMSE over k = 1 .. n-1, windows W = 50.
        let mut estimates = vec![Vector3::zeros()];
        estimates.extend(records.iter().map(|r| r.posterior().mean));
        let errors = instantaneous_errors(&estimates, &truth).unwrap();
        for (k, (e, want)) in errors.iter().zip(rows(&expected["e"])).enumerate() {
            for i in 0..3 {
                close(e[i], want[i], TOL, 1e-6, &format!("{} e k={k}", set.name));
            }
        }
        let r = rmse_per_state(&errors[1..]).unwrap();
        for (i, want) in floats(&expected["rmse"]).into_iter().enumerate() {
            close(r[i], want, TOL, 0.0, &format!("{} rmse {i}", set.name));
        }
        let (w_rmse, w_bias, w_std) = (
            rows(&expected["window_rmse"]),
            rows(&expected["window_bias"]),
            rows(&expected["window_std"]),
        );
        for i in 0..3 {
            let series: Vec<f64> = errors[1..].iter().map(|e| e[i]).collect();
            let w = sliding_window(&series, 50).unwrap();
            assert_eq!(w.len(), w_rmse.len());
            for j in 0..w.len() {
                let what = |s: &str| format!("{} window {s} {j} state {i}", set.name);
                close(w.rmse[j], w_rmse[j][i], TOL, 0.0, &what("rmse"));
                // Bias crosses zero: compare on the window's RMSE scale.
                close(w.bias[j], w_bias[j][i], TOL, w.rmse[j], &what("bias"));
                close(w.std[j], w_std[j][i], TOL, 0.0, &what("std"));
            }
        }
    }
}

#[test]
fn the_trace_metric_unit_case_holds() {
    let data = trace();
    let case = &data["metric_unit_case"];
    let e = floats(&case["e"]);
    let w = sliding_window(&e, case["W"].as_u64().unwrap() as usize).unwrap();
    for (ours, want) in [
        (&w.rmse, floats(&case["window_rmse"])),
        (&w.bias, floats(&case["window_bias"])),
        (&w.std, floats(&case["window_std"])),
    ] {
        for (a, b) in ours.iter().zip(want) {
            close(*a, b, 1e-12, 1e-3, "unit case");
        }
    }
    // Eq 18 as printed, sqrt(sum e / (W - 1) - bias^2), has a negative radicand in the third
    // window (the trace stores NaN there): the reason for the corrected form.
    let third = &e[2..5];
    let bias = third.iter().sum::<f64>() / 3.0;
    assert!(third.iter().sum::<f64>() / 2.0 - bias * bias < 0.0);
    assert!(case["std_as_printed"][2].is_null());
}

#[test]
fn ekf_equals_kf_on_the_angle_model() {
    let target = paper002::target();
    let mut rng = kalibra_sim::MonteCarlo::new(1, 11).rng(0);
    let truth = target.truth(&mut rng).unwrap();
    let z: Vec<Vector1<f64>> = ManoeuvringTarget::measurements(&truth, R, &mut rng).unwrap();
    for set in &Q_SETS {
        let model = AngularTarget::diagonal(target.dt(), set.diag).unwrap();
        let h = AngularTarget::angle_measurement(R).unwrap();
        let mut kf = Kf::new(&model, &h, Vector3::zeros(), Matrix3::identity()).unwrap();
        let mut ekf = Ekf::new(&model, &h, Vector3::zeros(), Matrix3::identity()).unwrap();
        let a = kf
            .run_collect(z.iter().map(Some), Start::PredictFirst)
            .unwrap();
        let b = ekf
            .run_collect(z.iter().map(Some), Start::PredictFirst)
            .unwrap();
        for (ra, rb) in a.iter().zip(&b) {
            let (pa, pb) = (ra.posterior(), rb.posterior());
            assert!((pa.mean - pb.mean).amax() <= 1e-12 * (1.0 + pa.mean.amax()));
            assert!((pa.cov - pb.cov).amax() <= 1e-12 * pa.cov.amax());
        }
    }
}

#[test]
fn the_quick_reproduction_holds_the_claims_that_reproduce() {
    let report = paper002::run(&Config::quick()).unwrap();
    let verdict = |id: &str| report.claim(id).expect("claim exists").verdict;
    // The Monte Carlo ordering Q2 < Q1 < Q3 over 200 truths (fixed seed 2025): the spec's
    // independent implementation found Q2 best in about 99% of truths.
    assert!(
        report.fraction_ordering_holds >= 0.9,
        "ordering in {}",
        report.fraction_ordering_holds
    );
    assert_eq!(verdict("ordering"), Verdict::Reproduced);
    assert_eq!(verdict("q3-bias"), Verdict::Reproduced);
    assert_eq!(verdict("q3-std"), Verdict::Reproduced);
    // The claims that do not reproduce, and why: the measurement-noise floor keeps every set
    // above the quoted magnitudes (Q2's floor exceeds 0.136 deg even at dt = 0.001 s).
    assert_eq!(verdict("q2-phase-rmse"), Verdict::NotReproduced);
    for row in &report.floor_vs_dt {
        assert!(
            row.floor[1] > 0.136,
            "Q2 floor {} at dt {}",
            row.floor[1],
            row.dt
        );
        assert!(row.floor[1] < row.floor[0] && row.floor[0] < row.floor[2]);
    }
    for set in &Q_SETS {
        let r = &report.q_sets[set.name];
        // No filter beats its own noise floor by more than Monte Carlo scatter.
        assert!(r.mc_mean_rmse_theta_phase > 0.95 * r.noise_floor_theta);
    }
    // The Q3/Q2 ratio stays far below the quoted 2.5; the ordering reverses for strong
    // manoeuvres (Q3 best at 8x the default amplitude).
    assert!(report.sweep.iter().all(|r| r.q3_over_q2 < 1.4));
    let strongest = report.sweep.last().unwrap();
    assert!(strongest.ordering.starts_with("Q3"));
    assert!(report.first_reversal_amplitude.is_some());
    // The report's template renders from this report (strict: a field it names that the
    // report lacks is an error).
    paper002::Paper002
        .markdown(&Config::quick(), &report)
        .unwrap();
}

#[test]
fn the_reproduction_does_not_depend_on_the_thread_count() {
    let mut config = Config::quick();
    config.truths = 8;
    config.sweep_truths = 4;
    config.sweep_scales = vec![1.0, 4.0];
    config.threads = 1;
    let one = paper002::run(&config).unwrap();
    config.threads = 2;
    let two = paper002::run(&config).unwrap();
    assert_eq!(one.q_sets, two.q_sets);
    assert_eq!(one.sweep, two.sweep);
    assert_eq!(one.claims, two.claims);
}
