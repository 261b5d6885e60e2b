//! The batched step as a pulp operation, shared by [`KfBatch`](super::KfBatch) and
//! [`EkfBatch`](super::EkfBatch): the same arithmetic, in the same order, whether the model
//! matrices are broadcast (a linear model shared by every lane) or given per lane (a
//! nonlinear model's Jacobians, evaluated at each lane's own estimate).

// The kernels index matrices as the formulas do (`a[i][k] b[k][j]`); iterator chains would
// hide the algebra and add closures, which must not leave the dispatched function.
#![allow(clippy::needless_range_loop)]

use pulp::{Simd, WithSimd};

use kalibra_linalg::simd::{LaneCholesky, Reciprocal};

use super::{BATCH, BatchStep, JLanes, Lanes};
pub(super) use kalibra_linalg::simd::{load, store};

/// The factor every KF and EKF kernel solves with: multiplications by the reciprocals of the
/// pivots ([`Reciprocal`]).
pub(super) type Factor<S, const D: usize> = LaneCholesky<S, D, Reciprocal>;

/// Where the kernel reads a model matrix: one matrix broadcast to every lane
/// (`&[[f64; C]; R]`), or one per lane (`&[[Lanes; C]; R]`).
pub(super) trait Operand<const R: usize, const C: usize> {
    /// Entry `(i, j)` for the lanes of chunk `c` (one vector of the instruction set).
    fn at<S: Simd>(&self, simd: S, c: usize, i: usize, j: usize) -> S::f64s;
}

impl<const R: usize, const C: usize> Operand<R, C> for &[[f64; C]; R] {
    #[inline(always)]
    fn at<S: Simd>(&self, simd: S, _c: usize, i: usize, j: usize) -> S::f64s {
        simd.splat_f64s(self[i][j])
    }
}

impl<const R: usize, const C: usize> Operand<R, C> for &[[Lanes; C]; R] {
    #[inline(always)]
    fn at<S: Simd>(&self, _simd: S, c: usize, i: usize, j: usize) -> S::f64s {
        load::<S>(&self[i][j], c)
    }
}

/// A matrix the kernel's products read entry by entry: values computed in the step
/// (`[[S::f64s; C]; R]`), or a model operand ([`Model`]).
pub(super) trait Entries<S: Simd, const R: usize, const C: usize> {
    /// Entry `(i, j)`.
    fn at(&self, i: usize, j: usize) -> S::f64s;
}

impl<S: Simd, const R: usize, const C: usize> Entries<S, R, C> for [[S::f64s; C]; R] {
    #[inline(always)]
    fn at(&self, i: usize, j: usize) -> S::f64s {
        self[i][j]
    }
}

/// A model operand for the lanes of chunk `c`, read where it is used: a broadcast entry is
/// splatted at its use (from memory into the instruction) rather than all 44 of W1's `F`,
/// `Q`, `H`, `R` up front, which held more vectors than there are registers and went to the
/// stack and back.
pub(super) struct Model<'a, O, S> {
    op: &'a O,
    simd: S,
    c: usize,
}

impl<O: Operand<R, C>, S: Simd, const R: usize, const C: usize> Entries<S, R, C>
    for Model<'_, O, S>
{
    #[inline(always)]
    fn at(&self, i: usize, j: usize) -> S::f64s {
        self.op.at(self.simd, self.c, i, j)
    }
}

/// The entries of `m` as values (for code that indexes rows).
#[inline(always)]
fn values<S: Simd, const R: usize, const C: usize>(
    simd: S,
    m: &impl Entries<S, R, C>,
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            out[i][j] = m.at(i, j);
        }
    }
    out
}

