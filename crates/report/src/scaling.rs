//! How the cost of one NLL + gradient grows over a collection of PEtab problems
//! ([`write_scaling`]): each problem imported and evaluated at its nominal values on one
//! thread, the gradient by the counted choice between forward and adjoint sensitivities
//! (`Sensitivities::Auto`, whose first evaluation computes both ways and is not timed), the median of
//! repeated evaluations plotted against states × parameters on log–log axes, with the
//! least-squares power law through the points. Problems that cannot be imported or evaluated
//! are listed with the reason.

use std::path::{Path, PathBuf};
use std::time::Instant;

use plotters::coord::Shift;
use plotters::prelude::*;
use sysid_core::Sensitivities;
use sysid_ode::System as _;

use crate::chart::{DrawResult, FONT, Figure, decade, log_range};
use crate::look::look;
use crate::manifest::{Manifest, README, write};
use crate::options::Observer;

/// What [`write_scaling`] measures and where it writes.
#[derive(Clone, Debug)]
pub struct ScalingOptions {
    /// A directory of PEtab problems, a folder each (`<name>/<name>.yaml`, or
    /// `problem.yaml`, or the folder's only YAML file).
    pub dir: PathBuf,
    /// Where README.md, `scaling.{png,svg}` and `scaling.csv` go.
    pub out: PathBuf,
    /// Timed evaluations per problem, at most (their median is the figure's).
    pub repeat: usize,
    /// Seconds of timed evaluations after which a problem is evaluated no more (at least
    /// once).
    pub seconds: f64,
    /// Replace files at these paths that no report wrote.
    pub force: bool,
}

/// One problem's measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    /// The problem (its folder).
    pub problem: String,
    /// States of its model.
    pub states: usize,
    /// Entries of the gradient: the free unknowns and the noise scales.
    pub parameters: usize,
    /// Experiments (simulation conditions, with their preequilibrations).
    pub experiments: usize,
    /// Experiments whose gradient the counted choice takes by adjoint.
    pub by_adjoint: usize,
    /// Import, ms.
    pub import_ms: f64,
    /// Median time of one NLL + gradient, ms.
    pub ms: f64,
    /// Timed evaluations.
    pub evaluations: usize,
}

/// The figure: ms against states × parameters, log–log.
#[derive(Clone, Debug)]
pub struct Scaling {
    /// The title.
    pub title: String,
    /// The measured problems.
    pub points: Vec<Measured>,
}

/// The least-squares line ln ms = ln c + a·ln(n·p) through the points: (c, a); `None` with
/// fewer than two distinct sizes.
pub fn power_law(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let logs: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite())
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    let n = logs.len() as f64;
    let (mx, my) = logs.iter().fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let sxx: f64 = logs.iter().map(|(x, _)| (x - mx).powi(2)).sum();
    let sxy: f64 = logs.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    if logs.len() < 2 || sxx <= 0.0 {
        return None;
    }
    let a = sxy / sxx;
    Some(((my - a * mx).exp(), a))
}

impl Measured {
    /// States × parameters, the size of the forward sensitivity system.
    pub fn size(&self) -> f64 {
        (self.states * self.parameters.max(1)) as f64
    }

    /// Its row of the table and of the CSV, after the problem's name: states, parameters,
    /// n·p, experiments, by adjoint, import ms, ms per evaluation, evaluations.
    fn cells(&self) -> [String; 8] {
        [
            self.states.to_string(),
            self.parameters.to_string(),
            self.size().to_string(),
            self.experiments.to_string(),
            self.by_adjoint.to_string(),
            format!("{:.1}", self.import_ms),
            format!("{:.4}", self.ms),
            self.evaluations.to_string(),
        ]
    }
}

