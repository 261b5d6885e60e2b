//! The batched unscented Kalman filter: [`BATCH`] runs of one model, the sigma points
//! evaluated for all lanes at once and the unscented prediction and update stepped together,
//! with a fixed kappa or one chosen per lane from a grid (paper 001's adaptive UKFs).

// The kernels index matrices as the formulas do (`a[i][k] b[k][j]`); iterator chains would
// hide the algebra and add closures, which must not leave the dispatched function.
#![allow(clippy::needless_range_loop)]

use kalibra_linalg::simd::{Divide, LaneCholesky};
use kalibra_linalg::{LinalgError, SMatrix, SVector, SqrtMethod, sigma_sqrt};
use kalibra_models::lanes::{LaneDynamics, LaneSigmaMeasurement};
use pulp::{Simd, WithSimd};

use super::kernel::{Factor, add, load, mul, mul_t, norm_squared, store, symmetrize};
use super::lanes::{LaneState, lane_accessors, lane_estimates};
use super::{BATCH, BatchStep, Isa, Lanes};
use crate::{FilterError, KappaCriterion, KappaGrid, SigmaSet, SigmaWeights, UkfPrediction};

/// The per-lane state of a [`UkfBatch`] and its scratch, apart from the models so that a
/// pulp operation can borrow both.
#[derive(Clone, Debug)]
struct State<const N: usize, const M: usize> {
    lanes: LaneState<N, M>,
    /// The kappa of each lane's last successful update.
    kappa: [Option<f64>; BATCH],
    // The prediction's per-lane model evaluations.
    f: [[Lanes; N]; N],
    q: [[Lanes; N]; N],
    /// The unscented prediction's transformed points: `f(x)`, `f(x + spread L_j)`,
    /// `f(x - spread L_j)`, and a lane's prediction error (reported by the next update).
    fx0: [Lanes; N],
    fplus: [[Lanes; N]; N],
    fminus: [[Lanes; N]; N],
    predict_failure: [Option<FilterError>; BATCH],
    /// The prior's square root `L` (`L L^T = P-`) and whether it is the Cholesky factor (the
    /// semi-definite fallback of `sigma_sqrt` leaves the posterior criteria undefined).
    l: [[Lanes; N]; N],
    cholesky_prior: [bool; BATCH],
    r: [[Lanes; M]; M],
    /// `R`'s Cholesky factor (lower triangle) and whether it exists (positive pivots).
    lr: [[Lanes; M]; M],
    r_ok: [bool; BATCH],
    z0: [Lanes; M],
    /// The sigma points `x + spread L_j` and `x - spread L_j` of one column `j`.
    plus: [Lanes; N],
    minus: [Lanes; N],
    /// Their measurements as residuals from `z0`.
    dplus: [[Lanes; M]; N],
    dminus: [[Lanes; M]; N],
    /// One candidate's statistics.
    cand: Candidate<N, M>,
    /// The best candidate so far, per lane.
    best: Candidate<N, M>,
    best_value: Lanes,
    best_kappa: Lanes,
    has_best: [bool; BATCH],
    take: Lanes,
    /// The lane's error so far, and its first candidate error (what the scalar filter
    /// returns when every kappa fails).
    failure: [Option<FilterError>; BATCH],
    first_error: [Option<FilterError>; BATCH],
    out: BatchStep<N>,
}

/// The update at one kappa, lane by lane (the scalar `candidate`'s outputs).
#[derive(Clone, Copy, Debug)]
struct Candidate<const N: usize, const M: usize> {
    zhat: [Lanes; M],
    nu: [Lanes; M],
    pz: [[Lanes; M]; M],
    /// The diagonal of `Pz`'s Cholesky factor (positive and finite where it exists).
    pz_diag: [Lanes; M],
    pxz: [[Lanes; M]; N],
    gain: [[Lanes; M]; N],
    mean: [Lanes; N],
    cov: [[Lanes; N]; N],
    nis: Lanes,
    /// `|L^-1 K nu|^2` (the prior's term of the posterior criteria).
    prior_term: Lanes,
    /// `e^T R^-1 e`, `e = z (-) h(x+)`.
    meas_term: Lanes,
}

impl<const N: usize, const M: usize> Candidate<N, M> {
    fn new() -> Self {
        Self {
            zhat: [[0.0; BATCH]; M],
            nu: [[0.0; BATCH]; M],
            pz: [[[0.0; BATCH]; M]; M],
            pz_diag: [[0.0; BATCH]; M],
            pxz: [[[0.0; BATCH]; M]; N],
            gain: [[[0.0; BATCH]; M]; N],
            mean: [[0.0; BATCH]; N],
            cov: [[[0.0; BATCH]; N]; N],
            nis: [0.0; BATCH],
            prior_term: [0.0; BATCH],
            meas_term: [0.0; BATCH],
        }
    }
}

/// The factor the update solves with: division by each pivot ([`Divide`]), as nalgebra's
/// Cholesky and triangular solves divide (the batch kernel multiplies by reciprocals): with
/// the order of operations of the scalar UKF, a lane then reproduces the scalar filter's
/// numbers to the last bit where no fused multiply-add intervenes, which keeps an adaptive
/// kappa's choice the scalar's even between close candidates (`tests/batch_ukf.rs`).
type Chol<S, const D: usize> = LaneCholesky<S, D, Divide>;