/// One batched step: `with_simd` is compiled once per instruction set.
///
/// With `PREDICT`, `P` is first predicted as `F P F^T + Q`. The mean and the innovation come
/// from one of two places:
/// * `innovation: None` (the KF): the kernel predicts `x = F x` (with `PREDICT`) and forms
///   `nu = z - H x` itself;
/// * `innovation: Some(nu)` (the EKF): the caller has already written each lane's predicted
///   mean `f(x)` into `x` and evaluated its innovation `nu = z (-) h(f(x))`.
pub(super) struct Kernel<'a, const N: usize, const M: usize, const PREDICT: bool, F, Q, H, R> {
    pub f: F,
    pub q: Q,
    pub h: H,
    pub r: R,
    pub innovation: Option<&'a [Lanes; M]>,
    pub x: &'a mut [Lanes; N],
    pub p: &'a mut [[Lanes; N]; N],
    pub z: &'a [Lanes; M],
    pub truth: &'a [Lanes; N],
    pub gain: &'a mut [[Lanes; M]; N],
    pub out: &'a mut BatchStep<N>,
    /// With `PREDICT`: where to write the J1/J2 step terms, or `None` to skip them.
    pub terms: Option<&'a mut JLanes<M>>,
}

// The helpers below use plain loops over arrays, never closures (`std::array::from_fn`): a
// closure is a function of its own, compiled for the baseline instruction set unless it is
// inlined, and one left out of line can make the AVX-512 kernel slower than the scalar one
// (`cargo xtask bench w1` times the batched study on each instruction set).

/// `sum_k a[i][k] b[k][j]`, accumulated in `k` order like nalgebra's small products, with a
/// fused multiply-add where the instruction set has one.
#[inline(always)]
pub(super) fn mul<S: Simd, const R: usize, const K: usize, const C: usize>(
    simd: S,
    a: &impl Entries<S, R, K>,
    b: &impl Entries<S, K, C>,
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            let mut s = simd.mul_f64s(a.at(i, 0), b.at(0, j));
            for k in 1..K {
                s = simd.mul_add_e_f64s(a.at(i, k), b.at(k, j), s);
            }
            out[i][j] = s;
        }
    }
    out
}

/// `a v` for a vector `v`.
#[inline(always)]
fn mul_vec<S: Simd, const R: usize, const K: usize>(
    simd: S,
    a: &impl Entries<S, R, K>,
    v: &[S::f64s; K],
) -> [S::f64s; R] {
    let mut out = [simd.splat_f64s(0.0); R];
    for i in 0..R {
        let mut s = simd.mul_f64s(a.at(i, 0), v[0]);
        for k in 1..K {
            s = simd.mul_add_e_f64s(a.at(i, k), v[k], s);
        }
        out[i] = s;
    }
    out
}

/// `a b^T`.
#[inline(always)]
pub(super) fn mul_t<S: Simd, const R: usize, const K: usize, const C: usize>(
    simd: S,
    a: &impl Entries<S, R, K>,
    b: &impl Entries<S, C, K>,
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            let mut s = simd.mul_f64s(a.at(i, 0), b.at(j, 0));
            for k in 1..K {
                s = simd.mul_add_e_f64s(a.at(i, k), b.at(j, k), s);
            }
            out[i][j] = s;
        }
    }
    out
}

/// `a + b`.
#[inline(always)]
pub(super) fn add<S: Simd, const R: usize, const C: usize>(
    simd: S,
    a: &impl Entries<S, R, C>,
    b: &impl Entries<S, R, C>,
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            out[i][j] = simd.add_f64s(a.at(i, j), b.at(i, j));
        }
    }
    out
}

/// `(m + m^T) / 2` on the off-diagonal, as `kalibra_linalg::symmetrize`.
#[inline(always)]
pub(super) fn symmetrize<S: Simd, const D: usize>(simd: S, m: &mut [[S::f64s; D]; D]) {
    let half = simd.splat_f64s(0.5);
    for j in 0..D {
        for i in (j + 1)..D {
            let mean = simd.mul_f64s(half, simd.add_f64s(m[i][j], m[j][i]));
            m[i][j] = mean;
            m[j][i] = mean;
        }
    }
}

