//! The matrix vocabulary of kalibra.
//!
//! # What this crate is for
//! Every other kalibra crate speaks in the types and kernels defined here:
//!
//! * nalgebra matrices generic over their dimensions, fixed to `f64`. A dimension is a
//!   [`Dim`]: [`Const<N>`](Const) (aliases [`U1`](type@U1) .. [`U9`](type@U9)) for sizes
//!   known at compile time, which live on the stack and compile to straight-line code, or
//!   [`Dyn`] for sizes known only at run time. One generic implementation serves both.
//! * [`Alloc`], one bound-alias trait that collects the allocator bounds a filter over a state
//!   dimension `N` and a measurement dimension `M` needs, so each signature carries one line:
//!   `where DefaultAllocator: Alloc<N, M>`.
//! * [`Covariance`], a checked symmetric positive definite matrix that keeps its Cholesky
//!   factor, so solves, quadratic forms and log-determinants never refactorise.
//! * [`Gaussian`], a mean and a covariance by name, returned by every function that computes
//!   both.
//! * [`PsdMatrix`], a checked symmetric positive *semi*-definite matrix with a square-root
//!   factor, for process noise that is often rank-deficient (`Q = G G^T`).
//! * Kernels for the filter algebra: [`propagate`] (`F P F^T`), [`innovation_covariance`]
//!   (`P H^T` and `S`), the gain by [`Covariance::solve_right`], [`joseph_update`],
//!   [`standard_update`], [`product`], [`product_transpose`], [`cholesky_solve_right`],
//!   [`symmetrize`], [`sigma_sqrt`], a matrix square root for sigma points with a documented
//!   fallback, and the unscented transform's sums of outer products [`add_scatter`] and
//!   [`add_cross_scatter`]. For fixed sizes the products and the Cholesky solves are written
//!   out in the loops they inline into, in nalgebra's order of operations, so their bits are
//!   nalgebra's (the unit tests `fixed_products_equal_nalgebras_to_the_bit` and
//!   `fixed_solves_equal_nalgebras_to_the_bit`): nalgebra's out-of-line calls return small
//!   matrices through memory, where the next step waits to read them back (`cargo xtask bench
//!   smooth`). For the same reason these kernels, the Cholesky factorisation of
//!   [`Covariance::from_symmetric`] and [`quad_form_symmetric`] are always inlined: left to
//!   the compiler, a Monte Carlo study's scalar step kept some of them out of line (`cargo
//!   xtask bench w1`, the scalar library).
//! * [`discrete_lyapunov`]: the stationary covariance `X = A X A^T + Q` by Smith's doubling,
//!   with a typed error when the series diverges, and [`spectral_radius`] (Gelfand's formula
//!   by repeated squaring).
//! * Large run-time sizes through faer ([`backend`]): from [`FAER_MIN_DIM`] on, the `Dyn`
//!   kernels run faer's blocked, vectorised products and Cholesky factorisation on views of
//!   nalgebra's storage (faster than nalgebra's from that size on: `cargo xtask bench w4`),
//!   with nalgebra types at every interface (`backend.rs`). Fixed sizes never leave nalgebra.
//!   Which code runs is one decision per kernel call, by the calling thread's [`KernelPolicy`]
//!   ([`with_kernel_policy`]), which can also let faer use several threads within a step for
//!   `n >= ` [`PARALLEL_MIN_DIM`].
//!
//! * [`simd`]: the SIMD lane vocabulary of the batched filters and studies: the instruction
//!   set chosen at run time ([`simd::Isa`], dispatched through pulp), the lane layout
//!   ([`simd::BATCH`], [`simd::Lanes`]), lane-wise `atan2`, `sin`/`cos` and `exp`
//!   ([`simd::math`]), and the lane-wise Cholesky factor and triangular solves
//!   ([`simd::LaneCholesky`]).
//!
//! Files: `covariance.rs` ([`Covariance`]), `psd.rs` ([`PsdMatrix`], [`sigma_sqrt`]),
//! `kernels.rs` (the filter kernels), `backend.rs` (the faer dispatch), `lyapunov.rs`,
//! `gaussian.rs`, `scale.rs`, `alloc.rs`, `error.rs` ([`LinalgError`]), and the folder `simd/`.
//!
//! It is not a general linear-algebra library: it has no per-operation backend traits, and
//! faer sits underneath the kernels, not beside them in the API.
//!
//! # Notation
//! `P` is a state covariance (n x n), `F` a transition Jacobian, `Q` a process-noise covariance,
//! `H` a measurement Jacobian (m x n), `R` a measurement-noise covariance, `S = H P H^T + R` the
//! innovation covariance and `K = P H^T S^-1` the gain.
//!
//! # Numerical choices
//! * `f64` throughout.
//! * Never an explicit inverse where a solve will do: [`Covariance::solve`] and
//!   [`Covariance::quad_form`] use the stored Cholesky factor (a quadratic form is one triangular
//!   solve, `|L^-1 v|^2`).
//! * A matrix passed as a covariance must be symmetric to a relative tolerance of
//!   [`SYMMETRY_TOLERANCE`]; it is then made exactly symmetric (mean of the two triangles) before
//!   factorisation, so rounding from earlier products does not reject good input.
//! * Semi-definite factors pivot on the largest remaining diagonal entry and stop below a
//!   tolerance relative to the largest variance ([`PIVOT_TOLERANCE`]), so rank-deficient
//!   matrices factor reliably; a variance below about `1e-13 n` times the largest counts as zero.
//!
//! # Example
//! ```
//! use kalibra_linalg::{Covariance, Matrix2, Vector2};
//!
//! let s = Covariance::new(Matrix2::new(4.0, 1.0, 1.0, 3.0))?;
//! let nu = Vector2::new(1.0, -2.0);
//! // nu^T S^-1 nu through the Cholesky factor, no inverse formed.
//! let nis = s.quad_form(&nu)?;
//! let direct = (nu.transpose() * s.matrix().try_inverse().unwrap() * nu)[0];
//! assert!((nis - direct).abs() < 1e-12);
//! # Ok::<(), kalibra_linalg::LinalgError>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod alloc;
pub mod backend;
mod covariance;
mod error;
mod gaussian;
mod kernels;
mod lyapunov;
mod psd;
mod scale;
pub mod simd;

