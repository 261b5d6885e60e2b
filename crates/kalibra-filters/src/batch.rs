//! Batched Kalman filtering: [`BATCH`] Monte Carlo runs of one linear model stepped together,
//! in structure-of-arrays layout, with the SIMD instruction set chosen at run time.
//!
//! # What it is for
//! A Monte Carlo study runs thousands of independent filters on the same model. [`KfBatch`]
//! steps [`BATCH`] = 8 of them at once: every entry of every per-run quantity (state, covariance,
//! measurement, truth) is an array of 8 lanes, one per run, and the shared model matrices
//! `F, H, Q, R` are broadcast across the lanes. The arithmetic is the scalar [`Kf`](crate::Kf)'s
//! (predict `F P F^T + Q`, symmetrised; `S = H P H^T + R`, symmetrised and factorised by
//! Cholesky; `K` by a solve with that factor; Joseph update, symmetrised; NIS and NEES through
//! Cholesky factors), written out over fixed sizes `N`, `M` in the same order of operations,
//! so a lane agrees with the scalar filter of its run to rounding (fused multiply-adds where
//! the instruction set has them are the one difference).
//!
//! It is not a general filter API: the scalar filters are the reference and the interface for
//! one filter; this is how studies step many.
//!
//! # Dispatch
//! [`Isa`] names the instruction sets: AVX-512 (8 lanes per vector, one vector per batch),
//! AVX2 with FMA (4 lanes, two vectors), NEON (2 lanes, four vectors) and a scalar fallback (one
//! lane at a time, the plain multiply and add of the scalar filter). [`Isa::detect`] picks the
//! best the CPU has; [`Isa::from_str`](std::str::FromStr) parses an explicit choice (the xtask
//! passes the `KALIBRA_SIMD` environment variable through it: this library reads no
//! environment). The kernels are generic over [`pulp::Simd`] and dispatched through pulp, so a
//! portable build carries every path; everything the kernel calls is `#[inline(always)]` so
//! that it is compiled inside the dispatched function, for its instruction set.
//!
//! # Per-lane errors
//! A lane whose measurement is not finite, whose `S` is not positive definite, or whose
//! posterior is not finite fails alone: its state is left as it was (as the scalar filter's
//! is after a failed update), its [`BatchStep::nis`] is the [`FilterError`] the scalar
//! filter would return, and the other lanes go on.
//!
//! # Example
//! ```
//! use kalibra_filters::batch::{BATCH, BatchModel, Isa, KfBatch};
//! use kalibra_linalg::{Matrix1, Matrix2, Vector2};
//! use nalgebra::SMatrix;
//!
//! let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
//! let h = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
//! let model = BatchModel::new(f, Matrix2::identity() * 0.01, h, Matrix1::new(1.0))?;
//! let mut kf = KfBatch::new(Isa::detect(), model, Vector2::zeros(), Matrix2::identity())?;
//! // Eight runs, eight measurements; lane 3's is NaN and fails alone.
//! let mut z = [[0.5; BATCH]; 1];
//! z[0][3] = f64::NAN;
//! let truth = [[0.0; BATCH]; 2];
//! let step = kf.update(&z, &truth);
//! assert!(step.nis(3).is_err());
//! assert!(step.nis(0).is_ok_and(|nis| nis > 0.0));
//! # Ok::<(), kalibra_filters::FilterError>(())
//! ```

// The kernels index matrices as the formulas do (`a[i][k] b[k][j]`); iterator chains would
// hide the algebra and add closures, which must not leave the dispatched function.
#![allow(clippy::needless_range_loop)]

use std::str::FromStr;

use kalibra_linalg::{Definiteness, SMatrix, SVector, check_covariance, check_finite};
use pulp::{Simd, WithSimd};

use crate::FilterError;

/// Runs per batch: the lanes of one AVX-512 vector of f64. Narrower instruction sets step a
/// batch as several vectors, so the grouping of runs (and so every result) does not depend on
/// the instruction set.
pub const BATCH: usize = 8;

/// One f64 per run of a batch.
pub type Lanes = [f64; BATCH];

