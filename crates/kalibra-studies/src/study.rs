//! The [`Study`] trait every reproduced study implements, and [`Reproduce`], its type-erased
//! form that the [registry](crate::REGISTRY) lists.
//!
//! A study is a configuration (published size or a quick size for tests), a run that turns the
//! configuration into a serialisable report, the published claims judged on that report, a
//! one-line highlight, a Markdown report rendered from a template over the structured report,
//! and figures as data. Tests assert on the structured report and the claims; the Markdown is
//! only a view of them.

use kalibra_filters::batch::Isa;
use serde::Serialize;

use crate::StudyError;
use crate::claims::Claim;
use crate::figure::Figure;

/// Which configuration a study runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Size {
    /// The size the paper reports (or the full benchmark size).
    Paper,
    /// A reduced size that keeps every stage, for tests and a quick look.
    Quick,
}

impl Size {
    /// `"full"` or `"quick"`, as the reports print it.
    pub fn label(self) -> &'static str {
        match self {
            Size::Paper => "full",
            Size::Quick => "quick",
        }
    }
}

/// What a caller may set on any study: its size, a seed overriding the study's own, and the
/// thread count (which never changes the results).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Options {
    /// Published or quick size.
    pub size: Size,
    /// Replaces the study's default seed (studies without randomness ignore it).
    pub seed: Option<u64>,
    /// Worker threads; 0 uses every core.
    pub threads: usize,
    /// The instruction set of the batched Monte Carlo paths (`None`: detected at run time).
    /// Like the thread count, it changes the results only by rounding.
    pub simd: Option<Isa>,
}

impl Options {
    /// The published size with the study's own seed, on every core.
    pub fn paper() -> Self {
        Self {
            size: Size::Paper,
            seed: None,
            threads: 0,
            simd: None,
        }
    }

    /// The quick size with the study's own seed, on every core.
    pub fn quick() -> Self {
        Self {
            size: Size::Quick,
            ..Self::paper()
        }
    }
}

/// A figure with the file name its report links to.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NamedFigure {
    /// File name (for instance `anees.svg`), unique within the study.
    pub file: String,
    /// What to draw.
    pub figure: Figure,
}

impl NamedFigure {
    /// Names each figure of `(file, figure)` pairs.
    pub fn from_pairs(pairs: Vec<(String, Figure)>) -> Vec<Self> {
        pairs
            .into_iter()
            .map(|(file, figure)| Self { file, figure })
            .collect()
    }

    /// Names `figure` as `file`.
    pub fn new(file: impl Into<String>, figure: Figure) -> Self {
        Self {
            file: file.into(),
            figure,
        }
    }
}

/// A study's configuration: the sizes it comes in and what every run may override (the seed,
/// the thread count). Implement it with [`study_config!`](crate::study_config).
pub trait StudyConfig: Serialize + Sized {
    /// The configuration of `size`.
    fn for_size(size: Size) -> Self;
    /// The seed the configuration runs with, `None` when the study draws nothing at random.
    fn seed(&self) -> Option<u64>;
    /// Replaces the seed (ignored by a study without randomness).
    fn set_seed(&mut self, seed: u64);
    /// Sets the thread count (0: every core).
    fn set_threads(&mut self, threads: usize);
    /// Sets the instruction set of a study's batched path (ignored by a study without one).
    fn set_simd(&mut self, _isa: Isa) {}

    /// The configuration `options` select: its size, with the seed and thread count applied.
    fn from_options(options: &Options) -> Self {
        let mut config = Self::for_size(options.size);
        if let Some(seed) = options.seed {
            config.set_seed(seed);
        }
        config.set_threads(options.threads);
        if let Some(isa) = options.simd {
            config.set_simd(isa);
        }
        config
    }
}