pub use alloc::Alloc;
pub use backend::{
    FAER_MIN_DIM, KernelPolicy, PARALLEL_MIN_DIM, kernel_policy, with_kernel_policy,
};
pub use covariance::{
    Covariance, Definiteness, SYMMETRY_TOLERANCE, check_covariance, check_symmetric,
    quad_form_once, quad_form_symmetric,
};
pub use error::LinalgError;
pub use gaussian::Gaussian;
pub use kernels::{
    add_cross_scatter, add_scatter, all_finite, check_dim, check_finite, cholesky_solve_right,
    innovation_covariance, joseph_update, product, product_transpose, propagate, standard_update,
    symmetrize,
};
pub use lyapunov::{
    LYAPUNOV_MAX_DOUBLINGS, SPECTRAL_MAX_SQUARINGS, discrete_lyapunov, spectral_radius,
};
pub use psd::{PIVOT_TOLERANCE, PsdMatrix, SqrtMethod, semidefinite_factor, sigma_sqrt};
pub use scale::{binary_exponent, ldexp};

pub use nalgebra;
pub use nalgebra::{
    Const, DMatrix, DVector, DefaultAllocator, Dim, DimName, Dyn, Matrix1, Matrix2, Matrix3,
    Matrix4, OMatrix, OVector, SMatrix, SVector, U1, U2, U3, U4, U5, U6, U7, U8, U9, Vector1,
    Vector2, Vector3, Vector4, Vector6,
};