#[inline(always)]
pub(super) fn norm_squared<S: Simd, const D: usize>(simd: S, w: &[S::f64s; D]) -> S::f64s {
    let mut s = simd.mul_f64s(w[0], w[0]);
    for v in &w[1..] {
        s = simd.mul_add_e_f64s(*v, *v, s);
    }
    s
}

/// The health test's four independent sums, begun with the measurement's health `hz`, the
/// NIS and the posterior mean (four sums keep the chain short: 0 + 0 is 0 and NaN stays NaN
/// in any order).
#[inline(always)]
fn mean_health<S: Simd, const N: usize>(
    simd: S,
    hz: S::f64s,
    nis: S::f64s,
    x_post: &[S::f64s; N],
) -> [S::f64s; 4] {
    let zero = simd.splat_f64s(0.0);
    let mut sums = [hz, zero, zero, zero];
    sums[1] = health(simd, sums[1], nis);
    for i in 0..N {
        sums[(2 + i) % 4] = health(simd, sums[(2 + i) % 4], x_post[i]);
    }
    sums
}

/// The health sums' total: 0 where every entry tested was finite, NaN elsewhere.
#[inline(always)]
fn total<S: Simd>(simd: S, sums: [S::f64s; 4]) -> S::f64s {
    simd.add_f64s(
        simd.add_f64s(sums[0], sums[1]),
        simd.add_f64s(sums[2], sums[3]),
    )
}

/// `sum v * 0`: 0 if every entry is finite, NaN otherwise.
#[inline(always)]
fn health<S: Simd>(simd: S, acc: S::f64s, v: S::f64s) -> S::f64s {
    simd.mul_add_e_f64s(v, simd.splat_f64s(0.0), acc)
}

/// The half of a KF step that no measurement enters: with `PREDICT`, the prior
/// `P- = (F P) F^T + Q` symmetrised (else `P` as it is), `S = H (P- H^T) + R` symmetrised and
/// its factor, the gain `K` by a solve with it, and the Joseph posterior
/// `(I - K H) P- (I - K H)^T + (K R) K^T` symmetrised (`KalmanCore::predict` and `update`).
/// The per-lane kernel and [`CovarianceSchedule`] both call it, so a schedule's entries are
/// the values every lane of the kernel computes.
pub(super) struct Covariance<S: Simd, const N: usize, const M: usize> {
    /// `P-` (or `P` without prediction).
    pub prior: [[S::f64s; N]; N],
    /// `F P F^T`, the propagated part of the prior (the J terms' `A_k`); `P` without
    /// prediction.
    pub propagated: [[S::f64s; N]; N],
    /// The Cholesky factor of `S`.
    pub ls: Factor<S, M>,
    /// `K`.
    pub gain: [[S::f64s; M]; N],
    /// `P+`.
    pub posterior: [[S::f64s; N]; N],
}

