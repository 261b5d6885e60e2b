//! J1/J2 metrics: their bounds, the identity `J1k + J2k = m - tr(N_k)` along a real Kalman
//! step, agreement of fixed-size and `Dyn` matrices, and the crossover of J1 and J2.
//!
//! Conditioning: every random input is built so that its condition number is bounded, which
//! makes the absolute tolerances below meaningful (rounding error is about condition number
//! times machine epsilon). `F = I + E` and `H = [I_m 0] + E` with `|E|_2 <= 0.5`, so their
//! singular values lie in `[0.5, 1.5]`; a positive definite factor-built matrix is
//! `G G^T / k + c I` with entries of `G` in `[-1, 1]` and `c >= 0.05`, so its condition number
//! is below `1 + k / c`; noise scales span at most four decades.

use kalibra_linalg::{
    Alloc, Covariance, DMatrix, DefaultAllocator, Dim, OMatrix, SMatrix, joseph_update, propagate,
    symmetrize,
};
use kalibra_metrics::{JStep, SweepPoint, crossover, j_step};
use proptest::collection::vec;
use proptest::prelude::*;

/// `I + 0.5 U / n` (rows x cols, identity on the leading diagonal) from entries `U` in
/// `[-1, 1]`: `|0.5 U / n|_2 <= 0.5 |U|_F / n <= 0.5`.
fn near_identity(rows: usize, cols: usize, u: &[f64]) -> DMatrix<f64> {
    let scale = 0.5 / rows.max(cols) as f64;
    DMatrix::from_fn(rows, cols, |i, j| {
        f64::from(u8::from(i == j)) + scale * u[i + rows * j]
    })
}

/// `scale (G G^T / cols + c I)` from a rows x cols factor with entries in `[-1, 1]`.
fn gram(rows: usize, cols: usize, g: &[f64], c: f64, scale: f64) -> DMatrix<f64> {
    let g = DMatrix::from_column_slice(rows, cols, g);
    let mut out = &g * g.transpose() / cols as f64;
    for i in 0..rows {
        out[(i, i)] += c;
    }
    symmetrize(&mut out);
    out * scale
}

/// `(A_k, B_k, C_k)`.
type Abc<M> = (OMatrix<f64, M, M>, OMatrix<f64, M, M>, OMatrix<f64, M, M>);

/// One real Kalman update: `A_k, B_k, C_k` from `F, P+_{k-1}, Q, H, R`, optimal gain, Joseph
/// form.
fn kalman_abc<N: Dim, M: Dim>(
    f: &OMatrix<f64, N, N>,
    p: &OMatrix<f64, N, N>,
    q: &OMatrix<f64, N, N>,
    h: &OMatrix<f64, M, N>,
    r: &OMatrix<f64, M, M>,
) -> Abc<M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let fpf = propagate(f, p);
    let mut prior = &fpf + q;
    symmetrize(&mut prior);
    let s = Covariance::new(propagate(h, &prior) + r).expect("S is positive definite");
    // K = P- H^T S^-1, so K^T = S^-1 H P- (S and P- symmetric).
    let k = s.solve(&(h * &prior)).expect("sizes agree").transpose();
    let posterior = joseph_update(&prior, &k, h, r);
    (
        propagate(h, &fpf),
        propagate(h, q),
        propagate(h, &posterior),
    )
}

/// Inputs of one Kalman update, as `Dyn` matrices.
#[derive(Clone, Debug)]
struct Case {
    f: DMatrix<f64>,
    p: DMatrix<f64>,
    q: DMatrix<f64>,
    h: DMatrix<f64>,
    r: DMatrix<f64>,
}

/// A Kalman update with state dimension `n`, `m` measurements and a process noise of rank `rq`
/// (rank-deficient when `rq < n`).
fn case(n: usize, m: usize, rq: usize) -> impl Strategy<Value = Case> {
    (
        vec(-1.0f64..1.0, n * n),
        vec(-1.0f64..1.0, n * n),
        vec(-1.0f64..1.0, n * rq),
        vec(-1.0f64..1.0, m * n),
        vec(-1.0f64..1.0, m * m),
        -2.0f64..1.0,
        -2.0f64..2.0,
    )
        .prop_map(move |(uf, gp, gq, uh, gr, log_q, log_r)| Case {
            f: near_identity(n, n, &uf),
            p: gram(n, n, &gp, 0.5, 1.0),
            q: gram(n, rq, &gq, 0.0, 10f64.powf(log_q)),
            h: near_identity(m, n, &uh),
            r: gram(m, m, &gr, 0.2, 10f64.powf(log_r)),
        })
}

fn any_case() -> impl Strategy<Value = Case> {
    (2usize..=6)
        .prop_flat_map(|n| (Just(n), 1..=n, 1..=n))
        .prop_flat_map(|(n, m, rq)| case(n, m, rq))
}

fn fixed<const R: usize, const C: usize>(d: &DMatrix<f64>) -> SMatrix<f64, R, C> {
    SMatrix::from_iterator(d.iter().copied())
}

