//! The batched KF ([`KfBatch`]) lane by lane against the scalar [`Kf`], on every instruction set
//! this CPU has, forced in turn: estimates, NIS and NEES, and per-lane errors that hit only
//! their lane.

use kalibra_filters::batch::{BATCH, BatchModel, BatchStep, Isa, KfBatch, Lanes};
use kalibra_filters::{Filter, FilterError, Kf};
use kalibra_linalg::{Matrix2, Matrix4, SMatrix, U2, U4, Vector2, Vector4};
use kalibra_models::{LinearGaussian, LinearObservation};

fn matrices(r: Matrix2<f64>) -> (Matrix4<f64>, Matrix4<f64>, SMatrix<f64, 2, 4>, Matrix2<f64>) {
    let f = Matrix4::new(
        1., 0., 1., 0., 0., 1., 0., 1., 0., 0., 1., 0., 0., 0., 0., 1.,
    );
    let g = SMatrix::<f64, 4, 2>::new(0.5, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 1.0);
    let h = SMatrix::<f64, 2, 4>::new(1., 0., 0., 0., 0., 1., 0., 0.);
    (f, g * g.transpose(), h, r)
}

fn prior() -> (Vector4<f64>, Matrix4<f64>) {
    (
        Vector4::new(0.0, 0.0, 10.0, -5.0),
        Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0)),
    )
}

/// Lane `lane`'s measurement and truth at step `k`: deterministic, different per lane.
fn data(k: usize, lane: usize) -> (Vector2<f64>, Vector4<f64>) {
    let t = k as f64;
    let l = lane as f64;
    let x = Vector4::new(
        10.0 * t + 3.0 * (0.7 * t + l).sin(),
        -5.0 * t + 2.0 * (1.3 * t - l).cos(),
        10.0 + (0.1 * t * l).sin(),
        -5.0,
    );
    let z = Vector2::new(
        x[0] + 8.0 * (2.1 * t + l).sin(),
        x[1] - 9.0 * (1.7 * t).cos(),
    );
    (z, x)
}

fn lanes_at(k: usize) -> ([Lanes; 2], [Lanes; 4]) {
    let mut z = [[0.0; BATCH]; 2];
    let mut x = [[0.0; BATCH]; 4];
    for lane in 0..BATCH {
        let (zl, xl) = data(k, lane);
        for i in 0..2 {
            z[i][lane] = zl[i];
        }
        for i in 0..4 {
            x[i][lane] = xl[i];
        }
    }
    (z, x)
}

fn rel(a: f64, b: f64, scale: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(scale)
}

#[test]
fn every_lane_agrees_with_the_scalar_kf_on_every_instruction_set() {
    let (f, q, h, r) = matrices(Matrix2::identity() * 100.0);
    let (m0, p0) = prior();
    let (fm, hm) = (
        LinearGaussian::new(f, q).unwrap(),
        LinearObservation::<U4, U2>::new(h, r).unwrap(),
    );
    for isa in Isa::available() {
        let mut batch = KfBatch::new(isa, BatchModel::new(f, q, h, r).unwrap(), m0, p0).unwrap();
        assert_eq!(batch.isa(), isa);
        let mut scalar: Vec<_> = (0..BATCH)
            .map(|_| Kf::new(&fm, &hm, m0, p0).unwrap())
            .collect();
        let mut worst = 0.0f64;
        for k in 0..200 {
            let (z, x) = lanes_at(k);
            let step = if k == 0 {
                batch.update(&z, &x)
            } else {
                batch.predict_update(&z, &x)
            }
            .clone();
            assert!(step.all_ok());
            assert_eq!(step.step(), k);
            for (lane, kf) in scalar.iter_mut().enumerate() {
                if k > 0 {
                    kf.predict().unwrap();
                }
                let (zl, xl) = data(k, lane);
                let rec = kf.update(&zl).unwrap();
                let e = xl - rec.posterior().mean;
                worst = worst
                    .max(rel(step.nis(lane).unwrap(), rec.nis(), 0.0))
                    .max(rel(step.nees(lane).unwrap(), rec.nees(&e).unwrap(), 0.0));
                let (mean, cov) = (batch.mean(lane), batch.cov(lane));
                let p = &rec.posterior().cov;
                for i in 0..4 {
                    worst = worst.max(rel(mean[i], rec.posterior().mean[i], mean.norm()));
                    worst = worst.max(rel(step.error(lane)[i], e[i], e.norm()));
                    for j in 0..4 {
                        worst = worst.max(rel(cov[(i, j)], p[(i, j)], p.norm()));
                    }
                }
            }
        }
        assert!(
            worst <= 1e-12,
            "{isa}: largest relative difference {worst:e}"
        );
    }
}

