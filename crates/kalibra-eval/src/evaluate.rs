//! The evaluation: options, and the computation of a [`Report`] from a [`FilterLog`].

use std::collections::{BTreeMap, BTreeSet};

use kalibra_linalg::{Covariance, DMatrix, DVector, LinalgError};
use kalibra_metrics::{
    ChiSquareBand, Credibility, JHorizon, MetricsError, SquaredErrors, StepMean, j_step, nees, nis,
    normalized_innovation, paired_t_test, sliding_window, whiteness,
};

use crate::log::Array;
use crate::report::{
    Band, ComponentWindow, ConsistencyTest, Finding, FindingCount, Findings, JReport, LagReport,
    Reason, Report, RmseSeries, SCHEMA_VERSION, Summary, TestMethod, Verdict, VerdictKind,
    WhitenessReport, WindowReport,
};
use crate::{EvalError, FilterLog};

/// A named group of state components (position = `[0, 1]`), whose RMSE is reported beside the
/// components'.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Group {
    /// The group's name.
    pub name: String,
    /// Its components.
    pub components: Vec<usize>,
}

/// The options of an evaluation, and the evaluation itself ([`Evaluation::evaluate`]).
///
/// Defaults: confidence 0.95, window `max(2, K / 10)` samples, no groups, 10 whiteness lags
/// (fewer if the log is short), diagnostics (window, whiteness) on run 0.
///
/// ```
/// use kalibra_eval::{Evaluation, FilterLog, Matrices, Vectors, VerdictKind};
/// let log = FilterLog::new(1, 4)?
///     .with_innovation(Vectors::dense(1, vec![0.5, -1.0, 1.5, -0.2]))?
///     .with_innovation_cov(Matrices::constant(1, 1, vec![1.0]))?;
/// let report = Evaluation::new().lags(1)?.evaluate(&log)?;
/// assert_eq!(report.anis_per_step[1], Some(1.0));
/// assert_eq!(report.summary.verdict.kind, VerdictKind::Consistent);
/// # Ok::<(), kalibra_eval::EvalError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation {
    confidence: f64,
    window: Option<usize>,
    groups: Vec<Group>,
    lags: usize,
    run: usize,
}

impl Default for Evaluation {
    fn default() -> Self {
        Self::new()
    }
}

impl Evaluation {
    /// The default options.
    pub fn new() -> Self {
        Self {
            confidence: 0.95,
            window: None,
            groups: Vec::new(),
            lags: 10,
            run: 0,
        }
    }

    /// The confidence of every band and test.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] outside (0, 1).
    pub fn confidence(mut self, confidence: f64) -> Result<Self, EvalError> {
        if !(confidence > 0.0 && confidence < 1.0) {
            return Err(EvalError::InvalidOption {
                name: "confidence",
                value: confidence,
            });
        }
        self.confidence = confidence;
        Ok(self)
    }

    /// The sliding window `W` in samples.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] below 2 (the window's std divides by `W - 1`).
    pub fn window(mut self, window: usize) -> Result<Self, EvalError> {
        if window < 2 {
            return Err(EvalError::InvalidOption {
                name: "window",
                value: window as f64,
            });
        }
        self.window = Some(window);
        Ok(self)
    }

    /// Adds a group of components whose joint RMSE is reported.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] for an empty group (indices are checked against the log
    /// by [`Evaluation::evaluate`]).
    pub fn group(
        mut self,
        name: impl Into<String>,
        components: Vec<usize>,
    ) -> Result<Self, EvalError> {
        if components.is_empty() {
            return Err(EvalError::InvalidOption {
                name: "group size",
                value: 0.0,
            });
        }
        self.groups.push(Group {
            name: name.into(),
            components,
        });
        Ok(self)
    }

    /// The largest whiteness lag `L`.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] for 0.
    pub fn lags(mut self, lags: usize) -> Result<Self, EvalError> {
        if lags == 0 {
            return Err(EvalError::InvalidOption {
                name: "lags",
                value: 0.0,
            });
        }
        self.lags = lags;
        Ok(self)
    }

    /// The run whose sliding windows and whiteness are reported (default 0; checked by
    /// [`Evaluation::evaluate`]).
    pub fn diagnostic_run(mut self, run: usize) -> Self {
        self.run = run;
        self
    }

