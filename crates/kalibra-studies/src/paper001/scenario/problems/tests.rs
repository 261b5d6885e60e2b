//! Tests of the three problems: constants, geometry, initialisation against Monte Carlo and
//! closed forms, seeded simulation, errors, and an independent implementation's traces.

use super::*;
use kalibra_models::{Measurement, Platform, wrap_angle};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1e-300)
}

/// Sample mean and covariance of 2-vectors.
fn moments(samples: &[Vector2<f64>]) -> (Vector2<f64>, Matrix2<f64>) {
    let n = samples.len() as f64;
    let mean = samples.iter().sum::<Vector2<f64>>() / n;
    let cov = samples
        .iter()
        .map(|s| (s - mean) * (s - mean).transpose())
        .sum::<Matrix2<f64>>()
        / n;
    (mean, cov)
}

#[test]
fn problem_i_constants() {
    let s = BotScenario::problem_i().unwrap();
    assert_eq!(s.problem, BotProblem::I);
    assert_eq!((s.steps, s.first_label, s.eval_from), (41, 0, 1));
    assert_eq!(s.labels(), 0..41);
    assert_eq!(s.start, BotStart::PredictFirst);
    assert_eq!(s.position_indices(), &[0]);
    assert_eq!(s.velocity_indices(), Some(&[1][..]));
    assert_eq!(*s.dynamics.f(), Matrix2::new(1.0, 1.0, 0.0, 1.0));
    let q = Matrix2::new(0.25, 0.5, 0.5, 1.0) * 0.01;
    assert!((s.dynamics.q().matrix() - q).norm() < 1e-17);
    assert_eq!(s.truth_dynamics.q().matrix(), s.dynamics.q().matrix());
    let m = &s.measurement;
    assert_eq!(m.variance(), 0.0524 * 0.0524);
    assert_eq!(m.translational_variance(), (1.0, 1.0));
    assert_eq!(m.reference(), BearingReference::XAxis);
    assert_eq!(m.platform().positions().len(), 41);
    assert_eq!(m.platform().position(40), Vector2::new(160.0, -20.0));
    // Relative position (x_k - 4k, 20), whatever the velocity.
    for k in [0, 13, 40] {
        let x = Vector2::new(80.0 + k as f64, 1.0);
        let d = m.relative_position(k, &x);
        assert_eq!(d, Vector2::new(80.0 + k as f64 - 4.0 * k as f64, 20.0));
        let d2 = m.selection() * x - m.shift(k);
        assert_eq!(d, d2);
    }
    assert_eq!(
        (BotProblem::I.length_unit(), BotProblem::I.time_unit()),
        ("m", "s")
    );
}

#[test]
fn problem_ii_constants() {
    let s = BotScenario::problem_ii().unwrap();
    assert_eq!((s.steps, s.first_label, s.eval_from), (50, 1, 0));
    assert_eq!(s.labels(), 1..51);
    assert_eq!(s.start, BotStart::PredictFirst);
    assert_eq!(s.position_indices(), &[0, 1]);
    assert_eq!(s.velocity_indices(), Some(&[2, 3][..]));
    let f = s.dynamics.f();
    assert_eq!(f[(0, 2)], 1.0);
    assert_eq!(f[(1, 3)], 1.0);
    assert_eq!(f[(0, 1)], 0.0);
    // Qd = q G G^T with G for [x, y, xdot, ydot].
    let g = kalibra_linalg::nalgebra::Matrix4x2::new(0.5, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 1.0);
    let qd = g * g.transpose() * 9.92e-8;
    assert!((s.dynamics.q().matrix() - qd).norm() < 1e-22);
    assert_eq!(*s.truth_dynamics.q().matrix(), Matrix4::zeros());
    assert_eq!(s.truth_dynamics.f(), f);
    let m = &s.measurement;
    assert_eq!(m.reference(), BearingReference::North);
    assert!(close(m.variance(), (2.0 * PI / 180.0).powi(2), 1e-15));
    assert_eq!(m.translational_variance(), (0.0, 0.0));
    // Platform: 5 knots on -80 deg up to index 14, then on 146 deg.
    let p = m.platform().positions();
    assert_eq!(p.len(), 50);
    assert_eq!(p[0], Vector2::zeros());
    let knot = 1.852 / 60.0;
    for i in 0..49 {
        let v = p[i + 1] - p[i];
        let course = if i < 14 { -80.0 } else { 146.0 };
        assert!(close(v.norm(), 5.0 * knot, 1e-12), "{i}");
        let c = BearingReference::North.angle(v[0], v[1]).to_degrees();
        assert!((c - course).abs() < 1e-9, "{i}: {c}");
    }
    // Target: (7, 7) km, 15 knots on -135.4 deg, no process noise.
    let run = s.simulate(&mut ChaCha8Rng::seed_from_u64(0)).unwrap();
    let x0 = run.states[0];
    assert_eq!((x0[0], x0[1]), (7.0, 7.0));
    assert!(close(Vector2::new(x0[2], x0[3]).norm(), 15.0 * knot, 1e-12));
    assert!((BearingReference::North.angle(x0[2], x0[3]).to_degrees() + 135.4).abs() < 1e-9);
    for (i, x) in run.states.iter().enumerate() {
        let straight = x0.fixed_rows::<2>(0) + x0.fixed_rows::<2>(2) * i as f64;
        assert!((x.fixed_rows::<2>(0) - straight).norm() < 1e-12, "{i}");
    }
    assert_eq!(
        (BotProblem::II.length_unit(), BotProblem::II.time_unit()),
        ("km", "min")
    );
}

