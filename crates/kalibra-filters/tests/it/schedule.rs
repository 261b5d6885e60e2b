//! A batch that follows a [`KfSchedule`] against one that computes its covariances itself
//! ([`KfBatch::new`]), on every instruction set this CPU has: every output of every step, and
//! every lane's mean, covariance and gain after it, must be the same to the bit, through
//! failed lanes, restarted lanes, a prediction where the schedule has none, a schedule that
//! ends before the run, and one that stops where the covariance overflows.

use std::sync::Arc;

use kalibra_filters::batch::{BATCH, BatchModel, BatchStep, Isa, KfBatch, KfSchedule, Lanes};
use kalibra_linalg::{SMatrix, SVector};

/// A small deterministic generator (xorshift64*), so that the cases need no seed handling.
struct Gen(u64);

impl Gen {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (bits >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// The same value, bit for bit, or the same error.
fn same(
    a: Result<f64, kalibra_filters::FilterError>,
    b: Result<f64, kalibra_filters::FilterError>,
) -> bool {
    match (a, b) {
        (Ok(x), Ok(y)) => x.to_bits() == y.to_bits(),
        (Err(x), Err(y)) => x == y,
        _ => false,
    }
}

fn bits<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Vec<u64> {
    m.iter().map(|v| v.to_bits()).collect()
}

fn assert_same_step<const N: usize>(a: &BatchStep<N>, b: &BatchStep<N>, what: &str) {
    assert_eq!(a.step(), b.step(), "{what}");
    assert_eq!(a.ok(), b.ok(), "{what}");
    for lane in 0..BATCH {
        assert!(same(a.nis(lane), b.nis(lane)), "{what}: NIS of lane {lane}");
        assert!(
            same(a.nees(lane), b.nees(lane)),
            "{what}: NEES of lane {lane}"
        );
        let (ea, eb) = (a.error(lane), b.error(lane));
        for i in 0..N {
            assert_eq!(
                ea[i].to_bits(),
                eb[i].to_bits(),
                "{what}: error of lane {lane}"
            );
        }
    }
}

fn assert_same_state<const N: usize, const M: usize>(
    a: &KfBatch<N, M>,
    b: &KfBatch<N, M>,
    what: &str,
) {
    for lane in 0..BATCH {
        assert_eq!(
            bits(&a.mean(lane)),
            bits(&b.mean(lane)),
            "{what}: mean of lane {lane}"
        );
        assert_eq!(
            bits(&a.cov(lane)),
            bits(&b.cov(lane)),
            "{what}: covariance of lane {lane}"
        );
        assert_eq!(
            bits(&a.gain(lane)),
            bits(&b.gain(lane)),
            "{what}: gain of lane {lane}"
        );
    }
}

/// What happens to the batches at a step, besides the update.
#[derive(Clone, Copy, PartialEq)]
enum Event {
    None,
    /// Lane `.0`'s measurement is NaN.
    NanMeasurement(usize),
    /// Lane `.0` restarts from its own estimate before the update.
    Restart(usize),
    /// An update without a prediction (the schedule predicts at every step after the first).
    UpdateOnly,
}

struct Case<const N: usize, const M: usize> {
    model: BatchModel<N, M>,
    x0: SVector<f64, N>,
    p0: SMatrix<f64, N, N>,
    updates: usize,
    steps: usize,
    events: Vec<(usize, Event)>,
    /// Whether the batch must still follow the schedule after the last step.
    scheduled_at_end: bool,
}

fn random_case<const N: usize, const M: usize>(
    g: &mut Gen,
    stable: bool,
) -> (BatchModel<N, M>, SVector<f64, N>, SMatrix<f64, N, N>) {
    // F near the identity (or growing, to overflow the covariance), Q, R and P0 as A A^T + I.
    let scale = if stable { 0.3 } else { 1e40 };
    let f = SMatrix::<f64, N, N>::identity() * if stable { 1.0 } else { 1e40 }
        + SMatrix::from_fn(|_, _| scale * g.unit());
    let a = SMatrix::<f64, N, N>::from_fn(|_, _| g.unit());
    let q = a * a.transpose() * 0.1;
    let b = SMatrix::<f64, M, M>::from_fn(|_, _| g.unit());
    let r = b * b.transpose() + SMatrix::<f64, M, M>::identity();
    let h = SMatrix::<f64, M, N>::from_fn(|_, _| g.unit());
    let c = SMatrix::<f64, N, N>::from_fn(|_, _| g.unit());
    let p0 = c * c.transpose() + SMatrix::<f64, N, N>::identity();
    let x0 = SVector::<f64, N>::from_fn(|_, _| 10.0 * g.unit());
    (BatchModel::new(f, q, h, r).unwrap(), x0, p0)
}

fn run_case<const N: usize, const M: usize>(case: &Case<N, M>, g: &mut Gen, name: &str) {
    for isa in Isa::available() {
        let schedule =
            Arc::new(KfSchedule::new(isa, case.model.clone(), case.p0, case.updates).unwrap());
        let mut fast = KfBatch::scheduled(schedule.clone(), case.x0).unwrap();
        let mut full = KfBatch::new(isa, case.model.clone(), case.x0, case.p0).unwrap();
        assert_eq!(fast.isa(), isa);
        let mut data = Gen(g.0 ^ 0x9e37_79b9_7f4a_7c15);
        for k in 0..case.steps {
            let what = format!("{name}, {isa}, step {k}");
            let event = case
                .events
                .iter()
                .find(|(at, _)| *at == k)
                .map_or(Event::None, |(_, e)| *e);
            let mut z = [[0.0; BATCH]; M];
            let mut truth = [[0.0; BATCH]; N];
            for lane in 0..BATCH {
                for zi in z.iter_mut() {
                    zi[lane] = 5.0 * data.unit();
                }
                for ti in truth.iter_mut() {
                    ti[lane] = 5.0 * data.unit();
                }
            }
            match event {
                Event::NanMeasurement(lane) => z[0][lane] = f64::NAN,
                Event::Restart(lane) => {
                    let x = SVector::<f64, N>::from_fn(|_, _| data.unit());
                    let p = SMatrix::<f64, N, N>::identity() * 2.0;
                    fast.set_lane(lane, x, p).unwrap();
                    full.set_lane(lane, x, p).unwrap();
                }
                _ => {}
            }
            let (a, b) = if k == 0 || event == Event::UpdateOnly {
                (
                    fast.update(&z, &truth).clone(),
                    full.update(&z, &truth).clone(),
                )
            } else {
                (
                    fast.predict_update(&z, &truth).clone(),
                    full.predict_update(&z, &truth).clone(),
                )
            };
            assert_same_step(&a, &b, &what);
            assert_same_state(&fast, &full, &what);
        }
        assert_eq!(fast.is_scheduled(), case.scheduled_at_end, "{name}, {isa}");
    }
}

#[test]
fn a_scheduled_batch_gives_the_unscheduled_batchs_numbers_to_the_bit() {
    let mut g = Gen(0x5eed_1234_abcd_0001);
    for round in 0..6 {
        // A 4-state model with 2 measurements, and a 2-state one with 1.
        let (model, x0, p0) = random_case::<4, 2>(&mut g, true);
        let plain = |events: Vec<(usize, Event)>, updates: usize, steps: usize, end: bool| Case {
            model: model.clone(),
            x0,
            p0,
            updates,
            steps,
            events,
            scheduled_at_end: end,
        };
        run_case(
            &plain(vec![], 60, 60, true),
            &mut g,
            &format!("round {round}: no event"),
        );
        run_case(
            &plain(vec![], 40, 60, false),
            &mut g,
            &format!("round {round}: past the schedule's end"),
        );
        run_case(
            &plain(
                vec![(17, Event::NanMeasurement(round % BATCH))],
                60,
                60,
                false,
            ),
            &mut g,
            &format!("round {round}: a NaN measurement"),
        );
        run_case(
            &plain(vec![(0, Event::NanMeasurement(3))], 60, 30, false),
            &mut g,
            &format!("round {round}: a NaN measurement at step 0"),
        );
        run_case(
            &plain(vec![(9, Event::Restart(5))], 60, 30, false),
            &mut g,
            &format!("round {round}: a restarted lane"),
        );
        run_case(
            &plain(vec![(12, Event::UpdateOnly)], 60, 30, false),
            &mut g,
            &format!("round {round}: an update without prediction"),
        );
        let (model, x0, p0) = random_case::<2, 1>(&mut g, true);
        let case = Case {
            model,
            x0,
            p0,
            updates: 50,
            steps: 50,
            events: vec![(30, Event::NanMeasurement(7))],
            scheduled_at_end: false,
        };
        run_case(
            &case,
            &mut g,
            &format!("round {round}: 2 states, a NaN measurement"),
        );
    }
}

#[test]
fn a_schedule_stops_where_the_covariance_overflows_and_the_batch_fails_as_without_it() {
    let mut g = Gen(0x0bad_cafe_0000_0002);
    let (model, x0, p0) = random_case::<2, 1>(&mut g, false);
    let schedule = KfSchedule::new(Isa::Scalar, model.clone(), p0, 20).unwrap();
    assert!(
        !schedule.is_empty() && schedule.len() < 20,
        "the covariance grows by 1e80 a step: {} updates",
        schedule.len()
    );
    let case = Case {
        model,
        x0,
        p0,
        updates: 20,
        steps: 20,
        events: vec![],
        scheduled_at_end: false,
    };
    run_case(&case, &mut g, "overflowing covariance");
}

#[test]
fn a_schedule_refuses_what_a_batch_refuses() {
    let mut g = Gen(7);
    let (model, x0, p0) = random_case::<2, 1>(&mut g, true);
    assert!(KfSchedule::new(Isa::Scalar, model.clone(), -p0, 5).is_err());
    let schedule = Arc::new(KfSchedule::new(Isa::Scalar, model, p0, 5).unwrap());
    assert_eq!(schedule.len(), 5);
    assert!(schedule.posterior(4).is_some() && schedule.posterior(5).is_none());
    let nan = SVector::<f64, 2>::from_fn(|_, _| f64::NAN);
    assert!(KfBatch::scheduled(schedule.clone(), nan).is_err());
    // A refused restart leaves the batch on its schedule.
    let mut batch = KfBatch::scheduled(schedule, x0).unwrap();
    assert!(batch.set_lane(0, x0, -p0).is_err());
    assert!(batch.is_scheduled());
    let lanes: [Lanes; 2] = [[0.0; BATCH]; 2];
    batch.update(&[[1.0; BATCH]], &lanes);
    assert!(batch.is_scheduled());
}