    /// Evaluates `log` (definitions in the crate documentation).
    ///
    /// # Errors
    /// [`EvalError::NothingToEvaluate`] if the log holds neither truth, estimate and
    /// covariance nor innovation and its covariance; [`EvalError::GroupIndex`] for a group
    /// naming a component the state does not have; [`EvalError::InvalidOption`] for a
    /// diagnostic run beyond the log; [`EvalError::Metrics`] if a metric fails on data that
    /// passed the checks (not expected).
    pub fn evaluate(&self, log: &FilterLog) -> Result<Report, EvalError> {
        let state = match (&log.truth, &log.estimate, &log.covariance) {
            (Some(t), Some(e), Some(p)) => Some((t, e, p)),
            _ => None,
        };
        let innov = match (&log.innovation, &log.innovation_cov) {
            (Some(v), Some(s)) => Some((v, s)),
            _ => None,
        };
        if state.is_none() && innov.is_none() {
            return Err(EvalError::NothingToEvaluate);
        }
        if self.run >= log.runs() {
            return Err(EvalError::InvalidOption {
                name: "diagnostic run",
                value: self.run as f64,
            });
        }
        let steps = log.steps();
        let mut report = Report {
            schema_version: SCHEMA_VERSION,
            runs: log.runs(),
            steps: (0..steps).collect(),
            times: log.times.clone(),
            state_dim: log.state_dim(),
            measurement_dim: log.measurement_dim(),
            confidence: self.confidence,
            anees_per_step: Vec::new(),
            anees_band: Vec::new(),
            nees_runs_per_step: Vec::new(),
            anis_per_step: Vec::new(),
            anis_band: Vec::new(),
            nis_runs_per_step: Vec::new(),
            nci_per_step: Vec::new(),
            rmse_per_step: Vec::new(),
            window: None,
            whiteness: None,
            j: None,
            findings: Findings::default(),
            summary: Summary {
                anees: None,
                anis: None,
                nci: None,
                anees_fraction_inside: None,
                anis_fraction_inside: None,
                whiteness_fraction_inside: None,
                anees_test: None,
                anis_test: None,
                verdict: Verdict {
                    kind: VerdictKind::Undetermined,
                    statistic: None,
                    evidence: String::new(),
                    test: String::new(),
                },
            },
        };
        let mut bands = BandCache::new(self.confidence);
        let mut state_valid = None;
        if let Some((t, e, p)) = state {
            state_valid = Some(self.state(log, t, e, p, &mut bands, &mut report)?);
        }
        if let Some((v, s)) = innov {
            self.innovation(log, v, s, &mut bands, &mut report)?;
        }
        if let (Some(model), Some(p), Some(valid)) = (&log.model, &log.covariance, &state_valid) {
            report.j = self.j(log, model, p, valid)?;
        }
        report.summary.verdict = verdict(&report.summary, self.confidence, &report);
        Ok(report)
    }

