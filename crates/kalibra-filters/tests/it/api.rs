//! The public API's conveniences for outside users: filters as trait objects, whole-sequence
//! runs that report every step, the step record's derived quantities, and the opt-in to an
//! unchecked initial covariance.

use approx::assert_relative_eq;
use kalibra_filters::{ConstantGainKf, Ekf, Filter, Kf, SigmaSet, Srf, Start, Ukf};
use kalibra_linalg::{Matrix4, U1, U2, U4, Vector1, Vector2, Vector4};
use kalibra_models::{Bearing, BearingReference, Kinematic, Stationary};

use crate::common::{p0, truth, w1};

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
        let s = rec.s_matrix();
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

mod as_given {
    use super::*;
    use kalibra_filters::{FilterError, FilterOptions, InitialCheck, StepRecord, UpdateForm};
    use kalibra_linalg::{Matrix2, SMatrix};
    use kalibra_models::{Dynamics, LinearGaussian, LinearObservation};

    /// Paper 000's printed initial covariance, entry by entry: asymmetric ((2,4) is -1.73e6,
    /// (4,2) is -0.73e6) and indefinite.
    fn p0_printed() -> Matrix4<f64> {
        Matrix4::new(
            2.48e6, 0.0, -6.76e6, 0.0, //
            0.0, 1.24e6, 0.0, -1.73e6, //
            -6.76e6, 0.0, 1.47e7, 0.0, //
            0.0, -0.73e6, 0.0, 7.34e6,
        )
    }

    fn x0_printed() -> Vector4<f64> {
        Vector4::new(2.25e5, -2.81e3, 9.26e4, 6.75e3)
    }

    fn h() -> SMatrix<f64, 2, 4> {
        SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    }

    fn r_printed() -> Matrix2<f64> {
        Matrix2::new(10.54, -3.85, -3.85, 37.15)
    }

    /// Paper 000's drag-free model: the ballistic state `[x, vx, y, vy]` with `T = 2`, and
    /// `Q = 10^p Q_nom`.
    fn models(p: f64) -> (LinearGaussian<U4>, LinearObservation<U4, U2>) {
        let t = 2.0;
        let f = Matrix4::new(
            1.0, t, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, t, 0.0, 0.0, 0.0, 1.0,
        );
        let q_nom = Matrix4::new(
            2.48e5, 6.32e4, -5.10e5, -1.04e5, //
            6.32e4, 2.34e4, -1.04e5, -2.88e4, //
            -5.10e5, -1.04e5, 1.44e6, 3.45e5, //
            -1.04e5, -2.88e4, 3.45e5, 1.20e5,
        );
        (
            LinearGaussian::new(f, q_nom * 10f64.powf(p)).unwrap(),
            LinearObservation::new(h(), r_printed()).unwrap(),
        )
    }

    fn measurements(f: &LinearGaussian<U4>, n: usize) -> Vec<Vector2<f64>> {
        let mut x = Vector4::new(2.32e5, -2255.0, 8.8e4, -397.0);
        (0..n)
            .map(|k| {
                x = f.transition(k, &x);
                h() * x + Vector2::new(3.0 * (k as f64).sin(), -2.0 * (k as f64).cos())
            })
            .collect()
    }

    /// Paper 000's replay (`kalibra_papers::saha2012::replay`), copied: the KF in the paper's
    /// arithmetic, nothing symmetrised, the gain by LU. Returns per update the posterior, `S`,
    /// `K`, and J1, J2, `tr(N)` by LU as the replay computes them.
    #[allow(clippy::type_complexity)]
    fn replay(
        dynamics: &LinearGaussian<U4>,
        r: &Matrix2<f64>,
        zs: &[Vector2<f64>],
    ) -> Vec<(
        Vector4<f64>,
        Matrix4<f64>,
        Matrix2<f64>,
        SMatrix<f64, 4, 2>,
        [f64; 3],
    )> {
        let h = h();
        let (mut x, mut p) = (x0_printed(), p0_printed());
        let mut out = Vec::new();
        for (i, z) in zs.iter().enumerate() {
            let k = 2 + i + 1;
            let f = dynamics.jacobian(k - 1, &x);
            let q = dynamics.noise_cov(k - 1);
            x = dynamics.transition(k - 1, &x);
            let propagated = f * p * f.transpose();
            let prior = propagated + q;
            let a = h * propagated * h.transpose();
            let b = h * q * h.transpose();
            let s = h * prior * h.transpose() + r;
            let gain = s
                .transpose()
                .lu()
                .solve(&(h * prior.transpose()))
                .unwrap()
                .transpose();
            x += gain * (z - h * x);
            let ikh = Matrix4::identity() - gain * h;
            p = ikh * prior * ikh.transpose() + gain * r * gain.transpose();
            let c = h * p * h.transpose();
            let ab = a + b;
            let j1 = s.lu().solve(r).unwrap().trace();
            let j2 = ab.lu().solve(&b).unwrap().trace();
            let tr_n = ab.lu().solve(&(a - c)).unwrap().trace();
            out.push((x, p, s, gain, [j1, j2, tr_n]));
        }
        out
    }