/// Implements [`StudyConfig`] for a configuration type with `paper()` and `quick()`
/// constructors and a `threads` field: `study_config!(Config, seed)` when it has a `seed: u64`
/// field, `study_config!(Config, seed, simd)` when it also has a `simd: Option<Isa>` field
/// for a batched path, `study_config!(Config)` when the study draws nothing at random.
#[macro_export]
macro_rules! study_config {
    ($config:ty, seed) => {
        $crate::study_config!(@impl $config, |c: &$config| Some(c.seed), |c: &mut $config, s| c.seed = s);
    };
    ($config:ty, seed, simd) => {
        $crate::study_config!(@impl $config, |c: &$config| Some(c.seed), |c: &mut $config, s| c.seed = s,
            fn set_simd(&mut self, isa: kalibra_filters::batch::Isa) {
                self.simd = Some(isa);
            }
        );
    };
    ($config:ty) => {
        $crate::study_config!(@impl $config, |_: &$config| None, |_: &mut $config, _| ());
    };
    (@impl $config:ty, $get:expr, $set:expr $(, $extra:item)*) => {
        impl $crate::study::StudyConfig for $config {
            fn for_size(size: $crate::study::Size) -> Self {
                match size {
                    $crate::study::Size::Paper => Self::paper(),
                    $crate::study::Size::Quick => Self::quick(),
                }
            }
            fn seed(&self) -> Option<u64> {
                ($get)(self)
            }
            fn set_seed(&mut self, seed: u64) {
                ($set)(self, seed)
            }
            fn set_threads(&mut self, threads: usize) {
                self.threads = threads;
            }
            $($extra)*
        }
    };
}

/// One reproduced study, with its own configuration and report types.
///
/// Implement this for a study and add one line to [`crate::REGISTRY`]; `cargo xtask reproduce`
/// and the tests find it there.
pub trait Study: Sync {
    /// Size, seed and parameters of a run.
    type Config: StudyConfig;
    /// Everything the run computed, serialised to `results.json`.
    type Report: Serialize;

    /// Stable identifier: the paper number (`"000"` ... `"004"`) or the workload name
    /// (`"w1"`). It names the output directory and the report's links.
    fn id(&self) -> &'static str;

    /// A one-line title for the summary.
    fn title(&self) -> &'static str;

    /// The paper's citation, `None` for a study that reproduces no paper.
    fn paper(&self) -> Option<&'static str>;

    /// The configuration for `options` (the published or quick size, with the seed and thread
    /// count applied).
    fn config(&self, options: &Options) -> Self::Config {
        Self::Config::from_options(options)
    }

    /// The seed `config` runs with, `None` when the study draws nothing at random.
    fn seed(&self, config: &Self::Config) -> Option<u64> {
        config.seed()
    }

    /// What a run of `config` is about to do, in one line (printed before a long run).
    fn describe(&self, config: &Self::Config) -> String;

    /// Runs the study.
    ///
    /// # Errors
    /// [`StudyError`] when a model, filter, metric or bound fails.
    fn run(&self, config: &Self::Config) -> Result<Self::Report, StudyError>;

    /// The published claims, each with ours and a verdict (empty for a study without a paper).
    fn claims(&self, report: &Self::Report) -> Vec<Claim>;

    /// The one-line summary of what the run shows, for the reproduction index.
    ///
    /// # Errors
    /// [`StudyError::Report`] when the report lacks a part the summary needs.
    fn highlight(&self, config: &Self::Config, report: &Self::Report)
    -> Result<String, StudyError>;

    /// The report as Markdown, rendered from the study's template.
    ///
    /// # Errors
    /// [`StudyError::Template`] when the template does not render.
    fn markdown(&self, config: &Self::Config, report: &Self::Report) -> Result<String, StudyError>;

    /// The figures the report links to, as data.
    fn figures(&self, report: &Self::Report) -> Vec<NamedFigure>;

    /// Whether the study runs as shards ([`Study::run_shard`], [`Study::merge_shards`]).
    fn sharded(&self) -> bool {
        false
    }

