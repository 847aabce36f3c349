//! `sysid compare`: every chosen method on the same data from the same start.

use std::path::PathBuf;

use clap::Args;
use sysid_core::{Estimate, Problem};
use sysid_ode::System;

use crate::fit::{best_of_starts, prepare, with_starts};
use crate::format::significant;
use crate::integrator::IntegratorArgs;
use crate::methods::{
    MethodArgs, StartsArgs, default_methods, describe_starts, method, parse_list,
};
use crate::source::{Context, SourceArgs, WithProblem, with_problem};
use crate::{Format, Outcome};
use sysid_montecarlo::multistart::Starts;

/// Arguments of `sysid compare`.
#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The catalogue system (`sysid systems` lists them).
    #[arg(long, value_name = "NAME", required_unless_present_any = ["all", "model"], conflicts_with_all = ["all", "model"])]
    system: Option<String>,
    /// A model file instead of a catalogue system.
    #[arg(long, value_name = "FILE", conflicts_with = "all")]
    model: Option<PathBuf>,
    /// The data file for --model (default: the model's `[data] file`).
    #[arg(long, value_name = "CSV", requires = "model", conflicts_with_all = ["system", "all"])]
    data: Option<PathBuf>,
    /// Every catalogue system, one table each.
    #[arg(long)]
    all: bool,
    /// Comma-separated methods (default: all of them).
    #[arg(long, value_name = "A,B,C")]
    methods: Option<String>,
    /// Seed of the synthetic data.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    seed: u64,
    /// Output format: tables, or a JSON list of fit objects (one per method, converged or
    /// not).
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    #[command(flatten)]
    options: MethodArgs,
    #[command(flatten)]
    starts: StartsArgs,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// One method's outcome on one system.
pub struct Row {
    method: String,
    result: Result<(Estimate, Option<Starts>), String>,
}

/// Runs `sysid compare`.
pub fn run(args: &CompareArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    args.starts.options()?;
    let methods = match &args.methods {
        Some(list) => parse_list(list)?,
        None => default_methods().into_iter().map(String::from).collect(),
    };
    let sources: Vec<SourceArgs> = if args.all {
        sysid_systems::NAMES
            .iter()
            .map(|n| SourceArgs {
                system: Some(n.to_string()),
                model: None,
                data: None,
                seed: args.seed,
            })
            .collect()
    } else {
        vec![SourceArgs {
            system: args.system.clone(),
            model: args.model.clone(),
            data: args.data.clone(),
            seed: args.seed,
        }]
    };
    let mut json = Vec::new();
    let mut tables = Vec::new();
    for source in &sources {
        let with = CompareProblem { methods: &methods, args };
        let (table, records) = with_problem(source, with)?;
        tables.push(table);
        json.extend(records);
    }
    match args.format {
        Format::Json => crate::emit(&format!("{}\n", serde_json::to_string_pretty(&json)?))?,
        Format::Table => crate::emit(&tables.join("\n"))?,
    }
    Ok(Outcome::Success)
}

struct CompareProblem<'a> {
    methods: &'a [String],
    args: &'a CompareArgs,
}

impl WithProblem for CompareProblem<'_> {
    type Output = (String, Vec<serde_json::Value>);

    fn run<S: System + Clone + Send + Sync + 'static>(
        self,
        problem: Problem<S>,
        context: Context,
    ) -> anyhow::Result<Self::Output> {
        let problem = prepare(problem, &self.args.integrator, &self.args.options)?;
        let common = self.args.options.common();
        let starts = self.args.starts.options()?;
        let mut rows = Vec::with_capacity(self.methods.len());
        for name in self.methods {
            let m = method::<S>(name, &common)?;
            let result = match &starts {
                Some(options) => best_of_starts(&problem, &*m, options)
                    .map(|(e, s)| (e, Some(s)))
                    .map_err(|e| e.to_string()),
                None => m.fit(&problem).map(|e| (e, None)).map_err(|e| e.to_string()),
            };
            rows.push(Row { method: name.clone(), result });
        }
        let json = rows
            .iter()
            .map(|row| match &row.result {
                Ok((e, starts)) => with_starts(e.record(&context.name), starts.as_ref()),
                Err(message) => serde_json::json!({
                    "system": context.name, "method": row.method, "converged": false, "error": message,
                }),
            })
            .collect();
        Ok((table(&problem, &context, &rows), json))
    }
}

/// One table: a row per method, the estimates under their unknowns with the truth or
/// reference in the header.
fn table<S: System>(problem: &Problem<S>, context: &Context, rows: &[Row]) -> String {
    let mut out = format!("{}: {}\n", context.name, context.summary);
    let unknowns = problem.names();
    let label = context.expected_label;
    let mut header = format!(
        "  {:<16} {:>5} {:>5} {:>18} {:>10}",
        "method", "conv", "iter", "cost ε", "time ms"
    );
    for name in &unknowns {
        header += &format!(" {:>16}", name);
    }
    out += &header;
    out += "\n";
    let mut expected = format!("  {:<16} {:>5} {:>5} {:>18} {:>10}", label, "", "", "", "");
    for name in &unknowns {
        expected += &format!(
            " {:>16}",
            context.expected(name).map_or(String::new(), |v| significant(v, 8))
        );
    }
    out += &expected;
    out += "\n";
    for row in rows {
        match &row.result {
            Ok((e, starts)) => {
                let mut line = format!(
                    "  {:<24} {:>5} {:>5} {:>18} {:>10.3}",
                    row.method,
                    if e.converged() { "yes" } else { "no" },
                    e.iterations,
                    significant(e.cost, 10),
                    e.elapsed.as_secs_f64() * 1e3
                );
                for v in &e.values {
                    line += &format!(" {:>16}", significant(*v, 8));
                }
                out += &line;
                out += "\n";
                if !e.converged() {
                    out += &format!("  {:<24} └ {}\n", "", e.termination);
                }
                if let Some(s) = starts {
                    out += &format!("  {:<24} └ {}\n", "", describe_starts(s));
                }
            }
            Err(message) => out += &format!("  {:<24} error: {message}\n", row.method),
        }
    }
    out
}