    /// J1, J2 and `tr(N)` from a record, in the replay's arithmetic.
    fn j_of(rec: &StepRecord<U4, U2>) -> [f64; 3] {
        let (a, b, c) = (rec.compute_a(), rec.compute_b(), rec.compute_c());
        let ab = a + b;
        [
            rec.s_matrix().lu().solve(rec.r()).unwrap().trace(),
            ab.lu().solve(&b).unwrap().trace(),
            ab.lu().solve(&(a - c)).unwrap().trace(),
        ]
    }

    fn as_given() -> FilterOptions {
        FilterOptions {
            first_step: 2,
            initial_check: InitialCheck::AsGiven,
            ..FilterOptions::default()
        }
    }

    /// The options a caller passes to the opt-in constructors (whose check is implied).
    fn first_step_2() -> FilterOptions {
        FilterOptions {
            first_step: 2,
            ..FilterOptions::default()
        }
    }

    /// The opt-in KF and EKF reproduce the replay's numbers bit for bit on the printed `P0`,
    /// through steps where `S` is indefinite.
    #[test]
    fn the_as_given_kf_and_ekf_equal_a_hand_written_lu_replay_to_the_bit() {
        let mut indefinite = 0;
        for p in [-8.0, -2.0, 0.0, 1.0] {
            let (f, meas) = models(p);
            let zs = measurements(&f, 57);
            let replayed = replay(&f, &r_printed(), &zs);
            let kf = Kf::as_given(&f, &meas, x0_printed(), p0_printed(), first_step_2())
                .unwrap()
                .run_collect(zs.iter().map(Some), Start::PredictFirst)
                .unwrap();
            let ekf = Ekf::as_given(&f, &meas, x0_printed(), p0_printed(), first_step_2())
                .unwrap()
                .run_collect(zs.iter().map(Some), Start::PredictFirst)
                .unwrap();
            for records in [&kf, &ekf] {
                assert_eq!(records.len(), replayed.len());
                for (rec, (x, cov, s, gain, j)) in records.iter().zip(&replayed) {
                    assert_eq!(rec.initial_check(), InitialCheck::AsGiven);
                    assert!(rec.s().is_none());
                    assert_eq!(&rec.posterior().mean, x, "p {p} step {}", rec.step());
                    assert_eq!(&rec.posterior().cov, cov);
                    assert_eq!(rec.s_matrix(), s);
                    assert_eq!(rec.gain(), gain);
                    assert_eq!(j_of(rec), *j);
                    let sym = (s + s.transpose()) * 0.5;
                    indefinite += usize::from(sym.cholesky().is_none());
                }
            }
        }
        // The comparison covers steps the checked filters refuse.
        assert!(indefinite > 0);
    }