/// `sum w_i^2` in index order, without fused multiply-adds (nalgebra's `norm_squared`).
#[inline(always)]
fn sum_squares<S: Simd, const D: usize>(simd: S, w: &[S::f64s; D]) -> S::f64s {
    let mut s = simd.mul_f64s(w[0], w[0]);
    for v in &w[1..] {
        s = simd.add_f64s(s, simd.mul_f64s(*v, *v));
    }
    s
}

#[inline(always)]
fn load_vec<S: Simd, const D: usize>(simd: S, a: &[Lanes; D], c: usize) -> [S::f64s; D] {
    let mut out = [simd.splat_f64s(0.0); D];
    for i in 0..D {
        out[i] = load::<S>(&a[i], c);
    }
    out
}

#[inline(always)]
fn load_mat<S: Simd, const R: usize, const C: usize>(
    simd: S,
    a: &[[Lanes; C]; R],
    c: usize,
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            out[i][j] = load::<S>(&a[i][j], c);
        }
    }
    out
}

#[inline(always)]
fn store_vec<S: Simd, const D: usize>(a: &mut [Lanes; D], c: usize, v: &[S::f64s; D]) {
    for i in 0..D {
        store::<S>(&mut a[i], c, v[i]);
    }
}

#[inline(always)]
fn store_mat<S: Simd, const R: usize, const C: usize>(
    a: &mut [[Lanes; C]; R],
    c: usize,
    v: &[[S::f64s; C]; R],
) {
    for i in 0..R {
        for j in 0..C {
            store::<S>(&mut a[i][j], c, v[i][j]);
        }
    }
}

/// The weighted scatter of sigma points about `mean`, in the scalar UKF's order: the central
/// point's deviation `d0` weighted `cov_center`, then every point of `sets` (the `+` points,
/// then the `-` points) weighted `other`, each term `(d_a d_b) W` without fused
/// multiply-adds. The unscented prediction's covariance and the update's `Pz` both call it.
#[inline(always)]
fn scatter<S: Simd, const D: usize, const P: usize>(
    simd: S,
    d0: &[S::f64s; D],
    sets: [&[[S::f64s; D]; P]; 2],
    mean: &[S::f64s; D],
    cov_center: S::f64s,
    other: S::f64s,
) -> [[S::f64s; D]; D] {
    let mut cov = [[simd.splat_f64s(0.0); D]; D];
    for a in 0..D {
        for b in 0..D {
            cov[a][b] = simd.mul_f64s(simd.mul_f64s(d0[a], d0[b]), cov_center);
        }
    }
    let mut d = *d0;
    for point in sets.into_iter().flatten() {
        for i in 0..D {
            d[i] = simd.sub_f64s(point[i], mean[i]);
        }
        for a in 0..D {
            for b in 0..D {
                let t = simd.mul_f64s(simd.mul_f64s(d[a], d[b]), other);
                cov[a][b] = simd.add_f64s(cov[a][b], t);
            }
        }
    }
    cov
}

/// The linearised prediction as a pulp operation: the model's `f(x)`, `F`, `Q` per lane, then
/// `F P F^T + Q` symmetrised (`KalmanCore::predict`'s order, the batch kernel's products).
struct Predict<'a, const N: usize, D> {
    dynamics: &'a D,
    k: usize,
    x: &'a mut [Lanes; N],
    p: &'a mut [[Lanes; N]; N],
    f: &'a mut [[Lanes; N]; N],
    q: &'a mut [[Lanes; N]; N],
}

impl<const N: usize, D: LaneDynamics<N>> WithSimd for Predict<'_, N, D> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        self.dynamics
            .predict_lanes(simd, self.k, self.x, self.f, self.q);
        for c in 0..BATCH / S::F64_LANES {
            let f = load_mat(simd, self.f, c);
            let q = load_mat(simd, self.q, c);
            let p = load_mat(simd, self.p, c);
            let fp = mul(simd, &f, &p);
            let mut pp = add(simd, &mul_t(simd, &fp, &f), &q);
            symmetrize(simd, &mut pp);
            store_mat::<S, N, N>(self.p, c, &pp);
        }
    }
}

/// The unscented prediction as a pulp operation, in the scalar `unscented_predict`'s order:
/// the posterior's square root, `f` at the mean and at the `2n` sigma points, their weighted
/// mean and scatter (symmetrised), then `+ Q` and symmetrised again (`KalmanCore`'s
/// prediction). `F` and `Q` are evaluated at the mean.
struct PredictUnscented<'a, const N: usize, const M: usize, D> {
    dynamics: &'a D,
    state: &'a mut State<N, M>,
    w: SigmaWeights,
}

