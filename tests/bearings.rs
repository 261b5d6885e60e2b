//! Paper 001 (bearings-only tracking): exact replay of an independent implementation's
//! problem III traces for all five filters.
//!
//! `tests/data/bot-problem3-traces.json` is a copy of `shared/data/bot-problem3-traces.json`:
//! three runs of problem III (truth, bearings, and every filter's estimates) from an
//! independent Python implementation (numpy, float64). Two independent implementations agreed
//! on it to about 1e-11; we compare to 1e-9 relative.

use kalibra::filters::{Ekf, Filter, KappaCriterion, KappaGrid, SigmaSet, Srf, Ukf, UkfPrediction};
use kalibra::linalg::{Matrix2, U2, Vector1, Vector2};
use kalibra::models::{Bearing, BearingReference, LinearGaussian, Moving};
use serde_json::Value;

fn trace() -> Value {
    serde_json::from_str(include_str!("data/bot-problem3-traces.json")).expect("the trace parses")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

fn matrix2(v: &Value) -> Matrix2<f64> {
    let r: Vec<Vec<f64>> = v.as_array().expect("rows").iter().map(floats).collect();
    Matrix2::new(r[0][0], r[0][1], r[1][0], r[1][1])
}

const TOL: f64 = 1e-9;

type Platform = Moving<fn(usize) -> Vector2<f64>>;

fn unit_circle(k: usize) -> Vector2<f64> {
    Vector2::new((k as f64).cos(), (k as f64).sin())
}

fn models(config: &Value) -> (LinearGaussian<U2>, Bearing<U2, Platform>) {
    let f = Matrix2::new(0.9, 0.0, 0.0, 1.0);
    let dynamics = LinearGaussian::new(f, matrix2(&config["Qd"])).unwrap();
    let r = config["R_theta"].as_f64().unwrap();
    let platform: Platform = Moving(unit_circle);
    let bearing = Bearing::new(U2, [0, 1], BearingReference::XAxis, r, platform).unwrap();
    (dynamics, bearing)
}

/// Runs `filter` over the run's bearings (updating first at k = 0) and compares every
/// posterior (and chosen kappa) with the trace.
fn replay<F: Filter<U2, kalibra::linalg::U1>>(
    mut filter: F,
    run: &Value,
    name: &str,
    kappa: impl Fn(&F) -> Option<f64>,
) {
    let expected = &run["filters"][name];
    let zs: Vec<Vector1<f64>> = floats(&run["z"]).into_iter().map(Vector1::new).collect();
    let xs = expected["x"].as_array().unwrap();
    let ps = expected["P"].as_array().unwrap();
    let kappas = expected["kappa"].as_array().unwrap();
    let mut worst = 0.0f64;
    for (k, z) in zs.iter().enumerate() {
        if k > 0 {
            filter.predict().unwrap();
        }
        let rec = filter.update(z).unwrap();
        let post = rec.posterior();
        let x = floats(&xs[k]);
        let p = matrix2(&ps[k]);
        let scale_p = p.abs().max();
        for i in 0..2 {
            let scale = x[i].abs().max(1.0);
            let err = (post.mean[i] - x[i]).abs() / scale;
            worst = worst.max(err);
            assert!(
                err <= TOL,
                "{name} k={k} x[{i}]: {} vs {}",
                post.mean[i],
                x[i]
            );
            for j in 0..2 {
                let err = (post.cov[(i, j)] - p[(i, j)]).abs() / scale_p;
                worst = worst.max(err);
                assert!(
                    err <= TOL,
                    "{name} k={k} P[{i}{j}]: {} vs {}",
                    post.cov[(i, j)],
                    p[(i, j)]
                );
            }
        }
        if let Some(want) = kappas[k].as_f64() {
            assert_eq!(kappa(&filter), Some(want), "{name} kappa at k={k}");
        }
    }
    // Observed: below 1e-14 for every filter.
    assert!(worst <= TOL);
}

#[test]
fn replays_the_independent_problem3_traces() {
    let data = trace();
    let config = &data["config"];
    assert_eq!(config["kappa_ukf"].as_f64(), Some(1.0));
    let grid = KappaGrid::paper001(2).unwrap();
    let trace_grid = floats(&config["kappa_grid"]);
    assert_eq!(grid.values().len(), trace_grid.len());
    for (a, b) in grid.values().iter().zip(&trace_grid) {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "grid {a} vs {b}");
    }
    for run in data["runs"].as_array().unwrap() {
        let (dynamics, bearing) = models(config);
        let x0 = Vector2::from_vec(floats(&run["init_x"]));
        let p0 = matrix2(&run["init_P"]);
        replay(
            Ekf::new(&dynamics, &bearing, x0, p0).unwrap(),
            run,
            "EKF",
            |_| None,
        );
        let ukf = || {
            Ukf::new(&dynamics, &bearing, x0, p0, SigmaSet::recommended(2))
                .unwrap()
                .with_prediction(UkfPrediction::Linearised)
        };
        replay(ukf(), run, "UKF", |f| f.last_kappa());
        for (name, criterion) in [
            ("UKF-ML", KappaCriterion::MaximumLikelihood),
            ("UKF-MPP", KappaCriterion::MaximumPosterior),
        ] {
            let f = ukf().with_adaptive_kappa(criterion, grid.clone()).unwrap();
            replay(f, run, name, |f| f.last_kappa());
        }
        replay(
            Srf::new(&dynamics, &bearing, x0, p0).unwrap(),
            run,
            "SRF",
            |_| None,
        );
    }
}