    /// Runs shard `shard` of the study's Monte Carlo and returns its partial result
    /// (a [`kalibra_sim::Partial`], serialised by [`write_partial`]). [`Study::merge_shards`] of every shard's
    /// partial gives the report [`Study::run`] gives, to the bit.
    ///
    /// # Errors
    /// [`StudyError::NotSharded`] for a study that does not shard (the default); otherwise
    /// as [`Study::run`].
    fn run_shard(
        &self,
        config: &Self::Config,
        shard: kalibra_sim::Shard,
    ) -> Result<Vec<u8>, StudyError> {
        let _ = (config, shard);
        Err(not_sharded(self.id()))
    }

    /// The report of the study from the partial results of all its shards, in any order.
    ///
    /// # Errors
    /// [`StudyError::NotSharded`] for a study that does not shard (the default);
    /// [`StudyError::Partial`] for a part that is not this study's partial;
    /// [`StudyError::Shard`] for parts of other configurations, duplicates or gaps.
    fn merge_shards(
        &self,
        config: &Self::Config,
        parts: Vec<Vec<u8>>,
    ) -> Result<Self::Report, StudyError> {
        let _ = (config, parts);
        Err(not_sharded(self.id()))
    }
}

fn not_sharded(id: &'static str) -> StudyError {
    let sharded: Vec<&str> = crate::REGISTRY
        .iter()
        .filter(|s| s.sharded())
        .map(|s| s.id())
        .collect();
    StudyError::NotSharded(id, sharded.join(", "))
}

/// The identity of a study's Monte Carlo for its shards: seed and runs, a hash of the
/// configuration without its thread count (which never changes results), and the kalibra
/// version. Shards of the same identity merge; any other difference is refused.
///
/// # Errors
/// [`StudyError::Report`] if the configuration does not serialise.
pub fn study_id(
    config: &impl Serialize,
    mc: &kalibra_sim::MonteCarlo,
) -> Result<kalibra_sim::StudyId, StudyError> {
    let mut value = serde_json::to_value(config)
        .map_err(|e| StudyError::Report(format!("the configuration does not serialise: {e}")))?;
    if let Some(map) = value.as_object_mut() {
        map.remove("threads");
    }
    // serde_json's maps are ordered by key, so the text is canonical.
    let hash = kalibra_sim::config_hash(value.to_string().as_bytes());
    Ok(kalibra_sim::StudyId::new(
        mc,
        hash,
        concat!("kalibra ", env!("CARGO_PKG_VERSION")),
    ))
}

/// Reads shard partials written by [`write_partial`], naming the part that does not read.
///
/// # Errors
/// [`StudyError::Partial`] for bytes that are not a `Partial<A>`.
pub fn read_partials<A: serde::de::DeserializeOwned>(
    study: &'static str,
    parts: Vec<Vec<u8>>,
) -> Result<Vec<kalibra_sim::Partial<A>>, StudyError> {
    parts
        .iter()
        .enumerate()
        .map(|(i, bytes)| {
            ciborium::from_reader(bytes.as_slice()).map_err(|e| StudyError::Partial {
                study,
                shard: format!("part {i} of {}", parts.len()),
                message: e.to_string(),
            })
        })
        .collect()
}

/// Serialises a shard's partial result as CBOR (RFC 8949): compact, self-describing, and
/// exact for `f64` (each written in the shortest IEEE width that holds it exactly), and read
/// without parsing decimal floats, which dominates merging JSON partials (`cargo xtask bench
/// shards`).
///
/// # Errors
/// [`StudyError::Report`] if it does not serialise.
pub fn write_partial<A: Serialize>(
    partial: &kalibra_sim::Partial<A>,
) -> Result<Vec<u8>, StudyError> {
    let mut bytes = Vec::new();
    ciborium::into_writer(partial, &mut bytes)
        .map_err(|e| StudyError::Report(format!("the partial result does not serialise: {e}")))?;
    Ok(bytes)
}

