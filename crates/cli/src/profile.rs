//! `sysid profile`.

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::bail;
use clap::Args;
use sysid_profile::{
    Label, ProfileOptions, Profiled, Progress, objective, profile_from_optimum, threshold_95,
};

use crate::Outcome;
use crate::options::{Format, IntegratorArgs, MethodArg, MethodArgs, SourceArgs, StartsArgs};
use crate::output::Watch;
use crate::output::{emit, figure_writable};
use crate::problem::{Context, fit_from_starts, method, problem};

/// Arguments of `sysid profile`.
#[derive(Args, Debug)]
pub struct ProfileArgs {
    #[command(flatten)]
    source: SourceArgs,
    #[command(flatten)]
    method: MethodArg,
    /// Profile only these unknowns (comma-separated names; default: every unknown).
    #[arg(long, value_name = "A,B")]
    only: Option<String>,
    /// Simultaneous 95 % intervals: the threshold χ²ₖ(0.95)/2 for the k unknowns (those held
    /// on a bound at the optimum included; the noise scales set in closed form are not
    /// counted) instead of the pointwise χ²₁(0.95)/2 = 1.92.
    #[arg(long)]
    simultaneous: bool,
    /// Most points each side of a profile walks (a step retried at half its length is the same
    /// point; the points fitted while locating a crossing come on top). A side that runs out of
    /// them while still rising is `undecided`, unless the other side stayed below the threshold.
    #[arg(
        long,
        default_value_t = 60,
        value_name = "N",
        value_parser = crate::options::count,
        allow_hyphen_values = true
    )]
    max_points: usize,
    /// Also draw the profiles: FILE.png and FILE.svg (FILE without extension), one column
    /// per unknown, ΔNLL with the threshold and the interval above, the others' paths below.
    #[arg(long, value_name = "FILE")]
    figure: Option<std::path::PathBuf>,
    /// Output format: a readable table, or JSON (docs/json.md, `sysid profile`).
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    #[command(flatten)]
    options: MethodArgs,
    #[command(flatten)]
    starts: StartsArgs,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// Runs `sysid profile`.
pub fn run(args: &ProfileArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    args.integrator.validate()?;
    args.starts.options()?;
    args.starts.check_start(&args.options.start)?;
    args.method.check()?;
    if args.max_points == 0 {
        bail!("--max-points must be at least 1");
    }
    if args.options.max_iterations == Some(0) {
        bail!(
            "--max-iterations 0: a profile fits the optimum and re-optimises the other unknowns at every point, which takes at least 1 iteration"
        );
    }
    let (problem, context) = problem(&args.source, &args.integrator, &args.options)?;
    // Where the figure goes is checked before the work, not after it.
    if let Some(stem) = &args.figure {
        figure_writable(stem, &context.inputs, "--figure")?;
    }
    let names = problem.names();
    let only = match &args.only {
        None => Vec::new(),
        Some(list) => list
            .split(',')
            .map(|n| {
                let n = n.trim();
                if n.is_empty() {
                    bail!("--only: an empty name in `{list}` (two commas, or one at an end)");
                }
                names.iter().position(|x| x == n).ok_or_else(|| {
                    anyhow::anyhow!(
                        "--only: `{n}` is not an unknown (unknowns: {})",
                        names.join(", ")
                    )
                })
            })
            .collect::<anyhow::Result<Vec<usize>>>()?,
    };
    if let Some(twice) = only.iter().enumerate().find(|(k, i)| only[..*k].contains(i)) {
        bail!("--only: `{}` is named twice", names[*twice.1]);
    }
    let watch = context.watch(&args.method.method, args.options.log_every);
    let (optimum, starts) =
        fit_from_starts(&problem, &args.method.method, &args.options, &args.starts, &watch)
            .map_err(|e| context.blame(e))?;
    let settings = args.options.settings();
    let m = method(&args.method.method, &settings)?;
    let threshold = threshold_95(args.simultaneous.then_some(problem.unknowns().len()));
    let options =
        ProfileOptions { max_steps: args.max_points, threshold, ..ProfileOptions::default() };
    let traces = context.watch(&format!("{} profiles", args.method.method), args.options.log_every);
    let line: &Watch = &traces;
    // The points fitted on each unknown's profile and the profiles ended, for the line
    // (a profile is tens of fits, and one fit of a large model can take a minute).
    let fitted: Vec<AtomicUsize> = names.iter().map(|_| AtomicUsize::new(0)).collect();
    let ended = AtomicUsize::new(0);
    let total = if only.is_empty() { names.len() } else { only.len() };
    let told = |progress: Progress<'_>| match progress {
        Progress::Point { unknown, point, rise } => {
            let n = fitted[unknown].fetch_add(1, Ordering::Relaxed) + 1;
            line.say(&format!(
                "{}/{total} ended; {} = {} (point {n}), ΔNLL {} of {}",
                ended.load(Ordering::Relaxed),
                names[unknown],
                sysid_core::format::significant(point.value, 6),
                sysid_core::format::significant(rise, 3),
                sysid_core::format::significant(threshold, 3),
            ))
        }
        Progress::Traced { unknown, done, total } => {
            ended.store(done, Ordering::Relaxed);
            // After Ctrl-C the profiles end stopped, not traced (told on a rayon worker,
            // which does not carry the run's stop flags: the signal's own).
            let how = if crate::signals::requested() { "ended" } else { "traced" };
            line.say(&format!("{done}/{total} {how} (the last: {})", names[unknown]))
        }
        Progress::Better { point, was } => {
            // The profiles are traced again from the new optimum: their counts begin anew.
            fitted.iter().for_each(|n| n.store(0, Ordering::Relaxed));
            ended.store(0, Ordering::Relaxed);
            eprintln!(
                "better optimum found along a profile (objective {} against {was}): fitting again from there",
                point.nll
            )
        }
    };
    let profiled = profile_from_optimum(&*m, &problem, optimum.clone(), &only, &options, &told);
    traces.finish();
    let profiled = match profiled {
        // Ctrl-C or SIGTERM while the optimum was fitted again: the point the profiles began
        // from is not lost. (Stopped elsewhere, the profiles come back labelled `stopped`.)
        Err(sysid_profile::ProfileError::Interrupted) => {
            eprintln!(
                "stopped after a profile found a better point than the optimum: the profiles are not printed; the fit they began from ({}, objective {}): {}",
                optimum.termination,
                objective(&optimum),
                sysid_core::format::named_point(&optimum.names, &optimum.values)
            );
            return Ok(Outcome::NotConverged);
        }
        profiled => profiled.map_err(|e| context.blame(e.into()))?,
    };
    match args.format {
        Format::Json => {
            let record = profiled.record(&context.name, options.threshold);
            let mut value = serde_json::to_value(&record)?;
            // The multistart the optimum came from, as `fit --starts` prints it; not where a
            // profile found a better point and the optimum is the fit made from there.
            if let (Some(starts), true) = (&starts, profiled.better.is_empty()) {
                value["optimum"]["starts"] = serde_json::to_value(starts)?;
            }
            emit(&format!("{}\n", serde_json::to_string_pretty(&value)?))?
        }
        Format::Table => emit(&table(&context, &profiled))?,
    }
    let Profiled { optimum, profiles, .. } = &profiled;
    // The results are out before the figure is drawn: a figure that cannot be written
    // loses nothing.
    if let Some(stem) = &args.figure {
        let title = format!("{}: profile likelihoods", context.name);
        let figure =
            sysid_report::Profiles::new(title, &problem, optimum, options.threshold, profiles);
        let [png, svg] = sysid_report::save(&figure, stem)?;
        eprintln!("wrote {} and {}", png.display(), svg.display());
    }
    Ok(Outcome::Success)
}

