//! Noise estimators for `kalibra-tune`: EM, ALS and J1/J2 on every parameter.
//!
//! This manifest and this file are the estimators' branch's stand-in for the crate's own (on
//! merging, the crate's `lib.rs` gains `mod als; mod em; mod j1j2;` and the re-exports below,
//! and `shim` is dropped for `noise` and `problem`).
//!
//! * [`Em`]: expectation-maximisation (Shumway and Stoffer), honouring each form.
//! * [`Als`]: autocovariance least squares (Odelson, Rajamani and Rawlings 2006).
//! * [`ParameterSweep`]: the J1/J2 crossover on every free parameter around an estimate.

// Library code returns typed errors; an unwrap or expect must say why it cannot fail.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod als;
mod em;
mod j1j2;
mod shim;

pub use als::{ALS_LAGS, ALS_MAX_ITERATIONS, ALS_RANK_TOLERANCE, Als, AlsError, AlsEstimate};
pub use em::{EM_MAX_ITERATIONS, EM_TOLERANCE, Em, EmError, EmEstimate};
pub use j1j2::{
    CurveCrossover, CurvePoint, J_SWEEP_FROM, J_SWEEP_STEP, J_SWEEP_TO, ParameterCurve,
    ParameterSweep, SweepError,
};
/// The start convention of a [`NoiseProblem`].
pub use kalibra_filters::Start;
/// The matrix and vector types of a [`NoiseProblem`].
pub use kalibra_linalg::{DMatrix, DVector};
pub use shim::{
    CovarianceForm, FormKind, NoiseError, NoiseMatrices, NoiseMatrix, NoiseProblem, Parameter,
    ParameterKind, Parametrisation, Run,
};
