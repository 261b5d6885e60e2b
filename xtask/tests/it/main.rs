//! The integration tests of xtask, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod bench_figures;
mod cli;
mod shards;