/// Everything one study run produced, type-erased for the registry loop.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The seed the run used, if any.
    pub seed: Option<u64>,
    /// The configuration, serialised.
    pub config: serde_json::Value,
    /// The report, serialised.
    pub results: serde_json::Value,
    /// The published claims with verdicts.
    pub claims: Vec<Claim>,
    /// One-line summary for the index.
    pub highlight: String,
    /// The Markdown report.
    pub markdown: String,
    /// The figures the report links to.
    pub figures: Vec<NamedFigure>,
}

/// A [`Study`] with its types erased, as the registry lists it. Implemented for every
/// [`Study`]; implement [`Study`], not this.
pub trait Reproduce: Sync {
    /// See [`Study::id`].
    fn id(&self) -> &'static str;
    /// See [`Study::title`].
    fn title(&self) -> &'static str;
    /// See [`Study::paper`].
    fn paper(&self) -> Option<&'static str>;
    /// [`Study::describe`] of the configuration `options` selects.
    fn describe(&self, options: &Options) -> String;
    /// Runs the configuration `options` selects and collects everything it produces.
    ///
    /// # Errors
    /// Whatever the run, the highlight or the report template return, and
    /// [`StudyError::Report`] if the report does not serialise.
    fn reproduce(&self, options: &Options) -> Result<Outcome, StudyError>;
    /// See [`Study::sharded`].
    fn sharded(&self) -> bool;
    /// [`Study::run_shard`] of the configuration `options` selects.
    ///
    /// # Errors
    /// As [`Study::run_shard`].
    fn reproduce_shard(
        &self,
        options: &Options,
        shard: kalibra_sim::Shard,
    ) -> Result<Vec<u8>, StudyError>;
    /// What [`Reproduce::reproduce`] collects, from the partial results of every shard
    /// ([`Study::merge_shards`]) instead of a run.
    ///
    /// # Errors
    /// As [`Study::merge_shards`] and [`Reproduce::reproduce`].
    fn reproduce_merged(
        &self,
        options: &Options,
        parts: Vec<Vec<u8>>,
    ) -> Result<Outcome, StudyError>;
}

impl<S: Study> Reproduce for S {
    fn id(&self) -> &'static str {
        Study::id(self)
    }

    fn title(&self) -> &'static str {
        Study::title(self)
    }

    fn paper(&self) -> Option<&'static str> {
        Study::paper(self)
    }

    fn describe(&self, options: &Options) -> String {
        Study::describe(self, &self.config(options))
    }

    fn reproduce(&self, options: &Options) -> Result<Outcome, StudyError> {
        let config = self.config(options);
        let report = self.run(&config)?;
        outcome(self, &config, &report)
    }

    fn sharded(&self) -> bool {
        Study::sharded(self)
    }

    fn reproduce_shard(
        &self,
        options: &Options,
        shard: kalibra_sim::Shard,
    ) -> Result<Vec<u8>, StudyError> {
        self.run_shard(&self.config(options), shard)
    }

    fn reproduce_merged(
        &self,
        options: &Options,
        parts: Vec<Vec<u8>>,
    ) -> Result<Outcome, StudyError> {
        let config = self.config(options);
        let report = self.merge_shards(&config, parts)?;
        outcome(self, &config, &report)
    }
}

/// Everything a run of `study` produced, from its report.
fn outcome<S: Study>(
    study: &S,
    config: &S::Config,
    report: &S::Report,
) -> Result<Outcome, StudyError> {
    let json = |what: &str, value: Result<serde_json::Value, serde_json::Error>| {
        value.map_err(|e| StudyError::Report(format!("{what} does not serialise: {e}")))
    };
    Ok(Outcome {
        seed: study.seed(config),
        config: json("the configuration", serde_json::to_value(config))?,
        results: json("the report", serde_json::to_value(report))?,
        claims: study.claims(report),
        highlight: study.highlight(config, report)?,
        markdown: study.markdown(config, report)?,
        figures: study.figures(report),
    })
}
