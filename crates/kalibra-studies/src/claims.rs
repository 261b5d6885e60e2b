//! Published claims beside what kalibra computes, with a verdict: the rows of the reproduction
//! summary.

use serde::Serialize;

/// Whether a published claim holds in our computation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Ours is within the stated tolerance of the published value, or the claimed property
    /// holds.
    Reproduced,
    /// Ours is outside the tolerance, or the claimed property fails.
    NotReproduced,
    /// The paper gives too little to test the claim (no number, no criterion).
    NotTestable,
}

impl Verdict {
    /// `Reproduced` if `holds`, otherwise `NotReproduced`.
    pub fn from_bool(holds: bool) -> Self {
        if holds {
            Verdict::Reproduced
        } else {
            Verdict::NotReproduced
        }
    }

    /// The verdict as the report prints it.
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Reproduced => "reproduced",
            Verdict::NotReproduced => "not reproduced",
            Verdict::NotTestable => "not testable",
        }
    }
}

/// One published claim and our finding.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Claim {
    /// Short stable identifier within the paper (for tests and links).
    pub id: &'static str,
    /// What the paper claims, in a few words.
    pub claim: String,
    /// The published value or property, as printed.
    pub published: String,
    /// Ours.
    pub ours: String,
    /// The tolerance or criterion the verdict applies.
    pub tolerance: String,
    /// The verdict.
    pub verdict: Verdict,
    /// Anchor of the report section that explains the claim (and any gap).
    pub section: &'static str,
}

/// The header of the claims table.
pub(crate) const CLAIMS_HEADER: &str =
    "| claim | published | ours | tolerance | verdict |\n|---|---|---|---|---|\n";

/// One row of the claims table, linking the verdict to the section that explains it.
pub(crate) fn claims_row(
    claim: &str,
    published: &str,
    ours: &str,
    tolerance: &str,
    verdict: Verdict,
    section: &str,
) -> String {
    format!(
        "| {claim} | {published} | {ours} | {tolerance} | {} ([why](#{section})) |\n",
        verdict.label()
    )
}

/// Renders claims as a Markdown table (claim, published, ours, tolerance, verdict).
pub fn claims_table(claims: &[Claim]) -> String {
    let mut out = String::from(CLAIMS_HEADER);
    for c in claims {
        out.push_str(&claims_row(
            &c.claim,
            &c.published,
            &c.ours,
            &c.tolerance,
            c.verdict,
            c.section,
        ));
    }
    out
}