impl<const N: usize, const M: usize, D: LaneDynamics<N>> WithSimd
    for PredictUnscented<'_, N, M, D>
{
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let PredictUnscented {
            dynamics,
            state: st,
            w,
        } = self;
        let k = st.lanes.k;
        let chunks = BATCH / S::F64_LANES;
        for c in 0..chunks {
            let p = load_mat(simd, &st.lanes.p, c);
            store_mat::<S, N, N>(&mut st.l, c, &Chol::new(simd, &p).l);
        }
        for lane in 0..BATCH {
            let finite = (0..N).all(|i| (0..=i).all(|j| st.l[i][j][lane].is_finite()));
            if !finite {
                predict_fallback(st, lane);
            }
        }
        st.fx0 = st.lanes.x;
        dynamics.predict_lanes(simd, k, &mut st.fx0, &mut st.f, &mut st.q);
        let spread = simd.splat_f64s(w.spread);
        for j in 0..N {
            for c in 0..chunks {
                for i in 0..N {
                    let x = load::<S>(&st.lanes.x[i], c);
                    let d = simd.mul_f64s(load::<S>(&st.l[i][j], c), spread);
                    store::<S>(&mut st.fplus[j][i], c, simd.add_f64s(x, d));
                    store::<S>(&mut st.fminus[j][i], c, simd.sub_f64s(x, d));
                }
            }
            dynamics.transition_lanes(simd, k, &mut st.fplus[j]);
            dynamics.transition_lanes(simd, k, &mut st.fminus[j]);
        }
        let (mean_center, cov_center) = (
            simd.splat_f64s(w.mean_center),
            simd.splat_f64s(w.cov_center),
        );
        let other = simd.splat_f64s(w.other);
        let zero = simd.splat_f64s(0.0);
        for c in 0..chunks {
            let x0 = load_vec(simd, &st.fx0, c);
            let plus = load_mat(simd, &st.fplus, c);
            let minus = load_mat(simd, &st.fminus, c);
            // The points in the scalar's scratch order: the + points, then the - points.
            let mut mean = [zero; N];
            for i in 0..N {
                mean[i] = simd.mul_f64s(x0[i], mean_center);
            }
            for xi in plus.iter().chain(minus.iter()) {
                for i in 0..N {
                    mean[i] = simd.add_f64s(mean[i], simd.mul_f64s(xi[i], other));
                }
            }
            let mut d0 = [zero; N];
            for i in 0..N {
                d0[i] = simd.sub_f64s(x0[i], mean[i]);
            }
            let mut cov = scatter(simd, &d0, [&plus, &minus], &mean, cov_center, other);
            symmetrize(simd, &mut cov);
            let q = load_mat(simd, &st.q, c);
            let mut p = add(simd, &cov, &q);
            symmetrize(simd, &mut p);
            store_vec::<S, N>(&mut st.lanes.x, c, &mean);
            store_mat::<S, N, N>(&mut st.lanes.p, c, &p);
        }
    }
}

/// The scalar `sigma_sqrt` for lane `lane`'s posterior before an unscented prediction (off
/// the hot path): its factor, or the lane's prediction error (its sigma points then collapse
/// onto the mean; the next update reports the error).
#[cold]
#[inline(never)]
fn predict_fallback<const N: usize, const M: usize>(st: &mut State<N, M>, lane: usize) {
    let p = SMatrix::<f64, N, N>::from_fn(|i, j| st.lanes.p[i][j][lane]);
    let l = match sigma_sqrt(&p, "covariance for sigma points") {
        Ok((l, _)) => l,
        Err(e) => {
            st.predict_failure[lane] = Some(FilterError::at(st.lanes.k, e));
            SMatrix::zeros()
        }
    };
    for i in 0..N {
        for j in 0..N {
            st.l[i][j][lane] = l[(i, j)];
        }
    }
}

/// The unscented update of every lane as a pulp operation.
struct Update<'a, const N: usize, const M: usize, H> {
    measurement: &'a H,
    state: &'a mut State<N, M>,
    candidates: &'a [(f64, SigmaWeights)],
    criterion: Option<KappaCriterion>,
    z: &'a [Lanes; M],
    truth: &'a [Lanes; N],
}