#[inline(always)]
pub(super) fn covariance<S: Simd, const N: usize, const M: usize, const PREDICT: bool>(
    simd: S,
    f: &impl Entries<S, N, N>,
    q: &impl Entries<S, N, N>,
    h: &impl Entries<S, M, N>,
    r: &impl Entries<S, M, M>,
    p: [[S::f64s; N]; N],
) -> Covariance<S, N, M> {
    let zero = simd.splat_f64s(0.0);
    let one = simd.splat_f64s(1.0);
    let mut p = p;
    let mut propagated = p;
    if PREDICT {
        let fp = mul(simd, f, &p);
        propagated = mul_t(simd, &fp, f);
        p = add(simd, &propagated, q);
        symmetrize(simd, &mut p);
    }
    // P H^T, S = H (P H^T) + R symmetrised, its factor (KalmanCore::update).
    let pht = mul_t(simd, &p, h);
    let mut s = add(simd, &mul(simd, h, &pht), r);
    symmetrize(simd, &mut s);
    let ls = Factor::new(simd, &s);
    // K = (S^-1 (P H^T)^T)^T, one column of (P H^T)^T (a row of P H^T) at a time.
    let mut gain = [[zero; M]; N];
    for i in 0..N {
        gain[i] = ls.solve(simd, &pht[i]);
    }
    // Joseph: (I - K H) P (I - K H)^T + (K R) K^T, symmetrised.
    let mut ikh = mul(simd, &gain, h);
    for i in 0..N {
        for j in 0..N {
            ikh[i][j] = simd.neg_f64s(ikh[i][j]);
        }
        ikh[i][i] = simd.add_f64s(ikh[i][i], one);
    }
    let ikhp = mul(simd, &ikh, &p);
    let kr = mul(simd, &gain, r);
    let mut posterior = add(simd, &mul_t(simd, &ikhp, &ikh), &mul_t(simd, &kr, &gain));
    symmetrize(simd, &mut posterior);
    Covariance {
        prior: p,
        propagated,
        ls,
        gain,
        posterior,
    }
}

/// `nu = z - H x` for the lanes of chunk `c`, and the health of the measurement (0 if finite).
#[inline(always)]
fn innovate<S: Simd, const N: usize, const M: usize>(
    simd: S,
    h: &impl Entries<S, M, N>,
    x: &[S::f64s; N],
    zs: &[Lanes; M],
    c: usize,
) -> ([S::f64s; M], S::f64s) {
    let mut hz = simd.splat_f64s(0.0);
    let mut nu = [hz; M];
    let hx = mul_vec(simd, h, x);
    for i in 0..M {
        let zi = load::<S>(&zs[i], c);
        hz = health(simd, hz, zi);
        nu[i] = simd.sub_f64s(zi, hx[i]);
    }
    (nu, hz)
}

/// `x + K nu`.
#[inline(always)]
fn corrected<S: Simd, const N: usize, const M: usize>(
    simd: S,
    gain: &impl Entries<S, N, M>,
    x: &[S::f64s; N],
    nu: &[S::f64s; M],
) -> [S::f64s; N] {
    let knu = mul_vec(simd, gain, nu);
    let mut x_post = *x;
    for i in 0..N {
        x_post[i] = simd.add_f64s(x[i], knu[i]);
    }
    x_post
}

/// `truth - x+` for the lanes of chunk `c`.
#[inline(always)]
fn errors<S: Simd, const N: usize>(
    simd: S,
    truth: &[Lanes; N],
    c: usize,
    x_post: &[S::f64s; N],
) -> [S::f64s; N] {
    let mut e = *x_post;
    for i in 0..N {
        e[i] = simd.sub_f64s(load::<S>(&truth[i], c), x_post[i]);
    }
    e
}

impl<const N: usize, const M: usize, const PREDICT: bool, F, Q, H, R> WithSimd
    for Kernel<'_, N, M, PREDICT, F, Q, H, R>
