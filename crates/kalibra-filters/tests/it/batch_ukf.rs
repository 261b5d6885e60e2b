//! The batched UKF ([`UkfBatch`]) lane by lane against the scalar [`Ukf`], on every
//! instruction set this CPU has, forced in turn: a constant-velocity target seen by a bearing
//! sensor whose bearings cross the +-pi cut, with the symmetric and the scaled sigma sets, the
//! linearised prediction, the models lane-wise and per lane ([`PerLane`]), each adaptive
//! kappa criterion, and per-lane errors.

use std::collections::BTreeSet;
use std::f64::consts::PI;

use kalibra_filters::batch::{
    BATCH, Isa, LaneDynamics, LaneSigmaMeasurement, Lanes, PerLane, UkfBatch,
};
use kalibra_filters::{
    Filter, FilterError, KappaCriterion, KappaGrid, SigmaSet, Ukf, UkfPrediction,
};
use kalibra_linalg::{Matrix4, U4, Vector1, Vector2, Vector4};
use kalibra_models::{Bearing, BearingReference, LinearGaussian, Measurement, Tabulated};

use crate::lane_data;

type Sensor = Bearing<U4, Tabulated<2>>;

/// State `[x, vx, y, vy]`, unit time step.
fn dynamics() -> LinearGaussian<U4> {
    let f = Matrix4::new(
        1.0, 1.0, 0.0, 0.0, //
        0.0, 1.0, 0.0, 0.0, //
        0.0, 0.0, 1.0, 1.0, //
        0.0, 0.0, 0.0, 1.0,
    );
    let q = Matrix4::new(
        0.02, 0.01, 0.0, 0.0, //
        0.01, 0.02, 0.0, 0.0, //
        0.0, 0.0, 0.02, 0.01, //
        0.0, 0.0, 0.01, 0.02,
    );
    LinearGaussian::new(f, q).unwrap()
}

/// A bearing from a platform circling the origin (which makes the range observable, so that
/// rounding differences die out instead of growing along an unobservable direction); with
/// `translational`, the platform's position noise linearised
/// into `R` (paper 001's problem I), which makes `R` depend on the state.
fn sensor(translational: bool) -> Sensor {
    let s = Bearing::new(
        U4,
        [0, 2],
        BearingReference::XAxis,
        1e-3,
        Tabulated::new(
            (0..200)
                .map(|k| {
                    let a = 0.4 * k as f64;
                    Vector2::new(6.0 * a.cos(), 6.0 * a.sin())
                })
                .collect(),
        )
        .unwrap(),
    )
    .unwrap();
    if translational {
        s.with_translational_noise(0.3, 0.2).unwrap()
    } else {
        s
    }
}

/// Lane `lane`'s true state at step `k`: the odd lanes move along the negative x axis,
/// crossing y = 0, so their bearings jump across +-pi.
fn truth(k: usize, lane: usize) -> Vector4<f64> {
    let t = k as f64;
    let l = lane as f64;
    if lane % 2 == 1 {
        Vector4::new(-25.0 - l + 0.2 * t, 0.2, -3.0 + 0.15 * t, 0.15)
    } else {
        Vector4::new(10.0 + l + 0.3 * t, 0.3, 5.0 + l - 0.1 * t, -0.1)
    }
}

/// Lane `lane`'s bearing at step `k`: the truth's, perturbed deterministically, wrapped.
fn measurement(k: usize, lane: usize) -> Vector1<f64> {
    let mut z = sensor(false).measure(k, &truth(k, lane));
    z[0] += 0.03 * (1.3 * k as f64 + lane as f64).sin();
    if z[0] > PI {
        z[0] -= 2.0 * PI;
    } else if z[0] <= -PI {
        z[0] += 2.0 * PI;
    }
    z
}