impl<const N: usize, const M: usize, H: LaneSigmaMeasurement<N, M>> WithSimd
    for Update<'_, N, M, H>
{
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Update {
            measurement: h,
            state: st,
            candidates,
            criterion,
            z,
            truth,
        } = self;
        let k = st.lanes.k;
        let chunks = BATCH / S::F64_LANES;
        let at = |e| FilterError::at(k, e);
        // The prior's square root: Cholesky across the lanes, and a health sum (`sum v * 0`:
        // 0 when the prior and its factor are finite, NaN otherwise) so that the lanes check
        // them one by one only when something is not finite.
        let zero = simd.splat_f64s(0.0);
        for c in 0..chunks {
            let p = load_mat(simd, &st.lanes.p, c);
            let l = Chol::new(simd, &p).l;
            let mut health = zero;
            for i in 0..N {
                health = simd.mul_add_e_f64s(load::<S>(&st.lanes.x[i], c), zero, health);
                for j in 0..N {
                    health = simd.mul_add_e_f64s(p[i][j], zero, health);
                    health = simd.mul_add_e_f64s(l[i][j], zero, health);
                }
            }
            store_mat::<S, N, N>(&mut st.l, c, &l);
            store::<S>(&mut st.take, c, health);
        }
        for lane in 0..BATCH {
            st.failure[lane] = None;
            st.first_error[lane] = None;
            st.has_best[lane] = false;
            st.best_value[lane] = f64::INFINITY;
            // A non-finite prediction is the scalar's prediction error (the scalar filter
            // stops there); the update then checks the measurement first.
            let healthy = st.take[lane] == 0.0;
            let prior_finite = healthy
                || (0..N).all(|i| {
                    st.lanes.x[i][lane].is_finite()
                        && (0..N).all(|j| st.lanes.p[i][j][lane].is_finite())
                });
            if let Some(e) = st.predict_failure[lane].take() {
                st.failure[lane] = Some(e);
            } else if !prior_finite {
                st.failure[lane] = Some(FilterError::NonFinite {
                    what: "predicted covariance (process noise Q?)",
                    step: k,
                });
            } else if (0..M).any(|i| !z[i][lane].is_finite()) {
                st.failure[lane] = Some(at(LinalgError::NonFinite {
                    what: "measurement",
                }));
            }
        }
        // A lane whose factor is not finite takes the scalar `sigma_sqrt` (its semi-definite
        // fallback, or its error).
        for lane in 0..BATCH {
            let finite = st.take[lane] == 0.0
                || (0..N).all(|i| (0..=i).all(|j| st.l[i][j][lane].is_finite()));
            st.cholesky_prior[lane] = finite;
            if !finite {
                prior_fallback(st, lane);
            }
        }
        // R and the central measurement at the prior mean.
        h.noise_lanes(simd, k, &st.lanes.x, &mut st.r);
        h.measure_lanes(simd, k, &st.lanes.x, &mut st.z0);
        for lane in 0..BATCH {
            if st.failure[lane].is_none()
                && (0..M).any(|i| (0..M).any(|j| !st.r[i][j][lane].is_finite()))
            {
                st.failure[lane] = Some(at(LinalgError::NonFinite {
                    what: "measurement noise covariance R",
                }));
            }
        }
        let posterior = matches!(
            criterion,
            Some(KappaCriterion::MaximumPosterior | KappaCriterion::PureMap)
        );
        if posterior {
            // R's factor, for e^T R^-1 e (the scalar's `Covariance::from_symmetric(R)`).
            for c in 0..chunks {
                let r = load_mat(simd, &st.r, c);
                store_mat::<S, M, M>(&mut st.lr, c, &Chol::new(simd, &r).l);
            }
            for lane in 0..BATCH {
                st.r_ok[lane] = (0..M).all(|i| {
                    let d = st.lr[i][i][lane];
                    d > 0.0 && d.is_finite()
                });
            }
        }
        for &(kappa, w) in candidates {
            candidate(simd, h, st, z, w, posterior);
            choose(st, kappa, criterion);
            if candidates.len() == 1 {
                // A fixed kappa: the candidate is the update (no copy into `best`).
                break;
            }
            // Move the lanes that chose this candidate into the best one.
            for c in 0..chunks {
                let take = simd.equal_f64s(load::<S>(&st.take, c), simd.splat_f64s(1.0));
                select_candidate::<S, N, M>(simd, take, &st.cand, &mut st.best, c);
            }
        }
        commit(simd, st, truth, candidates.len() == 1);
    }
}

/// The scalar `sigma_sqrt` for lane `lane`'s prior (off the hot path): its factor, or the
/// lane's error.
#[cold]
#[inline(never)]
fn prior_fallback<const N: usize, const M: usize>(st: &mut State<N, M>, lane: usize) {
    let p = SMatrix::<f64, N, N>::from_fn(|i, j| st.lanes.p[i][j][lane]);
    match sigma_sqrt(&p, "prior covariance for sigma points") {
        Ok((l, method)) => {
            st.cholesky_prior[lane] = method == SqrtMethod::Cholesky;
            for i in 0..N {
                for j in 0..N {
                    st.l[i][j][lane] = l[(i, j)];
                }
            }
        }
        Err(e) => {
            if st.failure[lane].is_none() {
                st.failure[lane] = Some(FilterError::at(st.lanes.k, e));
            }
            // Finite values keep the other lanes' arithmetic free of NaN traps; the lane's
            // result is discarded.
            for i in 0..N {
                for j in 0..N {
                    st.l[i][j][lane] = 0.0;
                }
            }
        }
    }
}

