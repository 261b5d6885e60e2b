//! The log-likelihood of a time-invariant linear-Gaussian model in one allocation-free loop,
//! the fast path of [`crate::log_likelihood_of`].
//!
//! # Why
//! Maximum likelihood evaluates the log-likelihood hundreds of times (every finite-difference
//! gradient, every line-search trial, the Hessian of the information). Through the generic
//! [`kalibra_filters::Kf`] on run-time sizes every step allocates its matrices, keeps a full
//! step record and factorises `S` by a general routine; the noise problem is small and
//! time-invariant, so this loop keeps every matrix in buffers allocated once per evaluation
//! and writes the products out by hand (`cargo xtask bench tune` times both).
//!
//! # Sizes
//! The loop is compiled for each small system (up to 6 states and 3 measurements), the size
//! chosen once per evaluation: with every length a constant the short products unroll, their
//! bounds checks fold away and the mean stays in registers, which is what the steady state's
//! few dozen operations per step need (`cargo xtask bench tune`). Other sizes run the same
//! code on run-time lengths.
//!
//! # The steady state
//! The covariance recursion does not depend on the measurements. Once the prior covariance at
//! an update equals the prior at the previous update (one prediction apart, no missing
//! measurement between) to eight units of rounding of every entry's scale, three updates in a row, the recursion has
//! reached its fixed point as closely as its own rounding lets it (it wanders there by a few
//! units of the last place, and seldom repeats to the bit): from there on the loop updates only
//! the mean with the stored gain and factor of `S`, and returns to the full recursion at the
//! first step without a measurement. A covariance wrong by `d` relative moves each update's
//! log-density by about `d` relative, so the sum stays within `1e-12` of the full recursion's
//! while the recursion converges at a rate below about `0.99` per step; slower recursions (a
//! variance near zero) do not meet the test within a log of any practical length, and run in
//! full.
//!
//! # The same number
//! The arithmetic is the filter's (predict `F P F^T + Q` symmetrised, `S = H P H^T + R`
//! symmetrised and factorised by Cholesky, the gain by a solve with that factor, the Joseph
//! update symmetrised), in another order of summation: the unit tests hold it to `1e-12`
//! relative of the filter's sum. Where this loop cannot vouch for its answer (a pivot of `S`
//! not clearly positive, anything not finite) it returns `None` and the caller runs the
//! filter, whose error names the run and step.

use crate::NoiseProblem;
use kalibra_filters::Start;
use kalibra_linalg::DMatrix;

/// The largest state dimension the loop takes; larger problems go through the filter, whose
/// kernels hand large products to faer.
pub(crate) const MAX_STATE: usize = 32;

/// A pivot of `S`'s Cholesky factor below this fraction of its diagonal entry sends the
/// evaluation to the filter, so that the filter decides (and names) a nearly singular `S`.
const PIVOT_FLOOR: f64 = 1e-10;

/// Two consecutive priors count as equal when no entry `(i, j)` differs by more than this many
/// units of rounding of `sqrt(P_ii P_jj)`, its natural scale: the recursion's own rounding
/// keeps it wandering by a few units of the last place about its fixed point, so equality to
/// the bit is seldom reached. A scale common to all entries (the largest) would let a small
/// variance settle off by many of its own units, which shifts every later step the same way
/// and the finite-difference gradient of the sum with it.
const STEADY_ULPS: f64 = 8.0;

/// Consecutive updates whose priors must count as equal before the steady state is taken.
const STEADY_HITS: usize = 3;

/// Whether the `n x n` prior `p` equals `prev` to [`STEADY_ULPS`] entry by entry.
#[inline(always)]
fn settled(p: &[f64], prev: &[f64], n: usize) -> bool {
    let (p, prev) = (&p[..n * n], &prev[..n * n]);
    let tol = STEADY_ULPS * f64::EPSILON;
    (0..n).all(|j| {
        (0..n).all(|i| {
            // Each root first: the product of two variances near 2^1000 overflows, which
            // would make every prior count as settled (`steady_state_is_scale_free`).
            let scale = p[i + i * n].abs().sqrt() * p[j + j * n].abs().sqrt();
            (p[i + j * n] - prev[i + j * n]).abs() <= tol * scale
        })
    })
}