    /// NEES, NCI, RMSE and windows; returns which cells had a valid covariance.
    fn state(
        &self,
        log: &FilterLog,
        truth: &Array,
        estimate: &Array,
        cov: &Array,
        bands: &mut BandCache,
        report: &mut Report,
    ) -> Result<Vec<bool>, EvalError> {
        let (runs, steps, n) = (log.runs(), log.steps(), truth.rows);
        for g in &self.groups {
            if let Some(&index) = g.components.iter().find(|&&i| i >= n) {
                return Err(EvalError::GroupIndex {
                    group: g.name.clone(),
                    index,
                    dim: n,
                });
            }
        }
        let mut means = StepMean::new(steps);
        let mut cred = Credibility::new(steps, n);
        let mut squared = SquaredErrors::new(steps, n);
        let mut per_run = vec![(0.0, 0usize); runs];
        let mut valid = vec![false; runs * steps];
        let mut findings = FindingTally::default();
        let mut window_series: Vec<(usize, DVector<f64>)> = Vec::new();
        for run in 0..runs {
            for step in 0..steps {
                let (Some(x), Some(xhat)) = (truth.vector(run, step), estimate.vector(run, step))
                else {
                    continue;
                };
                if !xhat.iter().all(|v| v.is_finite()) {
                    findings.add("estimate", run, step, Reason::NonFiniteVector);
                    continue;
                }
                // RMSE and windows need no covariance: estimate minus truth (paper 002's sign).
                let error = &xhat - &x;
                squared.push_slice(step, error.as_slice())?;
                if run == self.run {
                    window_series.push((step, error.clone()));
                }
                let Some(p) = cov.matrix(run, step) else {
                    continue;
                };
                match nees(&error, &p) {
                    Ok(value) => {
                        means.push(step, value / n as f64)?;
                        cred.push_nees(step, error.as_slice(), value)?;
                        per_run[run].0 += value / n as f64;
                        per_run[run].1 += 1;
                        valid[run * steps + step] = true;
                    }
                    Err(err) => findings.add("covariance", run, step, reason(err)?),
                }
            }
        }
        report.findings.state = findings.finish();
        let (per_step, band, counts) = per_step_stats(&means, n, bands)?;
        report.summary.anees_fraction_inside = fraction_inside(&per_step, &band);
        report.anees_per_step = per_step;
        report.anees_band = band;
        report.nees_runs_per_step = counts;
        report.summary.anees_test = consistency_test("anees", n, &per_run, self.confidence)?;
        report.summary.anees = report.summary.anees_test.as_ref().map(|t| t.value);
        if runs >= 2 {
            report.nci_per_step = (0..steps)
                .map(|k| {
                    if cred.runs(k) < 2 {
                        return Ok(None);
                    }
                    let s = cred.step_summary(k)?;
                    Ok(s.nci.is_finite().then_some(s.nci))
                })
                .collect::<Result<_, MetricsError>>()?;
            let nci: Vec<f64> = report.nci_per_step.iter().flatten().copied().collect();
            report.summary.nci =
                (!nci.is_empty()).then(|| nci.iter().sum::<f64>() / nci.len() as f64);
        }
        let mut series: Vec<(String, Vec<usize>)> =
            (0..n).map(|i| (format!("x{i}"), vec![i])).collect();
        series.extend(
            self.groups
                .iter()
                .map(|g| (g.name.clone(), g.components.clone())),
        );
        report.rmse_per_step = series
            .into_iter()
            .map(|(name, components)| {
                let values: Vec<Option<f64>> = (0..steps)
                    .map(|k| {
                        let r = squared.rmse_group(k, &components)?;
                        Ok(r.is_finite().then_some(r))
                    })
                    .collect::<Result<_, MetricsError>>()?;
                let present: Vec<usize> = (0..steps).filter(|&k| values[k].is_some()).collect();
                let over_time = match present.as_slice() {
                    [] => None,
                    _ => {
                        let ms: f64 = present
                            .iter()
                            .map(|&k| values[k].unwrap_or(0.0).powi(2))
                            .sum();
                        Some((ms / present.len() as f64).sqrt())
                    }
                };
                Ok(RmseSeries {
                    name,
                    components,
                    values,
                    over_time,
                })
            })
            .collect::<Result<_, EvalError>>()?;
        let window = self.window.unwrap_or((steps / 10).max(2));
        if window_series.len() >= window {
            let components = (0..n)
                .map(|i| {
                    let e: Vec<f64> = window_series.iter().map(|(_, v)| v[i]).collect();
                    let w = sliding_window(&e, window)?;
                    Ok(ComponentWindow {
                        component: i,
                        rmse: w.rmse,
                        bias: w.bias,
                        std: w.std,
                    })
                })
                .collect::<Result<_, MetricsError>>()?;
            report.window = Some(WindowReport {
                run: self.run,
                window,
                start_steps: window_series[..=window_series.len() - window]
                    .iter()
                    .map(|(k, _)| *k)
                    .collect(),
                components,
            });
        }
        Ok(valid)
    }

