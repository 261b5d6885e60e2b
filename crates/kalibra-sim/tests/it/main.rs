//! The integration tests of kalibra-sim, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod batch;
mod lanes;
mod shard;
mod value_stability;