where
    F: Operand<N, N>,
    Q: Operand<N, N>,
    H: Operand<M, N>,
    R: Operand<M, M>,
{
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Kernel {
            f: fs,
            q: qs,
            h: hs,
            r: rs,
            innovation,
            x: xs,
            p: ps,
            z: zs,
            truth,
            gain: gains,
            out,
            mut terms,
        } = self;
        let zero = simd.splat_f64s(0.0);
        for c in 0..BATCH / S::F64_LANES {
            // The model for these lanes, read where it is used.
            let f = Model { op: &fs, simd, c };
            let q = Model { op: &qs, simd, c };
            let h = Model { op: &hs, simd, c };
            let r = Model { op: &rs, simd, c };
            let mut x = [zero; N];
            let mut p = [[zero; N]; N];
            for i in 0..N {
                x[i] = load::<S>(&xs[i], c);
                for j in 0..N {
                    p[i][j] = load::<S>(&ps[i][j], c);
                }
            }
            // x- = F x (the KF; the EKF's caller wrote f(x)).
            if PREDICT && innovation.is_none() {
                x = mul_vec(simd, &f, &x);
            }
            // The prior, S's factor, the gain and the Joseph posterior: no measurement enters.
            // The prediction is kept even if the update fails (the selection below keeps `x`
            // and `p`, now the prior), as in the scalar filter.
            let Covariance {
                prior: p,
                propagated,
                ls,
                gain,
                posterior: p_post,
            } = covariance::<S, N, M, PREDICT>(simd, &f, &q, &h, &r, p);
            // nu = z - H x (or the caller's), the health of the measurement in it; x+ = x + K nu.
            let (nu, hz) = match innovation {
                None => innovate(simd, &h, &x, zs, c),
                Some(given) => {
                    let mut hz = zero;
                    let mut nu = [zero; M];
                    for i in 0..M {
                        hz = health(simd, hz, load::<S>(&zs[i], c));
                        nu[i] = load::<S>(&given[i], c);
                        hz = health(simd, hz, nu[i]);
                    }
                    (nu, hz)
                }
            };
            let x_post = corrected(simd, &gain, &x, &nu);
            // NIS through the factor of S.
            let nis = norm_squared(simd, &ls.solve_lower(simd, &nu));
            // Health: 0 if the measurement, the NIS (so S's factor) and the posterior are all
            // finite, NaN otherwise; a lane keeps its old estimate unless it is 0. P+ is
            // symmetric (`symmetrize` wrote one value to both triangles), so its upper triangle
            // says all; four independent sums keep the test short (0 + 0 is 0 and NaN stays
            // NaN in any order).
            let mut sums = mean_health(simd, hz, nis, &x_post);
            let mut t = 0;
            for i in 0..N {
                for j in i..N {
                    sums[t % 4] = health(simd, sums[t % 4], p_post[i][j]);
                    t += 1;
                }
            }
            let ok = total(simd, sums);
            let keep = simd.equal_f64s(ok, zero);
            // The common case, every lane healthy, stores the posterior without a selection
            // (and without waiting for the health test: the branch is predicted).
            let failing = simd.xor_m64s(keep, simd.equal_f64s(zero, zero));
            if simd.first_true_m64s(failing) == S::F64_LANES {
                for i in 0..N {
                    store::<S>(&mut xs[i], c, x_post[i]);
                    for j in 0..N {
                        store::<S>(&mut ps[i][j], c, p_post[i][j]);
                    }
                }
            } else {
                for i in 0..N {
                    store::<S>(&mut xs[i], c, simd.select_f64s(keep, x_post[i], x[i]));
                    for j in 0..N {
                        store::<S>(
                            &mut ps[i][j],
                            c,
                            simd.select_f64s(keep, p_post[i][j], p[i][j]),
                        );
                    }
                }
            }
            // NEES of the truth against the posterior, through P+'s factor.
            let e = errors(simd, truth, c, &x_post);
            let lp = Factor::new(simd, &p_post);
            let nees = norm_squared(simd, &lp.solve_lower(simd, &e));
            store::<S>(&mut out.nis, c, nis);
            store::<S>(&mut out.nees, c, nees);
            if let (true, Some(t)) = (PREDICT, terms.as_deref_mut()) {
                let (h, r, q) = (values(simd, &h), values(simd, &r), values(simd, &q));
                j_terms(simd, c, &h, &r, &propagated, &q, &p_post, t);
            }
            store::<S>(&mut out.health, c, ok);
            for i in 0..N {
                for j in 0..M {
                    store::<S>(&mut gains[i][j], c, gain[i][j]);
                }
            }
            for i in 0..N {
                store::<S>(&mut out.error[i], c, e[i]);
            }
        }
    }
}

