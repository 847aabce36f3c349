//! Where a problem comes from: a catalogue system or a model file with its data.

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use sysid_core::Problem;
use sysid_model::Model;
use sysid_ode::System;
use sysid_systems::{Case, Visit};

/// `--system NAME` or `--model FILE [--data CSV]`.
#[derive(Args, Debug, Clone)]
pub struct SourceArgs {
    /// A catalogue system (`sysid systems` lists them).
    #[arg(long, value_name = "NAME", required_unless_present = "model", conflicts_with = "model")]
    pub system: Option<String>,
    /// A model file (TOML; its keys in docs/model-files.md).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    // A catalogue system has data of its own: --data with --system is an error, not ignored.
    // `requires = "model"` alone does not refuse it: clap drops a requirement that conflicts
    // with an argument given (--model conflicts with --system).
    /// The data file (CSV) to use instead of the model file's `[data] file`.
    #[arg(long, value_name = "CSV", requires = "model", conflicts_with = "system")]
    pub data: Option<PathBuf>,
    /// Seed of a catalogue system's synthetic data (fixed data ignore it).
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
}

/// What a report says about the problem besides the fit.
#[derive(Clone, Debug, Default)]
pub struct Context {
    /// The system's or model's name.
    pub name: String,
    /// One line describing it.
    pub summary: String,
    /// Expected values of unknowns (reference answer or truth), by name.
    pub expected: Vec<(String, f64)>,
    /// "reference", "truth" or "".
    pub expected_label: &'static str,
    /// The reference cost and its source.
    pub reference_cost: Option<(f64, &'static str)>,
}

impl Context {
    /// The expected value of an unknown, if any.
    pub fn expected(&self, name: &str) -> Option<f64> {
        self.expected.iter().find(|(n, _)| n == name).map(|p| p.1)
    }
}

/// Something to do with a problem of any system type.
pub trait WithProblem {
    /// What it produces.
    type Output;
    /// Does it.
    fn run<S: System + Clone + Send + Sync + 'static>(
        self,
        problem: Problem<S>,
        context: Context,
    ) -> anyhow::Result<Self::Output>;
}

struct Catalogue<W> {
    seed: u64,
    with: W,
}

impl<W: WithProblem> Visit for Catalogue<W> {
    type Output = anyhow::Result<W::Output>;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        let problem = case.problem(self.seed).with_context(|| format!("system {}", case.name))?;
        let expected = case
            .unknowns
            .iter()
            .filter_map(|u| case.expected(&u.name).map(|v| (u.name.clone(), v)))
            .collect();
        let context = Context {
            name: case.name.into(),
            summary: case.summary.into(),
            expected,
            expected_label: match (&case.reference, case.truth.is_empty()) {
                (Some(_), _) => "reference",
                (None, false) => "truth",
                (None, true) => "",
            },
            reference_cost: case.reference.as_ref().map(|r| (r.cost, r.source)),
        };
        self.with.run(problem, context)
    }
}

/// Builds the problem of `source` and hands it to `with`.
pub fn with_problem<W: WithProblem>(source: &SourceArgs, with: W) -> anyhow::Result<W::Output> {
    match (&source.system, &source.model) {
        (Some(name), _) => sysid_systems::visit(name, Catalogue { seed: source.seed, with })
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "unknown system `{name}` (systems: {})",
                    sysid_systems::NAMES.join(", ")
                )
            })?,
        (None, Some(path)) => {
            let model = Model::load(path)?;
            let problem = model.problem(source.data.as_deref())?;
            let context = Context {
                name: path.display().to_string(),
                summary: "model file".into(),
                ..Context::default()
            };
            with.run(problem, context)
        }
        (None, None) => anyhow::bail!("give --system NAME or --model FILE"),
    }
}
