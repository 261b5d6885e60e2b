//! The integration tests of kalibra-tune, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod common;

mod als;
mod coverage;
mod em;
mod em_pykalman;
mod j1j2;
mod ml;
mod ml_nonlinear;
mod report;
mod report_nonlinear;
mod statsmodels;
mod sweep_q;