/// The mean and the vectors of its update, held by value for `Fixed` sizes so that the
/// steady state keeps them in registers.
struct Mean<N: Dim, M: Dim> {
    x: N::Vector,
    xt: N::Vector,
    nu: M::Vector,
    w: M::Vector,
}

/// What an update needs of `S` besides the innovation: the gain, the factor of `S` and the
/// constant `m ln(2 pi) + ln det S` of the log-density.
#[derive(Clone)]
struct Factor {
    gain: Vec<f64>,
    l: Vec<f64>,
    constant: f64,
}

/// Column-major matrices of the loop, allocated once per evaluation.
struct Buffers {
    factor: Factor,
    p: Vec<f64>,
    fp: Vec<f64>,
    prev_prior: Vec<f64>,
    pht: Vec<f64>,
    s: Vec<f64>,
    ikh: Vec<f64>,
    ap: Vec<f64>,
    kr: Vec<f64>,
}

impl Buffers {
    fn new(n: usize, m: usize) -> Self {
        Self {
            factor: Factor {
                gain: vec![0.0; n * m],
                l: vec![0.0; m * m],
                constant: 0.0,
            },
            p: vec![0.0; n * n],
            fp: vec![0.0; n * n],
            prev_prior: vec![0.0; n * n],
            pht: vec![0.0; n * m],
            s: vec![0.0; m * m],
            ikh: vec![0.0; n * n],
            ap: vec![0.0; n * n],
            kr: vec![0.0; n * m],
        }
    }
}

/// A size of the loop's matrices: a constant (`Fixed`), so that the compiler unrolls the
/// products of a small system, or a `usize` known at run time.
trait Dim: Copy {
    /// A vector of this length.
    type Vector: AsRef<[f64]> + AsMut<[f64]>;
    fn get(self) -> usize;
    fn vector(self) -> Self::Vector;
}

#[derive(Clone, Copy)]
struct Fixed<const D: usize>;

impl<const D: usize> Dim for Fixed<D> {
    type Vector = [f64; D];
    #[inline(always)]
    fn get(self) -> usize {
        D
    }
    fn vector(self) -> [f64; D] {
        [0.0; D]
    }
}

impl Dim for usize {
    type Vector = Vec<f64>;
    #[inline(always)]
    fn get(self) -> usize {
        self
    }
    fn vector(self) -> Vec<f64> {
        vec![0.0; self]
    }
}

// The helpers below are inlined into [`counted_in`] and cut their slices to the exact sizes
// first, so that with `Fixed` sizes every length is a constant: the loops unroll and their
// bounds checks fold away.

/// `c = a b` for column-major `a` (`r x k`) and `b` (`k x cols`), summing over `k` in order.
#[inline(always)]
fn mul(a: &[f64], b: &[f64], c: &mut [f64], r: usize, k: usize, cols: usize) {
    mul_strided(a, b, c, r, k, cols, (1, k));
}

/// `c = a b^T` for column-major `a` (`r x k`) and `b` (`cols x k`), summing over `k` in order.
#[inline(always)]
fn mul_t(a: &[f64], b: &[f64], c: &mut [f64], r: usize, k: usize, cols: usize) {
    mul_strided(a, b, c, r, k, cols, (cols, 1));
}

/// `c = a B` where `B[l, j]` is `b[l * step.0 + j * step.1]` (`k x cols`, `b` holding
/// `k * cols` values), summing over `k` in order: [`mul`] and [`mul_t`] read `b` by these steps.
#[inline(always)]
fn mul_strided(
    a: &[f64],
    b: &[f64],
    c: &mut [f64],
    r: usize,
    k: usize,
    cols: usize,
    step: (usize, usize),
) {
    let (a, b, c) = (&a[..r * k], &b[..k * cols], &mut c[..r * cols]);
    for j in 0..cols {
        for i in 0..r {
            let mut v = 0.0;
            for l in 0..k {
                v += a[i + l * r] * b[l * step.0 + j * step.1];
            }
            c[i + j * r] = v;
        }
    }
}

/// `(m + m^T) / 2` in place.
#[inline(always)]
fn symmetrize(m: &mut [f64], n: usize) {
    let m = &mut m[..n * n];
    for j in 0..n {
        for i in (j + 1)..n {
            let mean = 0.5 * (m[i + j * n] + m[j + i * n]);
            m[i + j * n] = mean;
            m[j + i * n] = mean;
        }
    }
}

