//! J1/J2 on every parameter: the scaled-Q curve is the existing `Q` sweep, every curve passes
//! through the estimate at `p = 0`, crossovers are reported on the parameters' own scale and
//! off-diagonal entries are skipped with a reason.

use kalibra_tune::{
    CovarianceForm, DMatrix, DVector, NoiseMatrices, NoiseProblem, ParameterSweep, Parametrisation,
    Run, Start, TuneProblem, Tuning,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// A constant-velocity track seen in position, 150 steps, some missing.
fn track(seed: u64) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>, Run) {
    let f = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]);
    let h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let q = DMatrix::from_row_slice(2, 2, &[1.0 / 3.0, 0.5, 0.5, 1.0]) * 0.05;
    let l = q.clone().cholesky().unwrap().l();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut x = DVector::zeros(2);
    let run = (0..150)
        .map(|k| {
            x = &f * &x + &l * DVector::from_fn(2, |_, _| normal());
            let z = &h * &x + DVector::from_element(1, 0.7 * normal());
            (k % 13 != 5).then_some(z)
        })
        .collect();
    (f, h, q, run)
}

#[test]
fn scaled_q_curve_is_the_q_sweep() {
    let (f, h, q, run) = track(5);
    let r = DMatrix::from_element(1, 1, 0.49);
    let (x0, p0) = (DVector::zeros(2), DMatrix::identity(2, 2) * 10.0);
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(q.clone()),
        CovarianceForm::fixed(r.clone()),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        f.clone(),
        h.clone(),
        x0.clone(),
        p0.clone(),
        Start::PredictFirst,
        noise,
        vec![run.clone()],
    )
    .unwrap();
    let estimate = NoiseMatrices {
        qw: q.clone(),
        r: r.clone(),
        q: q.clone(),
    };
    let sweep = ParameterSweep::new();
    let curves = sweep.sweep(&problem, &estimate).unwrap();
    assert_eq!(curves.len(), 1);
    let old = TuneProblem::new(f, h, q, r, x0, p0, run).unwrap();
    let report = Tuning::new()
        .grid(sweep.exponents().to_vec())
        .tune(&old)
        .unwrap();
    for (ours, theirs) in curves[0].points.iter().zip(&report.points) {
        assert_eq!(ours.p, theirs.p);
        assert!((ours.j1 - theirs.j1).abs() < 1e-12 && (ours.j2 - theirs.j2).abs() < 1e-12);
    }
    let (ours, theirs) = (
        curves[0].crossover.as_ref().unwrap(),
        report.crossover.as_ref().unwrap(),
    );
    assert!(
        (ours.p - theirs.p).abs() < 1e-12,
        "{} vs {}",
        ours.p,
        theirs.p
    );
    assert!((ours.value - 10f64.powf(theirs.p)).abs() < 1e-12);
}

#[test]
fn every_parameter_has_its_curve() {
    let (f, h, _, run) = track(9);
    let noise = Parametrisation::new(
        None,
        // Three free parameters (the most one measurement of two states identifies).
        CovarianceForm::full(DMatrix::from_row_slice(2, 2, &[0.02, 0.02, 0.02, 0.05])).fix(0, 0),
        CovarianceForm::diagonal(DMatrix::from_element(1, 1, 0.5)),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        f,
        h,
        DVector::zeros(2),
        DMatrix::identity(2, 2) * 10.0,
        Start::UpdateFirst,
        noise,
        vec![run.clone(), run],
    )
    .unwrap();
    let qw = DMatrix::from_row_slice(2, 2, &[0.02, 0.02, 0.02, 0.05]);
    let estimate = NoiseMatrices {
        qw: qw.clone(),
        r: DMatrix::from_element(1, 1, 0.5),
        q: qw,
    };
    let sweep = ParameterSweep::new()
        .grid(vec![-2.0, -1.0, 0.0, 1.0, 2.0])
        .unwrap();
    let curves = sweep.sweep(&problem, &estimate).unwrap();
    let names: Vec<_> = curves.iter().map(|c| c.parameter.name.as_str()).collect();
    assert_eq!(names, ["Qw[1,0]", "Qw[1,1]", "R[0,0]"]);
    // The off-diagonal entry is skipped with its reason.
    assert!(curves[0].skipped.is_some() && curves[0].points.is_empty());
    // Every swept curve passes through the estimate at p = 0.
    let at_zero: Vec<_> = curves
        .iter()
        .filter(|c| c.skipped.is_none())
        .map(|c| (c.points[2].j1, c.points[2].j2))
        .collect();
    for w in at_zero.windows(2) {
        assert!((w[0].0 - w[1].0).abs() < 1e-12 && (w[0].1 - w[1].1).abs() < 1e-12);
    }
    // Raising the velocity variance raises S, so J1 falls (J2 = tr((A + B)^-1 B) sees Q only
    // through B = H Q H^T, the position variance, fixed here); raising R raises J1 and lowers
    // J2.
    let q = &curves[1].points;
    assert!(q[0].j1 > q[4].j1);
    let r = &curves[2].points;
    assert!(r[0].j1 < r[4].j1 && r[0].j2 > r[4].j2);
    assert!((r[4].value - 0.5 * 100.0).abs() < 1e-12);
    for c in curves
        .iter()
        .filter_map(|c| c.crossover.as_ref().zip(Some(c.value)))
    {
        assert!((c.0.value - c.1 * 10f64.powf(c.0.p)).abs() < 1e-12 * c.0.value);
    }
}

#[test]
fn a_bad_grid_is_refused() {
    assert!(ParameterSweep::new().grid(vec![]).is_err());
    assert!(ParameterSweep::new().grid(vec![0.0, 0.0]).is_err());
    assert!(ParameterSweep::new().grid(vec![0.0, 400.0]).is_err());
}
