//! The integration tests of kalibra-metrics, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod hypothesis;
mod innovation;
mod metrics;
mod window;
