//! Filters on run-time sizes around the faer threshold agree with nalgebra's code: after 100
//! steps the posterior covariances of the two paths differ by at most 1e-12 relative. Each case runs the same filter twice, once with the default kernel policy (faer
//! from `FAER_MIN_DIM`) or with faer at every size, once with `KernelPolicy::NALGEBRA` (the code
//! before faer).

use kalibra_filters::{
    ConstantGainKf, Filter, FilterOptions, Kf, SigmaSet, Ukf, UpdateForm, steady_state,
};
use kalibra_linalg::{
    DMatrix, DVector, Dyn, FAER_MIN_DIM, KernelPolicy, spectral_radius, with_kernel_policy,
};
use kalibra_models::{LinearGaussian, LinearObservation};
use proptest::prelude::*;

/// The agreement required of the two paths, relative in the Frobenius norm.
const TOLERANCE: f64 = 1e-12;

/// Steps per run.
const STEPS: usize = 100;

/// A random linear-Gaussian problem of state dimension `n` and measurement dimension `m`:
/// dense `F` scaled to spectral radius `rho`, dense `H`, symmetric positive definite `Q`, `R`,
/// `P0` (`A A^T / k + c I`).
#[derive(Clone, Debug)]
struct Problem {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    p0: DMatrix<f64>,
    zs: Vec<DVector<f64>>,
}

fn spd(v: &[f64], k: usize, c: f64) -> DMatrix<f64> {
    let a = DMatrix::from_column_slice(k, k, &v[..k * k]);
    let s = &a * a.transpose() / k as f64 + DMatrix::identity(k, k) * c;
    (&s + s.transpose()) * 0.5
}

fn problem(sizes: impl Strategy<Value = (usize, usize)>) -> impl Strategy<Value = Problem> {
    sizes.prop_flat_map(|(n, m)| {
        let entries = prop::collection::vec(-1.0f64..1.0, 3 * n * n + 2 * m * m + m * n);
        let measurements = prop::collection::vec(-3.0f64..3.0, STEPS * m);
        (entries, measurements, 0.3f64..0.99).prop_map(move |(v, z, rho)| {
            let (f_end, h_end) = (n * n, n * n + m * n);
            let f = DMatrix::from_column_slice(n, n, &v[..f_end]);
            let radius = spectral_radius(&f).expect("finite");
            let f = if radius > 0.0 { f * (rho / radius) } else { f };
            let h = DMatrix::from_column_slice(m, n, &v[f_end..h_end]);
            let rest = &v[h_end..];
            let q = spd(rest, n, 0.01) * 0.1;
            let p0 = spd(&rest[n * n..], n, 1.0);
            let r = spd(&rest[2 * n * n..], m, 0.1);
            let zs = z.chunks(m).map(DVector::from_column_slice).collect();
            Problem { f, h, q, r, p0, zs }
        })
    })
}

/// State dimensions around the threshold, every measurement dimension up to `n`.
fn around_threshold() -> impl Strategy<Value = (usize, usize)> {
    ((FAER_MIN_DIM - 4)..=(FAER_MIN_DIM + 12)).prop_flat_map(|n| (Just(n), 1..=n))
}

fn relative(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

/// The posterior covariance after [`STEPS`] predict-update steps of the filter `make` builds.
fn run<F: Filter<Dyn, Dyn>>(
    policy: KernelPolicy,
    problem: &Problem,
    make: impl Fn() -> F,
) -> DMatrix<f64> {
    with_kernel_policy(policy, || {
        let mut filter = make();
        for z in &problem.zs {
            filter.predict().expect("predict");
            filter.update(z).expect("update");
        }
        filter.covariance().clone()
    })
}

/// The filters of the comparison, each on both paths, and what they give.
fn compare(policy: KernelPolicy, p: &Problem) -> Result<(), TestCaseError> {
    let n = p.f.nrows();
    let dynamics = LinearGaussian::new(p.f.clone(), p.q.clone()).unwrap();
    let measurement = LinearObservation::new(p.h.clone(), p.r.clone()).unwrap();
    let x0 = DVector::zeros(n);
    let (dynamics, measurement, x0) = (&dynamics, &measurement, &x0);
    for form in [UpdateForm::Joseph, UpdateForm::Standard] {
        let kf = || {
            let options = FilterOptions {
                update: form,
                ..FilterOptions::default()
            };
            Kf::with_options(dynamics, measurement, x0.clone(), p.p0.clone(), options).unwrap()
        };
        let a = run(policy, p, kf);
        let b = run(KernelPolicy::NALGEBRA, p, kf);
        prop_assert!(
            relative(&a, &b) <= TOLERANCE,
            "KF {form:?}: {:e}",
            relative(&a, &b)
        );
    }
    let ukf = || {
        Ukf::new(
            dynamics,
            measurement,
            x0.clone(),
            p.p0.clone(),
            SigmaSet::Symmetric { kappa: 0.0 },
        )
        .unwrap()
    };
    let (a, b) = (run(policy, p, ukf), run(KernelPolicy::NALGEBRA, p, ukf));
    prop_assert!(relative(&a, &b) <= TOLERANCE, "UKF: {:e}", relative(&a, &b));
    let limit =
        |policy| with_kernel_policy(policy, || steady_state(&p.f, &p.h, &p.q, &p.r).unwrap());
    let (a, b) = (limit(policy), limit(KernelPolicy::NALGEBRA));
    prop_assert!(
        relative(&a.prior, &b.prior) <= TOLERANCE,
        "steady-state prior"
    );
    prop_assert!(relative(&a.gain, &b.gain) <= TOLERANCE, "steady-state gain");
    let cgkf = || {
        ConstantGainKf::new(
            &dynamics,
            &measurement,
            x0.clone(),
            p.p0.clone(),
            b.gain.clone(),
        )
        .unwrap()
    };
    let (a, b) = (run(policy, p, cgkf), run(KernelPolicy::NALGEBRA, p, cgkf));
    prop_assert!(
        relative(&a, &b) <= TOLERANCE,
        "constant-gain KF: {:e}",
        relative(&a, &b)
    );
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// The library's default against nalgebra around the threshold: nalgebra's results to the
    /// bit below it, faer's to 1e-12 from it on.
    #[test]
    fn default_path_agrees_with_nalgebra_around_the_threshold(p in problem(around_threshold())) {
        compare(KernelPolicy::DEFAULT, &p)?;
        if p.f.nrows() < FAER_MIN_DIM {
            let kf = |policy| run(policy, &p, || {
                let dynamics = LinearGaussian::new(p.f.clone(), p.q.clone()).unwrap();
                let measurement = LinearObservation::new(p.h.clone(), p.r.clone()).unwrap();
                Kf::new(dynamics, measurement, DVector::zeros(p.f.nrows()), p.p0.clone()).unwrap()
            });
            prop_assert_eq!(kf(KernelPolicy::DEFAULT), kf(KernelPolicy::NALGEBRA));
        }
    }

    /// faer at every size, down to one state, against nalgebra.
    #[test]
    fn faer_agrees_with_nalgebra_at_every_size(
        p in problem((1usize..=24).prop_flat_map(|n| (Just(n), 1..=n)))
    ) {
        compare(KernelPolicy::faer_from(0), &p)?;
    }
}