/// The unscented measurement statistics and update at weights `w`, for every lane, in the
/// scalar `candidate`'s order of operations.
#[inline(always)]
fn candidate<S: Simd, const N: usize, const M: usize, H: LaneSigmaMeasurement<N, M>>(
    simd: S,
    h: &H,
    st: &mut State<N, M>,
    z: &[Lanes; M],
    w: SigmaWeights,
    posterior: bool,
) {
    let k = st.lanes.k;
    let chunks = BATCH / S::F64_LANES;
    let spread = simd.splat_f64s(w.spread);
    // Sigma measurements as residuals from the central one: unwrapped around it.
    for j in 0..N {
        for c in 0..chunks {
            for i in 0..N {
                let x = load::<S>(&st.lanes.x[i], c);
                let d = simd.mul_f64s(load::<S>(&st.l[i][j], c), spread);
                store::<S>(&mut st.plus[i], c, simd.add_f64s(x, d));
                store::<S>(&mut st.minus[i], c, simd.sub_f64s(x, d));
            }
        }
        h.sigma_residual_lanes(simd, k, &st.plus, &st.z0, &mut st.dplus[j]);
        h.sigma_residual_lanes(simd, k, &st.minus, &st.z0, &mut st.dminus[j]);
    }
    let other = simd.splat_f64s(w.other);
    let cov_center = simd.splat_f64s(w.cov_center);
    let cross = simd.splat_f64s(w.spread * w.other);
    let zero = simd.splat_f64s(0.0);
    for c in 0..chunks {
        let dp = load_mat(simd, &st.dplus, c);
        let dm = load_mat(simd, &st.dminus, c);
        // dbar = sum W (Z_i - z0) over the points + then -, as the scalar's scratch order.
        let mut dbar = [zero; M];
        for d in dp.iter().chain(dm.iter()) {
            for a in 0..M {
                dbar[a] = simd.add_f64s(dbar[a], simd.mul_f64s(d[a], other));
            }
        }
        // Pz = dbar dbar^T W0c + sum W (d - dbar)(d - dbar)^T + R, symmetrised.
        // (The central residual's deviation is `-dbar`, whose products are dbar's exactly.)
        let pz = scatter(simd, &dbar, [&dp, &dm], &dbar, cov_center, other);
        let r = load_mat(simd, &st.r, c);
        let mut pz = add(simd, &pz, &r);
        symmetrize(simd, &mut pz);
        // Pxz = sum_j L_j (Z_j+ - Z_j-)^T W spread: the central point has no deviation and
        // dbar cancels in each pair.
        let mut pxz = [[zero; M]; N];
        for j in 0..N {
            let mut dz = [zero; M];
            for a in 0..M {
                dz[a] = simd.sub_f64s(dp[j][a], dm[j][a]);
            }
            for i in 0..N {
                let lij = load::<S>(&st.l[i][j], c);
                for a in 0..M {
                    let t = simd.mul_f64s(simd.mul_f64s(lij, dz[a]), cross);
                    pxz[i][a] = simd.add_f64s(pxz[i][a], t);
                }
            }
        }
        let mut zhat = [zero; M];
        for a in 0..M {
            zhat[a] = simd.add_f64s(load::<S>(&st.z0[a], c), dbar[a]);
        }
        store_vec::<S, M>(&mut st.cand.zhat, c, &zhat);
        store_mat::<S, M, M>(&mut st.cand.pz, c, &pz);
        store_mat::<S, N, M>(&mut st.cand.pxz, c, &pxz);
    }
    h.normalize_lanes(simd, &mut st.cand.zhat);
    h.residual_lanes(simd, z, &st.cand.zhat, &mut st.cand.nu);
    for c in 0..chunks {
        let pz = load_mat(simd, &st.cand.pz, c);
        let pxz = load_mat(simd, &st.cand.pxz, c);
        let nu = load_vec(simd, &st.cand.nu, c);
        let ls = Chol::new(simd, &pz);
        // K = (Pz^-1 Pxz^T)^T, a row of Pxz at a time (nalgebra's `solve` of the transpose).
        let mut gain = [[zero; M]; N];
        for i in 0..N {
            gain[i] = ls.solve(simd, &pxz[i]);
        }
        // K nu, in nalgebra's column order without fused multiply-adds.
        let mut knu = [zero; N];
        for i in 0..N {
            let mut s = simd.mul_f64s(gain[i][0], nu[0]);
            for a in 1..M {
                s = simd.add_f64s(s, simd.mul_f64s(gain[i][a], nu[a]));
            }
            knu[i] = s;
        }
        let mut mean = [zero; N];
        for i in 0..N {
            mean[i] = simd.add_f64s(load::<S>(&st.lanes.x[i], c), knu[i]);
        }
        // P+ = P- - (K Pz) K^T, symmetrised (as the scalar's commit does).
        let mut kpz = [[zero; M]; N];
        for i in 0..N {
            for b in 0..M {
                let mut s = simd.mul_f64s(gain[i][0], pz[0][b]);
                for a in 1..M {
                    s = simd.add_f64s(s, simd.mul_f64s(gain[i][a], pz[a][b]));
                }
                kpz[i][b] = s;
            }
        }
        let mut cov = [[zero; N]; N];
        for i in 0..N {
            for j in 0..N {
                let mut s = simd.mul_f64s(kpz[i][0], gain[j][0]);
                for a in 1..M {
                    s = simd.add_f64s(s, simd.mul_f64s(kpz[i][a], gain[j][a]));
                }
                cov[i][j] = simd.sub_f64s(load::<S>(&st.lanes.p[i][j], c), s);
            }
        }
        symmetrize(simd, &mut cov);
        let nis = sum_squares(simd, &ls.solve_lower(simd, &nu));
        let mut diag = [zero; M];
        for a in 0..M {
            diag[a] = ls.l[a][a];
        }
        store_vec::<S, M>(&mut st.cand.pz_diag, c, &diag);
        store_mat::<S, N, M>(&mut st.cand.gain, c, &gain);
        store_vec::<S, N>(&mut st.cand.mean, c, &mean);
        store_mat::<S, N, N>(&mut st.cand.cov, c, &cov);
        store::<S>(&mut st.cand.nis, c, nis);
        if posterior {
            // nu^T U nu = |L^-1 K nu|^2: the prior's density at x+.
            let l = Chol::from_lower(simd, load_mat(simd, &st.l, c));
            let prior = sum_squares(simd, &l.solve_lower(simd, &knu));
            store::<S>(&mut st.cand.prior_term, c, prior);
        }
    }
    if posterior {
        // e = z (-) h(x+), and e^T R^-1 e through R's factor.
        let mut zc = [[0.0; BATCH]; M];
        h.measure_lanes(simd, k, &st.cand.mean, &mut zc);
        let mut e = [[0.0; BATCH]; M];
        h.residual_lanes(simd, z, &zc, &mut e);
        for c in 0..chunks {
            let lr = Chol::from_lower(simd, load_mat(simd, &st.lr, c));
            let ev = load_vec(simd, &e, c);
            let q = sum_squares(simd, &lr.solve_lower(simd, &ev));
            store::<S>(&mut st.cand.meas_term, c, q);
        }
    }
}

