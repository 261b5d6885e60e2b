//! Tuning: sweeps `Q = 10^p Q_nom` over a grid of `p`, and initial tuning: two-point
//! differencing for the initial state, and the adaptive initial covariance `P_ad` and process
//! noise `Q_ad` of Saha, Ghosh and Goswami (IEEE TIM 2014, eqs 22 and 23).
//!
//! # Notation
//! `N` states, `M` measurements; `F_{k-1}` the transition Jacobian at step `k - 1`, `H_k` the
//! measurement Jacobian at step `k`, `R` the measurement-noise covariance. The method
//! evaluates `P_ad` "in an offline EKF with `Q = 0`"; [`p_ad`] takes the trajectory to
//! evaluate it along, so the caller chooses (a noise-free truth, or a filter's estimates).

use std::ops::RangeInclusive;

use kalibra_linalg::{
    Alloc, Const, Covariance, DefaultAllocator, Definiteness, Dim, Gaussian, LinalgError, OMatrix,
    OVector, PsdMatrix, SMatrix, SVector, check_covariance, check_finite,
};
use kalibra_models::{Dynamics, Measurement, ModelError};
use rayon::prelude::*;

use kalibra_sim::SimError;

/// Errors of the tuning helpers.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TuningError {
    /// A parameter outside its domain.
    #[error("invalid parameter {name} = {value}")]
    InvalidParameter {
        /// Which parameter.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// Too few steps to average over.
    #[error("{what} needs at least {needed} steps, got {got}")]
    TooShort {
        /// What was computed.
        what: &'static str,
        /// Steps needed.
        needed: usize,
        /// Steps given.
        got: usize,
    },
    /// A matrix failed its check (for `P_ad`: the averaged information matrix is singular, so
    /// the state is not observable along the trajectory).
    #[error(transparent)]
    Linalg(#[from] LinalgError),
    /// A model failed.
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// The most points [`grid`] makes.
pub const GRID_MAX_POINTS: usize = 10_000_000;

/// The grid `from, from + step, ...` over `from..=to`, up to and including `to` (within
/// `step / 1000`), each point computed as `from + i step` so that rounding does not accumulate.
///
/// The ends come as a range so that they cannot be swapped with the step.
///
/// ```
/// let g = kalibra_tune::grid(-2.0..=1.0, 0.5).unwrap();
/// assert_eq!(g, vec![-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0]);
/// ```
///
/// # Errors
/// [`TuningError::InvalidParameter`] unless `step > 0`, `to >= from` and all are finite, or
/// for a grid of more than [`GRID_MAX_POINTS`] points (checked before anything is allocated).
pub fn grid(range: RangeInclusive<f64>, step: f64) -> Result<Vec<f64>, TuningError> {
    let (from, to) = range.into_inner();
    if !(step.is_finite() && step > 0.0) {
        return Err(TuningError::InvalidParameter {
            name: "grid step",
            value: step,
        });
    }
    if !(from.is_finite() && to.is_finite() && to >= from) {
        return Err(TuningError::InvalidParameter {
            name: "grid end",
            value: to,
        });
    }
    // Ends of opposite signs near the limit: their difference overflows, its ratio to the
    // step need not (`tests/extreme_floats.rs`).
    let span = to - from;
    let ratio = if span.is_finite() {
        span / step
    } else {
        to / step - from / step
    };
    let intervals = (ratio + 1e-3).floor();
    // Each point is a filter run or more: a grid beyond this is a mistake in the step, not a
    // study, and would exhaust memory before any work.
    if intervals.is_nan() || intervals >= GRID_MAX_POINTS as f64 {
        return Err(TuningError::InvalidParameter {
            name: "grid points (at most GRID_MAX_POINTS)",
            value: intervals + 1.0,
        });
    }
    let n = intervals as usize;
    // Near f64::MAX `i step` can overflow where the point does not (from halves), and a last
    // point within `step / 1000` past `to` can overflow itself (it is `to`).
    let point = |i: f64| {
        let p = from + i * step;
        if p.is_finite() {
            return p;
        }
        let p = (0.5 * from + i * (0.5 * step)) * 2.0;
        if p.is_finite() { p.min(to) } else { to }
    };
    Ok((0..=n).map(|i| point(i as f64)).collect())
}

/// Evaluates `point(p)` at every `p` of `grid`, in parallel over grid points, and returns the
/// results in grid order. Each point is independent (a deterministic filter run per `Q`), so
/// the results do not depend on `threads` (0: rayon's global pool). The error of the first
/// failing point in grid order is returned, as `SimError::Run { run: index, .. }`.
///
/// ```
/// let squares = kalibra_tune::sweep(&[1.0, 2.0, 3.0], 2, |p| Ok::<_, std::fmt::Error>(p * p))?;
/// assert_eq!(squares, vec![1.0, 4.0, 9.0]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`SimError::Run`] for a failing point; [`SimError::ThreadPool`] if the pool cannot be built.
pub fn sweep<T, E, F>(grid: &[f64], threads: usize, point: F) -> Result<Vec<T>, SimError<E>>
where
    T: Send,
    E: std::error::Error + Send + 'static,
    F: Fn(f64) -> Result<T, E> + Sync + Send,
{
    let work = || {
        grid.par_iter()
            .enumerate()
            .map(|(run, &p)| point(p).map_err(|source| SimError::Run { run, source }))
            .collect::<Vec<_>>()
            .into_iter()
            .collect()
    };
    kalibra_sim::in_pool((threads > 0).then_some(threads), work)
}

/// Two-point differencing (Bar-Shalom, Li, Kirubarajan 2001, p. 247): from two position
/// measurements `z1`, `z2` (`D` axes) taken `t` apart with noise covariances `r1`, `r2`, the
/// state `[position = z2, velocity = (z2 - z1) / t]` and its exact covariance
/// `J blockdiag(r1, r2) J^T`. `position[i]` and `velocity[i]` are the state indices of axis
/// `i`; other states (if `N > 2 D`) get zero mean and zero covariance. The result is a
/// [`Gaussian`]: `mean` is the state, `cov` its covariance.
///
/// ```
/// use kalibra_linalg::{Gaussian, Matrix1, Vector1};
/// let Gaussian { mean: x, cov: p } = kalibra_tune::two_point_init::<2, 1>(
///     &Vector1::new(10.0), &Vector1::new(14.0), &Matrix1::new(1.0), &Matrix1::new(1.0), 2.0, [0], [1])?;
/// assert_eq!(x, kalibra_linalg::Vector2::new(14.0, 2.0));
/// // var(v) = (r1 + r2) / t^2, cov(x, v) = r2 / t.
/// assert_eq!(p, kalibra_linalg::Matrix2::new(1.0, 0.5, 0.5, 0.5));
/// # Ok::<(), kalibra_tune::TuningError>(())
/// ```
///
/// # Errors
/// [`TuningError::InvalidParameter`] for `t` below the smallest normal number (its reciprocal
/// would overflow) or not finite, an index out of range or used twice;
/// [`TuningError::Linalg`] for non-finite measurements or a noise covariance that is not
/// symmetric positive semi-definite, and [`LinalgError::NonFinite`] for a velocity
/// `(z2 - z1) / t` or a covariance `(r1 + r2) / t^2` beyond f64's range.
pub fn two_point_init<const N: usize, const D: usize>(
    z1: &SVector<f64, D>,
    z2: &SVector<f64, D>,
    r1: &SMatrix<f64, D, D>,
    r2: &SMatrix<f64, D, D>,
    t: f64,
    position: [usize; D],
    velocity: [usize; D],
) -> Result<Gaussian<Const<N>>, TuningError> {
    // From the smallest normal number on, `1 / t` is finite (subnormal `t` overflow it).
    if !(t.is_finite() && t >= f64::MIN_POSITIVE) {
        return Err(TuningError::InvalidParameter {
            name: "differencing interval t",
            value: t,
        });
    }
    let mut used = [false; N];
    for &i in position.iter().chain(&velocity) {
        if i >= N || used[i] {
            return Err(TuningError::InvalidParameter {
                name: "state index",
                value: i as f64,
            });
        }
        used[i] = true;
    }
    check_finite(z1, "first measurement")?;
    check_finite(z2, "second measurement")?;
    PsdMatrix::named(*r1, "first measurement noise")?;
    PsdMatrix::named(*r2, "second measurement noise")?;
    let mut x = SVector::<f64, N>::zeros();
    // J maps [z1; z2] (2 D) to the state (N).
    let mut j = OMatrix::<f64, kalibra_linalg::Dyn, kalibra_linalg::Dyn>::zeros(N, 2 * D);
    for a in 0..D {
        x[position[a]] = z2[a];
        let dz = z2[a] - z1[a];
        // Opposite signs near the limit: divided first, `|z2| / t + |z1| / t` is the velocity
        // whenever that is representable.
        x[velocity[a]] = if dz.is_finite() {
            dz / t
        } else {
            z2[a] / t - z1[a] / t
        };
        j[(position[a], D + a)] = 1.0;
        j[(velocity[a], a)] = -1.0 / t;
        j[(velocity[a], D + a)] = 1.0 / t;
    }
    let mut r = OMatrix::<f64, kalibra_linalg::Dyn, kalibra_linalg::Dyn>::zeros(2 * D, 2 * D);
    r.view_mut((0, 0), (D, D)).copy_from(r1);
    r.view_mut((D, D), (D, D)).copy_from(r2);
    let p = &j * r * j.transpose();
    let mut out = SMatrix::<f64, N, N>::zeros();
    out.copy_from(&p);
    kalibra_linalg::symmetrize(&mut out);
    check_finite(&x, "two-point velocity (beyond f64's range)")?;
    check_finite(&out, "two-point covariance (beyond f64's range)")?;
    Ok(Gaussian { mean: x, cov: out })
}

/// The adaptive initial covariance `P_ad` (Saha, Ghosh and Goswami 2014, eq 22):
/// `[(1/n) sum_{k=1..n} F_{k-1}^T H_k^T R_k^-1 H_k F_{k-1}]^-1`, with `F_{k-1}` the dynamics Jacobian at `states[k-1]` (step `first_step + k - 1`) and
/// `H_k`, `R_k` the measurement Jacobian and noise at `states[k]`; `n = states.len() - 1`.
///
/// # Errors
/// [`TuningError::TooShort`] for fewer than two states; [`TuningError::Linalg`] if an `R_k` is
/// not positive definite or the averaged information matrix is singular (the state is not
/// observable in one step along the trajectory), or an input or the result is not finite
/// (information near the smallest normal number), or (`Dyn` sizes) a state or a Jacobian whose
/// size disagrees with the models' (`DimensionMismatch`).
pub fn p_ad<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>>(
    dynamics: &D,
    measurement: &H,
    states: &[OVector<f64, N>],
    first_step: usize,
) -> Result<OMatrix<f64, N, N>, TuningError>
where
    DefaultAllocator: Alloc<N, M>,
{
    if states.len() < 2 {
        return Err(TuningError::TooShort {
            what: "P_ad",
            needed: 2,
            got: states.len(),
        });
    }
    // The last step index, `first_step + states.len() - 1`, must be a usize.
    if first_step.checked_add(states.len()).is_none() {
        return Err(TuningError::InvalidParameter {
            name: "first step (step indices beyond usize)",
            value: first_step as f64,
        });
    }
    let n = dynamics.state_dim();
    let m = measurement.meas_dim();
    // `Dyn` sizes meet here: every state must have the dynamics' size before a model sees it,
    // and the Jacobians the sizes the products need, or nalgebra would panic on the product.
    for state in states {
        kalibra_linalg::check_dim(n.value(), state.nrows(), "state")?;
    }
    let mut info = OMatrix::<f64, N, N>::zeros_generic(n, n);
    for (i, pair) in states.windows(2).enumerate() {
        let k = first_step + i + 1;
        let f = dynamics.jacobian(k - 1, &pair[0]);
        let h = measurement.jacobian(k, &pair[1]);
        kalibra_linalg::check_dim(n.value(), f.ncols(), "transition Jacobian F columns")?;
        kalibra_linalg::check_dim(n.value(), h.ncols(), "measurement Jacobian H columns")?;
        kalibra_linalg::check_dim(m.value(), h.nrows(), "measurement Jacobian H rows")?;
        let r = Covariance::named(
            measurement.noise_cov(k, &pair[1]),
            "measurement noise covariance R",
        )?;
        let hf = h * f;
        // (H F)^T R^-1 (H F) through one solve with the factor of R.
        info += hf.transpose() * r.solve(&hf)?;
    }
    info /= (states.len() - 1) as f64;
    kalibra_linalg::symmetrize(&mut info);
    let info = Covariance::named(info, "averaged information matrix of P_ad")?;
    let p = info.inverse();
    // Information near the smallest normal number has an inverse beyond f64's range.
    check_finite(&p, "P_ad (beyond f64's range)")?;
    Ok(p)
}

/// The adaptive process noise `Q_ad` (Saha, Ghosh and Goswami 2014, eq 23):
/// `(1/n) sum_{k=1..n} [Q_guess - (P+_k - P-_k)]` over the `(P-_k, P+_k)` pairs of a filter
/// run with `Q = Q_guess` (the method starts that filter from [`p_ad`]). The result is
/// symmetrised; it need not be positive semi-definite, and is not checked (the value is
/// returned as computed, for the caller to judge).
///
/// # Errors
/// [`TuningError::TooShort`] for no pairs; [`TuningError::Linalg`] for a `q_guess` that is not
/// square, matrices whose rows or columns differ from it, and for a `q_guess`, prior or
/// posterior that is not a covariance (non-finite, asymmetric or indefinite:
/// [`check_covariance`], semi-definite).
pub fn q_ad<'a, N: Dim>(
    q_guess: &OMatrix<f64, N, N>,
    steps: impl IntoIterator<Item = (&'a OMatrix<f64, N, N>, &'a OMatrix<f64, N, N>)>,
) -> Result<OMatrix<f64, N, N>, TuningError>
where
    DefaultAllocator: Alloc<N>,
{
    kalibra_linalg::check_dim(q_guess.nrows(), q_guess.ncols(), "Q guess (square)")?;
    check_covariance(q_guess, "Q guess", Definiteness::SemiDefinite)?;
    let mut sum = q_guess.clone() * 0.0;
    let mut count = 0usize;
    for (prior, posterior) in steps {
        kalibra_linalg::check_dim(q_guess.nrows(), q_guess.ncols(), "Q guess (square)")?;
        kalibra_linalg::check_dim(q_guess.nrows(), prior.nrows(), "prior covariance")?;
        kalibra_linalg::check_dim(q_guess.ncols(), prior.ncols(), "prior covariance columns")?;
        kalibra_linalg::check_dim(q_guess.nrows(), posterior.nrows(), "posterior covariance")?;
        kalibra_linalg::check_dim(
            q_guess.ncols(),
            posterior.ncols(),
            "posterior covariance columns",
        )?;
        check_covariance(prior, "prior covariance", Definiteness::SemiDefinite)?;
        check_covariance(
            posterior,
            "posterior covariance",
            Definiteness::SemiDefinite,
        )?;
        sum += prior - posterior;
        count += 1;
    }
    if count == 0 {
        return Err(TuningError::TooShort {
            what: "Q_ad",
            needed: 1,
            got: 0,
        });
    }
    let mut q = q_guess + sum / count as f64;
    kalibra_linalg::symmetrize(&mut q);
    check_finite(&q, "Q_ad")?;
    Ok(q)
}

#[cfg(test)]
mod tests {
    /// `Dyn` sizes that disagree are errors naming the sizes, not panics inside nalgebra.
    #[test]
    fn p_ad_and_q_ad_check_dyn_sizes() {
        use kalibra_linalg::{DMatrix, DVector, Dyn};
        let cv = kalibra_models::Kinematic::constant_velocity(2, 1.0).unwrap();
        let f = cv.dynamics(Dyn(4)).unwrap();
        let h = cv
            .position_measurement(Dyn(4), Dyn(2), DMatrix::identity(2, 2))
            .unwrap();
        let good = vec![DVector::zeros(4), DVector::from_element(4, 1.0)];
        let r = p_ad(&f, &h, &good, 0);
        assert!(
            !matches!(
                r,
                Err(TuningError::Linalg(LinalgError::DimensionMismatch { .. }))
            ),
            "{r:?}"
        );
        let bad = vec![DVector::zeros(4), DVector::zeros(3)];
        assert!(matches!(
            p_ad(&f, &h, &bad, 0),
            Err(TuningError::Linalg(LinalgError::DimensionMismatch { .. }))
        ));
        let q = DMatrix::<f64>::identity(2, 2);
        let (square, wide) = (DMatrix::<f64>::identity(2, 2), DMatrix::<f64>::zeros(2, 3));
        assert!(q_ad(&q, [(&square, &square)]).is_ok());
        assert!(matches!(
            q_ad(&q, [(&wide, &square)]),
            Err(TuningError::Linalg(LinalgError::DimensionMismatch { .. }))
        ));
        let wide_guess = DMatrix::<f64>::zeros(2, 3);
        assert!(q_ad(&wide_guess, [(&wide, &wide)]).is_err());
    }

    /// `q_ad`'s covariances go through the shared check, so an indefinite or asymmetric
    /// guess or pair is an error rather than averaged into an `Ok`.
    #[test]
    fn q_ad_refuses_matrices_that_are_not_covariances() {
        let q = Matrix2::new(1.0, 0.0, 0.0, 1.0);
        let p = Matrix2::new(2.0, 0.5, 0.5, 1.0);
        assert!(q_ad(&q, [(&p, &q)]).is_ok());
        let indefinite = Matrix2::new(1.0, 2.0, 2.0, 1.0);
        let asymmetric = Matrix2::new(2.0, 0.5, 0.0, 1.0);
        for (guess, prior, posterior) in [
            (&indefinite, &p, &q),
            (&q, &indefinite, &q),
            (&q, &p, &asymmetric),
        ] {
            assert!(
                matches!(
                    q_ad(guess, [(prior, posterior)]),
                    Err(TuningError::Linalg(
                        LinalgError::NotPositiveSemiDefinite { .. }
                            | LinalgError::NotSymmetric { .. }
                    ))
                ),
                "{guess} {prior} {posterior}"
            );
        }
    }

    /// An absurd grid is refused before anything is allocated; the largest allowed is built.
    #[test]
    fn grid_size_is_checked_up_front() {
        for (range, step) in [
            (0.0..=1e300, 1e-300),
            (0.0..=1.0, 1e-12),
            (-1e308..=1e308, 1.0),
        ] {
            assert!(matches!(
                grid(range, step),
                Err(TuningError::InvalidParameter { .. })
            ));
        }
        let largest = grid(0.0..=(GRID_MAX_POINTS - 1) as f64, 1.0).unwrap();
        assert_eq!(largest.len(), GRID_MAX_POINTS);
        assert!(grid(0.0..=GRID_MAX_POINTS as f64, 1.0).is_err());
    }

    use super::*;
    use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
    use kalibra_models::{Kinematic, LinearObservation, ProcessNoise};

    #[test]
    fn grid_hits_both_ends_without_drift() {
        let g = grid(-13.0..=6.0, 0.01).unwrap();
        assert_eq!(g.len(), 1901);
        assert_eq!(g[0], -13.0);
        assert!((g[1900] - 6.0).abs() < 1e-12);
        assert!(grid(0.0..=1.0, 0.0).is_err());
        assert!(grid(1.0..=0.0, 0.1).is_err());
    }

    #[test]
    fn sweep_is_ordered_and_reports_the_first_failure() {
        let g: Vec<f64> = (0..100).map(f64::from).collect();
        let out = sweep(&g, 2, Ok::<_, std::fmt::Error>).unwrap();
        assert_eq!(out, g);
        let err = sweep(&g, 2, |p| {
            if p >= 40.0 {
                Err(std::fmt::Error)
            } else {
                Ok(p)
            }
        })
        .unwrap_err();
        assert!(matches!(err, SimError::Run { run: 40, .. }));
    }

    #[test]
    fn two_point_covariance_matches_the_textbook_blocks() {
        // Interleaved [x, vx, y, vy], full 2x2 R: the x-y cross terms follow R's off-diagonal.
        let r = Matrix2::new(4.0, 1.0, 1.0, 9.0);
        let Gaussian { mean: x, cov: p } = two_point_init::<4, 2>(
            &Vector2::new(0.0, 10.0),
            &Vector2::new(2.0, 16.0),
            &r,
            &r,
            2.0,
            [0, 2],
            [1, 3],
        )
        .unwrap();
        assert_eq!(x, Vector4::new(2.0, 1.0, 16.0, 3.0));
        let t = 2.0;
        let expect = |a: usize, b: usize| {
            Matrix2::new(
                r[(a, b)],
                r[(a, b)] / t,
                r[(a, b)] / t,
                2.0 * r[(a, b)] / (t * t),
            )
        };
        for (a, b) in [(0, 0), (0, 1), (1, 1)] {
            let block = p.fixed_view::<2, 2>(2 * a, 2 * b).into_owned();
            assert!(
                (block - expect(a, b)).abs().max() < 1e-12,
                "{a}{b}: {block}"
            );
        }
        assert!(two_point_init::<4, 2>(&x.xy(), &x.xy(), &r, &r, 2.0, [0, 0], [1, 3]).is_err());
        assert!(two_point_init::<4, 2>(&x.xy(), &x.xy(), &r, &r, 0.0, [0, 2], [1, 3]).is_err());
    }

    #[test]
    fn p_ad_is_the_inverse_averaged_information_and_rejects_unobservable_steps() {
        let cv = Kinematic::constant_velocity(2, 1.0)
            .unwrap()
            .noise(ProcessNoise::Discrete { q: 1.0 });
        let f = cv.dynamics(U4).unwrap();
        let states = vec![Vector4::zeros(); 4];
        // Positions only: one step's information (H F)^T R^-1 (H F) has rank 2 of 4.
        let h = cv
            .position_measurement(U4, U2, Matrix2::identity() * 4.0)
            .unwrap();
        assert!(matches!(
            p_ad(&f, &h, &states, 0),
            Err(TuningError::Linalg(LinalgError::NotPositiveDefinite { .. }))
        ));
        // Full state with R = 2 I: P_ad = 2 (F^T F)^-1.
        let full = LinearObservation::new(Matrix4::identity(), Matrix4::identity() * 2.0).unwrap();
        let p = p_ad(&f, &full, &states, 0).unwrap();
        let fm = cv.transition_matrix(U4).unwrap();
        let expect = (fm.transpose() * fm).try_inverse().unwrap() * 2.0;
        assert!((p - expect).abs().max() < 1e-12, "{p} vs {expect}");
        assert!(p_ad(&f, &full, &states[..1], 0).is_err());
    }

    #[test]
    fn q_ad_averages_the_covariance_drop() {
        let q = Matrix2::identity();
        let pairs = [
            (Matrix2::identity() * 3.0, Matrix2::identity()),
            (Matrix2::identity() * 5.0, Matrix2::identity()),
        ];
        let out = q_ad(&q, pairs.iter().map(|(a, b)| (a, b))).unwrap();
        assert_eq!(out, Matrix2::identity() * 4.0);
        assert!(q_ad(&q, std::iter::empty()).is_err());
    }
}