/// `sum_j (M^-1 b_j)_j = tr(M^-1 B)` through `M`'s Cholesky factor, for a symmetric `B` (so its
/// rows are its columns).
#[inline(always)]
fn trace_solve<S: Simd, const D: usize>(
    simd: S,
    factor: &Factor<S, D>,
    b: &[[S::f64s; D]; D],
) -> S::f64s {
    let mut t = simd.splat_f64s(0.0);
    for j in 0..D {
        let y = factor.solve(simd, &b[j]);
        t = simd.add_f64s(t, y[j]);
    }
    t
}

/// `(H X) H^T`, symmetrised: a covariance seen through `H`, as the scalar record's
/// `compute_a`, `compute_b` and `compute_c`.
#[inline(always)]
fn projected<S: Simd, const N: usize, const M: usize>(
    simd: S,
    h: &[[S::f64s; N]; M],
    x: &[[S::f64s; N]; N],
) -> [[S::f64s; M]; M] {
    let mut out = mul_t(simd, &mul(simd, h, x), h);
    symmetrize(simd, &mut out);
    out
}

/// The J1/J2 step terms (paper 003) of chunk `c`, as `kalibra_metrics::j_step` forms them:
/// `A = H F P F^T H^T`, `B = H Q H^T`, `C = H P+ H^T`; `J1k = tr(S^-1 R)` with
/// `S = (A + B) + R`, `J2k = tr((A + B)^-1 B)`, `tr(N_k) = tr((A + B)^-1 (A - C))`, `tr(B)`.
/// A lane whose `A + B` is not positive definite gets NaN traces (its caller falls back to
/// the scalar function, which solves by LU there).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn j_terms<S: Simd, const N: usize, const M: usize>(
    simd: S,
    c: usize,
    h: &[[S::f64s; N]; M],
    r: &[[S::f64s; M]; M],
    propagated: &[[S::f64s; N]; N],
    q: &[[S::f64s; N]; N],
    p_post: &[[S::f64s; N]; N],
    t: &mut JLanes<M>,
) {
    let a = projected(simd, h, propagated);
    let b = projected(simd, h, q);
    let cc = projected(simd, h, p_post);
    let mut ab = add(simd, &a, &b);
    symmetrize(simd, &mut ab);
    let mut s = add(simd, &ab, r);
    symmetrize(simd, &mut s);
    let j1 = trace_solve(simd, &Factor::new(simd, &s), r);
    let lab = Factor::new(simd, &ab);
    let j2 = trace_solve(simd, &lab, &b);
    let mut a_minus_c = a;
    let mut tr_b = b[0][0];
    for i in 0..M {
        for j in 0..M {
            a_minus_c[i][j] = simd.sub_f64s(a[i][j], cc[i][j]);
            store::<S>(&mut t.a[i][j], c, a[i][j]);
            store::<S>(&mut t.b[i][j], c, b[i][j]);
            store::<S>(&mut t.c[i][j], c, cc[i][j]);
            store::<S>(&mut t.r[i][j], c, r[i][j]);
        }
        if i > 0 {
            tr_b = simd.add_f64s(tr_b, b[i][i]);
        }
    }
    let tr_n = trace_solve(simd, &lab, &a_minus_c);
    store::<S>(&mut t.j1, c, j1);
    store::<S>(&mut t.j2, c, j2);
    store::<S>(&mut t.tr_n, c, tr_n);
    store::<S>(&mut t.tr_b, c, tr_b);
}

/// One update of a [`KfSchedule`](super::KfSchedule): what [`covariance`] and the factor of
/// `P+` give every lane that starts the update from the schedule's covariance, as plain
/// numbers (broadcast again where they are used).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct ScheduleStep<const N: usize, const M: usize> {
    /// Whether the update was preceded by a prediction.
    pub predicted: bool,
    /// `P-` (or `P` without prediction): what a lane whose update fails keeps.
    pub prior: [[f64; N]; N],
    /// `K`.
    pub gain: [[f64; M]; N],
    /// The factor of `S` and the reciprocals of its diagonal.
    pub ls: ([[f64; M]; M], [f64; M]),
    /// `P+`.
    pub posterior: [[f64; N]; N],
    /// The factor of `P+` (for the NEES) and the reciprocals of its diagonal; NaN where `P+`
    /// has none, as the kernel's.
    pub lp: ([[f64; N]; N], [f64; N]),
}