    /// NIS and whiteness.
    fn innovation(
        &self,
        log: &FilterLog,
        innovation: &Array,
        s_array: &Array,
        bands: &mut BandCache,
        report: &mut Report,
    ) -> Result<(), EvalError> {
        let (steps, m) = (log.steps(), innovation.rows);
        let runs = log.runs();
        let mut means = StepMean::new(steps);
        let mut per_run = vec![(0.0, 0usize); runs];
        let mut findings = FindingTally::default();
        let mut normalized: Vec<Option<DVector<f64>>> = vec![None; steps];
        let mut diagnostic = Vec::new();
        for (run, totals) in per_run.iter_mut().enumerate() {
            for step in 0..steps {
                let (Some(nu), Some(s)) = (innovation.vector(run, step), s_array.matrix(run, step))
                else {
                    continue;
                };
                if !nu.iter().all(|v| v.is_finite()) {
                    findings.add("innovation", run, step, Reason::NonFiniteVector);
                    continue;
                }
                let s = match Covariance::named(s, "innovation covariance S") {
                    Ok(s) => s,
                    Err(err) => {
                        findings.add("innovation_cov", run, step, reason(err.into())?);
                        continue;
                    }
                };
                let value = nis(&nu, &s)?;
                means.push(step, value / m as f64)?;
                totals.0 += value / m as f64;
                totals.1 += 1;
                if run == self.run {
                    diagnostic.push((step, normalized_innovation(&nu, &s)?));
                }
            }
        }
        for (step, w) in diagnostic {
            normalized[step] = Some(w);
        }
        report.findings.innovation = findings.finish();
        let (per_step, band, counts) = per_step_stats(&means, m, bands)?;
        report.summary.anis_fraction_inside = fraction_inside(&per_step, &band);
        report.anis_per_step = per_step;
        report.anis_band = band;
        report.nis_runs_per_step = counts;
        report.summary.anis_test = consistency_test("anis", m, &per_run, self.confidence)?;
        report.summary.anis = report.summary.anis_test.as_ref().map(|t| t.value);
        let present = normalized.iter().flatten().count();
        let lags = self.lags.min(present.saturating_sub(2));
        if lags > 0 {
            match whiteness(&normalized, lags, self.confidence) {
                Ok(w) => {
                    report.summary.whiteness_fraction_inside = Some(w.fraction_inside());
                    report.whiteness = Some(WhitenessReport {
                        run: self.run,
                        lags: w
                            .lags
                            .iter()
                            .map(|l| LagReport {
                                lag: l.lag,
                                autocorrelation: l.autocorrelation,
                                bound: l.bound,
                                pairs: l.pairs,
                                inside: l.inside(),
                            })
                            .collect(),
                        fraction_inside: w.fraction_inside(),
                        box_pierce: w.box_pierce,
                        p_value: w.p_value,
                        white: w.white(),
                    });
                }
                // Gaps can leave a lag with fewer than two pairs, and an all-zero innovation
                // sequence has no correlation: no whiteness section, not an error.
                Err(MetricsError::TooFewSamples { .. } | MetricsError::Degenerate { .. }) => {}
                Err(e) => return Err(e.into()),
            }
        }
        Ok(())
    }

    /// `J1`/`J2` over every update whose two posterior covariances are valid.
    fn j(
        &self,
        log: &FilterLog,
        model: &crate::log::Model,
        cov: &Array,
        valid: &[bool],
    ) -> Result<Option<JReport>, EvalError> {
        let (runs, steps) = (log.runs(), log.steps());
        let mut horizon = JHorizon::new();
        let (mut j1, mut j2) = (StepMean::new(steps), StepMean::new(steps));
        let mut failed = 0;
        for run in 0..runs {
            for step in 1..steps {
                if !(valid[run * steps + step - 1] && valid[run * steps + step]) {
                    continue;
                }
                let cells = (
                    cov.matrix(run, step - 1),
                    cov.matrix(run, step),
                    model.f.matrix(run, step),
                    model.h.matrix(run, step),
                    model.q.matrix(run, step),
                    model.r.matrix(run, step),
                );
                let (Some(p0), Some(p1), Some(f), Some(h), Some(q), Some(r)) = cells else {
                    continue;
                };
                let ht = h.transpose();
                let hf = &h * &f;
                let a: DMatrix<f64> = &hf * &p0 * hf.transpose();
                let b: DMatrix<f64> = &h * &q * &ht;
                let c: DMatrix<f64> = &h * &p1 * &ht;
                match j_step(&a, &b, &r, &c) {
                    Ok(js) => {
                        horizon.push(&js);
                        j1.push(step, js.j1)?;
                        j2.push(step, js.j2)?;
                    }
                    Err(_) => failed += 1,
                }
            }
        }
        if horizon.updates() == 0 {
            return Ok(None);
        }
        let summary = horizon.summary(horizon.updates())?;
        let series = |s: &StepMean| -> Vec<Option<f64>> {
            (0..steps)
                .map(|k| (s.count(k) > 0).then(|| s.mean(k)))
                .collect()
        };
        Ok(Some(JReport {
            j1_per_step: series(&j1),
            j2_per_step: series(&j2),
            j1: summary.j1,
            j2: summary.j2,
            nq_mean_log10: summary.nq_mean_log10,
            nq_log10_mean: summary.nq_log10_mean,
            updates: summary.updates,
            indefinite_updates: summary.indefinite_updates,
            failed_updates: failed,
        }))
    }
}

