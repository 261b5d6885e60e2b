//! The integration tests of kalibra-cli, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod common;

mod eval;
mod eval_property;
mod extremes;
mod generate_fixtures;
mod options;
mod tune;
mod tune_noise;