impl Figure for Scaling {
    fn size(&self) -> (u32, u32) {
        (900, 560)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let xy: Vec<(f64, f64)> = self.points.iter().map(|p| (p.size(), p.ms)).collect();
        let (xlo, xhi) = log_range(xy.iter().map(|p| p.0));
        let (ylo, yhi) = log_range(xy.iter().map(|p| p.1));
        let law = power_law(&xy);
        let caption = match law {
            Some((_, a)) => format!(
                "median of one NLL + gradient at nominal, one thread (filled: adjoint for some experiment); line: ms ∝ (n·p)^{a:.2}"
            ),
            None => "median of one NLL + gradient at nominal, one thread".to_string(),
        };
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, (FONT, 14))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d((xlo..xhi).log_scale(), (ylo..yhi).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("states × parameters (n·p)")
            .x_label_formatter(&|v| decade(*v))
            .y_desc("ms per NLL + gradient")
            .y_label_formatter(&|v| decade(*v))
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 14))
            .draw()?;
        if let Some((c, a)) = law {
            let line = [xlo, xhi].map(|x| (x, c * x.powf(a)));
            let inside = line.iter().all(|(_, y)| *y > 0.0 && y.is_finite());
            if inside {
                chart.draw_series(std::iter::once(PathElement::new(
                    line.to_vec(),
                    BLACK.mix(0.5).stroke_width(1),
                )))?;
            }
        }
        let color = look(0).color;
        for p in &self.points {
            let style = if p.by_adjoint > 0 { color.filled() } else { color.stroke_width(2) };
            let label = p.problem.split('_').next().unwrap_or(&p.problem).to_string();
            let font = (FONT, 11).into_font().color(&BLACK.mix(0.8));
            chart.draw_series(std::iter::once(
                EmptyElement::at((p.size(), p.ms))
                    + Circle::new((0, 0), 4, style)
                    + Text::new(label, (6, -12), font),
            ))?;
        }
        Ok(())
    }
}

