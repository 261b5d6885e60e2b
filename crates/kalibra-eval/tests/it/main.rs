//! The integration tests of kalibra-eval, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod filterpy;
mod log;
mod monte_carlo;
mod report_equals_metrics;
mod stream;
