//! The integration tests of kalibra-models, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod lanes;
mod value_stability;
