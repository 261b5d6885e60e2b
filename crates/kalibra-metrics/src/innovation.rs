//! Innovation-covariance tuning metrics `J1` and `J2` (Saha, Goswami and Ghosh 2012; Saha,
//! Ghosh and Goswami, IEEE TIM 2014), their averages over a horizon, and the crossover of `J1`
//! and `J2` along a sweep of the process-noise scale.
//!
//! # Notation
//! For one filter update `k` with `m` measurements:
//!
//! * `A_k = H_k F P+_{k-1} F^T H_k^T`: the propagated posterior, seen through `H_k`;
//! * `B_k = H_k Q_{k-1} H_k^T`: the process noise, seen through `H_k`;
//! * `S_k = A_k + B_k + R_k`: the innovation covariance;
//! * `C_k = H_k P+_k H_k^T`: the new posterior, seen through `H_k`.
//!
//! Then `J1k = tr(S_k^-1 R_k)` (the share of the innovation covariance that is measurement
//! noise), `J2k = tr((A_k + B_k)^-1 B_k)` (the share of the predicted measurement covariance
//! that is process noise), and `N_k = (A_k + B_k)^-1 (A_k - C_k)`. At the optimal gain
//! (Joseph or standard update) `J1k + J2k = m - tr(N_k)`. Scaling `Q` up moves `J1` down and
//! `J2` up; the papers tune `Q` at the crossover of the two or at the edges of their plateaus.
//!
//! Bounds: `0 <= J1k <= m` when `R_k` and `A_k + B_k` are positive semi-definite (then the
//! eigenvalues of `S^-1 R` lie in `[0, 1]`), and `0 <= J2k <= m` when `A_k` and `B_k` are
//! positive semi-definite with a non-singular sum. An indefinite initial covariance (as printed
//! in the 2012 paper) can make `A_k + B_k` indefinite and break the second bound; [`j_step`] reports
//! that in [`JStep::a_plus_b_definite`] instead of hiding it.
//!
//! Over a horizon: `J1 = sum_k J1k / divisor`, `J2` likewise, and the process-noise level `nq`
//! in decades, either the mean of `log10 tr(B_k)` (the 2012 paper) or `log10` of the mean of
//! `tr(B_k)` (the 2014 paper); see [`JHorizon`].
//!
//! # Numerical choices
//! Every trace is of a solve through a factorisation, never of an explicit inverse: Cholesky
//! for `S_k` and for a positive definite `A_k + B_k`, LU with partial pivoting for an indefinite
//! `A_k + B_k`. The inputs are projections of covariances and may be asymmetric by rounding:
//! each must be symmetric to [`SYMMETRY_TOLERANCE`](kalibra_linalg::SYMMETRY_TOLERANCE)
//! (relative) and is rejected beyond it, and the sums `A_k + B_k` and `S_k` are then replaced
//! by the mean of themselves and their transposes, which changes them by rounding only. The
//! right-hand sides `B_k`, `R_k`, `A_k - C_k` are used as given: for a symmetric `X` the trace
//! `tr(X^-1 Y)` does not depend on the antisymmetric part of `Y`.

use kalibra_linalg::nalgebra::DMatrix;
use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, LinalgError, OMatrix, check_symmetric, symmetrize,
};

use crate::{Merge, MetricsError};

/// The `J1`/`J2` metrics of one filter update (notation at [`j_step`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JStep {
    /// `J1k = tr(S_k^-1 R_k)`.
    pub j1: f64,
    /// `J2k = tr((A_k + B_k)^-1 B_k)`.
    pub j2: f64,
    /// `tr(N_k) = tr((A_k + B_k)^-1 (A_k - C_k))`; `J1k + J2k = m - tr(N_k)` at the optimal
    /// gain.
    pub tr_n: f64,
    /// `tr(B_k)`, from which the process-noise level `nq` is computed.
    pub tr_b: f64,
    /// Whether `A_k + B_k` is positive definite (its Cholesky factorisation succeeded). When
    /// `false`, `J2k` and `tr(N_k)` came from an LU solve and `J2k` may lie outside `[0, m]`.
    pub a_plus_b_definite: bool,
}

