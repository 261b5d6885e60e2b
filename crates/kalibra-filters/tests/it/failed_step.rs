//! A failing step leaves the filter exactly as it was: mean, covariance, step index and last
//! record, for every filter (KF, EKF, UKF with symmetric and scaled sets and adaptive kappa,
//! SRF, constant-gain KF). Property test: random sequences of predictions and updates with
//! measurements from ordinary to hostile (NaN, infinities, 1e308, subnormals); after every
//! operation that returns an error, the filter's state equals its state before.

use kalibra_filters::{
    ConstantGainKf, Ekf, Filter, KappaCriterion, KappaGrid, Kf, SigmaSet, Srf, Ukf,
};
use kalibra_linalg::{Dim, Matrix4, OVector, U1, U2, U4, Vector2, Vector4};
use kalibra_models::{Bearing, BearingReference, Kinematic, Stationary};
use proptest::prelude::*;

// Shared fixtures; this test needs the model and P0, not the simulated truth.
#[allow(dead_code)]
use crate::common::{p0, w1};

/// One operation on a filter: predict, or update with these measurement values.
#[derive(Clone, Debug)]
enum Op {
    Predict,
    Update(Vec<f64>),
}

/// Values from ordinary to hostile.
fn value() -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => -200.0..200.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(1e308),
        1 => Just(-1e308),
        1 => Just(1e-310),
        1 => Just(std::f64::consts::PI),
        1 => Just(-std::f64::consts::PI),
    ]
}

fn ops(m: usize) -> impl Strategy<Value = Vec<Op>> {
    prop::collection::vec(
        prop_oneof![
            1 => Just(Op::Predict),
            2 => prop::collection::vec(value(), m).prop_map(Op::Update),
        ],
        1..25,
    )
}

/// Everything a caller can see of a filter, to the bit (Debug prints every number exactly).
fn snapshot<M: Dim>(f: &dyn Filter<U4, M>) -> String
where
    kalibra_linalg::DefaultAllocator: kalibra_linalg::Alloc<U4, M>,
{
    format!(
        "{:?} {:?} {} {:?}",
        f.mean(),
        f.covariance(),
        f.step_index(),
        f.last_record()
    )
}

/// Applies `ops`, checking after each error that nothing changed; returns the errors seen.
fn check<M: Dim>(filter: &mut dyn Filter<U4, M>, ops: &[Op], m: M) -> usize
where
    kalibra_linalg::DefaultAllocator: kalibra_linalg::Alloc<U4, M>,
{
    let mut errors = 0;
    for op in ops {
        let before = snapshot(filter);
        let failed = match op {
            Op::Predict => filter.predict().is_err(),
            Op::Update(z) => {
                let z = OVector::<f64, M>::from_iterator_generic(m, U1, z.iter().copied());
                filter.update(&z).is_err()
            }
        };
        if failed {
            errors += 1;
            assert_eq!(snapshot(filter), before, "state changed by a failed {op:?}");
        }
    }
    errors
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The position-measuring filters on W1's model.
    #[test]
    fn a_failed_step_leaves_a_linear_model_filter_as_it_was(ops in ops(2)) {
        let (f, h) = w1();
        let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
        let gain = ConstantGainKf::steady_state_gain(&f, &h, 0, &x0).unwrap();
        let grid = KappaGrid::new(vec![-1.0, 0.0, 1.0, 2.0]).unwrap();
        let mut bank: Vec<Box<dyn Filter<U4, U2> + '_>> = vec![
            Box::new(Kf::new(&f, &h, x0, p0()).unwrap()),
            Box::new(Ekf::new(&f, &h, x0, p0()).unwrap()),
            Box::new(Ukf::new(&f, &h, x0, p0(), SigmaSet::recommended(4)).unwrap()),
            Box::new(
                Ukf::new(&f, &h, x0, p0(), SigmaSet::Scaled { alpha: 0.5, beta: 2.0, kappa: 0.0 })
                    .unwrap(),
            ),
            Box::new(
                Ukf::new(&f, &h, x0, p0(), SigmaSet::recommended(4))
                    .unwrap()
                    .with_adaptive_kappa(KappaCriterion::MaximumLikelihood, grid.clone())
                    .unwrap(),
            ),
            Box::new(
                Ukf::new(&f, &h, x0, p0(), SigmaSet::recommended(4))
                    .unwrap()
                    .with_adaptive_kappa(KappaCriterion::MaximumPosterior, grid)
                    .unwrap(),
            ),
            Box::new(ConstantGainKf::new(&f, &h, x0, p0(), gain).unwrap()),
        ];
        for filter in bank.iter_mut() {
            check(filter.as_mut(), &ops, U2);
        }
    }

    /// The bearings-only filters (EKF, UKF, SRF), bearings at and across +-pi included.
    #[test]
    fn a_failed_step_leaves_a_bearings_filter_as_it_was(ops in ops(1)) {
        let cv = Kinematic::constant_velocity(2, 1.0).unwrap().dynamics(U4).unwrap();
        let sensor = Bearing::new(
            U4,
            [0, 1],
            BearingReference::XAxis,
            1e-4,
            Stationary(Vector2::zeros()),
        )
        .unwrap();
        let x0 = Vector4::new(-100.0, 1.0, 1.0, 0.5);
        let p = Matrix4::identity() * 10.0;
        let mut bank: Vec<Box<dyn Filter<U4, U1> + '_>> = vec![
            Box::new(Ekf::new(&cv, &sensor, x0, p).unwrap()),
            Box::new(Ukf::new(&cv, &sensor, x0, p, SigmaSet::recommended(4)).unwrap()),
            Box::new(Srf::new(&cv, &sensor, x0, p).unwrap()),
        ];
        for filter in bank.iter_mut() {
            check(filter.as_mut(), &ops, U1);
        }
    }
}

/// The property above is not vacuous: an update whose posterior overflows fails after the
/// prior was formed (the case that used to lose the last record), and the record survives.
#[test]
fn an_update_that_overflows_keeps_the_last_record() {
    let (f, h) = w1();
    let mut kf = Kf::new(&f, &h, Vector4::zeros(), p0()).unwrap();
    // The estimate moves near -1e308; a measurement near +1.8e308 then gives an innovation
    // beyond f64's range, found only once the posterior is computed.
    kf.update(&Vector2::new(-1e308, -1e308)).unwrap();
    let before = snapshot(&kf);
    assert!(kf.update(&Vector2::new(1.79e308, 1.79e308)).is_err());
    assert!(kf.last_record().is_some());
    assert_eq!(snapshot(&kf), before);
}