/// An instruction set a batched kernel runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Isa {
    /// x86-64 AVX-512 (pulp's `V4`): 8 f64 lanes per vector, fused multiply-add.
    Avx512,
    /// x86-64 AVX2 with FMA (pulp's `V3`): 4 lanes per vector, fused multiply-add.
    Avx2,
    /// aarch64 NEON: 2 lanes per vector, fused multiply-add.
    Neon,
    /// No SIMD: one lane at a time, separate multiply and add like the scalar filters.
    Scalar,
}

impl Isa {
    /// Every instruction set, widest first.
    pub const ALL: [Isa; 4] = [Isa::Avx512, Isa::Avx2, Isa::Neon, Isa::Scalar];

    /// The widest instruction set this CPU runs (at run time, not the build's target).
    pub fn detect() -> Isa {
        Self::ALL
            .into_iter()
            .find(|isa| isa.is_available())
            .unwrap_or(Isa::Scalar)
    }

    /// Whether this CPU runs `self`.
    pub fn is_available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => pulp::x86::V4::try_new().is_some(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => pulp::x86::V3::try_new().is_some(),
            #[cfg(target_arch = "aarch64")]
            Isa::Neon => pulp::aarch64::Neon::try_new().is_some(),
            Isa::Scalar => true,
            #[allow(unreachable_patterns)] // Every arm above exists on some target.
            _ => false,
        }
    }

    /// The instruction sets this CPU runs, widest first (the scalar fallback always).
    pub fn available() -> Vec<Isa> {
        Self::ALL.into_iter().filter(|i| i.is_available()).collect()
    }

    /// f64 lanes per vector.
    pub fn lanes(self) -> usize {
        match self {
            Isa::Avx512 => 8,
            Isa::Avx2 => 4,
            Isa::Neon => 2,
            Isa::Scalar => 1,
        }
    }

    /// The lowercase name [`Isa::from_str`](std::str::FromStr) parses.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Avx512 => "avx512",
            Isa::Avx2 => "avx2",
            Isa::Neon => "neon",
            Isa::Scalar => "scalar",
        }
    }

    /// `self` if this CPU runs it.
    ///
    /// # Errors
    /// [`FilterError::Unsupported`] if it does not.
    pub fn checked(self) -> Result<Isa, FilterError> {
        if self.is_available() {
            Ok(self)
        } else {
            Err(FilterError::Unsupported {
                what: match self {
                    Isa::Avx512 => "instruction set avx512 on this CPU",
                    Isa::Avx2 => "instruction set avx2 on this CPU",
                    Isa::Neon => "instruction set neon on this CPU",
                    Isa::Scalar => "the scalar fallback",
                },
            })
        }
    }

    /// Runs `op` with this instruction set's pulp token (the scalar fallback if the CPU does
    /// not have it; constructors check with [`Isa::checked`] first).
    #[inline]
    fn dispatch<Op: WithSimd>(self, op: Op) -> Op::Output {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                if let Some(simd) = pulp::x86::V4::try_new() {
                    return Simd::vectorize(simd, op);
                }
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => {
                if let Some(simd) = pulp::x86::V3::try_new() {
                    return Simd::vectorize(simd, op);
                }
            }
            #[cfg(target_arch = "aarch64")]
            Isa::Neon => {
                if let Some(simd) = pulp::aarch64::Neon::try_new() {
                    return Simd::vectorize(simd, op);
                }
            }
            _ => {}
        }
        Simd::vectorize(pulp::Scalar::new(), op)
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Isa {
    type Err = FilterError;

    /// Parses `avx512`, `avx2`, `neon` or `scalar` (any case, surrounding blanks ignored), or
    /// `auto` (or nothing) for [`Isa::detect`]. The result is checked against the CPU.
    ///
    /// ```
    /// use kalibra_filters::batch::Isa;
    /// assert_eq!("scalar".parse::<Isa>()?, Isa::Scalar);
    /// assert!("sse9".parse::<Isa>().is_err());
    /// # Ok::<(), kalibra_filters::FilterError>(())
    /// ```
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let isa = match text.trim().to_ascii_lowercase().as_str() {
            "" | "auto" => return Ok(Isa::detect()),
            "avx512" | "avx-512" => Isa::Avx512,
            "avx2" => Isa::Avx2,
            "neon" => Isa::Neon,
            "scalar" => Isa::Scalar,
            _ => {
                return Err(FilterError::UnknownIsa {
                    name: text.to_owned(),
                });
            }
        };
        isa.checked()
    }
}

