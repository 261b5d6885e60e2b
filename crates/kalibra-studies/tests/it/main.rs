//! The integration tests of kalibra-studies, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod angle;
mod bearings;
mod reentry;
mod surrogate;
mod w1;
