//! Report templates: the prose of a study's report lives in a Markdown template beside its
//! code (`<study>/report.md`), filled from the serialised configuration, report and claims.
//!
//! Templates use [minijinja](https://docs.rs/minijinja) (Jinja2 syntax) in strict mode, so a
//! misspelt field is an error, not an empty string. Numbers are formatted by filters whose
//! names say the format, since Jinja's own number printing follows Python rather than the
//! fixed decimals a table wants:
//!
//! | filter | output for `0.0123` |
//! |---|---|
//! | `x \| fixed(3)` | `0.012` |
//! | `x \| signed(3)` | `+0.012` (always a sign, as Rust's `{:+.3}`) |
//! | `x \| percent(1)` | `1.2` (the value times 100) |
//! | `x \| sci(2)` | `1.23e-2` |
//! | `text \| cell` | the text with `\|` escaped, for a table cell |
//!
//! and `claims_table(claims)` renders the claims as the Markdown table every report shows.

use minijinja::{Environment, UndefinedBehavior, Value, value::ViaDeserialize};
use serde::Serialize;

use crate::StudyError;
use crate::claims::{CLAIMS_HEADER, claims_row};

/// A number as the filters receive it: integers and floats alike.
fn number(value: &Value) -> Result<f64, minijinja::Error> {
    f64::try_from(value.clone()).map_err(|_| {
        minijinja::Error::new(
            minijinja::ErrorKind::InvalidOperation,
            format!("{value} is not a number"),
        )
    })
}

/// `NaN`, `inf` and `-inf` print as `n/a` and `±inf`: a report row with a missing value reads
/// better than Rust's `NaN`.
fn special(v: f64) -> Option<String> {
    if v.is_nan() {
        Some("n/a".into())
    } else if v.is_infinite() {
        Some(if v > 0.0 { "inf" } else { "-inf" }.into())
    } else {
        None
    }
}

fn fixed(value: Value, digits: Option<usize>) -> Result<String, minijinja::Error> {
    let v = number(&value)?;
    Ok(special(v).unwrap_or_else(|| format!("{:.*}", digits.unwrap_or(3), v)))
}

fn signed(value: Value, digits: Option<usize>) -> Result<String, minijinja::Error> {
    let v = number(&value)?;
    Ok(special(v).unwrap_or_else(|| format!("{:+.*}", digits.unwrap_or(3), v)))
}

fn percent(value: Value, digits: Option<usize>) -> Result<String, minijinja::Error> {
    let v = number(&value)?;
    Ok(special(v).unwrap_or_else(|| format!("{:.*}", digits.unwrap_or(1), 100.0 * v)))
}

fn sci(value: Value, digits: Option<usize>) -> Result<String, minijinja::Error> {
    let v = number(&value)?;
    Ok(special(v).unwrap_or_else(|| format!("{:.*e}", digits.unwrap_or(2), v)))
}

fn cell(value: String) -> String {
    value.replace('|', "\\|")
}

fn claims(list: ViaDeserialize<Vec<ClaimRow>>) -> String {
    let mut out = String::from(CLAIMS_HEADER);
    for c in list.0 {
        out.push_str(&claims_row(
            &c.claim,
            &c.published,
            &c.ours,
            &c.tolerance,
            c.verdict,
            &c.section,
        ));
    }
    out
}

/// A claim as it comes back from the template context (owned strings).
#[derive(serde::Deserialize)]
struct ClaimRow {
    claim: String,
    published: String,
    ours: String,
    tolerance: String,
    verdict: crate::claims::Verdict,
    section: String,
}

/// Renders `source` (a template named `name`, for error messages) with `context`.
///
/// # Errors
/// [`StudyError::Template`] with the template's name and the line of the failure when the
/// template does not parse or refers to something `context` lacks.
pub fn render(name: &str, source: &str, context: &impl Serialize) -> Result<String, StudyError> {
    let mut env = Environment::new();
    env.set_undefined_behavior(UndefinedBehavior::Strict);
    env.set_trim_blocks(true);
    env.set_lstrip_blocks(true);
    env.set_keep_trailing_newline(true);
    env.add_filter("fixed", fixed);
    env.add_filter("signed", signed);
    env.add_filter("percent", percent);
    env.add_filter("sci", sci);
    env.add_filter("cell", cell);
    env.add_function("claims_table", claims);
    let describe = |e: minijinja::Error| {
        let mut message = format!("{name}: {e}");
        if let Some(line) = e.line() {
            message = format!("{name}, line {line}: {e}");
        }
        StudyError::Template(message)
    };
    let template = env
        .template_from_named_str(name, source)
        .map_err(describe)?;
    template
        .render(Value::from_serialize(context))
        .map_err(describe)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filters_format_numbers_and_specials() {
        let out = render(
            "t",
            "{{ a | fixed(2) }} {{ a | percent }} {{ a | sci(1) }} {{ b | fixed }} {{ n | fixed(1) }} {{ s | cell }}",
            &serde_json::json!({ "a": 0.0123, "b": null, "n": 3, "s": "a|b" }),
        );
        // `null` (a NaN serialised by serde_json) is not a number: the template is wrong.
        assert!(matches!(out, Err(StudyError::Template(_))));
        let out = render(
            "t",
            "{{ a | fixed(2) }} {{ a | percent }} {{ a | sci(1) }} {{ n | fixed(1) }} {{ s | cell }}",
            &serde_json::json!({ "a": 0.0123, "n": 3, "s": "a|b" }),
        )
        .unwrap();
        assert_eq!(out, "0.01 1.2 1.2e-2 3.0 a\\|b");
        assert_eq!(fixed(Value::from(f64::NAN), None).unwrap(), "n/a");
        assert_eq!(percent(Value::from(f64::INFINITY), None).unwrap(), "inf");
        assert_eq!(signed(Value::from(0.0123), Some(2)).unwrap(), "+0.01");
        assert_eq!(signed(Value::from(-0.0001), Some(3)).unwrap(), "-0.000");
    }

    #[test]
    fn a_misspelt_field_is_an_error_with_the_line() {
        let err = render("w1/report.md", "ok\n{{ reprot.x }}", &serde_json::json!({}))
            .unwrap_err()
            .to_string();
        assert!(err.contains("w1/report.md, line 2"), "{err}");
    }
}