/// Chi-square bands for the mean of `samples` normalised values, computed once per count.
struct BandCache {
    confidence: f64,
    cache: BTreeMap<(usize, usize), Band>,
}

impl BandCache {
    fn new(confidence: f64) -> Self {
        Self {
            confidence,
            cache: BTreeMap::new(),
        }
    }

    fn get(&mut self, dof: usize, samples: usize) -> Result<Band, MetricsError> {
        if let Some(b) = self.cache.get(&(dof, samples)) {
            return Ok(*b);
        }
        let b = ChiSquareBand::for_normalized_mean(dof as f64, samples, self.confidence)?;
        let b = Band {
            lower: b.lower,
            upper: b.upper,
        };
        self.cache.insert((dof, samples), b);
        Ok(b)
    }
}

type PerStep = (Vec<Option<f64>>, Vec<Option<Band>>, Vec<usize>);

fn per_step_stats(
    means: &StepMean,
    dof: usize,
    bands: &mut BandCache,
) -> Result<PerStep, MetricsError> {
    let mut values = Vec::with_capacity(means.steps());
    let mut band = Vec::with_capacity(means.steps());
    let mut counts = Vec::with_capacity(means.steps());
    for k in 0..means.steps() {
        let c = means.count(k) as usize;
        counts.push(c);
        if c == 0 {
            values.push(None);
            band.push(None);
        } else {
            values.push(Some(means.mean(k)));
            band.push(Some(bands.get(dof, c)?));
        }
    }
    Ok((values, band, counts))
}

fn fraction_inside(values: &[Option<f64>], bands: &[Option<Band>]) -> Option<f64> {
    let pairs: Vec<(f64, Band)> = values
        .iter()
        .zip(bands)
        .filter_map(|(v, b)| Some(((*v)?, (*b)?)))
        .collect();
    (!pairs.is_empty())
        .then(|| pairs.iter().filter(|(v, b)| b.contains(*v)).count() as f64 / pairs.len() as f64)
}

/// The test of the mean normalised statistic: a t-test over the runs' time averages for
/// several runs, the chi-square band of the time average for one.
fn consistency_test(
    statistic: &str,
    dof: usize,
    per_run: &[(f64, usize)],
    confidence: f64,
) -> Result<Option<ConsistencyTest>, EvalError> {
    let samples: usize = per_run.iter().map(|r| r.1).sum();
    if samples == 0 {
        return Ok(None);
    }
    let value = per_run.iter().map(|r| r.0).sum::<f64>() / samples as f64;
    let averages: Vec<f64> = per_run
        .iter()
        .filter(|r| r.1 > 0)
        .map(|r| r.0 / r.1 as f64)
        .collect();
    let direction = |high: bool| {
        if high {
            VerdictKind::Optimistic
        } else {
            VerdictKind::Pessimistic
        }
    };
    if averages.len() >= 2 {
        let ones = vec![1.0; averages.len()];
        match paired_t_test(&averages, &ones) {
            Ok(t) => {
                let outcome = if t.p_value >= 1.0 - confidence {
                    VerdictKind::Consistent
                } else {
                    direction(t.statistic > 0.0)
                };
                return Ok(Some(ConsistencyTest {
                    statistic: statistic.into(),
                    value,
                    samples,
                    method: TestMethod::RunAverageT,
                    band: None,
                    t: Some(t.statistic),
                    p_value: Some(t.p_value),
                    outcome,
                }));
            }
            // Every run with the same average (a log copied across runs): fall back to the
            // chi-square band below.
            Err(MetricsError::Degenerate { .. }) => {}
            Err(e) => return Err(e.into()),
        }
    }
    let b = ChiSquareBand::for_normalized_mean(dof as f64, samples, confidence)?;
    let band = Band {
        lower: b.lower,
        upper: b.upper,
    };
    let outcome = if band.contains(value) {
        VerdictKind::Consistent
    } else {
        direction(value > band.upper)
    };
    Ok(Some(ConsistencyTest {
        statistic: statistic.into(),
        value,
        samples,
        method: TestMethod::TimeAverageChiSquare,
        band: Some(band),
        t: None,
        p_value: None,
        outcome,
    }))
}

