//! A `Dyn` model whose answers have the wrong size: the EKF and the UKF
//! (plain and adaptive) check every vector and matrix the user's model returns, and a wrong
//! one is a `DimensionMismatch` naming both sizes at that step, with the filter left as it
//! was; before, nalgebra panicked inside the sigma-point sums or the covariance products.

use kalibra_filters::{
    ConstantGainKf, Ekf, Filter, FilterError, KappaCriterion, KappaGrid, SigmaSet, Ukf,
};
use kalibra_linalg::{DMatrix, DVector, Dyn};
use kalibra_models::{Dynamics, Measurement};

/// Which answer of the model is wrong.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Wrong {
    Nothing,
    Transition,
    Jacobian,
    ProcessNoise,
    Measure,
    MeasurementJacobian,
    MeasurementNoise,
    Residual,
}

const ALL: [Wrong; 7] = [
    Wrong::Transition,
    Wrong::Jacobian,
    Wrong::ProcessNoise,
    Wrong::Measure,
    Wrong::MeasurementJacobian,
    Wrong::MeasurementNoise,
    Wrong::Residual,
];

/// A random walk of two states, both measured, that answers `wrong` with one row too many.
#[derive(Clone, Debug)]
struct Model(Wrong);

const N: usize = 2;

impl Model {
    fn size(&self, what: Wrong, n: usize) -> usize {
        if self.0 == what { n + 1 } else { n }
    }
}

impl Dynamics<Dyn> for Model {
    fn state_dim(&self) -> Dyn {
        Dyn(N)
    }
    fn transition(&self, _: usize, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_fn(self.size(Wrong::Transition, N), |i, _| {
            x.get(i).copied().unwrap_or(0.0)
        })
    }
    fn jacobian(&self, _: usize, _: &DVector<f64>) -> DMatrix<f64> {
        DMatrix::identity(self.size(Wrong::Jacobian, N), N)
    }
    fn noise_cov(&self, _: usize) -> DMatrix<f64> {
        let n = self.size(Wrong::ProcessNoise, N);
        DMatrix::identity(n, n) * 0.1
    }
}

impl Measurement<Dyn, Dyn> for Model {
    fn meas_dim(&self) -> Dyn {
        Dyn(N)
    }
    fn measure(&self, _: usize, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_fn(self.size(Wrong::Measure, N), |i, _| {
            x.get(i).copied().unwrap_or(0.0)
        })
    }
    fn jacobian(&self, _: usize, _: &DVector<f64>) -> DMatrix<f64> {
        DMatrix::identity(self.size(Wrong::MeasurementJacobian, N), N)
    }
    fn noise_cov(&self, _: usize, _: &DVector<f64>) -> DMatrix<f64> {
        let m = self.size(Wrong::MeasurementNoise, N);
        DMatrix::identity(m, m)
    }
    fn residual(&self, z: &DVector<f64>, zhat: &DVector<f64>) -> DVector<f64> {
        let m = self.size(Wrong::Residual, N);
        DVector::from_fn(m, |i, _| {
            z.get(i).copied().unwrap_or(0.0) - zhat.get(i).copied().unwrap_or(0.0)
        })
    }
}

fn start() -> (DVector<f64>, DMatrix<f64>) {
    (DVector::from_vec(vec![1.0, -1.0]), DMatrix::identity(N, N))
}

/// Everything a caller can see of a filter, to the bit.
fn snapshot(f: &dyn Filter<Dyn, Dyn>) -> String {
    format!(
        "{:?} {:?} {} {:?}",
        f.mean(),
        f.covariance(),
        f.step_index(),
        f.last_record()
    )
}

/// One update and one prediction with the model answering `wrong`: the step whose model call
/// is wrong fails with a dimension mismatch naming 2 and 3, and leaves the filter unchanged.
/// `unused` is the answer this filter never asks for (the UKF's measurement Jacobian, which
/// it replaces by the statistical linearisation when the prior has a Cholesky factor).
fn check(filter: &mut dyn Filter<Dyn, Dyn>, wrong: Wrong, unused: Wrong, who: &str) {
    let z = DVector::from_vec(vec![0.5, -0.5]);
    let mut failures = 0;
    for op in ["update", "predict"] {
        let before = snapshot(filter);
        let result = match op {
            "update" => filter.update(&z).map(|_| ()),
            _ => filter.predict(),
        };
        match result {
            Ok(()) => {}
            Err(FilterError::DimensionMismatch {
                expected, found, ..
            }) => {
                assert_eq!((expected, found), (2, 3), "{who} {wrong:?} {op}");
                assert_eq!(
                    snapshot(filter),
                    before,
                    "{who} {wrong:?} {op}: state changed"
                );
                failures += 1;
            }
            Err(e) => panic!("{who} {wrong:?} {op}: {e:?}"),
        }
    }
    let expected = usize::from(wrong != Wrong::Nothing && wrong != unused);
    assert_eq!(failures, expected, "{who} {wrong:?}");
}

#[test]
fn ekf_refuses_model_answers_of_the_wrong_size() {
    for wrong in std::iter::once(Wrong::Nothing).chain(ALL) {
        let (x0, p0) = start();
        let mut ekf = Ekf::new(Model(wrong), Model(wrong), x0, p0).unwrap();
        check(&mut ekf, wrong, Wrong::Nothing, "EKF");
    }
}

/// The constant-gain KF shares the EKF's prediction and update; its gain is given, so only the
/// answers a step asks for are checked (the measurement noise enters only S, which the record
/// reports, so it is checked too).
#[test]
fn constant_gain_kf_refuses_model_answers_of_the_wrong_size() {
    for wrong in std::iter::once(Wrong::Nothing).chain(ALL) {
        let (x0, p0) = start();
        let gain = DMatrix::identity(N, N) * 0.5;
        let mut kf = ConstantGainKf::new(Model(wrong), Model(wrong), x0, p0, gain).unwrap();
        check(&mut kf, wrong, Wrong::Nothing, "constant-gain KF");
    }
}

#[test]
fn ukf_refuses_model_answers_of_the_wrong_size() {
    for wrong in std::iter::once(Wrong::Nothing).chain(ALL) {
        for set in [
            SigmaSet::recommended(N),
            SigmaSet::Scaled {
                alpha: 0.5,
                beta: 2.0,
                kappa: 0.0,
            },
        ] {
            let (x0, p0) = start();
            let mut ukf = Ukf::new(Model(wrong), Model(wrong), x0, p0, set).unwrap();
            check(&mut ukf, wrong, Wrong::MeasurementJacobian, "UKF");
        }
        let (x0, p0) = start();
        let grid = KappaGrid::new(vec![0.0, 1.0]).unwrap();
        let mut adaptive = Ukf::new(Model(wrong), Model(wrong), x0, p0, SigmaSet::recommended(N))
            .unwrap()
            .with_adaptive_kappa(KappaCriterion::MaximumLikelihood, grid)
            .unwrap();
        check(
            &mut adaptive,
            wrong,
            Wrong::MeasurementJacobian,
            "adaptive UKF",
        );
    }
}
