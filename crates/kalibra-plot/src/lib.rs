//! Figures as data, and a deterministic SVG writer for them.
//!
//! # What this crate is for
//! A study of `kalibra-studies` or a report of `kalibra eval` says what it wants drawn as a
//! [`Figure`] (series of points, reference lines and points, axis labels, a log axis): plain
//! data, serialisable, which tests can check without parsing a drawing. [`ToSvg`] renders a
//! figure to a standalone SVG document as a `String`. The crate writes no file and prints
//! nothing; its callers decide where the SVG goes (`cargo xtask reproduce` writes it beside a
//! study's report, `kalibra eval` beside a log's and inline in its HTML).
//!
//! It is not a general plotting library: line and marker plots on linear or log10 y axes, no
//! more. It is our own rather than a plotting crate so that output is byte-identical on every
//! machine (text is set by the viewer, never measured from system fonts): see
//! `docs/ARCHITECTURE.md`, Decisions.
//!
//! # Where each job lives
//! * [`figure`]: the figure as data ([`Figure`], [`Series`], [`Annotation`], [`Style`]).
//! * `svg`: the deterministic SVG writer ([`ToSvg`]).
//!
//! # Example
//! ```
//! use kalibra_plot::{Annotation, Figure, Series, ToSvg};
//! let svg = Figure::new("Position error", "time [s]", "RMSE [m]")
//!     .log_y()
//!     .series(Series::line("EKF", vec![(0.0, 10.0), (1.0, 3.0), (2.0, 1.5)]))
//!     .series(Series::markers("UKF", vec![(0.0, 9.0), (1.0, 2.5), (2.0, 1.2)]).dashed())
//!     .annotate(Annotation::VLine { x: 1.0, label: "manoeuvre".into() })
//!     .to_svg();
//! assert!(svg.starts_with("<svg"));
//! // Deterministic: the same figure gives the same bytes.
//! let again = Figure::new("Position error", "time [s]", "RMSE [m]")
//!     .log_y()
//!     .series(Series::line("EKF", vec![(0.0, 10.0), (1.0, 3.0), (2.0, 1.5)]))
//!     .series(Series::markers("UKF", vec![(0.0, 9.0), (1.0, 2.5), (2.0, 1.2)]).dashed())
//!     .annotate(Annotation::VLine { x: 1.0, label: "manoeuvre".into() })
//!     .to_svg();
//! assert_eq!(svg, again);
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
pub mod figure;
mod svg;

pub use figure::{Annotation, DEFAULT_HEIGHT, DEFAULT_WIDTH, Figure, Series, Style};
pub use svg::ToSvg;