/// The shared, time-invariant linear model of a batch: `x_{k+1} = F x_k + w_k`, `w ~ N(0, Q)`,
/// `z_k = H x_k + v_k`, `v ~ N(0, R)`, stored row-major for broadcasting.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchModel<const N: usize, const M: usize> {
    f: [[f64; N]; N],
    q: [[f64; N]; N],
    h: [[f64; N]; M],
    r: [[f64; M]; M],
}

fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> [[f64; C]; R] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

impl<const N: usize, const M: usize> BatchModel<N, M> {
    /// A model from its matrices.
    ///
    /// # Errors
    /// [`FilterError::Initial`] if `F` or `H` is not finite, or `Q` or `R` is not a symmetric
    /// positive semi-definite matrix (the check the scalar models apply).
    pub fn new(
        f: SMatrix<f64, N, N>,
        q: SMatrix<f64, N, N>,
        h: SMatrix<f64, M, N>,
        r: SMatrix<f64, M, M>,
    ) -> Result<Self, FilterError> {
        let init = FilterError::Initial;
        check_finite(&f, "transition matrix F").map_err(init)?;
        check_finite(&h, "measurement matrix H").map_err(init)?;
        check_covariance(&q, "process noise Q", Definiteness::SemiDefinite).map_err(init)?;
        check_covariance(&r, "measurement noise R", Definiteness::SemiDefinite).map_err(init)?;
        Ok(Self {
            f: rows(&f),
            q: rows(&q),
            h: rows(&h),
            r: rows(&r),
        })
    }
}

/// The results of one batched update, lane by lane.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchStep<const N: usize> {
    k: usize,
    nis: Lanes,
    nees: Lanes,
    error: [Lanes; N],
    // 0 where the lane's update succeeded, NaN where it failed (the kernel's health sum).
    health: Lanes,
    // The error of a lane's update, and of its NEES (the update's, or the NEES's own).
    failure: [Option<FilterError>; BATCH],
    nees_failure: [Option<FilterError>; BATCH],
}

impl<const N: usize> BatchStep<N> {
    fn new() -> Self {
        Self {
            k: 0,
            nis: [0.0; BATCH],
            nees: [0.0; BATCH],
            error: [[0.0; BATCH]; N],
            health: [0.0; BATCH],
            failure: std::array::from_fn(|_| None),
            nees_failure: std::array::from_fn(|_| None),
        }
    }

    /// The step index of the update.
    pub fn step(&self) -> usize {
        self.k
    }

    /// Lane `lane`'s update: its NIS `nu^T S^-1 nu`, or the error of the update (the lane's
    /// state is then as before it, as the scalar filter's is).
    ///
    /// # Errors
    /// The [`FilterError`] the scalar filter's update would return for this lane.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn nis(&self, lane: usize) -> Result<f64, FilterError> {
        match &self.failure[lane] {
            Some(e) => Err(e.clone()),
            None => Ok(self.nis[lane]),
        }
    }

    /// Lane `lane`'s NEES `e^T P+^-1 e` against the truth given to the update, through the
    /// Cholesky factor of `P+` as the scalar record's `nees`.
    ///
    /// # Errors
    /// The update's error ([`BatchStep::nis`]), or [`FilterError::NotPositiveDefinite`] if
    /// `P+` has no Cholesky factor.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn nees(&self, lane: usize) -> Result<f64, FilterError> {
        match (&self.failure[lane], &self.nees_failure[lane]) {
            (Some(e), _) | (None, Some(e)) => Err(e.clone()),
            (None, None) => Ok(self.nees[lane]),
        }
    }

    /// Whether every lane's update and NEES succeeded.
    pub fn all_ok(&self) -> bool {
        self.failure
            .iter()
            .chain(&self.nees_failure)
            .all(Option::is_none)
    }

    /// Lane `lane`'s estimation error `x - x+` (meaningful when [`BatchStep::nis`] is `Ok`).
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn error(&self, lane: usize) -> [f64; N] {
        std::array::from_fn(|i| self.error[i][lane])
    }
}