/// One problem: imported, then NLL + gradient at nominal, once to make the choice between
/// forward and adjoint (untimed), then up to `repeat` timed evaluations within `seconds`.
fn measure(dir: &Path, name: &str, repeat: usize, seconds: f64) -> Result<Measured, String> {
    let yaml = crate::petab::problem_yaml(dir, name);
    let started = Instant::now();
    let imported = sysid_petab::import(&yaml).map_err(|e| e.to_string())?;
    let problem = imported.model.problem(None).map_err(|e| e.to_string())?;
    let import_ms = started.elapsed().as_secs_f64() * 1e3;
    let z = problem.unknowns().coordinates(&problem.guesses());
    let evaluate = || match problem.nll_gradient(&z, Sensitivities::Auto) {
        Ok(Some(g)) => Ok(g),
        Ok(None) => Err("no likelihood".to_string()),
        Err(e) => Err(e.to_string()),
    };
    let first = evaluate()?;
    let mut times = Vec::new();
    let timed = Instant::now();
    while times.len() < repeat.max(1)
        && (times.is_empty() || timed.elapsed().as_secs_f64() < seconds)
    {
        let t = Instant::now();
        evaluate()?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok(Measured {
        problem: name.to_string(),
        states: problem.experiments()[0].system().signature().n_states(),
        parameters: first.gradient.len(),
        experiments: problem.experiments().len(),
        by_adjoint: first.by_adjoint.len(),
        import_ms,
        ms: times[times.len() / 2],
        evaluations: times.len(),
    })
}

/// The files [`write_scaling`] owns in its directory.
const FILES: [&str; 4] = [README, "scaling.png", "scaling.svg", "scaling.csv"];

/// Measures every problem of `options.dir` on one thread and writes README.md (the table and
/// the figure), `scaling.{png,svg}` and `scaling.csv` into `options.out`; returns the
/// README's path.
pub fn write_scaling(options: &ScalingOptions, observer: &dyn Observer) -> anyhow::Result<PathBuf> {
    if options.repeat == 0 {
        anyhow::bail!("--repeat must be at least 1");
    }
    if !(options.seconds.is_finite() && options.seconds >= 0.0) {
        anyhow::bail!("the seconds per problem must be a number ≥ 0, got {}", options.seconds);
    }
    let names = crate::petab::problems(&options.dir);
    if names.is_empty() {
        anyhow::bail!("{} holds no PEtab problem folders", options.dir.display());
    }
    let planned: Vec<String> = FILES.iter().map(|f| f.to_string()).collect();
    let manifest = Manifest::prepare_files(&options.out, planned, options.force)?;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut outcomes = Vec::new();
    observer.begin(&format!("{} problems", names.len()), names.len() as u64);
    for (i, name) in names.iter().enumerate() {
        let outcome = pool.install(|| measure(&options.dir, name, options.repeat, options.seconds));
        match &outcome {
            Ok(m) => observer.note(&format!("{name}: {:.3} ms per NLL + gradient", m.ms)),
            Err(e) => observer.note(&format!("{name}: not measured: {e}")),
        }
        outcomes.push((name.clone(), outcome));
        observer.advance(i as u64 + 1, names.len() as u64);
    }
    observer.end();
    let written = write_files(options, &outcomes);
    manifest.close()?;
    written
}

fn write_files(
    options: &ScalingOptions,
    outcomes: &[(String, Result<Measured, String>)],
) -> anyhow::Result<PathBuf> {
    let points: Vec<Measured> =
        outcomes.iter().filter_map(|(_, o)| o.as_ref().ok()).cloned().collect();
    let mut csv = String::from(
        "problem,states,parameters,states_x_parameters,experiments,adjoint_experiments,import_ms,ms_per_evaluation,evaluations\n",
    );
    for p in &points {
        csv += &format!("{},{}\n", p.problem, p.cells().join(","));
    }
    write(&options.out.join("scaling.csv"), &csv)?;
    let figure = Scaling {
        title: "The cost of one NLL + gradient against the problem's size".into(),
        points: points.clone(),
    };
    crate::chart::save(&figure, &options.out.join("scaling"))?;
    let law = power_law(&points.iter().map(|p| (p.size(), p.ms)).collect::<Vec<_>>());
    write(&options.out.join(README), &markdown(options, outcomes, law))?;
    Ok(options.out.join(README))
}

fn markdown(
    options: &ScalingOptions,
    outcomes: &[(String, Result<Measured, String>)],
    law: Option<(f64, f64)>,
) -> String {
    let mut md =
        String::from("# The cost of one NLL + gradient over a collection of PEtab problems\n\n");
    let folder = options
        .dir
        .file_name()
        .map_or_else(|| options.dir.display().to_string(), |f| f.to_string_lossy().to_string());
    let measured = outcomes.iter().filter(|(_, o)| o.is_ok()).count();
    md += &format!(
        "The {measured} problems of a folder `{folder}` that import and evaluate (of {}), each \
         imported and evaluated at its nominal values on one thread (`Sensitivities::Auto`: \
         each experiment's gradient by forward or adjoint sensitivities, whichever took fewer \
         counted operations in its first, untimed evaluation, which computes both), the median of up to {} timed evaluations within \
         {} s. n is the model's states, p the entries of the gradient (free unknowns and noise \
         scales). Regenerated by `sysid report --scaling DIR --scaling-repeat {} \
         --scaling-seconds {} --out OUT`, DIR that folder (for the collection, a clone's \
         `Benchmark-Models`), into OUT/scaling.\n\n",
        outcomes.len(),
        options.repeat,
        options.seconds,
        options.repeat,
        options.seconds,
    );
    md += "![ms per NLL + gradient against states × parameters](scaling.png)\n\n";
    if let Some((c, a)) = law {
        md += &format!(
            "The least-squares line through the points in log–log: ms ≈ {c:.3e}·(n·p)^{a:.2}. \
             The size explains the cost only in part: the number of experiments, the stiffness \
             and the steady states of preequilibration move problems of one size by decades.\n\n"
        );
    }
    md += "| problem | states n | parameters p | n·p | experiments | by adjoint | import ms | ms per NLL + gradient | evaluations |\n";
    md += "|---|---|---|---|---|---|---|---|---|\n";
    for (name, outcome) in outcomes {
        match outcome {
            Ok(p) => md += &format!("| {name} | {} |\n", p.cells().join(" | ")),
            Err(e) => {
                let reason = e.lines().next().unwrap_or("").replace('|', "\\|");
                md += &format!("| {name} | not measured: {reason} | | | | | | | |\n");
            }
        }
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on ms = 0.02·(n·p)^1.3 give back c = 0.02 and a = 1.3; one size alone gives none.
    #[test]
    fn the_power_law_is_the_least_squares_line_in_log_log() {
        let points: Vec<(f64, f64)> =
            [10.0, 300.0, 4e4, 2e6].iter().map(|&x: &f64| (x, 0.02 * x.powf(1.3))).collect();
        let (c, a) = power_law(&points).expect("a line");
        assert!((c - 0.02).abs() <= 1e-12 && (a - 1.3).abs() <= 1e-12, "{c} {a}");
        assert_eq!(power_law(&[(5.0, 1.0), (5.0, 2.0)]), None);
        assert_eq!(power_law(&[(5.0, 1.0)]), None);
    }
}