fn lanes_at(k: usize) -> ([Lanes; 1], [Lanes; 4]) {
    let mut z = [[0.0; BATCH]; 1];
    let mut x = [[0.0; BATCH]; 4];
    for lane in 0..BATCH {
        z[0][lane] = measurement(k, lane)[0];
        let xl = truth(k, lane);
        for i in 0..4 {
            x[i][lane] = xl[i];
        }
    }
    (z, x)
}

fn prior(lane: usize) -> (Vector4<f64>, Matrix4<f64>) {
    let t = truth(0, lane);
    let offset = Vector4::new(1.0, -0.1, -0.5, 0.05) * (1.0 + 0.1 * lane as f64);
    (
        t + offset,
        Matrix4::from_diagonal(&Vector4::new(4.0, 0.25, 4.0, 0.25)),
    )
}

fn rel(a: f64, b: f64, scale: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(scale)
}

/// A batch on the given models, every lane from its own prior.
fn batch<D: LaneDynamics<4>, H: LaneSigmaMeasurement<4, 1>>(
    isa: Isa,
    dynamics: D,
    measurement: H,
    set: SigmaSet,
    criterion: Option<KappaCriterion>,
) -> UkfBatch<4, 1, D, H> {
    let (m0, p0) = prior(0);
    let mut b = UkfBatch::new(
        isa,
        dynamics,
        measurement,
        m0,
        p0,
        set,
        UkfPrediction::Linearised,
    )
    .unwrap();
    if let Some(c) = criterion {
        b = b.with_adaptive_kappa(c, &grid()).unwrap();
    }
    for lane in 0..BATCH {
        let (m, p) = prior(lane);
        b.set_lane(lane, m, p).unwrap();
    }
    b
}

/// Paper 001's grid for n = 4: ten values on [0, 76].
fn grid() -> KappaGrid {
    KappaGrid::equidistant(0.0, 76.0, 10).unwrap()
}

fn scalar(
    lane: usize,
    set: SigmaSet,
    criterion: Option<KappaCriterion>,
    translational: bool,
) -> Ukf<U4, kalibra_linalg::U1, LinearGaussian<U4>, Sensor> {
    let (m, p) = prior(lane);
    let u = Ukf::new(dynamics(), sensor(translational), m, p, set)
        .unwrap()
        .with_prediction(UkfPrediction::Linearised);
    match criterion {
        Some(c) => u.with_adaptive_kappa(c, grid()).unwrap(),
        None => u,
    }
}

/// What a comparison saw.
struct Seen {
    /// Over means, covariances, NIS and NEES.
    worst: f64,
    /// Over gains.
    worst_gain: f64,
    wrapped: usize,
    kappas: BTreeSet<u64>,
}

/// Runs the batch and the scalar filters of every lane for `steps` steps (step 0 an update
/// alone) and compares each lane's mean, covariance, gain, NIS, NEES and kappa.
fn compare<D: LaneDynamics<4>, H: LaneSigmaMeasurement<4, 1>>(
    mut b: UkfBatch<4, 1, D, H>,
    set: SigmaSet,
    criterion: Option<KappaCriterion>,
    translational: bool,
    steps: usize,
) -> Seen {
    let isa = b.isa();
    let mut filters: Vec<_> = (0..BATCH)
        .map(|lane| scalar(lane, set, criterion, translational))
        .collect();
    let mut seen = Seen {
        worst: 0.0,
        worst_gain: 0.0,
        wrapped: 0,
        kappas: BTreeSet::new(),
    };
    for k in 0..steps {
        let (z, x) = lanes_at(k);
        let step = if k == 0 {
            b.update(&z, &x)
        } else {
            b.predict_update(&z, &x)
        }
        .clone();
        assert!(step.all_ok(), "{isa}, step {k}");
        assert_eq!(step.step(), k);
        for (lane, ukf) in filters.iter_mut().enumerate() {
            if k > 0 {
                ukf.predict().unwrap();
            }
            let zl = measurement(k, lane);
            let rec = ukf.update(&zl).unwrap();
            if (zl[0] - rec.predicted_measurement()[0]).abs() > PI {
                seen.wrapped += 1;
            }
            let e = truth(k, lane) - rec.posterior().mean;
            let mut w = seen.worst;
            // NIS and NEES relative to their expected values where they are smaller (a tiny
            // NIS inherits the cancellation of z - zhat).
            w = w.max(rel(step.nis(lane).unwrap(), rec.nis(), 1.0)).max(rel(
                step.nees(lane).unwrap(),
                rec.nees(&e).unwrap(),
                4.0,
            ));
            let (mean, cov, gain) = (b.mean(lane), b.cov(lane), b.gain(lane));
            let p = &rec.posterior().cov;
            for i in 0..4 {
                w = w.max(rel(mean[i], rec.posterior().mean[i], mean.norm()));
                seen.worst_gain =
                    seen.worst_gain
                        .max(rel(gain[(i, 0)], rec.gain()[(i, 0)], gain.norm()));
                for j in 0..4 {
                    w = w.max(rel(cov[(i, j)], p[(i, j)], p.norm()));
                }
            }
            seen.worst = w;
            let kappa = ukf.last_kappa().unwrap();
            assert_eq!(
                b.kappa(lane),
                Some(kappa),
                "{isa}, {criterion:?}, lane {lane}, step {k}"
            );
            seen.kappas.insert(kappa.to_bits());
        }
    }
    seen
}