/// [`BATCH`] Kalman filters on one [`BatchModel`], stepped together (see the
/// [module docs](self)).
#[derive(Clone, Debug)]
pub struct KfBatch<const N: usize, const M: usize> {
    isa: Isa,
    model: BatchModel<N, M>,
    k: usize,
    x: [Lanes; N],
    p: [[Lanes; N]; N],
    out: BatchStep<N>,
}

impl<const N: usize, const M: usize> KfBatch<N, M> {
    /// [`BATCH`] filters at step 0, each from the estimate `(x0, P0)`, on instruction set `isa`.
    ///
    /// # Errors
    /// [`FilterError::Unsupported`] if the CPU does not run `isa`; [`FilterError::Initial`] if
    /// `x0` is not finite or `P0` not symmetric positive semi-definite (the scalar check).
    pub fn new(
        isa: Isa,
        model: BatchModel<N, M>,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
    ) -> Result<Self, FilterError> {
        let isa = isa.checked()?;
        let init = FilterError::Initial;
        check_finite(&x0, "initial mean").map_err(init)?;
        // The scalar filter's check, and its symmetrised copy.
        let p0 = kalibra_linalg::PsdMatrix::named(p0, "initial covariance")
            .map_err(init)?
            .matrix()
            .clone_owned();
        Ok(Self {
            isa,
            model,
            k: 0,
            x: std::array::from_fn(|i| [x0[i]; BATCH]),
            p: std::array::from_fn(|i| std::array::from_fn(|j| [p0[(i, j)]; BATCH])),
            out: BatchStep::new(),
        })
    }

    /// Restarts lane `lane` from its own estimate `(x, P)` (for instance runs with their own
    /// priors), checked as [`KfBatch::new`] checks the shared one.
    ///
    /// # Errors
    /// [`FilterError::Initial`] as [`KfBatch::new`]; the lane is then unchanged.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn set_lane(
        &mut self,
        lane: usize,
        x: SVector<f64, N>,
        p: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        let init = FilterError::Initial;
        check_finite(&x, "initial mean").map_err(init)?;
        let p = kalibra_linalg::PsdMatrix::named(p, "initial covariance")
            .map_err(init)?
            .matrix()
            .clone_owned();
        for i in 0..N {
            self.x[i][lane] = x[i];
            for j in 0..N {
                self.p[i][j][lane] = p[(i, j)];
            }
        }
        Ok(())
    }

    /// The instruction set the batch runs on.
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// The current step index.
    pub fn step_index(&self) -> usize {
        self.k
    }

    /// Lane `lane`'s current mean.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn mean(&self, lane: usize) -> SVector<f64, N> {
        SVector::from_fn(|i, _| self.x[i][lane])
    }

    /// Lane `lane`'s current covariance.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn cov(&self, lane: usize) -> SMatrix<f64, N, N> {
        SMatrix::from_fn(|i, j| self.p[i][j][lane])
    }

    /// Updates every lane at the current step with its measurement `z[i][lane]` and computes
    /// its NIS, and its NEES against the true state `truth[i][lane]` (pass zeros where there
    /// is no truth and ignore the NEES).
    pub fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        self.run::<false>(z, truth)
    }

    /// Predicts every lane from step `k` to `k + 1`, then updates it as [`KfBatch::update`]
    /// does: one pass over the batch. A lane whose update fails keeps its prediction (the
    /// scalar filter's state after a prediction and a failed update).
    pub fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        self.k += 1;
        self.run::<true>(z, truth)
    }

    fn run<const PREDICT: bool>(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        let isa = self.isa;
        isa.dispatch(Kernel::<N, M, PREDICT> {
            model: &self.model,
            x: &mut self.x,
            p: &mut self.p,
            z,
            truth,
            out: &mut self.out,
        });
        self.out.k = self.k;
        // The kernel's health sum is 0 for a lane whose update succeeded and NaN otherwise;
        // the NEES is checked apart, as the scalar record's `nees` is a separate call.
        for lane in 0..BATCH {
            self.out.failure[lane] = (self.out.health[lane] != 0.0).then(|| self.explain(lane, z));
            self.out.nees_failure[lane] =
                (!self.out.nees[lane].is_finite()).then_some(FilterError::NotPositiveDefinite {
                    what: "posterior covariance P+",
                    step: self.k,
                });
        }
        &self.out
    }

    /// The scalar filter's error for a failed lane (off the hot path).
    #[cold]
    #[inline(never)]
    fn explain(&self, lane: usize, z: &[Lanes; M]) -> FilterError {
        let k = self.k;
        if z.iter().any(|zi| !zi[lane].is_finite()) {
            return FilterError::NonFinite {
                what: "measurement",
                step: k,
            };
        }
        if (0..N).any(|i| (0..N).any(|j| !self.p[i][j][lane].is_finite()))
            || (0..N).any(|i| !self.x[i][lane].is_finite())
        {
            return FilterError::NonFinite {
                what: "predicted covariance (process noise Q?)",
                step: k,
            };
        }
        let nis = self.out.nis[lane];
        if !nis.is_finite() {
            return FilterError::NotPositiveDefinite {
                what: "innovation covariance S",
                step: k,
            };
        }
        FilterError::NonFinite {
            what: "posterior estimate",
            step: k,
        }
    }
}

