//! The integration tests of kalibra-io, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod errors;
mod readers_fuzz;
