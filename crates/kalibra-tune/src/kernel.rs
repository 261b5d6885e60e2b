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
fn settled(p: &[f64], prev: &[f64], n: usize) -> bool {
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

/// Column-major matrices of the loop, allocated once per evaluation.
struct Buffers {
    x: Vec<f64>,
    xt: Vec<f64>,
    p: Vec<f64>,
    fp: Vec<f64>,
    prev_prior: Vec<f64>,
    pht: Vec<f64>,
    s: Vec<f64>,
    l: Vec<f64>,
    gain: Vec<f64>,
    ikh: Vec<f64>,
    ap: Vec<f64>,
    kr: Vec<f64>,
    nu: Vec<f64>,
    w: Vec<f64>,
}

impl Buffers {
    fn new(n: usize, m: usize) -> Self {
        Self {
            x: vec![0.0; n],
            xt: vec![0.0; n],
            p: vec![0.0; n * n],
            fp: vec![0.0; n * n],
            prev_prior: vec![0.0; n * n],
            pht: vec![0.0; n * m],
            s: vec![0.0; m * m],
            l: vec![0.0; m * m],
            gain: vec![0.0; n * m],
            ikh: vec![0.0; n * n],
            ap: vec![0.0; n * n],
            kr: vec![0.0; n * m],
            nu: vec![0.0; m],
            w: vec![0.0; m],
        }
    }
}

/// `c = a b` for column-major `a` (`r x k`) and `b` (`k x c`), summing over `k` in order.
/// Written over exact chunks, so that the short loops carry no bounds checks.
#[inline]
fn mul(a: &[f64], b: &[f64], c: &mut [f64], r: usize, k: usize) {
    for (cj, bj) in c.chunks_exact_mut(r).zip(b.chunks_exact(k)) {
        cj.fill(0.0);
        for (al, &blj) in a.chunks_exact(r).zip(bj) {
            for (ci, &ai) in cj.iter_mut().zip(al) {
                *ci += ai * blj;
            }
        }
    }
}

/// `c = a b^T` for column-major `a` (`r x k`) and `b` (`cols x k`), summing over `k` in order.
#[inline]
fn mul_t(a: &[f64], b: &[f64], c: &mut [f64], r: usize, cols: usize) {
    for (j, cj) in c.chunks_exact_mut(r).enumerate() {
        cj.fill(0.0);
        for (al, bl) in a.chunks_exact(r).zip(b.chunks_exact(cols)) {
            let bjl = bl[j];
            for (ci, &ai) in cj.iter_mut().zip(al) {
                *ci += ai * bjl;
            }
        }
    }
}

/// `(m + m^T) / 2` in place.
#[inline]
fn symmetrize(m: &mut [f64], n: usize) {
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
#[inline]
fn cholesky(s: &[f64], l: &mut [f64], m: usize) -> Option<()> {
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

/// Solves `L y = b` in place.
#[inline]
fn forward(l: &[f64], b: &mut [f64], m: usize) {
    for i in 0..m {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i + k * m] * b[k];
        }
        b[i] = v / l[i + i * m];
    }
}

/// Solves `L^T y = b` in place.
#[inline]
fn backward(l: &[f64], b: &mut [f64], m: usize) {
    for i in (0..m).rev() {
        let mut v = b[i];
        for k in (i + 1)..m {
            v -= l[k + i * m] * b[k];
        }
        b[i] = v / l[i + i * m];
    }
}

/// The steady state: the gain, the factor of `S`, `ln det S` and the prior covariance that
/// repeat at every update.
struct Steady {
    gain: Vec<f64>,
    l: Vec<f64>,
    log_det: f64,
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
    let f = problem.f().as_slice();
    let h = problem.h().as_slice();
    let (q, r) = (q.as_slice(), r.as_slice());
    let ln_2pi = std::f64::consts::TAU.ln();
    let mut b = Buffers::new(n, m);
    let mut total = 0.0;
    let mut steady_updates = 0;
    let predict_first = problem.start() == Start::PredictFirst;
    for run in problem.runs() {
        b.x.copy_from_slice(problem.x0().as_slice());
        b.p.copy_from_slice(problem.p0().as_slice());
        symmetrize(&mut b.p, n);
        // Whether `prev_prior` holds the prior of the last update, one prediction before the
        // current one with no missing measurement between.
        let mut chained = false;
        let mut hits = 0;
        let mut steady: Option<Steady> = None;
        for (i, z) in run.iter().enumerate() {
            let predict = i > 0 || predict_first;
            if predict && let Some(st) = steady.take() {
                // x = F x; the covariance is the steady prior.
                mul(f, &b.x, &mut b.xt, n, n);
                std::mem::swap(&mut b.x, &mut b.xt);
                if let Some(z) = z {
                    steady_updates += 1;
                    total +=
                        mean_update(&mut b, &st.gain, &st.l, st.log_det, h, z.as_slice(), ln_2pi);
                    steady = Some(st);
                } else {
                    // Back to the full recursion from the steady prior.
                    b.p.copy_from_slice(&st.prior);
                    chained = false;
                    hits = 0;
                }
                continue;
            }
            if predict {
                mul(f, &b.x, &mut b.xt, n, n);
                std::mem::swap(&mut b.x, &mut b.xt);
                mul(f, &b.p, &mut b.fp, n, n);
                mul_t(&b.fp, f, &mut b.p, n, n);
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
            mul_t(&b.p, h, &mut b.pht, n, m);
            mul(h, &b.pht, &mut b.s, m, n);
            for (sij, rij) in b.s.iter_mut().zip(r) {
                *sij += rij;
            }
            symmetrize(&mut b.s, m);
            cholesky(&b.s, &mut b.l, m)?;
            // K^T = S^-1 (P H^T)^T, row by row of P H^T.
            for row in 0..n {
                for c in 0..m {
                    b.w[c] = b.pht[row + c * n];
                }
                forward(&b.l, &mut b.w, m);
                backward(&b.l, &mut b.w, m);
                for c in 0..m {
                    b.gain[row + c * n] = b.w[c];
                }
            }
            let log_det: f64 = 2.0 * (0..m).map(|j| b.l[j + j * m].ln()).sum::<f64>();
            // The mean's update with this step's gain.
            let (gain, l) = (std::mem::take(&mut b.gain), std::mem::take(&mut b.l));
            total += mean_update(&mut b, &gain, &l, log_det, h, z.as_slice(), ln_2pi);
            (b.gain, b.l) = (gain, l);
            // Joseph: (I - K H) P (I - K H)^T + K R K^T, symmetrised.
            mul(&b.gain, h, &mut b.ikh, n, m);
            for v in b.ikh.iter_mut() {
                *v = -*v;
            }
            for d in 0..n {
                b.ikh[d + d * n] += 1.0;
            }
            mul(&b.ikh, &b.p, &mut b.ap, n, n);
            mul_t(&b.ap, &b.ikh, &mut b.fp, n, n);
            mul(&b.gain, r, &mut b.kr, n, m);
            mul_t(&b.kr, &b.gain, &mut b.ap, n, n);
            for (pij, (a, k)) in b.p.iter_mut().zip(b.fp.iter().zip(&b.ap)) {
                *pij = a + k;
            }
            symmetrize(&mut b.p, n);
            if !(b.p.iter().all(|v| v.is_finite()) && b.x.iter().all(|v| v.is_finite())) {
                return None;
            }
            if converged {
                steady = Some(Steady {
                    gain: b.gain.clone(),
                    l: b.l.clone(),
                    log_det,
                    prior: b.prev_prior.clone(),
                });
            }
        }
    }
    total.is_finite().then_some((total, steady_updates))
}

/// `x += K nu` with `nu = z - H x`, the gain `K` and the factor `L` of `S`; returns the
/// update's log-density.
#[inline]
fn mean_update(
    b: &mut Buffers,
    gain: &[f64],
    l: &[f64],
    log_det: f64,
    h: &[f64],
    z: &[f64],
    ln_2pi: f64,
) -> f64 {
    let (n, m) = (b.x.len(), b.nu.len());
    mul(h, &b.x, &mut b.nu, m, n);
    for (v, zi) in b.nu.iter_mut().zip(z) {
        *v = zi - *v;
    }
    b.w.copy_from_slice(&b.nu);
    forward(l, &mut b.w, m);
    let quad: f64 = b.w.iter().map(|v| v * v).sum();
    for c in 0..m {
        let nc = b.nu[c];
        for (xi, ki) in b.x.iter_mut().zip(&gain[c * n..(c + 1) * n]) {
            *xi += ki * nc;
        }
    }
    -0.5 * (m as f64 * ln_2pi + log_det + quad)
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