fn verdict(summary: &Summary, confidence: f64, report: &Report) -> Verdict {
    let Some(test) = summary.anees_test.as_ref().or(summary.anis_test.as_ref()) else {
        return Verdict {
            kind: VerdictKind::Undetermined,
            statistic: None,
            evidence: "no valid NEES or NIS in the log".into(),
            test: String::new(),
        };
    };
    let name = test.statistic.to_uppercase();
    let fraction = if test.statistic == "anees" {
        summary.anees_fraction_inside
    } else {
        summary.anis_fraction_inside
    };
    let pct = 100.0 * confidence;
    let mut evidence = format!(
        "{name} = {:.4} over {} samples ({} runs x {} steps); {:.1}% of steps inside their {pct}% band",
        test.value,
        test.samples,
        report.runs,
        report.steps.len(),
        100.0 * fraction.unwrap_or(f64::NAN),
    );
    let test_words = match test.method {
        TestMethod::RunAverageT => {
            evidence += &format!(
                "; t = {:.3}, p = {:.3e}",
                test.t.unwrap_or(f64::NAN),
                test.p_value.unwrap_or(f64::NAN)
            );
            format!(
                "two-sided one-sample t-test at {pct}% of the runs' time-averaged {name} against 1 (runs independent)"
            )
        }
        TestMethod::TimeAverageChiSquare => {
            if let Some(b) = test.band {
                evidence += &format!("; band [{:.4}, {:.4}]", b.lower, b.upper);
            }
            format!(
                "time-averaged {name} against its two-sided {pct}% chi-square band (Bar-Shalom, Li and Kirubarajan 2001, sec. 5.4.2)"
            )
        }
    };
    if let Some(w) = &report.whiteness {
        evidence += &format!(
            "; innovations of run {} {} (Box-Pierce p = {:.3e})",
            w.run,
            if w.white { "white" } else { "not white" },
            w.p_value
        );
    }
    let f = &report.findings;
    if f.state.cells + f.innovation.cells > 0 {
        evidence += &format!(
            "; {} cells left out as findings",
            f.state.cells + f.innovation.cells
        );
    }
    Verdict {
        kind: test.outcome,
        statistic: Some(test.statistic.clone()),
        evidence,
        test: test_words,
    }
}

fn reason(err: MetricsError) -> Result<Reason, EvalError> {
    match err {
        MetricsError::Linalg(LinalgError::NonFinite { .. }) => Ok(Reason::NonFinite),
        MetricsError::Linalg(LinalgError::NotSymmetric { .. }) => Ok(Reason::NotSymmetric),
        MetricsError::Linalg(LinalgError::NotPositiveDefinite { .. }) => {
            Ok(Reason::NotPositiveDefinite)
        }
        other => Err(other.into()),
    }
}

#[derive(Default)]
struct FindingTally {
    count: FindingCount,
    steps: BTreeSet<usize>,
}

impl FindingTally {
    fn add(&mut self, array: &str, run: usize, step: usize, reason: Reason) {
        let c = &mut self.count;
        c.cells += 1;
        match reason {
            Reason::NonFinite => c.non_finite += 1,
            Reason::NotSymmetric => c.not_symmetric += 1,
            Reason::NotPositiveDefinite => c.not_positive_definite += 1,
            Reason::NonFiniteVector => c.non_finite_vector += 1,
        }
        self.steps.insert(step);
        // Cells arrive in run-major order, so the first recorded is the first.
        c.first.get_or_insert(Finding {
            array: array.into(),
            run,
            step,
            reason,
        });
    }

    fn finish(mut self) -> FindingCount {
        self.count.steps = self.steps.len();
        self.count
    }
}