/// `J1k`, `J2k`, `tr(N_k)` and `tr(B_k)` of one update from `A_k`, `B_k`, `R_k` and `C_k`.
///
/// Notation (as in the module documentation), for an update with `m` measurements:
/// `A_k = H_k F P+_{k-1} F^T H_k^T`, `B_k = H_k Q_{k-1} H_k^T`, `S_k = A_k + B_k + R_k`,
/// `C_k = H_k P+_k H_k^T`; `J1k = tr(S_k^-1 R_k)`, `J2k = tr((A_k + B_k)^-1 B_k)`,
/// `N_k = (A_k + B_k)^-1 (A_k - C_k)`, and `J1k + J2k = m - tr(N_k)` at the optimal gain.
///
/// The inputs are projections of covariances and may be asymmetric by rounding: each must be
/// symmetric to [`SYMMETRY_TOLERANCE`](kalibra_linalg::SYMMETRY_TOLERANCE) (relative; beyond it
/// is an error, never rounding), and the sums `A_k + B_k` and `S_k` are then replaced by the
/// mean of themselves and their transposes. `B_k`, `R_k` and `A_k - C_k` enter only as
/// right-hand sides of solves, as given.
///
/// `S_k = A_k + B_k + R_k` must be positive definite. `A_k + B_k` need not be: if its Cholesky
/// factorisation fails, the traces come from an LU solve and
/// [`JStep::a_plus_b_definite`] is `false`; only a singular `A_k + B_k` is an error.
///
/// ```
/// use kalibra_linalg::Matrix2;
/// use kalibra_metrics::j_step;
/// // Two decoupled channels: A + B = diag(3, 2), S = diag(4, 4), and the optimal update
/// // leaves C = G - G S^-1 G = diag(0.75, 1).
/// let a = Matrix2::new(2.0, 0.0, 0.0, 1.0);
/// let b = Matrix2::identity();
/// let r = Matrix2::new(1.0, 0.0, 0.0, 2.0);
/// let c = Matrix2::new(0.75, 0.0, 0.0, 1.0);
/// let j = j_step(&a, &b, &r, &c)?;
/// assert!((j.j1 - (1.0 / 4.0 + 2.0 / 4.0)).abs() < 1e-15);
/// assert!((j.j2 - (1.0 / 3.0 + 1.0 / 2.0)).abs() < 1e-15);
/// assert!((j.j1 + j.j2 - (2.0 - j.tr_n)).abs() < 1e-15);
/// assert!(j.a_plus_b_definite);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// * [`MetricsError::Linalg`] if an input is not square, holds a non-finite value, or is
///   asymmetric beyond [`SYMMETRY_TOLERANCE`](kalibra_linalg::SYMMETRY_TOLERANCE) (each named),
///   or if `S_k` is not positive definite.
/// * [`MetricsError::DimensionMismatch`] if `B_k`, `R_k` or `C_k` differs in size from `A_k`
///   (possible only with `Dyn`).
/// * [`MetricsError::InvalidParameter`] for `m = 0`.
/// * [`MetricsError::Singular`] if `A_k + B_k` is singular to working precision.
pub fn j_step<M: Dim>(
    a: &OMatrix<f64, M, M>,
    b: &OMatrix<f64, M, M>,
    r: &OMatrix<f64, M, M>,
    c: &OMatrix<f64, M, M>,
) -> Result<JStep, MetricsError>
where
    DefaultAllocator: Alloc<M>,
{
    check_symmetric(a, "A_k = H F P+ F^T H^T")?;
    let m = a.nrows();
    for (x, what) in [(b, "B_k = H Q H^T"), (r, "R_k"), (c, "C_k = H P+_k H^T")] {
        check_symmetric(x, what)?;
        if x.nrows() != m {
            return Err(MetricsError::DimensionMismatch {
                what,
                expected: m,
                found: x.nrows(),
            });
        }
    }
    if m == 0 {
        return Err(MetricsError::InvalidParameter {
            name: "measurement dimension m",
            value: 0.0,
        });
    }

    let mut ab = a + b;
    symmetrize(&mut ab);
    let mut s = &ab + r;
    symmetrize(&mut s);
    let s = Covariance::from_symmetric(s, "innovation covariance S = A + B + R")?;
    let j1 = s.trace_solve(r)?;
    let a_minus_c = a - c;

    let (j2, tr_n, a_plus_b_definite) = match Covariance::from_symmetric(ab, "A + B") {
        Ok(ab) => (ab.trace_solve(b)?, ab.trace_solve(&a_minus_c)?, true),
        Err(_) => {
            // The factorisation consumed the matrix; forming the sum again costs m^2 additions
            // on a path that runs only for an indefinite prior, and spares the usual path a copy.
            let mut ab = a + b;
            symmetrize(&mut ab);
            let (j2, tr_n) = lu_traces(&ab, b, &a_minus_c)?;
            (j2, tr_n, false)
        }
    };

    let tr_b = b.trace();
    if !(j1.is_finite() && j2.is_finite() && tr_n.is_finite() && tr_b.is_finite()) {
        // Finite inputs overflowing somewhere in the solves: report it, never return inf/NaN.
        return Err(LinalgError::NonFinite {
            what: "J1/J2 traces (overflow)",
        }
        .into());
    }
    Ok(JStep {
        j1,
        j2,
        tr_n,
        tr_b,
        a_plus_b_definite,
    })
}