#[test]
fn a_nan_measurement_fails_only_its_lane() {
    let (f, q, h, r) = matrices(Matrix2::identity() * 100.0);
    let (m0, p0) = prior();
    let (fm, hm) = (
        LinearGaussian::new(f, q).unwrap(),
        LinearObservation::<U4, U2>::new(h, r).unwrap(),
    );
    for isa in Isa::available() {
        let model = BatchModel::new(f, q, h, r).unwrap();
        let mut clean = KfBatch::new(isa, model.clone(), m0, p0).unwrap();
        let mut dirty = KfBatch::new(isa, model, m0, p0).unwrap();
        let mut kf3 = Kf::new(&fm, &hm, m0, p0).unwrap();
        for k in 0..12 {
            let (z, x) = lanes_at(k);
            let mut z_bad = z;
            if k == 5 {
                z_bad[1][3] = f64::NAN;
            }
            let (a, b) = if k == 0 {
                (
                    clean.update(&z, &x).clone(),
                    dirty.update(&z_bad, &x).clone(),
                )
            } else {
                (
                    clean.predict_update(&z, &x).clone(),
                    dirty.predict_update(&z_bad, &x).clone(),
                )
            };
            if k > 0 {
                kf3.predict().unwrap();
            }
            let mut z3 = data(k, 3).0;
            z3[1] = z_bad[1][3];
            let scalar = kf3.update(&z3).map(|rec| rec.nis());
            whole_batch_views_agree(&a);
            whole_batch_views_agree(&b);
            for lane in 0..BATCH {
                if lane == 3 && k == 5 {
                    let expected = FilterError::NonFinite {
                        what: "measurement",
                        step: 5,
                    };
                    assert_eq!(scalar, Err(expected.clone()));
                    assert_eq!(b.nis(lane), Err(expected.clone()), "{isa}");
                    assert_eq!(b.nees(lane), Err(expected), "{isa}");
                    // Left at its prediction, as the scalar filter is.
                    assert_eq!(dirty.mean(3), *kf3.mean(), "{isa}");
                    assert!(!b.ok()[lane]);
                } else if lane == 3 && k > 5 {
                    // Lane 3 went on from its prediction: no longer the clean lane's numbers.
                    assert!(b.nis(lane).is_ok());
                    assert_ne!(b.nis(lane), a.nis(lane));
                } else {
                    // Every other lane: bit for bit the run without the NaN.
                    assert_eq!(b.nis(lane), a.nis(lane), "{isa}, lane {lane}, step {k}");
                    assert_eq!(b.nees(lane), a.nees(lane), "{isa}, lane {lane}, step {k}");
                    assert_eq!(dirty.cov(lane), clean.cov(lane));
                }
            }
        }
    }
}

