//! The public API's conveniences for outside users: filters as trait objects, whole-sequence
//! runs that report every step, the step record's derived quantities, and the opt-in to an
//! unchecked initial covariance.

use approx::assert_relative_eq;
use kalibra_filters::{ConstantGainKf, Ekf, Filter, Kf, SigmaSet, Srf, Start, Ukf};
use kalibra_linalg::{Matrix4, U1, U2, U4, Vector1, Vector2, Vector4};
use kalibra_models::{Bearing, BearingReference, Kinematic, Stationary};

mod common;
use common::{p0, truth, w1};

/// A bank of different filters in one `Vec` of trait objects, stepped together.
#[test]
fn a_bank_of_different_filters_is_one_vec_of_trait_objects() {
    let (f, h) = w1();
    let t = truth(3, 40);
    let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let gain = ConstantGainKf::steady_state_gain(&f, &h, 0, &x0).unwrap();
    let mut bank: Vec<Box<dyn Filter<U4, U2> + '_>> = vec![
        Box::new(Kf::new(&f, &h, x0, p0()).unwrap()),
        Box::new(Ekf::new(&f, &h, x0, p0()).unwrap()),
        Box::new(Ukf::new(&f, &h, x0, p0(), SigmaSet::recommended(4)).unwrap()),
        Box::new(ConstantGainKf::new(&f, &h, x0, p0(), gain).unwrap()),
    ];
    for (k, z) in t.measurements.iter().enumerate() {
        for filter in bank.iter_mut() {
            if k > 0 {
                filter.predict().unwrap();
            }
            let rec = filter.update(z).unwrap();
            assert_eq!(rec.step(), k);
        }
    }
    // The KF, EKF and UKF agree on a linear-Gaussian model; the constant gain differs.
    for other in &bank[1..3] {
        assert_relative_eq!(bank[0].mean(), other.mean(), max_relative = 1e-9);
        assert_relative_eq!(
            bank[0].covariance(),
            other.covariance(),
            max_relative = 1e-9
        );
    }
    assert!(
        bank.iter()
            .all(|f| f.step_index() == 39 && f.last_record().is_some())
    );

    // The provided sequence methods run on a boxed filter as well.
    let mut boxed: Box<dyn Filter<U4, U2> + '_> = Box::new(Kf::new(&f, &h, x0, p0()).unwrap());
    let records = boxed
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    assert_eq!(records.len(), 40);
    assert_eq!(boxed.mean(), bank[0].mean());
}

/// Bearings-only filters, the shifted Rayleigh filter among them, share one bank too.
#[test]
fn a_bearings_bank_holds_the_srf() {
    let cv = Kinematic::constant_velocity(2, 1.0)
        .unwrap()
        .dynamics(U4)
        .unwrap();
    let sensor = Bearing::new(
        U4,
        [0, 1],
        BearingReference::XAxis,
        1e-4,
        Stationary(Vector2::zeros()),
    )
    .unwrap();
    let x0 = Vector4::new(100.0, 10.0, -1.0, 0.5);
    let p = Matrix4::identity() * 10.0;
    let mut bank: Vec<Box<dyn Filter<U4, U1> + '_>> = vec![
        Box::new(Ekf::new(&cv, &sensor, x0, p).unwrap()),
        Box::new(Ukf::new(&cv, &sensor, x0, p, SigmaSet::recommended(4)).unwrap()),
        Box::new(Srf::new(&cv, &sensor, x0, p).unwrap()),
    ];
    let zs: Vec<Vector1<f64>> = (1..=10)
        .map(|k| {
            let (x, y) = (100.0 - k as f64, 10.0 + 0.5 * k as f64);
            Vector1::new(y.atan2(x))
        })
        .collect();
    for filter in bank.iter_mut() {
        let mut updates = 0;
        filter
            .run(zs.iter().map(Some), Start::PredictFirst, |_| updates += 1)
            .unwrap();
        assert_eq!((updates, filter.step_index()), (10, 10));
        let bearing = filter.mean()[1].atan2(filter.mean()[0]);
        assert!((bearing - zs[9][0]).abs() < 0.01, "{bearing}");
    }
}