/// The lower Cholesky factor of the symmetric `s` into `l`; `None` unless every pivot is
/// finite and above [`PIVOT_FLOOR`] of its diagonal entry.
#[inline(always)]
fn cholesky(s: &[f64], l: &mut [f64], m: usize) -> Option<()> {
    let (s, l) = (&s[..m * m], &mut l[..m * m]);
    l.fill(0.0);
    for j in 0..m {
        let mut d = s[j + j * m];
        for k in 0..j {
            d -= l[j + k * m] * l[j + k * m];
        }
        // NaN fails both comparisons.
        let clear = d.is_finite() && d > PIVOT_FLOOR * s[j + j * m];
        if !clear {
            return None;
        }
        let ljj = d.sqrt();
        l[j + j * m] = ljj;
        for i in (j + 1)..m {
            let mut v = s[i + j * m];
            for k in 0..j {
                v -= l[i + k * m] * l[j + k * m];
            }
            l[i + j * m] = v / ljj;
        }
    }
    Some(())
}

/// Solves `L y = b` into `y`.
#[inline(always)]
fn forward(l: &[f64], b: &[f64], y: &mut [f64], m: usize) {
    let (l, b, y) = (&l[..m * m], &b[..m], &mut y[..m]);
    for i in 0..m {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i + k * m] * y[k];
        }
        y[i] = v / l[i + i * m];
    }
}

/// Solves `L^T y = b` in place.
#[inline(always)]
fn backward(l: &[f64], b: &mut [f64], m: usize) {
    let (l, b) = (&l[..m * m], &mut b[..m]);
    for i in (0..m).rev() {
        let mut v = b[i];
        for k in (i + 1)..m {
            v -= l[k + i * m] * b[k];
        }
        b[i] = v / l[i + i * m];
    }
}

/// The steady state: the factor of the update and the prior covariance that repeat at every
/// update.
struct Steady {
    factor: Factor,
    prior: Vec<f64>,
}