#[test]
fn problem_iii_constants() {
    let s = BotScenario::problem_iii().unwrap();
    assert_eq!((s.steps, s.first_label, s.eval_from), (51, 0, 0));
    assert_eq!(s.labels(), 0..51);
    assert_eq!(s.start, BotStart::UpdateFirst);
    assert_eq!(s.position_indices(), &[0, 1]);
    assert_eq!(s.velocity_indices(), None);
    assert_eq!(*s.dynamics.f(), Matrix2::new(0.9, 0.0, 0.0, 1.0));
    assert_eq!(*s.dynamics.q().matrix(), Matrix2::new(0.1, 0.01, 0.01, 0.1));
    let m = &s.measurement;
    assert_eq!(
        (m.variance(), m.reference()),
        (0.025, BearingReference::XAxis)
    );
    assert_eq!(m.platform().positions().len(), 51);
    for k in [0usize, 1, 7, 50] {
        let p = m.platform().position(k);
        assert_eq!(p, Vector2::new((k as f64).cos(), (k as f64).sin()));
    }
    let Gaussian { mean: x, cov: p } = s.initialize(&[]).unwrap();
    assert_eq!(x, Vector2::new(20.0, 5.0));
    assert_eq!(p, Matrix2::identity() * 0.1);
    assert_eq!(
        (BotProblem::III.length_unit(), BotProblem::III.time_unit()),
        ("", "")
    );
}

/// Problem II's true relative position and its rate at time `t` (min), on the
/// piecewise-straight paths between the tabulated minutes.
fn problem_ii_relative(
    states: &[Vector4<f64>],
    platform: &[Vector2<f64>],
    t: f64,
) -> (Vector2<f64>, Vector2<f64>) {
    let i = (t.floor() as usize).min(states.len() - 2);
    let f = t - i as f64;
    let d = |j: usize| states[j].fixed_rows::<2>(0).into_owned() - platform[j];
    let rate = d(i + 1) - d(i);
    (d(i) + rate * f, rate)
}

#[test]
fn problem_ii_bearing_rate_peaks_near_125_deg_per_min_at_25_min() {
    let s = BotScenario::problem_ii().unwrap();
    let run = s.simulate(&mut ChaCha8Rng::seed_from_u64(1)).unwrap();
    let platform = s.measurement.platform().positions();
    let (mut peak, mut at) = (0.0f64, 0.0);
    for j in 0..49_000 {
        let t = j as f64 / 1000.0;
        let (d, dd) = problem_ii_relative(&run.states, platform, t);
        // Nautical bearing atan2(dx, dy): rate (dy dx' - dx dy') / r^2.
        let rate = ((d[1] * dd[0] - d[0] * dd[1]) / d.norm_squared()).to_degrees();
        if rate.abs() > peak.abs() {
            (peak, at) = (rate, t);
        }
    }
    assert!(
        (120.0..130.0).contains(&peak),
        "peak {peak} deg/min at {at}"
    );
    assert!((24.5..25.5).contains(&at), "peak {peak} deg/min at {at}");
}