/// `tr(X^-1 Y1)` and `tr(X^-1 Y2)` through an LU factorisation with partial pivoting of a
/// (symmetric, indefinite) `X`.
fn lu_traces<M: Dim>(
    x: &OMatrix<f64, M, M>,
    y1: &OMatrix<f64, M, M>,
    y2: &OMatrix<f64, M, M>,
) -> Result<(f64, f64), MetricsError>
where
    DefaultAllocator: Alloc<M>,
{
    const WHAT: &str = "A + B";
    // Copied to dynamic storage: nalgebra's LU needs a `DimMin` bound that a generic `M: Dim`
    // does not carry, and this path runs only at updates with an indefinite prior.
    let m = x.nrows();
    let to_dyn = |v: &OMatrix<f64, M, M>| DMatrix::from_iterator(m, m, v.iter().copied());
    let lu = to_dyn(x).lu();
    // Singular to working precision when the smallest pivot is below m ulps of the largest
    // (a cheap stand-in for a condition estimate). Near that bound J2k is huge but genuine:
    // that is the spike an indefinite prior produces, so it is reported, not rejected.
    let pivots = lu.u().diagonal().abs();
    let (smallest, largest) = (pivots.min(), pivots.max());
    // Written so that a NaN pivot (overflow in the elimination) also counts as singular.
    let well_posed = smallest > m as f64 * f64::EPSILON * largest;
    if !well_posed {
        return Err(MetricsError::Singular { what: WHAT });
    }
    let trace_solve = |y: &OMatrix<f64, M, M>| {
        lu.solve(&to_dyn(y))
            .map(|z| z.trace())
            .ok_or(MetricsError::Singular { what: WHAT })
    };
    Ok((trace_solve(y1)?, trace_solve(y2)?))
}

/// The horizon averages of `J1`/`J2` and the process-noise level `nq`, from a [`JHorizon`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JSummary {
    /// `J1 = sum_k J1k / divisor`.
    pub j1: f64,
    /// `J2 = sum_k J2k / divisor`.
    pub j2: f64,
    /// Mean over the updates of `log10 tr(B_k)` (the 2012 paper's `nq`); `-inf` if some `B_k`
    /// is 0.
    pub nq_mean_log10: f64,
    /// `log10` of the mean over the updates of `tr(B_k)` (the 2014 paper's `nq`).
    pub nq_log10_mean: f64,
    /// Number of updates pushed.
    pub updates: usize,
    /// The divisor of `J1` and `J2`.
    pub divisor: usize,
    /// Number of updates whose `A_k + B_k` was not positive definite.
    pub indefinite_updates: usize,
    /// Largest `J1k`.
    pub max_j1k: f64,
    /// Largest `J2k` (above `m` only at an indefinite update).
    pub max_j2k: f64,
}

/// Streaming accumulator of the per-update [`JStep`]s of one filter run (or of several partial
/// runs, through [`Merge`]).
///
/// The papers divide the sums of `J1k` and `J2k` by the horizon length even when the filter
/// skipped some points (a filter started from two-point differencing misses the first two,
/// for instance), so [`JHorizon::summary`] takes the divisor explicitly; the `nq` averages
/// divide by the number of updates.
///
/// ```
/// use kalibra_metrics::{JHorizon, JStep};
/// let mut h = JHorizon::new();
/// for (j1, j2, tr_b) in [(0.5, 0.25, 10.0), (0.3, 0.45, 1000.0)] {
///     h.push(&JStep { j1, j2, tr_n: 1.0 - j1 - j2, tr_b, a_plus_b_definite: true });
/// }
/// let plain = h.summary(h.updates())?; // mean over the updates that ran
/// assert!((plain.j1 - 0.4).abs() < 1e-15);
/// let paper = h.summary(4)?; // two skipped points count as zeros
/// assert!((paper.j2 - 0.175).abs() < 1e-15);
/// assert!((paper.nq_mean_log10 - 2.0).abs() < 1e-15); // mean of 1 and 3
/// assert!((paper.nq_log10_mean - 505f64.log10()).abs() < 1e-15);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// Serialised (serde, for a Monte Carlo shard's partial result) as
/// `{"sums": [...], "tr_b_exp": e, "updates": u, "indefinite": i}`, `sums` holding the IEEE-754
/// bit patterns of `sum_j1`, `sum_j2`, `sum_log10_tr_b`, `sum_tr_b`, `max_j1k` and `max_j2k`
/// as unsigned integers: the maxima start at `-inf` and a sum may be NaN, which JSON cannot
/// write as numbers, and bit patterns survive every format exactly. Deserialising checks that
/// the scale `tr_b_exp` is one the accumulator can reach (a multiple of 64 in `0..=1024`), so
/// a merge cannot overflow it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(into = "JHorizonData", try_from = "JHorizonData")]
pub struct JHorizon {
    sum_j1: f64,
    sum_j2: f64,
    sum_log10_tr_b: f64,
    /// The sum of `tr(B_k)` divided by `2^tr_b_exp`: the power of two grows when the sum
    /// would pass f64's range (traces near 1e308), so the mean's `log10` stays finite.
    sum_tr_b: f64,
    tr_b_exp: i32,
    updates: usize,
    indefinite: usize,
    max_j1k: f64,
    max_j2k: f64,
}