/// The sum of the updates' log-densities over every run with `Q = q` and `R = r`, or `None`
/// where the filter must decide (see the module docs).
pub(crate) fn log_likelihood(
    problem: &NoiseProblem,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<f64> {
    counted(problem, q, r).map(|(total, _)| total)
}

/// [`log_likelihood`] and the number of updates that ran in the steady state.
pub(crate) fn counted(
    problem: &NoiseProblem,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<(f64, usize)> {
    let n = problem.f().nrows();
    let m = problem.h().nrows();
    if n > MAX_STATE {
        return None;
    }
    // The loop compiled for each small size, chosen once per evaluation; other sizes run the
    // same code on run-time sizes.
    macro_rules! sized {
        ($(($a:literal, $b:literal)),* $(,)?) => {
            match (n, m) {
                $(($a, $b) => counted_in(Fixed::<$a>, Fixed::<$b>, problem, q, r),)*
                _ => counted_in(n, m, problem, q, r),
            }
        };
    }
    sized!(
        (1, 1),
        (2, 1),
        (2, 2),
        (3, 1),
        (3, 2),
        (3, 3),
        (4, 1),
        (4, 2),
        (4, 3),
        (4, 4),
        (5, 1),
        (5, 2),
        (5, 3),
        (6, 1),
        (6, 2),
        (6, 3),
    )
}

/// [`counted`] with `n` states and `m` measurements.
fn counted_in<N: Dim, M: Dim>(
    n: N,
    m: M,
    problem: &NoiseProblem,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<(f64, usize)> {
    // The mean apart from the matrices, so that the compiler keeps it in registers through the
    // steady state instead of storing and reloading it at every step (`cargo xtask bench tune`).
    let mut mean = Mean::<N, M> {
        x: n.vector(),
        xt: n.vector(),
        nu: m.vector(),
        w: m.vector(),
    };
    let (n, m) = (n.get(), m.get());
    let mut b = Buffers::new(n, m);
    let f = problem.f().as_slice();
    let h = problem.h().as_slice();
    let (q, r) = (q.as_slice(), r.as_slice());
    let m_ln_2pi = m as f64 * std::f64::consts::TAU.ln();
    let mut total = 0.0;
    let mut steady_updates = 0;
    let predict_first = problem.start() == Start::PredictFirst;
    for run in problem.runs() {
        mean.x.as_mut().copy_from_slice(problem.x0().as_slice());
        b.p.copy_from_slice(problem.p0().as_slice());
        symmetrize(&mut b.p, n);
        // Whether `prev_prior` holds the prior of the last update, one prediction before the
        // current one with no missing measurement between.
        let mut chained = false;
        let mut hits = 0;
        let mut steady: Option<Steady> = None;
        for (i, z) in run.iter().enumerate() {
            let predict = i > 0 || predict_first;
            if predict && let Some(st) = &steady {
                // x = F x; the covariance is the steady prior.
                predict_mean(&mut mean, f, n);
                if let Some(z) = z {
                    steady_updates += 1;
                    total += mean_update(&mut mean, &st.factor, h, z.as_slice(), n, m);
                } else {
                    // Back to the full recursion from the steady prior.
                    b.p.copy_from_slice(&st.prior);
                    steady = None;
                    chained = false;
                    hits = 0;
                }
                continue;
            }
            if predict {
                predict_mean(&mut mean, f, n);
                mul(f, &b.p, &mut b.fp, n, n, n);
                mul_t(&b.fp, f, &mut b.p, n, n, n);
                for (pij, qij) in b.p.iter_mut().zip(q) {
                    *pij += qij;
                }
                symmetrize(&mut b.p, n);
            } else {
                chained = false;
            }
            let Some(z) = z else {
                chained = false;
                hits = 0;
                continue;
            };
            if chained && settled(&b.p, &b.prev_prior, n) {
                hits += 1;
            } else {
                hits = 0;
            }
            let converged = hits >= STEADY_HITS;
            b.prev_prior.copy_from_slice(&b.p);
            chained = true;
            // P H^T, S = H P H^T + R.
            mul_t(&b.p, h, &mut b.pht, n, n, m);
            mul(h, &b.pht, &mut b.s, m, n, m);
            for (sij, rij) in b.s.iter_mut().zip(r) {
                *sij += rij;
            }
            symmetrize(&mut b.s, m);
            let fac = &mut b.factor;
            cholesky(&b.s, &mut fac.l, m)?;
            // K^T = S^-1 (P H^T)^T, row by row of P H^T.
            let (row_c, w) = (&mut mean.nu.as_mut()[..m], &mut mean.w.as_mut()[..m]);
            for row in 0..n {
                for (c, v) in row_c.iter_mut().enumerate() {
                    *v = b.pht[row + c * n];
                }
                forward(&fac.l, row_c, w, m);
                backward(&fac.l, w, m);
                for (c, wc) in w.iter().enumerate() {
                    fac.gain[row + c * n] = *wc;
                }
            }
            let log_det: f64 = 2.0 * (0..m).map(|j| fac.l[j + j * m].ln()).sum::<f64>();
            fac.constant = m_ln_2pi + log_det;
            // The mean's update with this step's gain.
            total += mean_update(&mut mean, &b.factor, h, z.as_slice(), n, m);
            // Joseph: (I - K H) P (I - K H)^T + K R K^T, symmetrised.
            let gain = &b.factor.gain;
            mul(gain, h, &mut b.ikh, n, m, n);
            for v in b.ikh.iter_mut() {
                *v = -*v;
            }
            for d in 0..n {
                b.ikh[d + d * n] += 1.0;
            }
            mul(&b.ikh, &b.p, &mut b.ap, n, n, n);
            mul_t(&b.ap, &b.ikh, &mut b.fp, n, n, n);
            mul(gain, r, &mut b.kr, n, m, m);
            mul_t(&b.kr, gain, &mut b.ap, n, m, n);
            for (pij, (a, k)) in b.p.iter_mut().zip(b.fp.iter().zip(&b.ap)) {
                *pij = a + k;
            }
            symmetrize(&mut b.p, n);
            if !(b.p.iter().all(|v| v.is_finite()) && mean.x.as_ref().iter().all(|v| v.is_finite()))
            {
                return None;
            }
            if converged {
                steady = Some(Steady {
                    factor: b.factor.clone(),
                    prior: b.prev_prior.clone(),
                });
            }
        }
    }
    total.is_finite().then_some((total, steady_updates))
}

/// `x = F x`.
#[inline(always)]
fn predict_mean<N: Dim, M: Dim>(mean: &mut Mean<N, M>, f: &[f64], n: usize) {
    mul(f, mean.x.as_ref(), mean.xt.as_mut(), n, n, 1);
    std::mem::swap(&mut mean.x, &mut mean.xt);
}

/// `x += K nu` with `nu = z - H x` and the update's factor; returns the update's
/// log-density.
#[inline(always)]
fn mean_update<N: Dim, M: Dim>(
    mean: &mut Mean<N, M>,
    factor: &Factor,
    h: &[f64],
    z: &[f64],
    n: usize,
    m: usize,
) -> f64 {
    let (z, gain) = (&z[..m], &factor.gain[..n * m]);
    let (x, nu, w) = (mean.x.as_mut(), mean.nu.as_mut(), mean.w.as_mut());
    let (x, nu, w) = (&mut x[..n], &mut nu[..m], &mut w[..m]);
    mul(h, x, nu, m, n, 1);
    for (v, zi) in nu.iter_mut().zip(z) {
        *v = zi - *v;
    }
    forward(&factor.l, nu, w, m);
    let quad: f64 = w.iter().map(|v| v * v).sum();
    for (&nc, kc) in nu.iter().zip(gain.chunks_exact(n)) {
        for (xi, ki) in x.iter_mut().zip(kc) {
            *xi += ki * nc;
        }
    }
    -0.5 * (factor.constant + quad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::likelihood::filter_log_likelihood;
    use crate::{CovarianceForm, Parametrisation, Run};
    use kalibra_linalg::DVector;
    use kalibra_models::{LinearGaussian, LinearObservation};
    use rand::RngExt;
    use rand_chacha::ChaCha8Rng;
    use rand_chacha::rand_core::SeedableRng;

    /// A 2-D constant-velocity target (4 states, positions measured) with noise through `G`,
    /// `runs` runs of `steps` steps, every `gap`-th step without a measurement (none if 0).
    fn problem(start: Start, runs: usize, steps: usize, gap: usize, seed: u64) -> NoiseProblem {
        let f = DMatrix::from_row_slice(
            4,
            4,
            &[
                1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
            ],
        );
        let h = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        let g = DMatrix::from_row_slice(4, 2, &[0.5, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 1.0]);
        let noise = Parametrisation::new(
            Some(g),
            CovarianceForm::diagonal(DMatrix::from_diagonal(&DVector::from_vec(vec![0.1, 0.3]))),
            CovarianceForm::full(DMatrix::from_row_slice(2, 2, &[2.0, 0.4, 0.4, 1.0])),
        )
        .unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let runs: Vec<Run> = (0..runs)
            .map(|_| {
                let mut pos = [0.0f64, 0.0];
                (0..steps)
                    .map(|k| {
                        pos[0] += 1.0 + rng.random_range(-0.5..0.5);
                        pos[1] += 0.5 + rng.random_range(-0.5..0.5);
                        (gap == 0 || k % gap != gap - 1).then(|| {
                            DVector::from_fn(2, |i, _| pos[i] + rng.random_range(-2.0..2.0))
                        })
                    })
                    .collect()
            })
            .collect();
        let p0 = DMatrix::from_diagonal(&DVector::from_vec(vec![10.0, 10.0, 4.0, 4.0]));
        NoiseProblem::new(f, h, DVector::zeros(4), p0, start, noise, runs).unwrap()
    }

    fn both(problem: &NoiseProblem, theta: &[f64]) -> ((f64, usize), f64) {
        let m = problem.noise().matrices(theta).unwrap();
        let dynamics = LinearGaussian::new(problem.f().clone(), m.q.clone()).unwrap();
        let sensor = LinearObservation::new(problem.h().clone(), m.r.clone()).unwrap();
        let fast = counted(problem, &m.q, &m.r).unwrap();
        // The same code on run-time sizes does the same operations in the same order.
        let (n, k) = (problem.f().nrows(), problem.h().nrows());
        assert_eq!(counted_in(n, k, problem, &m.q, &m.r), Some(fast));
        (
            fast,
            filter_log_likelihood(problem, &dynamics, &sensor).unwrap(),
        )
    }

    /// The loop and the filter give the same number to 1e-12 relative: with and without
    /// missing measurements, both starts, several runs, at several candidates; and the steady
    /// state is reached on the long logs, so that its path is what is compared.
    #[test]
    fn the_loop_equals_the_filter() {
        for (start, runs, steps, gap) in [
            (Start::UpdateFirst, 1, 2000, 0),
            (Start::PredictFirst, 3, 700, 0),
            (Start::UpdateFirst, 2, 900, 97),
            (Start::UpdateFirst, 2, 3000, 700),
            (Start::PredictFirst, 1, 40, 3),
        ] {
            let problem = problem(start, runs, steps, gap, 7);
            let base = problem.noise().start();
            for shift in [-3.0, 0.0, 0.5, 2.0] {
                let theta: Vec<f64> = base.iter().map(|t| t + shift).collect();
                let ((fast, steady), slow) = both(&problem, &theta);
                assert!(
                    (fast - slow).abs() <= 1e-12 * slow.abs(),
                    "{start:?} {runs}x{steps} gap {gap} shift {shift}: {fast} vs {slow}"
                );
                if gap == 0 || gap >= 700 {
                    assert!(
                        steady > runs * steps / 2,
                        "steady updates {steady} of {steps}"
                    );
                }
            }
        }
    }

    /// A singular `S` (no measurement noise and a measured state known exactly) is left to
    /// the filter, which names it.
    #[test]
    fn a_singular_s_is_left_to_the_filter() {
        let one = |v: f64| DMatrix::from_element(1, 1, v);
        let noise = Parametrisation::new(
            None,
            CovarianceForm::fixed(one(0.0)),
            CovarianceForm::fixed(one(0.0)),
        )
        .unwrap();
        let problem = NoiseProblem::new(
            one(1.0),
            one(1.0),
            DVector::zeros(1),
            one(0.0),
            Start::UpdateFirst,
            noise,
            vec![vec![Some(DVector::from_element(1, 1.0))]],
        )
        .unwrap();
        assert!(log_likelihood(&problem, &one(0.0), &one(0.0)).is_none());
        assert!(crate::log_likelihood(&problem, &[]).is_err());
    }
    /// A scalar walk at scale `2^k` (measurements and `x0` times `2^k`, every covariance
    /// times `2^(2k)`): every operation of the loop scales exactly, so the sum moves by
    /// `-N k ln 2` and the steady state starts at the same update, also where a product of
    /// two variances leaves f64.
    #[test]
    fn steady_state_is_scale_free() {
        let one = |v: f64| DMatrix::from_element(1, 1, v);
        let walk = |k: i32| {
            let s = 2f64.powi(k);
            let noise = Parametrisation::new(
                None,
                CovarianceForm::scaled(one(0.2 * s * s)),
                CovarianceForm::scaled(one(0.5 * s * s)),
            )
            .unwrap();
            let run = (0..40)
                .map(|i| {
                    let i = f64::from(i);
                    Some(DVector::from_element(1, s * (0.1 * i + (0.7 * i).sin())))
                })
                .collect();
            NoiseProblem::new(
                one(1.0),
                one(1.0),
                DVector::from_element(1, 0.05 * s),
                one(s * s),
                Start::PredictFirst,
                noise,
                vec![run],
            )
            .unwrap()
        };
        let at = |k: i32| {
            let problem = walk(k);
            let m = problem.noise().matrices(&[0.3, -0.2]).unwrap();
            counted(&problem, &m.q, &m.r).unwrap()
        };
        let (plain, steady) = at(0);
        assert!(steady > 0, "the plain walk reaches its steady state");
        for k in [-500, -300, 257, 300, 500] {
            let (scaled, scaled_steady) = at(k);
            let shift = 40.0 * f64::from(k) * std::f64::consts::LN_2;
            assert_eq!(scaled_steady, steady, "k = {k}");
            assert!(
                (scaled + shift - plain).abs() <= 1e-12 * shift.abs().max(1.0),
                "k = {k}: {scaled} + {shift} vs {plain}"
            );
        }
    }
}