#[test]
fn problem_ii_bearing_crosses_180_degrees_once_after_closest_approach() {
    let s = BotScenario::problem_ii().unwrap();
    let run = s.simulate(&mut ChaCha8Rng::seed_from_u64(2)).unwrap();
    let m = &s.measurement;
    let truth: Vec<f64> = (0..s.steps)
        .map(|i| m.measure(i, &run.states[i])[0])
        .collect();
    let jumps: Vec<usize> = (0..s.steps - 1)
        .filter(|&i| (truth[i + 1] - truth[i]).abs() > PI)
        .collect();
    assert_eq!(jumps, [25]);
    assert!(
        (truth[25].to_degrees() - 166.3).abs() < 0.1,
        "{}",
        truth[25]
    );
    assert!(
        (truth[26].to_degrees() + 138.8).abs() < 0.1,
        "{}",
        truth[26]
    );
    // The wrapped change is +55 deg; the noisy bearings (sigma 2 deg) do the same.
    let wrapped = wrap_angle(truth[26] - truth[25]).to_degrees();
    assert!((wrapped - 54.9).abs() < 0.1, "{wrapped}");
    let z = &run.measurements;
    let noisy = m.residual(&z[26], &z[25])[0].to_degrees();
    assert!((noisy - wrapped).abs() < 20.0, "{noisy}");
    assert!(z[26][0] - z[25][0] < -PI);
    // Closest approach: about 0.21 km at t = 24.9 min, just before the crossing.
    let platform = m.platform().positions();
    let (mut closest, mut at) = (f64::INFINITY, 0.0);
    for j in 0..49_000 {
        let t = j as f64 / 1000.0;
        let r = problem_ii_relative(&run.states, platform, t).0.norm();
        if r < closest {
            (closest, at) = (r, t);
        }
    }
    assert!(
        (closest - 0.21).abs() < 0.01 && (at - 24.9).abs() < 0.05,
        "{closest} at {at}"
    );
}

#[test]
fn problem_i_initial_variance_matches_a_monte_carlo() {
    let x0 = Vector2::from(I_X0);
    let draws = 200_000;
    // Returns (Monte Carlo variance of the position estimate about the truth, first-order
    // variance at the noiseless bearing) for the noises scaled by `scale`.
    let trial = |scale: f64, seed: u64| {
        let mut s = BotScenario::problem_i().unwrap();
        let m = &s.measurement;
        s.measurement = Bearing::from_coordinates(
            U2,
            m.coordinates(),
            m.reference(),
            m.variance() * scale,
            m.platform().clone(),
        )
        .unwrap()
        .with_translational_noise(scale, scale)
        .unwrap();
        let m = &s.measurement;
        let clean = m.measure(0, &x0);
        let first_order = s.initialize(&[clean]).unwrap().cov[(0, 0)];
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut acc = 0.0;
        for _ in 0..draws {
            let mut z = clean + m.sample_noise(0, &x0, &mut rng).unwrap();
            m.normalize(&mut z);
            let e = s.initialize(&[z]).unwrap().mean[0] - x0[0];
            acc += e * e;
        }
        (acc / draws as f64, first_order)
    };
    // Small noise (sigmas / 10): first order holds; the 2e5-draw estimate has a 0.3%
    // standard error and the second-order bias is 0.05% of the variance.
    let (mc, fo) = trial(0.01, 3);
    assert!(close(mc, fo, 0.02), "{mc} vs {fo}");
    assert!(close(
        fo,
        0.01 * (1.0 + 16.0) + 0.0524f64.powi(2) * 0.01 * 400.0 / (20f64 / 6800f64.sqrt()).powi(4),
        1e-9
    ));
    // The paper's noise: the true spread (a heavy tail from bearings near 0) is about twice
    // the first-order variance, which is what the filters get. Documented in the module.
    let (mc, fo) = trial(1.0, 4);
    assert!(
        (1.7..2.7).contains(&(mc / fo)),
        "{mc} vs {fo}: ratio {}",
        mc / fo
    );
    assert!((fo - 334.4).abs() < 0.1, "{fo}");
}