/// The readable report: the optimum's NLL, then a line per unknown.
fn table(context: &Context, profiled: &Profiled) -> String {
    let Profiled { certified, optimum, better, profiles } = profiled;
    let what = if optimum.prior.is_some() { "NLL plus the priors' term" } else { "NLL" };
    let mut text = format!(
        "{}: profile likelihoods ({}), {what} at the optimum {}\n",
        context.name,
        optimum.method,
        objective(optimum)
    );
    if !*certified {
        text += "  warning: the fit did not certify its optimum; the profiles start from its best point\n";
    }
    if optimum.termination == sysid_core::Termination::Interrupted && !better.is_empty() {
        text += "  warning: the run was stopped while the optimum was fitted again from a better point; the profiles start from that fit's best point, not a certified optimum\n";
    }
    if !better.is_empty() {
        text += &format!(
            "  warning: the profiles found a better optimum {} time(s) and started again from it\n",
            better.len()
        );
    }
    // A point's fit that stopped short lies above the profile, which then crosses early:
    // intervals too narrow, an unknown called identifiable that may not be.
    // Each profile holds the optimum too, which has its own warning above.
    let points = profiles.iter().flat_map(|p| &p.points).filter(|q| q.estimates != optimum.values);
    let (short, all) = (points.clone().filter(|q| !q.converged).count(), points.count());
    let stopped = profiles.iter().filter(|p| p.label == Label::Stopped).count();
    if stopped > 0 {
        text += &format!(
            "  warning: the run was stopped: {stopped} of the {} profiles are not done (their verdict `stopped`, a bound not reached shown as —; the JSON keeps the points fitted)\n",
            profiles.len()
        );
    }
    if short > 0 {
        text += &format!(
            "  warning: {short} of the {all} points' fits did not converge: their NLL may lie above the profile's, and the intervals may be too narrow (the JSON's `converged` says which)\n"
        );
    }
    text += &format!(
        "\n  {:<22} {:>14} {:>14} {:>14}  {}\n",
        "unknown", "estimate", "95 % low", "95 % high", "verdict"
    );
    for p in profiles {
        let none = if p.label == Label::Stopped { "—" } else { "open" };
        let bound = |v: Option<f64>| v.map_or(none.to_string(), |v| format!("{v:.6e}"));
        let i = optimum.names.iter().position(|n| n == &p.name).unwrap_or(0);
        let label = p.label.words();
        text += &format!(
            "  {:<22} {:>14.6e} {:>14} {:>14}  {label} ({} points)\n",
            p.name,
            optimum.values[i],
            bound(p.interval[0]),
            bound(p.interval[1]),
            p.points.len()
        );
    }
    for p in profiles {
        if let Some(message) = &p.failed {
            text += &format!(
                "  warning: a fit along {}'s profile panicked, a defect in sysid (please report it with the command): {message}; the points before it are kept\n",
                p.name
            );
        }
    }
    text
}