/// [`JHorizon`] as written and read, before its invariants are checked.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JHorizonData {
    sums: [u64; 6],
    tr_b_exp: i32,
    updates: usize,
    indefinite: usize,
}

/// The largest scale of `tr(B)`'s sum: 2^1024 per update already passes f64's range, and
/// 2^64 updates would not pass 2^64 more.
const MAX_TR_B_EXP: i32 = 1024;

impl From<JHorizon> for JHorizonData {
    fn from(h: JHorizon) -> Self {
        Self {
            sums: [
                h.sum_j1,
                h.sum_j2,
                h.sum_log10_tr_b,
                h.sum_tr_b,
                h.max_j1k,
                h.max_j2k,
            ]
            .map(f64::to_bits),
            tr_b_exp: h.tr_b_exp,
            updates: h.updates,
            indefinite: h.indefinite,
        }
    }
}

impl TryFrom<JHorizonData> for JHorizon {
    type Error = String;

    fn try_from(d: JHorizonData) -> Result<Self, String> {
        if !(0..=MAX_TR_B_EXP).contains(&d.tr_b_exp) || d.tr_b_exp % 64 != 0 {
            return Err(format!(
                "a J horizon scaled by 2^{}: expected a multiple of 64 in 0..={MAX_TR_B_EXP}",
                d.tr_b_exp
            ));
        }
        if d.indefinite > d.updates {
            return Err(format!(
                "a J horizon with {} indefinite updates of {}",
                d.indefinite, d.updates
            ));
        }
        let [sum_j1, sum_j2, sum_log10_tr_b, sum_tr_b, max_j1k, max_j2k] =
            d.sums.map(f64::from_bits);
        Ok(Self {
            sum_j1,
            sum_j2,
            sum_log10_tr_b,
            sum_tr_b,
            tr_b_exp: d.tr_b_exp,
            updates: d.updates,
            indefinite: d.indefinite,
            max_j1k,
            max_j2k,
        })
    }
}

impl Default for JHorizon {
    fn default() -> Self {
        Self::new()
    }
}