/// Per lane: whether the candidate at `kappa` is valid (the scalar `candidate`'s errors) and,
/// with an adaptive kappa, whether its criterion beats the best so far; writes 1 into `take`
/// for the lanes that take it.
fn choose<const N: usize, const M: usize>(
    st: &mut State<N, M>,
    kappa: f64,
    criterion: Option<KappaCriterion>,
) {
    let k = st.lanes.k;
    for lane in 0..BATCH {
        st.take[lane] = 0.0;
        if st.failure[lane].is_some() {
            continue;
        }
        let c = &st.cand;
        // Pz's factor: nalgebra's Cholesky fails on a pivot that is not positive (NaN
        // included), `Covariance::from_symmetric` on a non-finite diagonal.
        let pz_ok = (0..M).all(|a| {
            let d = c.pz_diag[a][lane];
            d > 0.0 && d.is_finite()
        });
        let error = if !pz_ok {
            let zhat_finite = (0..M).all(|a| c.zhat[a][lane].is_finite());
            Some(FilterError::at(
                k,
                if zhat_finite {
                    LinalgError::NotPositiveDefinite {
                        what: "innovation covariance Pz",
                    }
                } else {
                    LinalgError::NonFinite {
                        what: "sigma-point measurements",
                    }
                },
            ))
        } else if (0..N).any(|i| (0..M).any(|a| !c.gain[i][a][lane].is_finite())) {
            let rhs = (0..N).all(|i| (0..M).all(|a| c.pxz[i][a][lane].is_finite()));
            Some(FilterError::at(
                k,
                LinalgError::NonFinite {
                    what: if rhs { "solution" } else { "right-hand side" },
                },
            ))
        } else {
            None
        };
        if let Some(e) = error {
            st.first_error[lane].get_or_insert(e);
            continue;
        }
        let Some(criterion) = criterion else {
            st.take[lane] = 1.0;
            st.best_kappa[lane] = kappa;
            st.has_best[lane] = true;
            continue;
        };
        // ln |Pz| = sum ln(l_ii^2) (nalgebra's `ln_determinant`), per lane: no SIMD logarithm.
        let mut log_det = 0.0;
        for a in 0..M {
            let d = c.pz_diag[a][lane];
            log_det += (d * d).ln();
        }
        let nis = c.nis[lane];
        // A non-finite term makes the value non-finite, so the scalar's distinction between
        // an infinite and a NaN quadratic form cannot change the choice.
        let value = criterion.value(log_det, nis, || {
            let prior = if st.cholesky_prior[lane] {
                c.prior_term[lane]
            } else {
                f64::NAN
            };
            let meas = if st.r_ok[lane] {
                c.meas_term[lane]
            } else {
                f64::NAN
            };
            (prior, meas)
        });
        let best = st.has_best[lane].then_some(st.best_value[lane]);
        if KappaCriterion::improves(value, best) {
            st.take[lane] = 1.0;
            st.best_value[lane] = value;
            st.best_kappa[lane] = kappa;
            st.has_best[lane] = true;
        }
    }
}

#[inline(always)]
fn select_vec<S: Simd, const D: usize>(
    simd: S,
    take: S::m64s,
    from: &[Lanes; D],
    to: &mut [Lanes; D],
    c: usize,
) {
    for i in 0..D {
        let v = simd.select_f64s(take, load::<S>(&from[i], c), load::<S>(&to[i], c));
        store::<S>(&mut to[i], c, v);
    }
}

/// Copies the lanes of chunk `c` where `take` is set from `from` to `to`.
#[inline(always)]
fn select_candidate<S: Simd, const N: usize, const M: usize>(
    simd: S,
    take: S::m64s,
    from: &Candidate<N, M>,
    to: &mut Candidate<N, M>,
    c: usize,
) {
    select_vec(simd, take, &from.zhat, &mut to.zhat, c);
    select_vec(simd, take, &from.nu, &mut to.nu, c);
    select_vec(simd, take, &from.mean, &mut to.mean, c);
    select_vec(simd, take, &from.pz_diag, &mut to.pz_diag, c);
    for i in 0..N {
        select_vec(simd, take, &from.gain[i], &mut to.gain[i], c);
        select_vec(simd, take, &from.cov[i], &mut to.cov[i], c);
    }
    let mut nis = [to.nis];
    select_vec(simd, take, &[from.nis], &mut nis, c);
    to.nis = nis[0];
}