/// The bound on the gain's relative difference with the lane-wise bearing. Its arctangent is
/// within 3 ulp of glibc's, not equal to it, and `Pxz` sums differences of sigma bearings
/// (`Z_j+ - Z_j-`) that cancel: 1.8e-12 was measured with the posterior criteria, which pick
/// large kappas. Means, covariances, NIS and NEES stay within 1e-12, and with the scalar
/// models called per lane the gain does too.
const LANE_WISE_GAIN: f64 = 1e-11;

const SETS: [SigmaSet; 2] = [
    SigmaSet::Symmetric { kappa: 0.0 },
    SigmaSet::Scaled {
        alpha: 0.8,
        beta: 2.0,
        kappa: 1.0,
    },
];

#[test]
fn every_lane_agrees_with_the_scalar_ukf_on_every_instruction_set() {
    for isa in Isa::available() {
        for set in SETS {
            for translational in [false, true] {
                let d = dynamics();
                let h = sensor(translational);
                let lane_wise = compare(
                    batch(isa, d.clone(), h.clone(), set, None),
                    set,
                    None,
                    translational,
                    120,
                );
                let per_lane = compare(
                    batch(isa, PerLane(d), PerLane(h), set, None),
                    set,
                    None,
                    translational,
                    120,
                );
                for (what, seen, gain_bound) in [
                    ("lane-wise", lane_wise, LANE_WISE_GAIN),
                    ("per lane", per_lane, 1e-12),
                ] {
                    assert!(seen.wrapped > 0, "the data must cross the +-pi cut");
                    assert!(
                        seen.worst_gain <= gain_bound,
                        "{isa}, {set:?}, {what}: gain {:e}",
                        seen.worst_gain
                    );
                    assert_eq!(seen.kappas.len(), 1);
                    assert!(
                        seen.worst <= 1e-12,
                        "{isa}, {set:?}, {what}, translational {translational}: largest relative difference {:e}",
                        seen.worst
                    );
                }
            }
        }
    }
}