/// The larger of two values, NaN if either is: a NaN pushed by hand must reach the summary,
/// where `f64::max` would drop it.
fn max_keep_nan(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

impl JHorizon {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self {
            sum_j1: 0.0,
            sum_j2: 0.0,
            sum_log10_tr_b: 0.0,
            sum_tr_b: 0.0,
            tr_b_exp: 0,
            updates: 0,
            indefinite: 0,
            // J2k is negative at some indefinite updates, so the running maxima start below
            // every value.
            max_j1k: f64::NEG_INFINITY,
            max_j2k: f64::NEG_INFINITY,
        }
    }

    /// Adds one update. Values are taken as they are ([`j_step`] returns only finite ones);
    /// a non-finite value pushed by hand makes the affected summary fields NaN or infinite.
    pub fn push(&mut self, step: &JStep) {
        self.sum_j1 += step.j1;
        self.sum_j2 += step.j2;
        self.sum_log10_tr_b += step.tr_b.log10();
        self.add_tr_b(step.tr_b, 0);
        self.updates += 1;
        self.indefinite += usize::from(!step.a_plus_b_definite);
        self.max_j1k = max_keep_nan(self.max_j1k, step.j1);
        self.max_j2k = max_keep_nan(self.max_j2k, step.j2);
    }

    /// Adds `value * 2^exp` to the scaled sum of `tr(B_k)`. For ordinary traces the scale
    /// stays 2^0 and this is the plain sum, to the bit; a sum that would pass f64's range is
    /// rescaled by 2^64 first (exact, a power of two).
    fn add_tr_b(&mut self, value: f64, exp: i32) {
        // Bring both to the larger scale (exact for powers of two, short of underflow).
        if exp > self.tr_b_exp {
            self.sum_tr_b = crate::scale::ldexp(self.sum_tr_b, self.tr_b_exp - exp);
            self.tr_b_exp = exp;
        }
        let value = crate::scale::ldexp(value, exp - self.tr_b_exp);
        let mut sum = self.sum_tr_b + value;
        if sum.is_infinite() && value.is_finite() && self.sum_tr_b.is_finite() {
            self.tr_b_exp += 64;
            self.sum_tr_b = crate::scale::ldexp(self.sum_tr_b, -64);
            sum = self.sum_tr_b + crate::scale::ldexp(value, -64);
        }
        self.sum_tr_b = sum;
    }

    /// Number of updates pushed.
    pub fn updates(&self) -> usize {
        self.updates
    }

    /// The horizon averages, `J1` and `J2` divided by `divisor` and `nq` averaged over the
    /// updates.
    ///
    /// `nq_mean_log10` is `-inf` if some `tr(B_k)` is 0 (an update with no prediction before
    /// it) and NaN if some is negative (a `B_k` that is not positive semi-definite), as `log10`
    /// gives; neither is replaced by a finite value.
    ///
    /// # Errors
    /// [`MetricsError::Empty`] if nothing was pushed, [`MetricsError::DivisorBelowUpdates`] if
    /// `divisor < updates`.
    pub fn summary(&self, divisor: usize) -> Result<JSummary, MetricsError> {
        if self.updates == 0 {
            return Err(MetricsError::Empty {
                what: "filter updates",
            });
        }
        if divisor < self.updates {
            return Err(MetricsError::DivisorBelowUpdates {
                divisor,
                updates: self.updates,
            });
        }
        let n = self.updates as f64;
        Ok(JSummary {
            j1: self.sum_j1 / divisor as f64,
            j2: self.sum_j2 / divisor as f64,
            nq_mean_log10: self.sum_log10_tr_b / n,
            // log10(sum / n * 2^e); the second term is 0.0 for unscaled sums.
            nq_log10_mean: (self.sum_tr_b / n).log10()
                + f64::from(self.tr_b_exp) * std::f64::consts::LOG10_2,
            updates: self.updates,
            divisor,
            indefinite_updates: self.indefinite,
            max_j1k: self.max_j1k,
            max_j2k: self.max_j2k,
        })
    }
}

impl Merge for JHorizon {
    /// Adds the sums and counts and keeps the larger maxima. Merging never fails: every
    /// `JHorizon` has the same shape.
    fn merge(&mut self, other: &Self) {
        self.sum_j1 += other.sum_j1;
        self.sum_j2 += other.sum_j2;
        self.sum_log10_tr_b += other.sum_log10_tr_b;
        self.add_tr_b(other.sum_tr_b, other.tr_b_exp);
        self.updates += other.updates;
        self.indefinite += other.indefinite;
        self.max_j1k = max_keep_nan(self.max_j1k, other.max_j1k);
        self.max_j2k = max_keep_nan(self.max_j2k, other.max_j2k);
    }
}

/// One point of a sweep of the process-noise scale `Q = 10^p Q_nom`: the exponent, the level
/// `nq` reached (either definition of [`JSummary`]) and the horizon averages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepPoint {
    /// Exponent `p` of the scale `10^p`.
    pub p: f64,
    /// Process-noise level `nq`.
    pub nq: f64,
    /// Horizon average `J1`.
    pub j1: f64,
    /// Horizon average `J2`.
    pub j2: f64,
}

/// Where `J1` and `J2` cross along a sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crossover {
    /// Process-noise level `nq_c` at the crossing.
    pub nq: f64,
    /// `J_c = J1 = J2` at the crossing.
    pub j: f64,
    /// Exponent `p_c` at the crossing (`Q_comp = 10^p_c Q_nom`).
    pub p: f64,
}