/// Draws the polar description exactly and returns the sample moments of position and
/// velocity.
fn polar_draw(p: &Polar, draws: usize, seed: u64) -> [(Vector2<f64>, Matrix2<f64>); 2] {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let u = |a: f64| BearingReference::North.direction(a);
    let (mut pos, mut vel) = (Vec::with_capacity(draws), Vec::with_capacity(draws));
    for _ in 0..draws {
        let r = p.range + p.var_range.sqrt() * normal();
        let b = p.bearing + p.var_bearing.sqrt() * normal();
        let s = p.speed + p.var_speed.sqrt() * normal();
        let c = p.course + p.var_course.sqrt() * normal();
        pos.push(u(b) * r);
        vel.push(u(c) * s);
    }
    [moments(&pos), moments(&vel)]
}

#[test]
fn problem_ii_first_order_initialisation_matches_the_polar_draw_for_small_spreads() {
    let z = 0.7;
    let knot = 1.852 / 60.0;
    // Spreads small enough for first order: relative errors of order var_b and
    // var_a / a^2, here 1e-4 or less.
    let small = Polar {
        range: 98f64.sqrt(),
        var_range: 0.05f64.powi(2),
        bearing: z,
        var_bearing: 0.005f64.powi(2),
        speed: 15.0 * knot,
        var_speed: (0.1 * knot).powi(2),
        course: z + PI,
        var_course: 0.01f64.powi(2),
    };
    let (mean, cov) = small.first_order(BearingReference::North, Vector2::zeros());
    let [(mp, cp), (mv, cv)] = polar_draw(&small, 200_000, 5);
    let block = |i: usize| cov.fixed_view::<2, 2>(i, i).into_owned();
    for (sample, model, m_mean, s_mean) in [
        (cp, block(0), mean.fixed_rows::<2>(0), mp),
        (cv, block(2), mean.fixed_rows::<2>(2), mv),
    ] {
        // Entries to 3% of the block's scale (sampling error about 0.3%), means to a small
        // fraction of a standard deviation.
        assert!(
            (sample - model).abs().max() < 0.03 * model.abs().max(),
            "{sample} vs {model}"
        );
        let sd = model.trace().sqrt();
        assert!((s_mean - m_mean).norm() < 0.02 * sd, "{s_mean} vs {m_mean}");
    }
    assert_eq!(cov.fixed_view::<2, 2>(0, 2).into_owned(), Matrix2::zeros());
}