impl<const N: usize, const M: usize> ScheduleStep<N, M> {
    /// Whether a lane's update from this step's covariance can fail only through its own
    /// measurement: the prior, gain, factor of `S` and posterior are all finite (the NEES
    /// factor may be NaN: the kernel's NEES is then NaN for every lane, an error of the NEES
    /// alone).
    fn is_finite(&self) -> bool {
        let matrix = |m: &[[f64; N]; N]| m.iter().flatten().all(|v| v.is_finite());
        matrix(&self.prior)
            && matrix(&self.posterior)
            && self.gain.iter().flatten().all(|v| v.is_finite())
            && self
                .ls
                .0
                .iter()
                .flatten()
                .chain(&self.ls.1)
                .all(|v| v.is_finite())
    }
}

/// Lane 0 of a vector.
#[inline(always)]
fn first<S: Simd>(v: S::f64s) -> f64 {
    let mut lanes = [0.0; BATCH];
    store::<S>(&mut lanes, 0, v);
    lanes[0]
}

#[inline(always)]
fn first_matrix<S: Simd, const R: usize, const C: usize>(m: &[[S::f64s; C]; R]) -> [[f64; C]; R] {
    let mut out = [[0.0; C]; R];
    for i in 0..R {
        for j in 0..C {
            out[i][j] = first::<S>(m[i][j]);
        }
    }
    out
}

#[inline(always)]
fn first_vector<S: Simd, const D: usize>(v: &[S::f64s; D]) -> [f64; D] {
    let mut out = [0.0; D];
    for i in 0..D {
        out[i] = first::<S>(v[i]);
    }
    out
}

/// Every entry of `m` broadcast.
#[inline(always)]
fn splat_matrix<S: Simd, const R: usize, const C: usize>(
    simd: S,
    m: &[[f64; C]; R],
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            out[i][j] = simd.splat_f64s(m[i][j]);
        }
    }
    out
}

#[inline(always)]
fn splat_vector<S: Simd, const D: usize>(simd: S, v: &[f64; D]) -> [S::f64s; D] {
    let mut out = [simd.splat_f64s(0.0); D];
    for i in 0..D {
        out[i] = simd.splat_f64s(v[i]);
    }
    out
}

/// Builds a schedule: an update from `P0`, then predictions and updates, through
/// [`covariance`] on one vector of the instruction set (every lane holds the same numbers),
/// stopping before the first step whose covariance is not finite.
pub(super) struct BuildSchedule<'a, const N: usize, const M: usize> {
    pub f: &'a [[f64; N]; N],
    pub q: &'a [[f64; N]; N],
    pub h: &'a [[f64; N]; M],
    pub r: &'a [[f64; M]; M],
    pub p0: &'a [[f64; N]; N],
    pub updates: usize,
    pub out: &'a mut Vec<ScheduleStep<N, M>>,
}

