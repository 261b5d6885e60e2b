//! What the report template needs beyond the report's own fields: the printed tables, set
//! beside ours row by row.

use serde::Serialize;

use super::run::{Config, Report};
use super::scenario::{COMPONENTS, TABLE1, TABLE2_EMPIRICAL, TABLE2_SURROGATE};

/// The template's context.
#[derive(Serialize)]
pub(super) struct Context<'a> {
    config: &'a Config,
    report: &'a Report,
    components: [&'static str; 9],
    table2_empirical: [(f64, f64); 9],
    table2_surrogate: [f64; 9],
    table1: [[f64; 3]; 9],
}

impl<'a> Context<'a> {
    /// The context of `report` run with `config`.
    pub(super) fn new(config: &'a Config, report: &'a Report) -> Self {
        Self {
            config,
            report,
            components: COMPONENTS,
            table2_empirical: TABLE2_EMPIRICAL,
            table2_surrogate: TABLE2_SURROGATE,
            table1: TABLE1,
        }
    }
}