#[test]
fn every_adaptive_criterion_chooses_the_scalar_kappa_on_every_instruction_set() {
    let criteria = [
        KappaCriterion::MaximumLikelihood,
        KappaCriterion::MaximumPosterior,
        KappaCriterion::PureMap,
    ];
    for isa in Isa::available() {
        for criterion in criteria {
            for set in SETS {
                for translational in [false, true] {
                    let c = Some(criterion);
                    let d = dynamics();
                    let h = sensor(translational);
                    let lane_wise = compare(
                        batch(isa, d.clone(), h.clone(), set, c),
                        set,
                        c,
                        translational,
                        60,
                    );
                    let per_lane = compare(
                        batch(isa, PerLane(d), PerLane(h), set, c),
                        set,
                        c,
                        translational,
                        60,
                    );
                    for (what, seen, gain_bound) in [
                        ("lane-wise", lane_wise, LANE_WISE_GAIN),
                        ("per lane", per_lane, 1e-12),
                    ] {
                        assert!(
                            seen.worst_gain <= gain_bound,
                            "{isa}, {criterion:?}, {set:?}, {what}: gain {:e}",
                            seen.worst_gain
                        );
                        // The kappa must vary, or the choice was not tested.
                        assert!(
                            seen.kappas.len() > 1,
                            "{isa}, {criterion:?}, {set:?}, {what}: one kappa chosen throughout"
                        );
                        assert!(
                            seen.worst <= 1e-12,
                            "{isa}, {criterion:?}, {set:?}, {what}, translational {translational}: largest relative difference {:e}",
                            seen.worst
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn the_vector_paths_agree_to_the_bit() {
    // AVX-512 steps the batch as one vector, AVX2 as two: the same arithmetic per lane.
    let isas: Vec<Isa> = Isa::available()
        .into_iter()
        .filter(|i| matches!(i, Isa::Avx512 | Isa::Avx2))
        .collect();
    for criterion in [None, Some(KappaCriterion::MaximumPosterior)] {
        let mut runs = isas
            .iter()
            .map(|&isa| batch(isa, dynamics(), sensor(true), SETS[0], criterion))
            .collect::<Vec<_>>();
        for k in 1..=60 {
            let (z, x) = lanes_at(k);
            let steps: Vec<_> = runs
                .iter_mut()
                .map(|b| b.predict_update(&z, &x).clone())
                .collect();
            for (s, b) in steps.iter().zip(&runs).skip(1) {
                assert_eq!(s, &steps[0]);
                assert_eq!(b.means(), runs[0].means());
                for lane in 0..BATCH {
                    assert_eq!(b.cov(lane), runs[0].cov(lane));
                    assert_eq!(b.kappa(lane), runs[0].kappa(lane));
                }
            }
        }
    }
}

#[test]
fn a_nan_measurement_fails_only_its_lane_and_keeps_its_prediction() {
    for isa in Isa::available() {
        for criterion in [None, Some(KappaCriterion::MaximumLikelihood)] {
            let mut clean = batch(isa, dynamics(), sensor(false), SETS[0], criterion);
            let mut dirty = batch(isa, dynamics(), sensor(false), SETS[0], criterion);
            let mut ukf3 = scalar(3, SETS[0], criterion, false);
            ukf3.update(&measurement(0, 3)).unwrap();
            let (z, x) = lanes_at(0);
            clean.update(&z, &x);
            dirty.update(&z, &x);
            for k in 1..=12 {
                let (z, x) = lanes_at(k);
                let mut z_bad = z;
                if k == 5 {
                    z_bad[0][3] = f64::NAN;
                }
                let a = clean.predict_update(&z, &x).clone();
                let b = dirty.predict_update(&z_bad, &x).clone();
                ukf3.predict().unwrap();
                let kappa_before = ukf3.last_kappa();
                let scalar = ukf3.update(&Vector1::new(z_bad[0][3])).map(|rec| rec.nis());
                for lane in 0..BATCH {
                    if lane == 3 && k == 5 {
                        let expected = FilterError::NonFinite {
                            what: "measurement",
                            step: 5,
                        };
                        assert_eq!(scalar, Err(expected.clone()));
                        assert_eq!(b.nis(lane), Err(expected.clone()), "{isa}");
                        assert_eq!(b.nees(lane), Err(expected), "{isa}");
                        // The prediction kept, the kappa of the last update unchanged.
                        let d = dirty.mean(3) - ukf3.mean();
                        assert!(d.amax() <= 1e-12 * ukf3.mean().amax(), "{isa}: {d}");
                        let d = dirty.cov(3) - ukf3.covariance();
                        assert!(d.amax() <= 1e-12 * ukf3.covariance().amax(), "{isa}: {d}");
                        assert_eq!(dirty.kappa(3), kappa_before);
                    } else if lane == 3 {
                        // After the failure the lane goes on from its prediction, as the
                        // scalar filter does.
                        let nis = scalar.clone().unwrap();
                        assert!(rel(b.nis(3).unwrap(), nis, 1.0) <= 1e-12, "{isa}, step {k}");
                        let d = dirty.mean(3) - ukf3.mean();
                        assert!(d.amax() <= 1e-12 * ukf3.mean().amax(), "{isa}: {d}");
                        assert_eq!(dirty.kappa(3), ukf3.last_kappa());
                    } else {
                        assert_eq!(b.nis(lane), a.nis(lane), "{isa}, lane {lane}, step {k}");
                        assert_eq!(dirty.cov(lane), clean.cov(lane));
                        assert_eq!(dirty.kappa(lane), clean.kappa(lane));
                    }
                }
            }
        }
    }
}

#[test]
fn bad_sets_are_errors() {
    let (m, p) = prior(0);
    let bad = UkfBatch::new(
        Isa::Scalar,
        dynamics(),
        sensor(false),
        m,
        p,
        SigmaSet::Symmetric { kappa: -4.0 },
        UkfPrediction::Linearised,
    );
    assert!(matches!(bad, Err(FilterError::InvalidParameter { .. })));
    let b = UkfBatch::new(
        Isa::Scalar,
        dynamics(),
        sensor(false),
        m,
        p,
        SETS[0],
        UkfPrediction::Unscented,
    )
    .unwrap();
    let bad_grid = KappaGrid::new(vec![-5.0, 1.0]).unwrap();
    assert!(matches!(
        b.with_adaptive_kappa(KappaCriterion::PureMap, &bad_grid),
        Err(FilterError::InvalidParameter { .. })
    ));
}

/// The unscented prediction through a nonlinear transition (paper 004's axis, sine and
/// cosine terms), lane-wise and per lane, fixed and adaptive kappa, against the scalar UKF's
/// default (unscented) prediction; and it is not the linearised one.
#[test]
fn the_unscented_prediction_agrees_with_the_scalar_ukf_on_every_instruction_set() {
    use kalibra_linalg::{U3, Vector3};
    use kalibra_models::{AccelAxis, Stationary, Target3dParams};

    let axis = AccelAxis::new(Target3dParams::default(), 1).unwrap();
    let sensor = Bearing::new(
        U3,
        [0, 1],
        BearingReference::XAxis,
        1e-4,
        Stationary(Vector2::new(20.0, -1.0)),
    )
    .unwrap();
    // Lane `lane`'s truth and bearing at step `k`, seen from far away along the negative x
    // axis, so the bearings cross +-pi. (A sensor among the targets lets sigma points pass
    // near it, where the bearing's rounding is amplified without bound: the lane-wise
    // arithmetic, within 2 ulp of glibc's, then drifts from the scalar.)
    let data = |k: usize, lane: usize| {
        let x = lane_data::truth(k, lane);
        (lane_data::measured(k, lane, sensor.measure(k, &x), 0.01), x)
    };
    let prior = lane_data::prior;
    let set = SigmaSet::Symmetric { kappa: 0.5 };
    let grid = KappaGrid::equidistant(0.0, 57.0, 10).unwrap();
    type Scalar = Ukf<U3, kalibra_linalg::U1, AccelAxis, Bearing<U3, Stationary<2>>>;
    fn run<D: LaneDynamics<3>, H: LaneSigmaMeasurement<3, 1>>(
        mut b: UkfBatch<3, 1, D, H>,
        mut scalar: Vec<Scalar>,
        data: &dyn Fn(usize, usize) -> (Vector1<f64>, Vector3<f64>),
    ) -> (f64, usize) {
        let isa = b.isa();
        let mut worst = 0.0f64;
        let mut wrapped = 0;
        for k in 0..=150 {
            let mut z = [[0.0; BATCH]; 1];
            let mut x = [[0.0; BATCH]; 3];
            for lane in 0..BATCH {
                let (zl, xl) = data(k, lane);
                z[0][lane] = zl[0];
                for i in 0..3 {
                    x[i][lane] = xl[i];
                }
            }
            let step = if k == 0 {
                b.update(&z, &x)
            } else {
                b.predict_update(&z, &x)
            }
            .clone();
            assert!(step.all_ok(), "{isa}, step {k}");
            for (lane, f) in scalar.iter_mut().enumerate() {
                if k > 0 {
                    f.predict().unwrap();
                }
                let zl = data(k, lane).0;
                let rec = f.update(&zl).unwrap();
                if (zl[0] - rec.predicted_measurement()[0]).abs() > PI {
                    wrapped += 1;
                }
                worst = worst.max(rel(step.nis(lane).unwrap(), rec.nis(), 1.0));
                let (mean, cov) = (b.mean(lane), b.cov(lane));
                let p = &rec.posterior().cov;
                for i in 0..3 {
                    worst = worst.max(rel(mean[i], rec.posterior().mean[i], mean.norm()));
                    for j in 0..3 {
                        worst = worst.max(rel(cov[(i, j)], p[(i, j)], p.norm()));
                    }
                }
                assert_eq!(
                    b.kappa(lane),
                    f.last_kappa(),
                    "{isa}, lane {lane}, step {k}"
                );
            }
        }
        (worst, wrapped)
    }
    for isa in Isa::available() {
        for criterion in [None, Some(KappaCriterion::MaximumLikelihood)] {
            let make = |prediction| {
                let (m0, p0) = prior(0);
                let mut b =
                    UkfBatch::new(isa, axis, sensor.clone(), m0, p0, set, prediction).unwrap();
                let mut per_lane = UkfBatch::new(
                    isa,
                    PerLane(axis),
                    PerLane(sensor.clone()),
                    m0,
                    p0,
                    set,
                    prediction,
                )
                .unwrap();
                if let Some(c) = criterion {
                    b = b.with_adaptive_kappa(c, &grid).unwrap();
                    per_lane = per_lane.with_adaptive_kappa(c, &grid).unwrap();
                }
                for lane in 0..BATCH {
                    let (m, p) = prior(lane);
                    b.set_lane(lane, m, p).unwrap();
                    per_lane.set_lane(lane, m, p).unwrap();
                }
                (b, per_lane)
            };
            let scalar = || -> Vec<Scalar> {
                (0..BATCH)
                    .map(|lane| {
                        let (m, p) = prior(lane);
                        let u = Ukf::new(axis, sensor.clone(), m, p, set).unwrap();
                        match criterion {
                            Some(c) => u.with_adaptive_kappa(c, grid.clone()).unwrap(),
                            None => u,
                        }
                    })
                    .collect()
            };
            let (lane_wise, per_lane) = make(UkfPrediction::Unscented);
            for (what, (worst, wrapped)) in [
                ("lane-wise", run(lane_wise, scalar(), &data)),
                ("per lane", run(per_lane, scalar(), &data)),
            ] {
                assert!(wrapped > 0, "the data must cross the +-pi cut");
                assert!(
                    worst <= 1e-12,
                    "{isa}, {criterion:?}, {what}: largest relative difference {worst:e}"
                );
            }
            // The linearised prediction gives another prior: the unscented path was taken.
            let (mut unscented, _) = make(UkfPrediction::Unscented);
            let (mut linearised, _) = make(UkfPrediction::Linearised);
            let (z, x) = data(1, 0);
            let z = [[z[0]; BATCH]; 1];
            let x = [[x[0]; BATCH], [x[1]; BATCH], [x[2]; BATCH]];
            unscented.predict_update(&z, &x);
            linearised.predict_update(&z, &x);
            let d = (unscented.cov(0) - linearised.cov(0)).amax();
            assert!(d > 1e-6, "{isa}: {d:e}");
        }
    }
}