#[test]
fn problem_ii_initialisation_and_its_first_order_gap_at_the_paper_spreads() {
    let s = BotScenario::problem_ii().unwrap();
    let z = PI / 4.0; // the noiseless z_1: the target at (7, 7) from (0, 0)
    let Gaussian { mean: x, cov: p } = s.initialize(&[Vector1::new(z)]).unwrap();
    let knot = 1.852 / 60.0;
    assert!(
        (x[0] - 7.0).abs() < 1e-12 && (x[1] - 7.0).abs() < 1e-12,
        "{x}"
    );
    // Course z + pi = -135 deg at the true 15 knots: heading at the observer.
    assert!(close(Vector2::new(x[2], x[3]).norm(), 15.0 * knot, 1e-12));
    assert!((BearingReference::North.angle(x[2], x[3]) + 0.75 * PI).abs() < 1e-12);
    // Along range the variance is 16 km^2; across range r^2 R.
    let radial = Vector2::new(1.0, 1.0) / 2f64.sqrt();
    let across = Vector2::new(1.0, -1.0) / 2f64.sqrt();
    let pos = p.fixed_view::<2, 2>(0, 0).into_owned();
    let vel = p.fixed_view::<2, 2>(2, 2).into_owned();
    let r_theta = s.measurement.variance();
    assert!(close((radial.transpose() * pos * radial)[0], 16.0, 1e-12));
    assert!(close(
        (across.transpose() * pos * across)[0],
        98.0 * r_theta,
        1e-12
    ));
    assert!(close(
        (radial.transpose() * vel * radial)[0],
        (4.0 * knot).powi(2),
        1e-12
    ));
    let var_c = PI * PI / 12.0;
    let s2 = (15.0 * knot).powi(2);
    assert!(close(
        (across.transpose() * vel * across)[0],
        s2 * var_c,
        1e-12
    ));

    // The exact polar draw at the paper's spreads, in the same frame, against closed forms.
    let paper = Polar {
        range: 98f64.sqrt(),
        var_range: 16.0,
        bearing: z,
        var_bearing: r_theta,
        speed: 15.0 * knot,
        var_speed: (4.0 * knot).powi(2),
        course: z + PI,
        var_course: var_c,
    };
    let [(_, cp), (mv, cv)] = polar_draw(&paper, 400_000, 6);
    let along = |c: &Matrix2<f64>, u: &Vector2<f64>| (u.transpose() * c * u)[0];
    // Position: radial sigma_r^2; cross-range (r^2 + var_r) R, 16% above first order.
    assert!(close(along(&cp, &radial), 16.0, 0.02));
    assert!(close(along(&cp, &across), (98.0 + 16.0) * r_theta, 0.02));
    // Velocity: E[s^2] (1 - e^{-2 var_c}) / 2 across (about half of first order), and
    // E[s^2] (1 + e^{-2 var_c}) / 2 - s^2 e^{-var_c} along (about 2.8 times), mean speed
    // shrunk by e^{-var_c / 2}.
    let es2 = s2 + (4.0 * knot).powi(2);
    let exact_across = es2 * (1.0 - (-2.0 * var_c).exp()) / 2.0;
    let exact_along = es2 * (1.0 + (-2.0 * var_c).exp()) / 2.0 - s2 * (-var_c).exp();
    assert!(close(along(&cv, &across), exact_across, 0.02));
    assert!(close(along(&cv, &radial), exact_along, 0.02));
    assert!((0.5..0.55).contains(&(exact_across / (s2 * var_c))));
    assert!((2.6..3.0).contains(&(exact_along / (4.0 * knot).powi(2))));
    assert!(close(mv.norm(), 15.0 * knot * (-var_c / 2.0).exp(), 0.02));
}

#[test]
fn simulate_is_fixed_by_the_seed() {
    fn check<N: Dim>(s: &BotScenario<N>)
    where
        DefaultAllocator: Alloc<N> + Alloc<N, U1>,
    {
        let a = s.simulate(&mut ChaCha8Rng::seed_from_u64(9)).unwrap();
        let b = s.simulate(&mut ChaCha8Rng::seed_from_u64(9)).unwrap();
        let c = s.simulate(&mut ChaCha8Rng::seed_from_u64(10)).unwrap();
        assert_eq!(a.states, b.states);
        assert_eq!(a.measurements, b.measurements);
        assert_eq!((&a.init_mean, &a.init_cov), (&b.init_mean, &b.init_cov));
        assert_ne!(a.measurements, c.measurements);
    }
    check(&BotScenario::problem_i().unwrap());
    check(&BotScenario::problem_ii().unwrap());
    check(&BotScenario::problem_iii().unwrap());
}

#[test]
fn runs_have_the_scenario_dimensions_and_wrapped_bearings() {
    fn check<N: Dim>(s: &BotScenario<N>, n: usize)
    where
        DefaultAllocator: Alloc<N> + Alloc<N, U1>,
    {
        for seed in 0..20 {
            let run = s.simulate(&mut ChaCha8Rng::seed_from_u64(seed)).unwrap();
            assert_eq!(run.states.len(), s.steps);
            assert_eq!(run.measurements.len(), s.steps);
            assert!(run.states.iter().all(|x| x.nrows() == n));
            assert_eq!(run.init_mean.nrows(), n);
            assert_eq!(run.init_cov.shape(), (n, n));
            assert!(run.measurements.iter().all(|z| z[0] > -PI && z[0] <= PI));
            assert!(kalibra_linalg::all_finite(&run.init_cov));
            // The initial covariance is a covariance.
            assert!(run.init_cov.clone().cholesky().is_some());
        }
    }
    check(&BotScenario::problem_i().unwrap(), 2);
    check(&BotScenario::problem_ii().unwrap(), 4);
    check(&BotScenario::problem_iii().unwrap(), 2);
}

