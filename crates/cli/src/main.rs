//! `sysid`: identify dynamic systems and compare the classical methods.
//!
//! Exit codes: 0 success, 1 the method did not converge (its report is still printed),
//! 2 bad input (one line on stderr, nothing on stdout); docs/terminations.md has them all.
//! A long command stopped by Ctrl-C or SIGTERM prints what it has, then ends by the signal
//! ([`signals`]).

mod compare;
mod evaluate;
mod fit;
mod options;
mod output;
mod predict;
mod problem;
mod profile;
mod report;
mod signals;
mod simulate;
mod study;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// sysid identifies dynamic systems: it finds the unknown parameters and initial values of
/// an ODE model that fit measurements best in the least-squares sense (ε = Σ w r², no factor
/// ½), says how sure it is, and compares the classical methods that do it.
#[derive(Parser, Debug)]
#[command(name = "sysid", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Identify the unknowns of a catalogue system or a model file and print the estimates
    /// with standard errors, the cost and the iteration history.
    Fit(fit::FitArgs),
    /// Run several methods on the same data from the same start and print them side by
    /// side: convergence, iterations, cost, time, and each estimate next to the truth.
    Compare(compare::CompareArgs),
    /// The negative log-likelihood at the nominal values (or --set ones), with --gradient
    /// its gradient, each with its integration error, and the median time of one evaluation
    /// after the import (--repeat N).
    Evaluate(evaluate::EvaluateArgs),
    /// Write a catalogue system's data, or a model file's trajectory, as CSV (header row,
    /// time first).
    Simulate(simulate::SimulateArgs),
    /// Fit, then write the fitted trajectory of every state from t0 to a later time with a
    /// 95 % band from the linearised covariance (CSV).
    Predict(predict::PredictArgs),
    /// Monte-Carlo robustness study: many noise realisations and starts, every method on
    /// each, against a reference fit from the truth; success rates, accuracy against the
    /// Cramér–Rao bound, iterations and time (trials.jsonl, summary.json, summary.md in
    /// --out). With --basin, a map of convergence over a grid of starts instead.
    Study(study::StudyArgs),
    /// Fit, then trace the profile likelihood of every unknown (each fixed along a path,
    /// the others re-optimised by the method): 95 % intervals and an identifiability
    /// verdict per unknown.
    Profile(profile::ProfileArgs),
    /// Merge the shard directories of one study (`study --shard i/n`) into one, identical
    /// to an unsharded run.
    Merge(study::MergeArgs),
    /// The comparison report of the whole catalogue: for every system, convergence from the
    /// default start, a Monte-Carlo study, basins of convergence and the fit with its
    /// prediction band, as figures (PNG, SVG), their data (CSV, JSON) and README.md in --out.
    Report(report::ReportArgs),
    /// List the built-in benchmark systems, one line each.
    Systems,
}

/// What a command ends with: success, or a method that did not converge.
pub enum Outcome {
    /// Exit 0.
    Success,
    /// Exit 1.
    NotConverged,
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand {
                let _ = e.print();
                return ExitCode::from(2);
            }
            eprintln!("{}", one_line(&e.render().to_string()));
            return ExitCode::from(2);
        }
    };
    // The long commands stop at the first Ctrl-C or SIGTERM with what they have done (the
    // report's scaling figure times evaluations, which hear no stop: it ends at once).
    let stoppable = match &cli.command {
        Command::Report(args) => args.scaling.is_none(),
        command => matches!(
            command,
            Command::Fit(_)
                | Command::Compare(_)
                | Command::Predict(_)
                | Command::Study(_)
                | Command::Profile(_)
        ),
    };
    let signals = if stoppable { signals::Signals::install() } else { None };
    let result = match &signals {
        Some(s) => sysid_core::observer::stop_when(s.flag(), || run(cli.command)),
        None => run(cli.command),
    };
    let code = match result {
        Ok(Outcome::Success) => ExitCode::SUCCESS,
        Ok(Outcome::NotConverged) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {}", one_line(&format!("{e:#}")));
            ExitCode::from(2)
        }
    };
    if let Some(signal) = signals.as_ref().and_then(signals::Signals::received) {
        signals::Signals::end_by(signal);
    }
    code
}

/// Runs a command.
fn run(command: Command) -> anyhow::Result<Outcome> {
    match command {
        Command::Fit(args) => fit::run(&args),
        Command::Compare(args) => compare::run(&args),
        Command::Evaluate(args) => evaluate::run(&args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Predict(args) => predict::run(&args),
        Command::Study(args) => study::run(&args),
        Command::Profile(args) => profile::run(&args),
        Command::Merge(args) => study::merge(&args),
        Command::Report(args) => report::run(&args),
        Command::Systems => {
            let lines: Vec<String> = sysid_systems::summaries()
                .into_iter()
                .map(|(name, summary)| format!("{name:<26} {summary}\n"))
                .collect();
            output::emit(&lines.concat()).map(|()| Outcome::Success)
        }
    }
}

/// Folds a multi-line message (clap's usage errors) into one line.
fn one_line(message: &str) -> String {
    message
        .lines()
        .map(str::trim)
        .filter(|l| {
            !l.is_empty() && !l.starts_with("Usage:") && !l.starts_with("For more information")
        })
        .collect::<Vec<_>>()
        .join(" ")
}
