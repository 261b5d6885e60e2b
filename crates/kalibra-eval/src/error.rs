use kalibra_metrics::MetricsError;

/// Why a filter log could not be built or evaluated.
///
/// Bad shapes and bad options are errors; a covariance that is NaN, asymmetric or not positive
/// definite at some step is not (it is a finding about the filter under test, counted in the
/// report: see [`crate::Findings`]). Messages are lowercase fragments that read after "failed
/// to ...: ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// An array holds the wrong number of values or cells for its declared shape.
    #[error("array {array} holds {found} {unit}, expected {expected}")]
    Shape {
        /// The array's name (`"truth"`, `"covariance"`, ...).
        array: &'static str,
        /// What was counted (`"values"` or `"cells"`).
        unit: &'static str,
        /// The count its shape requires.
        expected: usize,
        /// The count given.
        found: usize,
    },
    /// One cell of an array has the wrong length.
    #[error("array {array} at run {run}, step {step} holds {found} values, expected {expected}")]
    CellLength {
        /// The array's name.
        array: &'static str,
        /// Run index.
        run: usize,
        /// Step index.
        step: usize,
        /// The length required.
        expected: usize,
        /// The length given.
        found: usize,
    },
    /// An array's dimension disagrees with the log (runs, steps, state or measurement size).
    #[error("array {array} has {what} {found}, but the log has {expected}")]
    Mismatch {
        /// The array's name.
        array: &'static str,
        /// Which dimension (`"runs"`, `"steps"`, `"state dimension"`, ...).
        what: &'static str,
        /// The log's value.
        expected: usize,
        /// The array's value.
        found: usize,
    },
    /// A value that must be finite is not (the truth, the times, a model matrix). Non-finite
    /// estimates, covariances and innovations are findings, not errors.
    #[error("array {array} holds a non-finite value at run {run}, step {step}")]
    NonFinite {
        /// The array's name.
        array: &'static str,
        /// Run index (0 for arrays shared by all runs).
        run: usize,
        /// Step index (0 for arrays shared by all steps).
        step: usize,
    },
    /// A value computed from finite data lies beyond f64's range: the estimation error
    /// `estimate - truth` of an estimate and a truth of opposite signs near `±f64::MAX`.
    #[error("{what} at run {run}, step {step} lies beyond f64's range")]
    OutOfRange {
        /// What was computed.
        what: &'static str,
        /// Run index.
        run: usize,
        /// Step index.
        step: usize,
    },
    /// Times that do not increase strictly.
    #[error("times do not increase strictly at step {step}")]
    TimesNotIncreasing {
        /// The first step whose time is not above the previous one.
        step: usize,
    },
    /// A log or an array with zero runs, steps or components.
    #[error("{what} is zero")]
    Empty {
        /// What is zero.
        what: &'static str,
    },
    /// An option outside its valid range.
    #[error("invalid option {name} = {value}")]
    InvalidOption {
        /// The option's name.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A component group names a component the state does not have, or is empty.
    #[error("group {group} names component {index}, but the state has {dim}")]
    GroupIndex {
        /// The group's name.
        group: String,
        /// The offending index.
        index: usize,
        /// The state dimension.
        dim: usize,
    },
    /// A cell fed to an [`crate::Evaluator`] a second time.
    #[error("run {run}, step {step} is given twice")]
    DuplicateCell {
        /// Run index.
        run: usize,
        /// Step index.
        step: usize,
    },
    /// A run or step index beyond what an [`crate::Evaluator`] takes
    /// ([`crate::MAX_RUNS`], [`crate::MAX_STEPS`]): its state grows with the largest index
    /// fed, so one absurd index would otherwise allocate gigabytes before anything failed.
    #[error("{what} {index} is beyond the largest an evaluation takes ({limit} - 1)")]
    IndexLimit {
        /// `"run"` or `"step"`.
        what: &'static str,
        /// The index given.
        index: usize,
        /// The limit ([`crate::MAX_RUNS`] or [`crate::MAX_STEPS`]).
        limit: usize,
    },
    /// Two evaluators of different options or contents cannot be merged.
    #[error("the evaluators to merge were made with different options or contents")]
    MergeMismatch,
    /// An [`crate::EvaluatorState`] that does not fit the evaluation and contents it is
    /// resumed with, or contradicts itself (a corrupt or foreign partial result).
    #[error("an evaluator's state does not fit: {0}")]
    State(String),
    /// A cell of the runs-by-steps rectangle that was never fed to an [`crate::Evaluator`]
    /// (every run needs every step, logged or not).
    #[error("run {run}, step {step} is missing (every run needs every step 0..{steps})")]
    MissingCell {
        /// Run index.
        run: usize,
        /// Step index (the first missing in the run).
        step: usize,
        /// Number of steps of the log.
        steps: usize,
    },
    /// The log holds nothing to evaluate: neither truth, estimate and covariance, nor
    /// innovation and innovation covariance.
    #[error("log holds neither truth, estimate and covariance nor innovation and its covariance")]
    NothingToEvaluate,
    /// A metric failed on valid data (a bug or an edge case worth reporting).
    #[error(transparent)]
    Metrics(#[from] MetricsError),
}