/// Writes each lane's chosen update into the state (or its error into the step), then the
/// NEES of every lane against `truth` through `P+`'s factor, as the batch kernel forms it.
#[inline(always)]
fn commit<S: Simd, const N: usize, const M: usize>(
    simd: S,
    st: &mut State<N, M>,
    truth: &[Lanes; N],
    fixed: bool,
) {
    let k = st.lanes.k;
    if fixed {
        // The one candidate is the best: swap it in rather than copy it lane by lane.
        std::mem::swap(&mut st.cand, &mut st.best);
    }
    let chunks = BATCH / S::F64_LANES;
    for lane in 0..BATCH {
        if st.failure[lane].is_none() && !st.has_best[lane] {
            st.failure[lane] = Some(st.first_error[lane].take().unwrap_or(
                FilterError::NonFinite {
                    what: "adaptive kappa criterion (every grid value)",
                    step: k,
                },
            ));
        }
        if st.failure[lane].is_none() {
            // `KalmanCore::check_and_store`: a non-finite posterior is an error, blamed on
            // the innovation if that is not finite.
            let b = &st.best;
            let finite = (0..N).all(|i| {
                b.mean[i][lane].is_finite() && (0..N).all(|j| b.cov[i][j][lane].is_finite())
            });
            if !finite {
                let nu_finite = (0..M).all(|a| b.nu[a][lane].is_finite());
                st.failure[lane] = Some(FilterError::NonFinite {
                    what: if nu_finite {
                        "posterior estimate"
                    } else {
                        "innovation"
                    },
                    step: k,
                });
            }
        }
        st.take[lane] = if st.failure[lane].is_none() {
            st.kappa[lane] = Some(st.best_kappa[lane]);
            1.0
        } else {
            0.0
        };
    }
    for c in 0..chunks {
        let take = simd.equal_f64s(load::<S>(&st.take, c), simd.splat_f64s(1.0));
        select_vec(simd, take, &st.best.mean, &mut st.lanes.x, c);
        for i in 0..N {
            select_vec(simd, take, &st.best.cov[i], &mut st.lanes.p[i], c);
            select_vec(simd, take, &st.best.gain[i], &mut st.lanes.gain[i], c);
        }
        // NEES of the truth against the lane's state (its posterior where it succeeded).
        let x = load_vec(simd, &st.lanes.x, c);
        let p = load_mat(simd, &st.lanes.p, c);
        let mut e = [simd.splat_f64s(0.0); N];
        for i in 0..N {
            e[i] = simd.sub_f64s(load::<S>(&truth[i], c), x[i]);
        }
        let lp = Factor::new(simd, &p);
        let nees = norm_squared(simd, &lp.solve_lower(simd, &e));
        store::<S>(&mut st.out.nees, c, nees);
        store_vec::<S, N>(&mut st.out.error, c, &e);
    }
    st.out.k = k;
    st.out.nis = st.best.nis;
    for lane in 0..BATCH {
        st.out.health[lane] = if st.failure[lane].is_none() {
            0.0
        } else {
            f64::NAN
        };
        st.out.failure[lane] = st.failure[lane].clone();
        st.out.nees_failure[lane] =
            (!st.out.nees[lane].is_finite()).then_some(FilterError::NotPositiveDefinite {
                what: "posterior covariance P+",
                step: k,
            });
    }
}

/// [`BATCH`] unscented Kalman filters on one model, stepped together: the scalar
/// [`Ukf`](crate::Ukf)'s update (sigma measurements as residuals from the central one,
/// `Pz`, `Pxz`, `K` by Cholesky solve, `P+ = P- - K Pz K^T` symmetrised), with a fixed sigma
/// set or kappa chosen per lane from a grid ([`UkfBatch::with_adaptive_kappa`], paper 001's
/// UKF-ML and UKF-MPP), predicting as [`UkfPrediction`] says: the linearised
/// `x- = f(x+)`, `P- = F P+ F^T + Q` (the batch kernel's products), or the unscented transform
/// of the posterior's sigma points through `f` (the scalar's order of operations, `f` through
/// [`LaneDynamics::transition_lanes`]). After a lane's failed update its next prediction
/// agrees with the scalar's to rounding (the scalar carries the prior's split of `P` into
/// propagated and noise parts, which adds the same terms in another order).
///
/// The measurement is evaluated for all lanes at once through [`LaneSigmaMeasurement`]
/// ([`PerLane`](super::PerLane) of any scalar model, or a lane-wise model such as
/// [`Bearing`](kalibra_models::Bearing)); the dynamics through [`LaneDynamics`]. The update's
/// factorisations divide by their pivots and its sums follow the scalar's order without fused
/// multiply-adds, so a lane reproduces the scalar filter of its run to rounding, and an
/// adaptive lane chooses the kappa the scalar chooses. Per-lane errors as in the
/// [module docs](super): a failed lane keeps its prior and reports the scalar's error.
///
/// ```
/// use kalibra_filters::batch::{BATCH, Isa, PerLane, UkfBatch};
/// use kalibra_filters::{SigmaSet, UkfPrediction};
/// use kalibra_linalg::{Matrix2, Vector2};
/// use kalibra_models::{Bearing, BearingReference, LinearGaussian, Stationary};
/// use nalgebra::U2;
///
/// let dynamics = LinearGaussian::new(Matrix2::new(0.9, 0.0, 0.0, 1.0), Matrix2::identity() * 0.1)?;
/// let sensor = Bearing::new(U2, [0, 1], BearingReference::XAxis, 0.025, Stationary(Vector2::zeros()))?;
/// let mut ukf = UkfBatch::new(
///     Isa::detect(), dynamics, sensor, Vector2::new(20.0, 5.0), Matrix2::identity() * 0.1,
///     SigmaSet::recommended(2), UkfPrediction::Linearised,
/// )?;
/// let z = [[0.25; BATCH]; 1];
/// let step = ukf.predict_update(&z, &[[0.0; BATCH]; 2]);
/// assert!(step.all_ok());
/// assert_eq!(ukf.kappa(0), Some(1.0));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct UkfBatch<const N: usize, const M: usize, D, H> {
    dynamics: D,
    measurement: H,
    set: SigmaSet,
    prediction: UkfPrediction,
    /// The set's own weights (the unscented prediction's, adaptive or not).
    weights: SigmaWeights,
    /// The kappas an update tries and their weights: the set's own, or the grid's.
    candidates: Vec<(f64, SigmaWeights)>,
    criterion: Option<KappaCriterion>,
    state: Box<State<N, M>>,
}

