//! The integration tests of the root package `kalibra`, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod extreme;

mod adversarial;
mod architecture;
mod consistency;
mod dev_dependencies;
mod extreme_floats;
mod extreme_sizes;
mod properties;
mod threads;