/// The first crossing of `J1` and `J2` along a sweep, by linear interpolation.
///
/// `points` are in sweep order, `p` strictly increasing. With `d_i = J1_i - J2_i`, the crossing
/// is the first point with `d_i = 0` exactly, or the first pair of consecutive points where `d`
/// changes sign, whichever comes first; between `i` and `i + 1`, with
/// `t = d_i / (d_i - d_{i+1})` in `(0, 1)`, `nq`, `p` and `J1` are interpolated linearly
/// (interpolating `J2` gives the same `J` up to rounding). The interpolated `nq` and `p` are
/// kept inside the bracketing points (rounding could otherwise step out by an ulp).
///
/// ```
/// use kalibra_metrics::{SweepPoint, crossover};
/// let pts = [
///     SweepPoint { p: 0.0, nq: 1.0, j1: 1.0, j2: 0.2 },
///     SweepPoint { p: 1.0, nq: 2.0, j1: 0.6, j2: 1.0 }, // d goes from 0.8 to -0.4
/// ];
/// let c = crossover(&pts)?.expect("a sign change");
/// assert!((c.p - 2.0 / 3.0).abs() < 1e-15 && (c.nq - 5.0 / 3.0).abs() < 1e-15);
/// assert!((c.j - (1.0 - 0.4 * 2.0 / 3.0)).abs() < 1e-15);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::InvalidSweep`] if any point holds a non-finite value or `p` does not
/// increase strictly. Every point is checked, also past the crossing, so that a broken sweep
/// is never mistaken for one with (or without) a crossing. `Ok(None)` means the sweep is valid
/// and `J1 - J2` keeps one strict sign throughout (or `points` is empty).
pub fn crossover(points: &[SweepPoint]) -> Result<Option<Crossover>, MetricsError> {
    for (index, pt) in points.iter().enumerate() {
        if ![pt.p, pt.nq, pt.j1, pt.j2].iter().all(|v| v.is_finite()) {
            return Err(MetricsError::InvalidSweep {
                index,
                reason: "holds a non-finite value",
            });
        }
        // Both values are finite here (checked above, in this pass and the previous one).
        if index > 0 && pt.p <= points[index - 1].p {
            return Err(MetricsError::InvalidSweep {
                index,
                reason: "does not increase p",
            });
        }
    }
    for (i, pt) in points.iter().enumerate() {
        let d = pt.j1 - pt.j2;
        if d == 0.0 {
            return Ok(Some(Crossover {
                nq: pt.nq,
                j: pt.j1,
                p: pt.p,
            }));
        }
        let Some(next) = points.get(i + 1) else {
            break;
        };
        let d_next = next.j1 - next.j2;
        // Signs compared directly, not through d * d_next < 0, which underflows to 0 for tiny
        // differences. A zero d_next is the next point's own crossing, found on the next pass.
        if d_next != 0.0 && (d < 0.0) != (d_next < 0.0) {
            let t = d / (d - d_next);
            let lerp = |x0: f64, x1: f64| (x0 + t * (x1 - x0)).clamp(x0.min(x1), x0.max(x1));
            return Ok(Some(Crossover {
                nq: lerp(pt.nq, next.nq),
                j: pt.j1 + t * (next.j1 - pt.j1),
                p: lerp(pt.p, next.p),
            }));
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::{DMatrix, Matrix2, SMatrix};

    #[test]
    fn horizon_serde_keeps_every_bit_and_refuses_bad_scales() {
        let bits = |h: &JHorizon| {
            let d = JHorizonData::from(h.clone());
            (d.sums, d.tr_b_exp, d.updates, d.indefinite)
        };
        // The empty horizon's maxima are -inf; a NaN pushed by hand reaches the sums; a huge
        // trace rescales the tr(B) sum.
        let mut h = JHorizon::new();
        let empty: JHorizon = serde_json::from_str(&serde_json::to_string(&h).unwrap()).unwrap();
        assert_eq!(bits(&empty), bits(&h));
        for (j1, tr_b) in [(f64::NAN, 1.0), (-0.0, 1e308), (0.5, 1e308)] {
            h.push(&JStep {
                j1,
                j2: 0.25,
                tr_n: 0.0,
                tr_b,
                a_plus_b_definite: false,
            });
        }
        assert_eq!(h.tr_b_exp, 64);
        let back: JHorizon = serde_json::from_str(&serde_json::to_string(&h).unwrap()).unwrap();
        assert_eq!(bits(&back), bits(&h));
        assert!(back.sum_j1.is_nan());
        for (exp, ok) in [
            (0, true),
            (1024, true),
            (-64, false),
            (32, false),
            (1088, false),
        ] {
            let text = serde_json::to_string(&h)
                .unwrap()
                .replace("\"tr_b_exp\":64", &format!("\"tr_b_exp\":{exp}"));
            assert_eq!(serde_json::from_str::<JHorizon>(&text).is_ok(), ok, "{exp}");
        }
        let text = serde_json::to_string(&h)
            .unwrap()
            .replace("\"indefinite\":3", "\"indefinite\":4");
        assert!(serde_json::from_str::<JHorizon>(&text).is_err());
    }

    fn m1(x: f64) -> SMatrix<f64, 1, 1> {
        SMatrix::<f64, 1, 1>::new(x)
    }

    #[test]
    fn scalar_case_by_hand() {
        let (a, b, r) = (3.0, 0.5, 2.0);
        // Optimal scalar update: c = g - g^2 / s with g = a + b.
        let (g, s) = (a + b, a + b + r);
        let c = g - g * g / s;
        let j = j_step(&m1(a), &m1(b), &m1(r), &m1(c)).unwrap();
        assert!((j.j1 - r / s).abs() < 1e-15);
        assert!((j.j2 - b / g).abs() < 1e-15);
        assert!((j.tr_n - (a - c) / g).abs() < 1e-15);
        assert!((j.j1 + j.j2 - (1.0 - j.tr_n)).abs() < 1e-15);
        assert_eq!(j.tr_b, b);
        assert!(j.a_plus_b_definite);
    }

    #[test]
    fn indefinite_prior_is_reported_not_hidden() {
        // a + b = -2 (an indefinite prior), s = 8: J2k = 1 / -2 is outside [0, 1].
        let j = j_step(&m1(-3.0), &m1(1.0), &m1(10.0), &m1(0.0)).unwrap();
        assert!(!j.a_plus_b_definite);
        assert!((j.j2 + 0.5).abs() < 1e-15);
        assert!((j.j1 - 10.0 / 8.0).abs() < 1e-15);
        assert!((j.tr_n - (-3.0 / -2.0)).abs() < 1e-15);

        // A 2 x 2 indefinite A + B against an explicit inverse (for checking only).
        let a = Matrix2::new(1.0, 2.0, 2.0, 0.5);
        let b = Matrix2::new(0.5, 0.1, 0.1, 0.5);
        let r = Matrix2::new(10.0, 0.0, 0.0, 10.0);
        let c = Matrix2::new(0.2, 0.0, 0.0, 0.3);
        let j = j_step(&a, &b, &r, &c).unwrap();
        let inv = (a + b).try_inverse().unwrap();
        assert!(!j.a_plus_b_definite);
        assert!((j.j2 - (inv * b).trace()).abs() < 1e-14);
        assert!((j.tr_n - (inv * (a - c)).trace()).abs() < 1e-14);
        assert!((j.j1 - ((a + b + r).try_inverse().unwrap() * r).trace()).abs() < 1e-14);
    }

    #[test]
    fn typed_errors() {
        // Singular A + B.
        assert_eq!(
            j_step(&m1(-1.0), &m1(1.0), &m1(1.0), &m1(0.0)),
            Err(MetricsError::Singular { what: "A + B" })
        );
        let singular = Matrix2::new(1.0, 1.0, 1.0, 1.0);
        assert!(matches!(
            j_step(
                &singular,
                &Matrix2::zeros(),
                &Matrix2::identity(),
                &Matrix2::zeros()
            ),
            Err(MetricsError::Singular { .. })
        ));
        // S not positive definite, named.
        assert_eq!(
            j_step(&m1(-5.0), &m1(1.0), &m1(1.0), &m1(0.0)),
            Err(MetricsError::Linalg(LinalgError::NotPositiveDefinite {
                what: "innovation covariance S = A + B + R"
            }))
        );
        // Non-finite input, named.
        assert_eq!(
            j_step(&m1(1.0), &m1(f64::NAN), &m1(1.0), &m1(0.0)),
            Err(MetricsError::Linalg(LinalgError::NonFinite {
                what: "B_k = H Q H^T"
            }))
        );
        // Asymmetric beyond rounding.
        assert!(matches!(
            j_step(
                &Matrix2::new(1.0, 0.5, 0.4, 1.0),
                &Matrix2::identity(),
                &Matrix2::identity(),
                &Matrix2::zeros()
            ),
            Err(MetricsError::Linalg(LinalgError::NotSymmetric { .. }))
        ));
        // Dyn sizes.
        let i2 = DMatrix::<f64>::identity(2, 2);
        let i3 = DMatrix::<f64>::identity(3, 3);
        assert_eq!(
            j_step(&i2, &i2, &i3, &i2),
            Err(MetricsError::DimensionMismatch {
                what: "R_k",
                expected: 2,
                found: 3
            })
        );
        assert!(matches!(
            j_step(&DMatrix::zeros(2, 3), &i2, &i2, &i2),
            Err(MetricsError::Linalg(LinalgError::DimensionMismatch { .. }))
        ));
        let e = DMatrix::<f64>::zeros(0, 0);
        assert!(matches!(
            j_step(&e, &e, &e, &e),
            Err(MetricsError::InvalidParameter { .. })
        ));
    }

    #[test]
    fn rounding_asymmetry_is_accepted() {
        let a = Matrix2::new(2.0, 0.3, 0.3 * (1.0 + 1e-14), 1.0);
        let b = Matrix2::identity();
        let j = j_step(&a, &b, &b, &Matrix2::zeros()).unwrap();
        assert!(j.a_plus_b_definite);
    }

    fn step(j1: f64, j2: f64, tr_b: f64, definite: bool) -> JStep {
        JStep {
            j1,
            j2,
            tr_n: 0.0,
            tr_b,
            a_plus_b_definite: definite,
        }
    }

    #[test]
    fn horizon_summary_and_merge() {
        let steps = [
            step(0.5, 0.2, 1.0, true),
            step(0.4, 2.5, 100.0, false),
            step(0.1, 0.9, 10.0, true),
        ];
        let mut h = JHorizon::new();
        assert_eq!(
            h.summary(3),
            Err(MetricsError::Empty {
                what: "filter updates"
            })
        );
        steps.iter().for_each(|s| h.push(s));
        assert_eq!(h.updates(), 3);
        assert_eq!(
            h.summary(2),
            Err(MetricsError::DivisorBelowUpdates {
                divisor: 2,
                updates: 3
            })
        );
        let s = h.summary(5).unwrap();
        assert!((s.j1 - 1.0 / 5.0).abs() < 1e-15);
        assert!((s.j2 - 3.6 / 5.0).abs() < 1e-15);
        assert!((s.nq_mean_log10 - 1.0).abs() < 1e-15);
        assert!((s.nq_log10_mean - 37f64.log10()).abs() < 1e-15);
        assert_eq!((s.updates, s.divisor, s.indefinite_updates), (3, 5, 1));
        assert_eq!((s.max_j1k, s.max_j2k), (0.5, 2.5));

        let mut first = JHorizon::new();
        first.push(&steps[0]);
        let mut rest = JHorizon::default();
        rest.push(&steps[1]);
        rest.push(&steps[2]);
        first.merge(&rest);
        let merged = first.summary(5).unwrap();
        assert!((merged.j1 - s.j1).abs() < 1e-15 && (merged.j2 - s.j2).abs() < 1e-15);
        assert_eq!(
            (merged.updates, merged.indefinite_updates, merged.max_j2k),
            (3, 1, 2.5)
        );
    }

    #[test]
    fn horizon_keeps_what_log10_and_nan_give() {
        let mut h = JHorizon::new();
        h.push(&step(0.5, -0.5, 0.0, false)); // B_k = 0, J2k negative
        h.push(&step(0.5, -0.7, 10.0, false));
        let s = h.summary(2).unwrap();
        assert_eq!(s.nq_mean_log10, f64::NEG_INFINITY);
        assert!((s.nq_log10_mean - 5f64.log10()).abs() < 1e-15);
        assert_eq!(s.max_j2k, -0.5);
        h.push(&step(f64::NAN, 0.0, 1.0, true));
        h.push(&step(0.9, 0.0, 1.0, true));
        assert!(h.summary(4).unwrap().max_j1k.is_nan());
    }

    fn pt(p: f64, j1: f64, j2: f64) -> SweepPoint {
        SweepPoint {
            p,
            nq: p + 6.0,
            j1,
            j2,
        }
    }

    #[test]
    fn crossover_cases() {
        assert_eq!(crossover(&[]), Ok(None));
        // No sign change.
        assert_eq!(crossover(&[pt(0.0, 1.0, 0.0), pt(1.0, 0.9, 0.1)]), Ok(None));
        // An exact zero is the crossing itself.
        let c = crossover(&[pt(0.0, 1.0, 0.0), pt(1.0, 0.5, 0.5), pt(2.0, 0.0, 1.0)])
            .unwrap()
            .unwrap();
        assert_eq!(
            c,
            Crossover {
                nq: 7.0,
                j: 0.5,
                p: 1.0
            }
        );
        // The first of several sign changes.
        let c = crossover(&[
            pt(0.0, 1.0, 0.0),
            pt(1.0, 0.0, 1.0),
            pt(2.0, 1.0, 0.0),
            pt(3.0, 0.0, 1.0),
        ])
        .unwrap()
        .unwrap();
        assert_eq!(
            c,
            Crossover {
                nq: 6.5,
                j: 0.5,
                p: 0.5
            }
        );
        // Upward crossing (J1 below J2 first).
        let c = crossover(&[pt(0.0, 0.0, 1.0), pt(1.0, 3.0, 0.0)])
            .unwrap()
            .unwrap();
        assert!((c.p - 0.25).abs() < 1e-15 && (c.j - 0.75).abs() < 1e-15);
    }

    #[test]
    fn crossover_rejects_broken_sweeps() {
        // A NaN past the crossing still makes the sweep invalid.
        assert_eq!(
            crossover(&[pt(0.0, 1.0, 0.0), pt(1.0, 0.0, 1.0), pt(2.0, f64::NAN, 1.0)]),
            Err(MetricsError::InvalidSweep {
                index: 2,
                reason: "holds a non-finite value"
            })
        );
        assert_eq!(
            crossover(&[pt(0.0, 1.0, 0.0), pt(0.0, 0.0, 1.0)]),
            Err(MetricsError::InvalidSweep {
                index: 1,
                reason: "does not increase p"
            })
        );
    }
}
