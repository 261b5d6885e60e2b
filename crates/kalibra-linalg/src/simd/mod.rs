//! The SIMD lane vocabulary of the batched filters and studies: [`BATCH`] runs side by side,
//! one f64 per run in a [`Lanes`] array, stepped on an instruction set chosen at run time.
//!
//! # Where each job lives
//! * [`Isa`] (`simd/isa.rs`): the instruction sets, detection, parsing and the dispatch of a
//!   pulp operation ([`Isa::dispatch`]), so that a portable build carries every path.
//! * [`BATCH`], [`Lanes`], [`load`] and [`store`] (this file): the lane layout, and one
//!   vector of an instruction set read from or written to it.
//! * [`math`] (`simd/math.rs`): lane-wise `atan2`, `sin`/`cos` and `exp` for models that
//!   evaluate their lanes together.
//! * [`LaneCholesky`] (`simd/cholesky.rs`): the lane-wise Cholesky factor and its
//!   triangular solves, generic over the [`Pivot`] rule ([`Reciprocal`] or [`Divide`]), which
//!   every batched filter factorises with.
//!
//! Everything a dispatched kernel calls is `#[inline(always)]`, so it compiles inside the
//! dispatched function, for its instruction set.
//!
//! # Example
//! ```
//! use kalibra_linalg::simd::{BATCH, Isa, Lanes, load, store};
//! use pulp::{Simd, WithSimd};
//!
//! struct Square<'a>(&'a mut Lanes);
//! impl WithSimd for Square<'_> {
//!     type Output = ();
//!     #[inline(always)]
//!     fn with_simd<S: Simd>(self, simd: S) {
//!         for c in 0..BATCH / S::F64_LANES {
//!             let v = load::<S>(self.0, c);
//!             store::<S>(self.0, c, simd.mul_f64s(v, v));
//!         }
//!     }
//! }
//! let mut x = [3.0; BATCH];
//! Isa::detect().dispatch(Square(&mut x));
//! assert_eq!(x, [9.0; BATCH]);
//! ```

mod cholesky;
mod isa;
pub mod math;

pub use cholesky::{Divide, LaneCholesky, Pivot, Reciprocal};
pub use isa::Isa;

use pulp::Simd;

/// Runs per batch: the lanes of one AVX-512 vector of f64. Narrower instruction sets step a
/// batch as several vectors, so the grouping of runs (and so every result) does not depend on
/// the instruction set.
pub const BATCH: usize = 8;

/// One f64 per run of a batch.
pub type Lanes = [f64; BATCH];

/// The lanes of chunk `c` of `a` as one vector of the instruction set of `S`
/// (`BATCH / S::F64_LANES` chunks per batch).
#[inline(always)]
pub fn load<S: Simd>(a: &Lanes, c: usize) -> S::f64s {
    S::as_simd_f64s(a).0[c]
}

/// Stores `v` into the lanes of chunk `c` of `a`.
#[inline(always)]
pub fn store<S: Simd>(a: &mut Lanes, c: usize, v: S::f64s) {
    S::as_mut_simd_f64s(a).0[c] = v;
}