/// Checks the identity, the bounds, and the traces against explicit inverses (for checking
/// only; the library never forms them).
fn check_kalman_step(j: &JStep, m: usize, a: &DMatrix<f64>, b: &DMatrix<f64>, r: &DMatrix<f64>) {
    let mf = m as f64;
    let tol = 1e-10 * mf;
    assert!(j.a_plus_b_definite);
    let gap = j.j1 + j.j2 - (mf - j.tr_n);
    assert!(gap.abs() <= tol, "J1 + J2 - (m - tr N) = {gap:e}");
    assert!(j.j1 >= -tol && j.j1 <= mf + tol, "J1k = {}", j.j1);
    assert!(j.j2 >= -tol && j.j2 <= mf + tol, "J2k = {}", j.j2);
    let ab = a + b;
    let s = &ab + r;
    let j1 = (s.try_inverse().unwrap() * r).trace();
    let j2 = (ab.try_inverse().unwrap() * b).trace();
    assert!((j.j1 - j1).abs() <= tol, "J1k {} vs {}", j.j1, j1);
    assert!((j.j2 - j2).abs() <= tol, "J2k {} vs {}", j.j2, j2);
    assert_eq!(j.tr_b, b.trace());
}

proptest! {
    /// (a) `0 <= J1k <= m` for `S = A + B + R` with `A`, `B` positive semi-definite (`A` of
    /// any rank, `B` positive definite so that `A + B` is invertible) and `R` positive
    /// definite.
    #[test]
    fn j1_lies_in_zero_to_m(
        (m, ra, ga, gb, gr) in (1usize..=6).prop_flat_map(|m| (1..=m).prop_flat_map(move |ra| (
            Just(m), Just(ra), vec(-1.0f64..1.0, m * ra), vec(-1.0f64..1.0, m * m),
            vec(-1.0f64..1.0, m * m),
        ))),
        scales in (-2.0f64..2.0, -2.0f64..2.0, -2.0f64..2.0),
    ) {
        let a = gram(m, ra, &ga, 0.0, 10f64.powf(scales.0));
        let b = gram(m, m, &gb, 0.05, 10f64.powf(scales.1));
        let r = gram(m, m, &gr, 0.05, 10f64.powf(scales.2));
        let j = j_step(&a, &b, &r, &DMatrix::zeros(m, m)).unwrap();
        let tol = 1e-10 * m as f64;
        prop_assert!(j.j1 >= -tol && j.j1 <= m as f64 + tol, "J1k = {}", j.j1);
        prop_assert!(j.a_plus_b_definite);
    }

    /// (b) `0 <= J2k <= m` for `A = H F P+ F^T H^T` from a positive semi-definite (possibly
    /// rank-deficient) `P+` and a positive definite `B`.
    #[test]
    fn j2_lies_in_zero_to_m(
        (n, m, rp, uf, gp, uh, gb) in (1usize..=6)
            .prop_flat_map(|n| (Just(n), 1..=n, 1..=n))
            .prop_flat_map(|(n, m, rp)| (
                Just(n), Just(m), Just(rp), vec(-1.0f64..1.0, n * n), vec(-1.0f64..1.0, n * rp),
                vec(-1.0f64..1.0, m * n), vec(-1.0f64..1.0, m * m),
            )),
        log_b in -2.0f64..2.0,
    ) {
        let f = near_identity(n, n, &uf);
        let p = gram(n, rp, &gp, 0.0, 1.0);
        let h = near_identity(m, n, &uh);
        let a = propagate(&h, &propagate(&f, &p));
        let b = gram(m, m, &gb, 0.05, 10f64.powf(log_b));
        let r = DMatrix::identity(m, m);
        let j = j_step(&a, &b, &r, &DMatrix::zeros(m, m)).unwrap();
        let tol = 1e-10 * m as f64;
        prop_assert!(j.j2 >= -tol && j.j2 <= m as f64 + tol, "J2k = {}", j.j2);
        prop_assert!(j.a_plus_b_definite);
    }

    /// (c) `J1k + J2k = m - tr(N_k)` to `1e-10 m` along one real Kalman step (optimal gain,
    /// Joseph form), with random sizes (`Dyn`), and the bounds on the same inputs.
    #[test]
    fn identity_holds_along_a_kalman_step(c in any_case()) {
        let m = c.h.nrows();
        let (a, b, cc) = kalman_abc(&c.f, &c.p, &c.q, &c.h, &c.r);
        let j = j_step(&a, &b, &c.r, &cc).unwrap();
        check_kalman_step(&j, m, &a, &b, &c.r);
    }

    /// (c, fixed sizes) The same identity with `n = 4`, `m = 2` in `SMatrix`, and the
    /// fixed-size results equal the `Dyn` results on the same inputs to rounding.
    #[test]
    fn identity_holds_with_fixed_sizes(c in (1usize..=4).prop_flat_map(|rq| case(4, 2, rq))) {
        let (a, b, cc) = kalman_abc(
            &fixed::<4, 4>(&c.f),
            &fixed::<4, 4>(&c.p),
            &fixed::<4, 4>(&c.q),
            &fixed::<2, 4>(&c.h),
            &fixed::<2, 2>(&c.r),
        );
        let j = j_step(&a, &b, &fixed::<2, 2>(&c.r), &cc).unwrap();
        let to_dyn = |x: &SMatrix<f64, 2, 2>| DMatrix::from_column_slice(2, 2, x.as_slice());
        check_kalman_step(&j, 2, &to_dyn(&a), &to_dyn(&b), &c.r);

        let (ad, bd, cd) = kalman_abc(&c.f, &c.p, &c.q, &c.h, &c.r);
        let jd = j_step(&ad, &bd, &c.r, &cd).unwrap();
        for (x, y) in [(j.j1, jd.j1), (j.j2, jd.j2), (j.tr_n, jd.tr_n), (j.tr_b, jd.tr_b)] {
            prop_assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "{x} vs {y}");
        }
    }

    /// (d) On a sweep with `J1` strictly decreasing and `J2` strictly increasing, a crossing is
    /// found exactly when `J1 - J2` starts non-negative and ends non-positive; it lies between
    /// the bracketing points (in `p`, `nq` and `J`), every earlier point has `J1 > J2`, and
    /// both straight lines, through the bracketing `J1` values and through the `J2` values,
    /// pass through `(p_c, J_c)`.
    #[test]
    fn crossover_of_monotone_sweeps(
        k in 2usize..30,
        start in (0.0f64..3.0, 0.0f64..3.0, -5.0f64..5.0),
        steps in vec((0.01f64..1.0, 0.01f64..0.5, 0.01f64..0.5), 30),
    ) {
        let (mut j1, mut j2, mut p) = start;
        let mut points = Vec::with_capacity(k);
        for &(dp, dj1, dj2) in &steps[..k] {
            points.push(SweepPoint { p, nq: 2.0 * p + 6.2, j1, j2 });
            p += dp;
            j1 -= dj1;
            j2 += dj2;
        }
        let d: Vec<f64> = points.iter().map(|q| q.j1 - q.j2).collect();
        let found = crossover(&points).unwrap();
        let expected = d[0] >= 0.0 && d[k - 1] <= 0.0;
        prop_assert_eq!(found.is_some(), expected);
        let Some(c) = found else { return Ok(()) };
        let first = d.iter().position(|&x| x <= 0.0).unwrap();
        prop_assert!(d[..first].iter().all(|&x| x > 0.0));
        if d[first] == 0.0 {
            prop_assert_eq!(c.p, points[first].p);
            prop_assert_eq!(c.j, points[first].j1);
            return Ok(());
        }
        let (lo, hi) = (&points[first - 1], &points[first]);
        prop_assert!(lo.p <= c.p && c.p <= hi.p);
        prop_assert!(lo.nq <= c.nq && c.nq <= hi.nq);
        prop_assert!(hi.j1.min(hi.j2) - 1e-12 <= c.j && c.j <= lo.j1.max(lo.j2) + 1e-12);
        let line = |y0: f64, y1: f64| y0 + (y1 - y0) * (c.p - lo.p) / (hi.p - lo.p);
        prop_assert!((line(lo.j1, hi.j1) - c.j).abs() <= 1e-9, "J1 line misses J_c");
        prop_assert!((line(lo.j2, hi.j2) - c.j).abs() <= 1e-9, "J2 line misses J_c");
    }
}