impl<const N: usize, const M: usize, D, H> UkfBatch<N, M, D, H>
where
    D: LaneDynamics<N>,
    H: LaneSigmaMeasurement<N, M>,
{
    /// [`BATCH`] filters at step 0, each from the estimate `(x0, P0)`, with sigma set `set`,
    /// predicting as `prediction` says, on instruction set `isa`.
    ///
    /// # Errors
    /// [`FilterError::Unsupported`] if the CPU does not run `isa`; [`FilterError::Initial`] if `x0` is not
    /// finite or `P0` not symmetric positive semi-definite (the scalar check);
    /// [`FilterError::InvalidParameter`] for a sigma set invalid at dimension `N`.
    pub fn new(
        isa: Isa,
        dynamics: D,
        measurement: H,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        set: SigmaSet,
        prediction: UkfPrediction,
    ) -> Result<Self, FilterError> {
        let isa = super::checked_isa(isa)?;
        let w = set.weights(N)?;
        let lanes = LaneState::new(isa, &x0, p0)?;
        let zn = [[[0.0; BATCH]; N]; N];
        let state = State {
            lanes,
            kappa: [None; BATCH],
            f: zn,
            q: zn,
            fx0: [[0.0; BATCH]; N],
            fplus: zn,
            fminus: zn,
            predict_failure: std::array::from_fn(|_| None),
            l: zn,
            cholesky_prior: [true; BATCH],
            r: [[[0.0; BATCH]; M]; M],
            lr: [[[0.0; BATCH]; M]; M],
            r_ok: [true; BATCH],
            z0: [[0.0; BATCH]; M],
            plus: [[0.0; BATCH]; N],
            minus: [[0.0; BATCH]; N],
            dplus: [[[0.0; BATCH]; M]; N],
            dminus: [[[0.0; BATCH]; M]; N],
            cand: Candidate::new(),
            best: Candidate::new(),
            best_value: [0.0; BATCH],
            best_kappa: [0.0; BATCH],
            has_best: [false; BATCH],
            take: [0.0; BATCH],
            failure: std::array::from_fn(|_| None),
            first_error: std::array::from_fn(|_| None),
            out: BatchStep::new(),
        };
        Ok(Self {
            dynamics,
            measurement,
            set,
            prediction,
            weights: w,
            candidates: vec![(set.kappa(), w)],
            criterion: None,
            state: Box::new(state),
        })
    }

    /// The same filters choosing kappa at every update, per lane: the value of `grid`
    /// minimising `criterion`, with the scalar [`Ukf`](crate::Ukf)'s rules (strictly smaller
    /// wins, so ties go to the smaller kappa; a non-finite value never wins; a lane where
    /// every kappa fails fails with the first kappa's error). The prediction keeps the set's
    /// own kappa.
    ///
    /// # Errors
    /// [`FilterError::InvalidParameter`] if a grid value gives an invalid sigma set.
    pub fn with_adaptive_kappa(
        mut self,
        criterion: KappaCriterion,
        grid: &KappaGrid,
    ) -> Result<Self, FilterError> {
        self.candidates = grid
            .values()
            .iter()
            .map(|&kappa| Ok((kappa, self.set.with_kappa(kappa).weights(N)?)))
            .collect::<Result<_, FilterError>>()?;
        self.criterion = Some(criterion);
        Ok(self)
    }

    lane_accessors!(state.lanes);

    lane_estimates!(state.lanes);

    /// Lane `lane`'s gain `K` of its last successful update.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn gain(&self, lane: usize) -> SMatrix<f64, N, M> {
        self.state.lanes.gain(lane)
    }

    /// The kappa of lane `lane`'s last successful update (the chosen one when adapting), as
    /// the scalar filter's `last_kappa`; `None` before the first.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn kappa(&self, lane: usize) -> Option<f64> {
        self.state.kappa[lane]
    }

    /// Predicts every lane from step `k` to `k + 1`, then updates it with its measurement
    /// `z[i][lane]` and computes its NIS `nu^T Pz^-1 nu`, and its NEES against
    /// `truth[i][lane]` (pass zeros where there is no truth and ignore the NEES). A lane whose
    /// update fails keeps its prediction, as the scalar filter does.
    pub fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        let isa = self.state.lanes.isa;
        let st = &mut *self.state;
        match self.prediction {
            UkfPrediction::Linearised => isa.dispatch(Predict {
                dynamics: &self.dynamics,
                k: st.lanes.k,
                x: &mut st.lanes.x,
                p: &mut st.lanes.p,
                f: &mut st.f,
                q: &mut st.q,
            }),
            _ => isa.dispatch(PredictUnscented {
                dynamics: &self.dynamics,
                state: st,
                w: self.weights,
            }),
        }
        let st = &mut *self.state;
        st.lanes.k += 1;
        self.update(z, truth)
    }

    /// Updates every lane at the current step without a prediction (a filter whose first
    /// measurement is at its initial step), as [`UkfBatch::predict_update`] updates.
    pub fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        self.state.lanes.isa.dispatch(Update {
            measurement: &self.measurement,
            state: &mut self.state,
            candidates: &self.candidates,
            criterion: self.criterion,
            z,
            truth,
        });
        &self.state.out
    }
}
