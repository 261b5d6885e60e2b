//! Figures as data: the studies' figures are [`kalibra_plot`] values, re-exported here so a
//! study writes `crate::figure::Figure`; `cargo xtask reproduce` renders them with
//! [`kalibra_plot::ToSvg`].

pub use kalibra_plot::figure::*;

/// Test helper: every figure has a drawable point and no `NaN` in its text.
#[cfg(test)]
pub(crate) fn assert_drawable(figures: &[(String, Figure)]) {
    for (name, fig) in figures {
        let finite = fig
            .series
            .iter()
            .flat_map(|s| &s.points)
            .any(|(x, y)| x.is_finite() && y.is_finite());
        assert!(finite, "{name} has no data");
        let text = std::iter::once(&fig.title)
            .chain(fig.series.iter().map(|s| &s.label))
            .chain([&fig.x_label, &fig.y_label]);
        for t in text {
            assert!(!t.contains("NaN"), "{name}: {t}");
        }
    }
}