/// `nq` of traces near f64::MAX: their sum passes f64's range, but the log10 of their mean is
/// about 308 (found by the readers' property test in kalibra-cli: a logged Q of 1e308 made the
/// report's `j.nq_log10_mean` infinite). Ordinary traces give the plain sum's value to the bit,
/// also across a merge.
#[test]
fn nq_of_traces_near_f64_max_is_finite() {
    use kalibra_metrics::{JHorizon, JStep, Merge};
    let step = |tr_b: f64| JStep {
        j1: 0.5,
        j2: 0.25,
        tr_n: 0.25,
        tr_b,
        a_plus_b_definite: true,
    };
    let mut h = JHorizon::new();
    for _ in 0..4 {
        h.push(&step(1e308));
    }
    let mut other = JHorizon::new();
    other.push(&step(1.5e308));
    h.merge(&other);
    let nq = h.summary(5).unwrap().nq_log10_mean;
    let want = 308.0 + (1.1f64).log10(); // mean (4e308 + 1.5e308) / 5 = 1.1e308
    assert!((nq - want).abs() < 1e-12, "{nq} vs {want}");

    let traces = [0.3, 2.5e-3, 17.0, 1.0 / 3.0];
    let mut plain = JHorizon::new();
    for t in traces {
        plain.push(&step(t));
    }
    let sum: f64 = traces.iter().fold(0.0, |s, t| s + t);
    assert_eq!(
        plain.summary(4).unwrap().nq_log10_mean.to_bits(),
        (sum / 4.0).log10().to_bits()
    );
}