/// The whole-batch views of a step ([`BatchStep::ok`], [`BatchStep::nis_lanes`],
/// [`BatchStep::nees_lanes`], [`BatchStep::errors`]) say what the per-lane calls say.
fn whole_batch_views_agree<const N: usize>(step: &BatchStep<N>) {
    let ok = step.ok();
    for (lane, ok) in ok.into_iter().enumerate() {
        assert_eq!(ok, step.nees(lane).is_ok(), "lane {lane}");
        if ok {
            assert_eq!(Ok(step.nis_lanes()[lane]), step.nis(lane));
            assert_eq!(Ok(step.nees_lanes()[lane]), step.nees(lane));
        }
        for i in 0..N {
            assert_eq!(
                step.errors()[i][lane].to_bits(),
                step.error(lane)[i].to_bits()
            );
        }
    }
    assert_eq!(ok.iter().all(|o| *o), step.all_ok());
}

#[test]
fn a_singular_s_fails_only_its_lane() {
    // R = 0 and lane 5 certain of its state (P0 = 0): its S is 0, not positive definite; the
    // other lanes' S is H P0 H^T, positive definite.
    let (f, q, h, r) = matrices(Matrix2::zeros());
    let (m0, p0) = prior();
    let fm = LinearGaussian::new(f, q).unwrap();
    let hm = LinearObservation::<U4, U2>::new(h, r).unwrap();
    let mut scalar = Kf::new(&fm, &hm, m0, Matrix4::zeros()).unwrap();
    let (z, x) = lanes_at(0);
    let expected = scalar
        .update(&data(0, 5).0)
        .map(|rec| rec.nis())
        .unwrap_err();
    assert!(matches!(
        expected,
        FilterError::NotPositiveDefinite {
            what: "innovation covariance S",
            step: 0
        }
    ));
    for isa in Isa::available() {
        let mut batch = KfBatch::new(isa, BatchModel::new(f, q, h, r).unwrap(), m0, p0).unwrap();
        batch.set_lane(5, m0, Matrix4::zeros()).unwrap();
        let step = batch.update(&z, &x);
        whole_batch_views_agree(step);
        // (R = 0 leaves every P+ singular: no lane has a NEES.)
        assert_eq!(step.ok(), [false; BATCH]);
        for lane in 0..BATCH {
            if lane == 5 {
                assert_eq!(step.nis(lane), Err(expected.clone()), "{isa}");
            } else {
                assert!(step.nis(lane).is_ok(), "{isa}, lane {lane}");
            }
        }
        assert_eq!(batch.cov(5), Matrix4::zeros());
        assert_eq!(batch.mean(5), m0);
    }
}

#[test]
fn bad_initial_estimates_and_models_are_errors() {
    let (f, q, h, r) = matrices(Matrix2::identity());
    let (m0, p0) = prior();
    let model = BatchModel::new(f, q, h, r).unwrap();
    let mut nan = m0;
    nan[2] = f64::NAN;
    assert!(matches!(
        KfBatch::new(Isa::Scalar, model.clone(), nan, p0),
        Err(FilterError::Initial(_))
    ));
    assert!(matches!(
        KfBatch::new(Isa::Scalar, model.clone(), m0, -p0),
        Err(FilterError::Initial(_))
    ));
    let mut batch = KfBatch::new(Isa::Scalar, model, m0, p0).unwrap();
    assert!(batch.set_lane(2, m0, -p0).is_err());
    assert_eq!(batch.cov(2), p0);
    assert!(matches!(
        BatchModel::new(f, -q, h, r),
        Err(FilterError::Initial(_))
    ));
}

#[test]
fn a_batch_on_an_instruction_set_the_cpu_lacks_is_refused_with_the_filters_error() {
    let (f, q, h, r, m0, p0) = (
        Matrix2::identity(),
        Matrix2::identity(),
        SMatrix::<f64, 1, 2>::new(1.0, 0.0),
        SMatrix::<f64, 1, 1>::new(1.0),
        Vector2::zeros(),
        Matrix2::identity(),
    );
    for isa in Isa::ALL {
        let model = BatchModel::new(f, q, h, r).unwrap();
        let batch = KfBatch::new(isa, model, m0, p0);
        if isa.is_available() {
            assert!(batch.is_ok());
        } else {
            assert!(matches!(batch, Err(FilterError::Unsupported { .. })));
        }
    }
}