/// One batched step as a pulp operation: `with_simd` is compiled once per instruction set.
struct Kernel<'a, const N: usize, const M: usize, const PREDICT: bool> {
    model: &'a BatchModel<N, M>,
    x: &'a mut [Lanes; N],
    p: &'a mut [[Lanes; N]; N],
    z: &'a [Lanes; M],
    truth: &'a [Lanes; N],
    out: &'a mut BatchStep<N>,
}

#[inline(always)]
fn load<S: Simd>(a: &Lanes, c: usize) -> S::f64s {
    S::as_simd_f64s(a).0[c]
}

#[inline(always)]
fn store<S: Simd>(a: &mut Lanes, c: usize, v: S::f64s) {
    S::as_mut_simd_f64s(a).0[c] = v;
}

// The helpers below use plain loops over arrays, never closures (`std::array::from_fn`): a
// closure is a function of its own, compiled for the baseline instruction set unless it is
// inlined, and one that was not made the AVX-512 kernel slower than the scalar one.

#[inline(always)]
fn splat<S: Simd, const R: usize, const C: usize>(simd: S, m: &[[f64; C]; R]) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            out[i][j] = simd.splat_f64s(m[i][j]);
        }
    }
    out
}

/// `sum_k a[i][k] b[k][j]`, accumulated in `k` order like nalgebra's small products, with a
/// fused multiply-add where the instruction set has one.
#[inline(always)]
fn mul<S: Simd, const R: usize, const K: usize, const C: usize>(
    simd: S,
    a: &[[S::f64s; K]; R],
    b: &[[S::f64s; C]; K],
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            let mut s = simd.mul_f64s(a[i][0], b[0][j]);
            for k in 1..K {
                s = simd.mul_add_e_f64s(a[i][k], b[k][j], s);
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
    a: &[[S::f64s; K]; R],
    v: &[S::f64s; K],
) -> [S::f64s; R] {
    let mut out = [simd.splat_f64s(0.0); R];
    for i in 0..R {
        let mut s = simd.mul_f64s(a[i][0], v[0]);
        for k in 1..K {
            s = simd.mul_add_e_f64s(a[i][k], v[k], s);
        }
        out[i] = s;
    }
    out
}

/// `a b^T`.
#[inline(always)]
fn mul_t<S: Simd, const R: usize, const K: usize, const C: usize>(
    simd: S,
    a: &[[S::f64s; K]; R],
    b: &[[S::f64s; K]; C],
) -> [[S::f64s; C]; R] {
    let mut out = [[simd.splat_f64s(0.0); C]; R];
    for i in 0..R {
        for j in 0..C {
            let mut s = simd.mul_f64s(a[i][0], b[j][0]);
            for k in 1..K {
                s = simd.mul_add_e_f64s(a[i][k], b[j][k], s);
            }
            out[i][j] = s;
        }
    }
    out
}

#[inline(always)]
fn add<S: Simd, const R: usize, const C: usize>(
    simd: S,
    a: &[[S::f64s; C]; R],
    b: &[[S::f64s; C]; R],
) -> [[S::f64s; C]; R] {
    let mut out = *a;
    for i in 0..R {
        for j in 0..C {
            out[i][j] = simd.add_f64s(a[i][j], b[i][j]);
        }
    }
    out
}

/// `(m + m^T) / 2` on the off-diagonal, as `kalibra_linalg::symmetrize`.
#[inline(always)]
fn symmetrize<S: Simd, const D: usize>(simd: S, m: &mut [[S::f64s; D]; D]) {
    let half = simd.splat_f64s(0.5);
    for j in 0..D {
        for i in (j + 1)..D {
            let mean = simd.mul_f64s(half, simd.add_f64s(m[i][j], m[j][i]));
            m[i][j] = mean;
            m[j][i] = mean;
        }
    }
}

/// The lower Cholesky factor `L` of a symmetric `a`, and the reciprocals of its diagonal:
/// each pivot is divided once and the other divisions by it are multiplications, which takes
/// the divider's latency off the chain of dependent operations (a division by `l_jj` and a
/// multiplication by its reciprocal differ by one rounding). NaN or infinite entries, never a
/// panic, for a matrix that is not positive definite: `sqrt` of a negative pivot is NaN, of
/// zero 0, and its reciprocal infinite.
#[inline(always)]
fn cholesky<S: Simd, const D: usize>(
    simd: S,
    a: &[[S::f64s; D]; D],
) -> ([[S::f64s; D]; D], [S::f64s; D]) {
    let one = simd.splat_f64s(1.0);
    let mut l = [[simd.splat_f64s(0.0); D]; D];
    let mut inv = [one; D];
    for j in 0..D {
        let mut d = a[j][j];
        for k in 0..j {
            d = simd.sub_f64s(d, simd.mul_f64s(l[j][k], l[j][k]));
        }
        let ljj = simd.sqrt_f64s(d);
        l[j][j] = ljj;
        inv[j] = simd.div_f64s(one, ljj);
        for i in (j + 1)..D {
            let mut s = a[i][j];
            for k in 0..j {
                s = simd.sub_f64s(s, simd.mul_f64s(l[i][k], l[j][k]));
            }
            l[i][j] = simd.mul_f64s(s, inv[j]);
        }
    }
    (l, inv)
}

/// Solves `L w = b` by forward substitution (`inv`: the reciprocals of `L`'s diagonal).
#[inline(always)]
fn forward<S: Simd, const D: usize>(
    simd: S,
    (l, inv): &([[S::f64s; D]; D], [S::f64s; D]),
    b: &[S::f64s; D],
) -> [S::f64s; D] {
    let mut w = *b;
    for i in 0..D {
        let mut s = w[i];
        for k in 0..i {
            s = simd.sub_f64s(s, simd.mul_f64s(l[i][k], w[k]));
        }
        w[i] = simd.mul_f64s(s, inv[i]);
    }
    w
}

/// Solves `L^T y = w` by backward substitution.
#[inline(always)]
fn backward<S: Simd, const D: usize>(
    simd: S,
    (l, inv): &([[S::f64s; D]; D], [S::f64s; D]),
    w: &[S::f64s; D],
) -> [S::f64s; D] {
    let mut y = *w;
    for i in (0..D).rev() {
        let mut s = y[i];
        for k in (i + 1)..D {
            s = simd.sub_f64s(s, simd.mul_f64s(l[k][i], y[k]));
        }
        y[i] = simd.mul_f64s(s, inv[i]);
    }
    y
}

#[inline(always)]
fn norm_squared<S: Simd, const D: usize>(simd: S, w: &[S::f64s; D]) -> S::f64s {
    let mut s = simd.mul_f64s(w[0], w[0]);
    for v in &w[1..] {
        s = simd.mul_add_e_f64s(*v, *v, s);
    }
    s
}

/// `sum v * 0`: 0 if every entry is finite, NaN otherwise.
#[inline(always)]
fn health<S: Simd>(simd: S, acc: S::f64s, v: S::f64s) -> S::f64s {
    simd.mul_add_e_f64s(v, simd.splat_f64s(0.0), acc)
}

impl<const N: usize, const M: usize, const PREDICT: bool> WithSimd for Kernel<'_, N, M, PREDICT> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Kernel {
            model,
            x: xs,
            p: ps,
            z: zs,
            truth,
            out,
        } = self;
        // The model, broadcast once per batch.
        let f = splat(simd, &model.f);
        let q = splat(simd, &model.q);
        let h = splat(simd, &model.h);
        let r = splat(simd, &model.r);
        let zero = simd.splat_f64s(0.0);
        let one = simd.splat_f64s(1.0);
        for c in 0..BATCH / S::F64_LANES {
            let mut x = [zero; N];
            let mut p = [[zero; N]; N];
            for i in 0..N {
                x[i] = load::<S>(&xs[i], c);
                for j in 0..N {
                    p[i][j] = load::<S>(&ps[i][j], c);
                }
            }
            if PREDICT {
                // x- = F x; P- = (F P) F^T + Q, symmetrised (KalmanCore::predict). The
                // prediction is kept even if the update fails (the selection below keeps `x`
                // and `p`, now the prior), as in the scalar filter.
                x = mul_vec(simd, &f, &x);
                let fp = mul(simd, &f, &p);
                p = add(simd, &mul_t(simd, &fp, &f), &q);
                symmetrize(simd, &mut p);
            }
            // P H^T, S = H (P H^T) + R symmetrised, its factor (KalmanCore::update).
            let pht = mul_t(simd, &p, &h);
            let mut s = add(simd, &mul(simd, &h, &pht), &r);
            symmetrize(simd, &mut s);
            let ls = cholesky(simd, &s);
            // K = (S^-1 (P H^T)^T)^T, one column of (P H^T)^T (a row of P H^T) at a time.
            let mut gain = [[zero; M]; N];
            for i in 0..N {
                gain[i] = backward(simd, &ls, &forward(simd, &ls, &pht[i]));
            }
            // nu = z - H x; x+ = x + K nu.
            let hx = mul_vec(simd, &h, &x);
            let mut hz = zero;
            let mut nu = [zero; M];
            for i in 0..M {
                let zi = load::<S>(&zs[i], c);
                hz = health(simd, hz, zi);
                nu[i] = simd.sub_f64s(zi, hx[i]);
            }
            let knu = mul_vec(simd, &gain, &nu);
            let mut x_post = [zero; N];
            for i in 0..N {
                x_post[i] = simd.add_f64s(x[i], knu[i]);
            }
            // Joseph: (I - K H) P (I - K H)^T + (K R) K^T, symmetrised.
            let mut ikh = mul(simd, &gain, &h);
            for i in 0..N {
                for j in 0..N {
                    ikh[i][j] = simd.neg_f64s(ikh[i][j]);
                }
                ikh[i][i] = simd.add_f64s(ikh[i][i], one);
            }
            let ikhp = mul(simd, &ikh, &p);
            let kr = mul(simd, &gain, &r);
            let mut p_post = add(simd, &mul_t(simd, &ikhp, &ikh), &mul_t(simd, &kr, &gain));
            symmetrize(simd, &mut p_post);
            // NIS through the factor of S.
            let nis = norm_squared(simd, &forward(simd, &ls, &nu));
            // Health: 0 if the measurement, the NIS (so S's factor) and the posterior are all
            // finite, NaN otherwise; a lane keeps its old estimate unless it is 0.
            let mut ok = health(simd, hz, nis);
            for i in 0..N {
                ok = health(simd, ok, x_post[i]);
                for j in 0..N {
                    ok = health(simd, ok, p_post[i][j]);
                }
            }
            let keep = simd.equal_f64s(ok, zero);
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
            // NEES of the truth against the posterior, through P+'s factor.
            let mut e = [zero; N];
            for i in 0..N {
                e[i] = simd.sub_f64s(load::<S>(&truth[i], c), x_post[i]);
            }
            let lp = cholesky(simd, &p_post);
            let nees = norm_squared(simd, &forward(simd, &lp, &e));
            store::<S>(&mut out.nis, c, nis);
            store::<S>(&mut out.nees, c, nees);
            store::<S>(&mut out.health, c, ok);
            for i in 0..N {
                store::<S>(&mut out.error[i], c, e[i]);
            }
        }
    }
}