#[test]
fn problem_iii_prior_draw_has_its_law() {
    let s = BotScenario::problem_iii().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let firsts: Vec<Vector2<f64>> = (0..4000)
        .map(|_| s.simulate(&mut rng).unwrap().states[0])
        .collect();
    let (mean, cov) = moments(&firsts);
    // Standard errors: 0.005 for the mean, 0.0022 for the variances.
    assert!(
        (mean - Vector2::new(20.0, 5.0)).abs().max() < 0.02,
        "{mean}"
    );
    assert!(
        (cov - Matrix2::identity() * 0.1).abs().max() < 0.01,
        "{cov}"
    );
}

#[test]
fn bad_data_and_a_mismatched_problem_are_errors() {
    let s = BotScenario::problem_i().unwrap();
    assert!(matches!(
        s.initialize(&[]),
        Err(ModelError::DimensionMismatch { .. })
    ));
    // A bearing along the target's line has no intersection.
    assert!(matches!(
        s.initialize(&[Vector1::new(0.0)]),
        Err(ModelError::NonFinite { .. })
    ));
    let mut wrong = BotScenario::problem_iii().unwrap();
    wrong.problem = BotProblem::II;
    assert!(matches!(
        wrong.simulate(&mut ChaCha8Rng::seed_from_u64(0)),
        Err(ModelError::DimensionMismatch { .. })
    ));
    let mut wrong = BotScenario::problem_ii().unwrap();
    wrong.problem = BotProblem::III;
    assert!(matches!(
        wrong.initialize(&[]),
        Err(ModelError::DimensionMismatch { .. })
    ));
}

#[test]
fn problem_iii_agrees_with_the_reference_traces() {
    // An independent implementation's runs (tests/data/README in the shared data): their
    // truth cannot be reproduced (another generator), but their bearings must be our
    // measurement function of their truth plus noise of the stated size.
    let text = include_str!("../../data/bot-problem3-traces.json");
    let data: serde_json::Value = serde_json::from_str(text).unwrap();
    let s = BotScenario::problem_iii().unwrap();
    let num = |v: &serde_json::Value| v.as_f64().unwrap();
    let vec2 = |v: &serde_json::Value| Vector2::new(num(&v[0]), num(&v[1]));
    let mat2 = |v: &serde_json::Value| {
        Matrix2::new(num(&v[0][0]), num(&v[0][1]), num(&v[1][0]), num(&v[1][1]))
    };
    let config = &data["config"];
    assert_eq!(config["K"].as_u64(), Some(s.steps as u64));
    assert_eq!(config["ref"].as_str(), Some("x"));
    assert_eq!(num(&config["R_theta"]), s.measurement.variance());
    assert_eq!(mat2(&config["Qd"]), *s.dynamics.q().matrix());
    assert_eq!(mat2(&config["Qd_truth"]), *s.truth_dynamics.q().matrix());
    let labels: Vec<u64> = config["labels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_u64().unwrap())
        .collect();
    assert_eq!(labels, s.labels().map(|l| l as u64).collect::<Vec<_>>());
    let Gaussian {
        mean: init_x,
        cov: init_p,
    } = s.initialize(&[]).unwrap();
    let sigma = s.measurement.variance().sqrt();
    let (mut worst, mut sum2, mut count) = (0.0f64, 0.0, 0);
    for run in data["runs"].as_array().unwrap() {
        assert_eq!(vec2(&run["init_x"]), init_x);
        assert_eq!(mat2(&run["init_P"]), init_p);
        let truth: Vec<Vector2<f64>> = run["truth"].as_array().unwrap().iter().map(vec2).collect();
        let z: Vec<f64> = run["z"].as_array().unwrap().iter().map(num).collect();
        assert_eq!((truth.len(), z.len()), (s.steps, s.steps));
        for (k, (x, z)) in truth.iter().zip(&z).enumerate() {
            assert!(*z > -PI && *z <= PI);
            let e = wrap_angle(z - s.measurement.measure(k, x)[0]);
            worst = worst.max(e.abs());
            sum2 += e * e;
            count += 1;
        }
    }
    assert!(worst < 5.0 * sigma, "worst residual {worst}");
    // 153 residuals: their RMS is within 20% of sigma unless the model disagrees.
    let rms = (sum2 / count as f64).sqrt();
    assert!(
        (0.8 * sigma..1.2 * sigma).contains(&rms),
        "rms {rms} vs {sigma}"
    );
}