impl<const N: usize, const M: usize> WithSimd for BuildSchedule<'_, N, M> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let f = Model {
            op: &self.f,
            simd,
            c: 0,
        };
        let q = Model {
            op: &self.q,
            simd,
            c: 0,
        };
        let h = Model {
            op: &self.h,
            simd,
            c: 0,
        };
        let r = Model {
            op: &self.r,
            simd,
            c: 0,
        };
        let mut p = splat_matrix(simd, self.p0);
        for k in 0..self.updates {
            let cov = if k == 0 {
                covariance::<S, N, M, false>(simd, &f, &q, &h, &r, p)
            } else {
                covariance::<S, N, M, true>(simd, &f, &q, &h, &r, p)
            };
            let lp = Factor::new(simd, &cov.posterior);
            let step = ScheduleStep {
                predicted: k > 0,
                prior: first_matrix::<S, N, N>(&cov.prior),
                gain: first_matrix::<S, N, M>(&cov.gain),
                ls: (
                    first_matrix::<S, M, M>(&cov.ls.l),
                    first_vector::<S, M>(&cov.ls.inv),
                ),
                posterior: first_matrix::<S, N, N>(&cov.posterior),
                lp: (
                    first_matrix::<S, N, N>(&lp.l),
                    first_vector::<S, N>(&lp.inv),
                ),
            };
            if !step.is_finite() {
                break;
            }
            self.out.push(step);
            p = cov.posterior;
        }
    }
}

/// A KF step of lanes that start it from a schedule's covariance: only the means are the
/// lanes' own (`x- = F x`, `nu = z - H x`, `x+ = x + K nu`, the NIS and NEES through the
/// schedule's factors), computed by the same functions in the same order as [`Kernel`], so
/// every lane's numbers are the kernel's to the bit.
pub(super) struct Scheduled<'a, const N: usize, const M: usize, const PREDICT: bool> {
    pub f: &'a [[f64; N]; N],
    pub h: &'a [[f64; N]; M],
    pub step: &'a ScheduleStep<N, M>,
    pub x: &'a mut [Lanes; N],
    pub z: &'a [Lanes; M],
    pub truth: &'a [Lanes; N],
    pub out: &'a mut BatchStep<N>,
}

impl<const N: usize, const M: usize, const PREDICT: bool> WithSimd
    for Scheduled<'_, N, M, PREDICT>
{
    /// Whether every lane's update succeeded.
    type Output = bool;

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) -> bool {
        let Scheduled {
            f: fs,
            h: hs,
            step,
            x: xs,
            z: zs,
            truth,
            out,
        } = self;
        let zero = simd.splat_f64s(0.0);
        let gain = splat_matrix(simd, &step.gain);
        let ls = Factor::from_parts(
            splat_matrix(simd, &step.ls.0),
            splat_vector(simd, &step.ls.1),
        );
        let lp = Factor::from_parts(
            splat_matrix(simd, &step.lp.0),
            splat_vector(simd, &step.lp.1),
        );
        let mut all_kept = true;
        for c in 0..BATCH / S::F64_LANES {
            let f = Model { op: &fs, simd, c };
            let h = Model { op: &hs, simd, c };
            let mut x = [zero; N];
            for i in 0..N {
                x[i] = load::<S>(&xs[i], c);
            }
            if PREDICT {
                x = mul_vec(simd, &f, &x);
            }
            let (nu, hz) = innovate(simd, &h, &x, zs, c);
            let x_post = corrected(simd, &gain, &x, &nu);
            let nis = norm_squared(simd, &ls.solve_lower(simd, &nu));
            // The kernel's health test without P+'s entries, which the schedule holds only
            // finite: 0 or NaN as the kernel's.
            let ok = total(simd, mean_health(simd, hz, nis, &x_post));
            let keep = simd.equal_f64s(ok, zero);
            for i in 0..N {
                store::<S>(&mut xs[i], c, simd.select_f64s(keep, x_post[i], x[i]));
            }
            let failing = simd.xor_m64s(keep, simd.equal_f64s(zero, zero));
            all_kept &= simd.first_true_m64s(failing) == S::F64_LANES;
            let e = errors(simd, truth, c, &x_post);
            let nees = norm_squared(simd, &lp.solve_lower(simd, &e));
            store::<S>(&mut out.nis, c, nis);
            store::<S>(&mut out.nees, c, nees);
            store::<S>(&mut out.health, c, ok);
            for i in 0..N {
                store::<S>(&mut out.error[i], c, e[i]);
            }
        }
        all_kept
    }
}