/// The record's log-likelihood, from the stored factor of `S`, equals the Gaussian density
/// computed directly with a determinant and an inverse; summed, it equals the joint density
/// of two independent updates' innovations.
#[test]
fn log_likelihood_matches_a_direct_computation() {
    let (f, h) = w1();
    let t = truth(5, 30);
    let mut kf = Kf::new(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), p0()).unwrap();
    let records = kf
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    for rec in &records {
        let s = rec.s().matrix();
        let nu = rec.innovation();
        let quad = (nu.transpose() * s.try_inverse().unwrap() * nu)[0];
        let direct = -0.5 * (2.0 * (2.0 * std::f64::consts::PI).ln() + s.determinant().ln() + quad);
        assert_relative_eq!(rec.log_likelihood(), direct, max_relative = 1e-12);
        // Consistent with the NIS it is built from.
        assert_relative_eq!(
            rec.log_likelihood(),
            -0.5 * (2.0 * (2.0 * std::f64::consts::PI).ln() + s.determinant().ln() + rec.nis()),
            max_relative = 1e-13
        );
    }
    // A larger innovation is less likely under the same S.
    let mut a = Kf::new(&f, &h, Vector4::zeros(), p0()).unwrap();
    let mut b = a.clone();
    let near = a.update(&Vector2::new(1.0, 0.0)).unwrap().log_likelihood();
    let far = b.update(&Vector2::new(30.0, 0.0)).unwrap().log_likelihood();
    assert!(near > far && far.is_finite());
}

/// `run_all` reports the initial estimate and every step, with or without a measurement, and
/// agrees with stepping by hand and with `run_collect`'s records.
#[test]
fn run_all_reports_every_step_including_gaps() {
    let (f, h) = w1();
    let t = truth(7, 12);
    let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    // Gaps at steps 2, 3 and the last one.
    let zs: Vec<Option<&Vector2<f64>>> = t
        .measurements
        .iter()
        .enumerate()
        .map(|(i, z)| (![2, 3, 11].contains(&i)).then_some(z))
        .collect();
    for start in [Start::PredictFirst, Start::UpdateFirst] {
        let trajectory = Kf::new(&f, &h, x0, p0())
            .unwrap()
            .run_all(zs.iter().copied(), start)
            .unwrap();
        let entries = trajectory.entries();
        assert_eq!(entries.len(), 1 + zs.len());
        let initial = trajectory.initial();
        assert_eq!((initial.step(), initial.updated()), (0, false));
        assert_eq!((initial.mean(), initial.covariance()), (&x0, &p0()));

        // By hand.
        let mut kf = Kf::new(&f, &h, x0, p0()).unwrap();
        for (i, (z, entry)) in zs.iter().zip(&entries[1..]).enumerate() {
            if i > 0 || start == Start::PredictFirst {
                kf.predict().unwrap();
            }
            let expected_step = i + usize::from(start == Start::PredictFirst);
            assert_eq!(entry.step(), expected_step);
            assert_eq!(entry.updated(), z.is_some());
            match z {
                Some(z) => {
                    let rec = kf.update(z).unwrap();
                    assert_eq!(entry.record().unwrap().posterior(), rec.posterior());
                    assert_eq!(entry.estimate(), rec.posterior());
                }
                None => assert!(entry.record().is_none()),
            }
            assert_eq!(entry.mean(), kf.mean());
            assert_eq!(entry.covariance(), kf.covariance());
        }
        assert_eq!(trajectory.last().mean(), kf.mean());
        assert!(!trajectory.last().updated());
        // A gap's covariance grows from the step before (prediction only).
        assert!(entries[4].covariance()[(0, 0)] > entries[3].covariance()[(0, 0)]);

        let collected = Kf::new(&f, &h, x0, p0())
            .unwrap()
            .run_collect(zs.iter().copied(), start)
            .unwrap();
        assert_eq!(trajectory.records().count(), collected.len());
        for (a, b) in trajectory.records().zip(&collected) {
            assert_eq!((a.step(), a.posterior()), (b.step(), b.posterior()));
        }
    }
    // An empty sequence gives the initial estimate alone.
    let empty = Kf::new(&f, &h, x0, p0())
        .unwrap()
        .run_all(std::iter::empty(), Start::PredictFirst)
        .unwrap();
    assert_eq!(empty.entries().len(), 1);
    assert_eq!(empty.last().mean(), &x0);
}
