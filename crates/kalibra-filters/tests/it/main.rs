//! The integration tests of kalibra-filters, linked into one test binary (linking one per file
//! dominated CI's build): each file is a module; `tests/architecture.rs` keeps it one.

mod common;
mod lane_data;
mod sqrt_common;

mod api;
mod batch;
mod batch_ekf;
mod batch_ukf;
mod dimensions;
mod failed_step;
mod kalman;
mod large;
mod model_sizes;
mod schedule;
mod smooth;
mod smooth_fixtures;
mod sqrt_ill_conditioned;
mod sqrt_kf;
mod sqrt_ukf;
mod unscented;