    /// An asymmetric `P0` is rejected by default and by the symmetric-only check, and runs
    /// with the opt-in; its records say what was not checked and give LU-based NIS, NEES and
    /// log-likelihood.
    #[test]
    fn an_asymmetric_p0_needs_the_opt_in_and_its_records_say_unchecked() {
        let (f, meas) = models(0.0);
        let zs = measurements(&f, 10);
        for check in [
            InitialCheck::PositiveSemiDefinite,
            InitialCheck::SymmetricOnly,
        ] {
            let options = FilterOptions {
                initial_check: check,
                ..FilterOptions::default()
            };
            for result in [
                Kf::with_options(&f, &meas, x0_printed(), p0_printed(), options).err(),
                Ekf::with_options(&f, &meas, x0_printed(), p0_printed(), options).err(),
            ] {
                assert!(
                    matches!(result, Some(FilterError::Initial(_))),
                    "{result:?}"
                );
            }
        }
        assert!(Kf::new(&f, &meas, x0_printed(), p0_printed()).is_err());
        // The opt-in still checks sizes and finiteness.
        let mut nan = p0_printed();
        nan[(1, 3)] = f64::NAN;
        assert!(matches!(
            Kf::as_given(&f, &meas, x0_printed(), nan, first_step_2()),
            Err(FilterError::Initial(_))
        ));
        // The variant in the options of a checked constructor is refused, not ignored.
        assert!(matches!(
            Kf::with_options(&f, &meas, x0_printed(), p0_printed(), as_given()),
            Err(FilterError::Unsupported { .. })
        ));

        let mut kf = Kf::as_given(&f, &meas, x0_printed(), p0_printed(), first_step_2()).unwrap();
        let trajectory = kf
            .run_all(zs.iter().map(Some), Start::PredictFirst)
            .unwrap();
        assert_eq!(trajectory.initial().covariance(), &p0_printed());
        for rec in trajectory.records() {
            assert_eq!(rec.initial_check(), InitialCheck::AsGiven);
            assert!(rec.s().is_none());
            let (s, nu) = (rec.s_matrix(), rec.innovation());
            let nis = (nu.transpose() * s.try_inverse().unwrap() * nu)[0];
            assert_relative_eq!(rec.nis(), nis, max_relative = 1e-9);
            let e = Vector4::new(1.0, -2.0, 3.0, 0.5);
            let p = &rec.posterior().cov;
            let nees = (e.transpose() * p.try_inverse().unwrap() * e)[0];
            assert_relative_eq!(rec.nees(&e).unwrap(), nees, max_relative = 1e-6);
            let det = s.determinant();
            let ll = rec.log_likelihood();
            if det > 0.0 {
                let m = 2.0 * std::f64::consts::TAU.ln();
                assert_relative_eq!(ll, -0.5 * (m + det.ln() + nis), max_relative = 1e-9);
            } else {
                assert!(ll.is_nan());
            }
        }
        // The posterior stays asymmetric: nothing was symmetrised.
        assert_ne!(kf.covariance(), &kf.covariance().transpose());

        // A checked filter's records say so.
        let mut checked = Kf::new(&f, &meas, x0_printed(), Matrix4::identity() * 1e6).unwrap();
        let rec = checked.update(&zs[0]).unwrap();
        assert_eq!(rec.initial_check(), InitialCheck::PositiveSemiDefinite);
        assert_eq!(rec.s().unwrap().matrix(), rec.s_matrix());
    }

    /// The standard update form runs as given too; the constant-gain KF, the UKF and the SRF
    /// refuse the opt-in with a typed error.
    #[test]
    fn other_forms_and_filters_with_the_opt_in() {
        let (f, meas) = models(0.0);
        let zs = measurements(&f, 5);
        let standard = FilterOptions {
            update: UpdateForm::Standard,
            ..first_step_2()
        };
        let mut kf = Kf::as_given(&f, &meas, x0_printed(), p0_printed(), standard).unwrap();
        kf.run(zs.iter().map(Some), Start::PredictFirst, |rec| {
            assert_eq!(rec.initial_check(), InitialCheck::AsGiven)
        })
        .unwrap();
        let gain = SMatrix::<f64, 4, 2>::new(0.5, 0.0, 0.1, 0.0, 0.0, 0.5, 0.0, 0.1);
        assert!(matches!(
            ConstantGainKf::with_options(&f, &meas, x0_printed(), p0_printed(), gain, as_given()),
            Err(FilterError::Unsupported { .. })
        ));
        assert!(matches!(
            Ukf::with_options(
                &f,
                &meas,
                x0_printed(),
                p0_printed(),
                SigmaSet::recommended(4),
                as_given()
            ),
            Err(FilterError::Unsupported { .. })
        ));
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
        assert!(matches!(
            Srf::with_options(&cv, &sensor, x0_printed(), p0_printed(), as_given()),
            Err(FilterError::Unsupported { .. })
        ));
        // A singular S is a typed error that leaves the filter as it was.
        let zero = LinearObservation::new(SMatrix::<f64, 2, 4>::zeros(), Matrix2::zeros()).unwrap();
        let mut singular =
            Kf::as_given(&f, &zero, x0_printed(), p0_printed(), first_step_2()).unwrap();
        assert!(matches!(
            singular.update(&zs[0]),
            Err(FilterError::Singular { step: 2, .. })
        ));
        assert_eq!(singular.mean(), &x0_printed());
    }
}
