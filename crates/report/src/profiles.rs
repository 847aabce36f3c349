//! Profile likelihoods: one column per unknown. Above, ΔNLL along the profile with the
//! threshold (dashed) and the interval's ends (vertical lines); below, how the other unknowns
//! compensate: each one's shift from the optimum along the path in its own coordinate over
//! that coordinate's scale (ln(θ/θ̂) on a log scale, Δθ/max(|θ̂|, |guess|, 1) otherwise), on a
//! linear axis through 0. The unknown's axis is logarithmic where it is estimated on a log
//! scale.

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;

use std::path::Path;
use sysid_core::{Estimate, Problem};
use sysid_ode::System;

use sysid_profile::{Outcome as Traced, Profile, ProfileOptions, profile};
use sysid_registry::{Registry, Settings};

use crate::chart::{DrawResult, FONT, Figure, padded, save, tick};
use crate::look::look;
use crate::manifest::write;

/// The profile of one unknown, as drawn.
#[derive(Clone, Debug)]
pub struct ProfilePanel {
    /// The unknown.
    pub name: String,
    /// Estimated on a log scale (the axis is logarithmic).
    pub log: bool,
    /// Its value at the optimum.
    pub optimum: f64,
    /// The interval's ends (None: open).
    pub interval: [Option<f64>; 2],
    /// The verdict, in words.
    pub label: String,
    /// (value, ΔNLL, the others' values relative to the optimum's), by value.
    pub points: Vec<(f64, f64, Vec<f64>)>,
}

/// The profiles figure of one problem.
#[derive(Clone, Debug)]
pub struct Profiles {
    /// The title.
    pub title: String,
    /// The threshold of ΔNLL.
    pub threshold: f64,
    /// The names of every unknown (the others' paths are labelled by them).
    pub names: Vec<String>,
    /// One panel per profiled unknown.
    pub panels: Vec<ProfilePanel>,
}

impl Profiles {
    /// The figure of `profiles`, traced around `optimum` (a fit of `problem`) up to
    /// `threshold`.
    pub fn new<S: System>(
        title: String,
        problem: &Problem<S>,
        optimum: &Estimate,
        threshold: f64,
        profiles: &[Profile],
    ) -> Self {
        let names = problem.names();
        let base = sysid_profile::objective(optimum);
        let unknowns = problem.unknowns();
        let at = unknowns.coordinates(&optimum.values);
        let panels = profiles
            .iter()
            .map(|p| {
                let i = names.iter().position(|n| n == &p.name).unwrap_or(0);
                let points = p
                    .points
                    .iter()
                    .map(|q| {
                        // Each other unknown's shift from the optimum in its own coordinate
                        // over that coordinate's scale: ln(θ/θ̂) on a log scale, else
                        // Δθ / max(|θ̂|, |guess|, 1). Signed: a ratio on a log axis lost
                        // every point where an unknown with a negative optimum changed sign.
                        let z = unknowns.coordinates(&q.estimates);
                        let others = (0..names.len())
                            .filter(|&j| j != i)
                            .map(|j| {
                                let u = &unknowns.list()[j];
                                (z[j] - at[j]) / u.coordinate_scale(at[j])
                            })
                            .collect();
                        (q.value, q.nll - base, others)
                    })
                    .collect();
                ProfilePanel {
                    name: p.name.clone(),
                    log: problem.unknowns().list()[i].log,
                    optimum: optimum.values[i],
                    interval: p.interval,
                    label: p.label.words().to_string(),
                    points,
                }
            })
            .collect();
        Self { title, threshold, names: names.to_vec(), panels }
    }
}

/// The most unknowns a profiles figure puts side by side.
const PER_ROW: usize = 6;

impl Figure for Profiles {
    fn size(&self) -> (u32, u32) {
        let (columns, bands) = self.grid();
        (340 * columns as u32, 640 * bands as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 20))?;
        let (columns, bands) = self.grid();
        let areas = root.split_evenly((2 * bands, columns));
        for (j, panel) in self.panels.iter().enumerate() {
            let (band, column) = (j / columns, j % columns);
            let top = &areas[2 * band * columns + column];
            let bottom = &areas[(2 * band + 1) * columns + column];
            let xs = || panel.points.iter().map(|p| p.0);
            let (x0, x1) =
                xs().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
            let y1 = panel.points.iter().map(|p| p.1).fold(self.threshold, f64::max);
            let caption = format!("{}: {}", panel.name, panel.label);
            if panel.log && x0 > 0.0 {
                let (lo, hi) = (x0 / 1.2, x1 * 1.2);
                self.column((top, bottom), panel, caption, ((lo..hi).log_scale(), lo, hi), y1)?;
            } else {
                let (lo, hi) = padded(x0, x1, 0.05);
                self.column((top, bottom), panel, caption, (lo..hi, lo, hi), y1)?;
            }
        }
        Ok(())
    }
}

impl Profiles {
    /// Panels per row, and rows: at most [`PER_ROW`] unknowns side by side, the rest in
    /// further rows (a catalogue system of 23 unknowns is four rows, not one strip).
    fn grid(&self) -> (usize, usize) {
        let n = self.panels.len().max(1);
        (n.min(PER_ROW), n.div_ceil(PER_ROW))
    }

    /// One unknown's column: the profile on `top`, the others' paths on `bottom`, both over
    /// the axis `x` (from `lo` to `hi`, linear or logarithmic), ΔNLL up to `y1`.
    fn column<DB, X>(
        &self,
        (top, bottom): (&DrawingArea<DB, Shift>, &DrawingArea<DB, Shift>),
        panel: &ProfilePanel,
        caption: String,
        (x, lo, hi): (X, f64, f64),
        y1: f64,
    ) -> DrawResult<DB>
    where
        DB: DrawingBackend,
        DB::ErrorType: 'static,
        X: AsRangedCoord<Value = f64> + Clone,
        X::CoordDescType: ValueFormatter<f64>,
    {
        let mut chart = ChartBuilder::on(top)
            .caption(caption, (FONT, 13))
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(44)
            .build_cartesian_2d(x.clone(), -0.05 * y1..1.05 * y1)?;
        chart
            .configure_mesh()
            .y_desc("ΔNLL")
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style((FONT, 11))
            .draw()?;
        draw_profile(&mut chart, panel, self.threshold, (lo, hi), y1)?;
        let mut others = ChartBuilder::on(bottom)
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(44)
            .build_cartesian_2d(x, others_range(panel))?;
        others
            .configure_mesh()
            .x_desc(panel.name.as_str())
            .y_desc("others' shift from the optimum")
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style((FONT, 11))
            .draw()?;
        draw_others(&mut others, panel, &self.names)
    }
}

/// The range of the others' shifts (a linear axis through 0).
fn others_range(panel: &ProfilePanel) -> std::ops::Range<f64> {
    let values = panel.points.iter().flat_map(|p| p.2.iter().copied()).filter(|v| v.is_finite());
    let (lo, hi) = values.fold((0.0f64, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    let (lo, hi) = padded(lo, hi, 0.05);
    lo..hi
}

fn draw_profile<DB, X>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, plotters::coord::types::RangedCoordf64>>,
    panel: &ProfilePanel,
    threshold: f64,
    (lo, hi): (f64, f64),
    top: f64,
) -> DrawResult<DB>
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64>,
{
    let line = panel.points.iter().map(|p| (p.0, p.1));
    chart.draw_series(LineSeries::new(line, BLACK.stroke_width(2)))?;
    chart.draw_series(panel.points.iter().map(|p| Circle::new((p.0, p.1), 2, BLACK.filled())))?;
    let steps = 24;
    let dashes = (0..steps).filter(|k| k % 2 == 0).map(|k| {
        let at = |k: usize| lo * (hi / lo).powf(k as f64 / steps as f64);
        let (a, b) = if lo > 0.0 {
            (at(k), at(k + 1))
        } else {
            let w = (hi - lo) / steps as f64;
            (lo + k as f64 * w, lo + (k + 1) as f64 * w)
        };
        PathElement::new(vec![(a, threshold), (b, threshold)], RGBColor(213, 94, 0).stroke_width(1))
    });
    chart.draw_series(dashes)?;
    for end in panel.interval.iter().flatten() {
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(*end, 0.0), (*end, top)],
            RGBColor(0, 114, 178).stroke_width(1),
        )))?;
    }
    chart.draw_series(std::iter::once(Circle::new((panel.optimum, 0.0), 4, RED.filled())))?;
    Ok(())
}

fn draw_others<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    panel: &ProfilePanel,
    names: &[String],
) -> DrawResult<DB>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let others: Vec<&String> = names.iter().filter(|n| **n != panel.name).collect();
    for (k, name) in others.iter().enumerate() {
        let color = look(k + 1).color;
        let path = panel.points.iter().filter_map(|p| {
            let v = *p.2.get(k)?;
            v.is_finite().then_some((p.0, v))
        });
        chart
            .draw_series(LineSeries::new(path, color.stroke_width(2)))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 14, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 10))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// The profile likelihoods of every unknown around `optimum`, each point re-optimised by
/// `method` with `settings` (`dir/profiles.json`, drawn as `dir/profiles.png|svg`); the
/// figure's caption, or None when a profile found a lower point than the fit (then said in
/// `profiles.json`).
pub(crate) fn write_profiles<S: System + Sync>(
    name: &str,
    problem: &Problem<S>,
    optimum: &Estimate,
    dir: &Path,
    method_name: &str,
    settings: &Settings,
) -> anyhow::Result<Option<String>> {
    let options = ProfileOptions::default();
    let method: sysid_registry::Boxed<S> = Registry::standard().build(method_name, settings)?;
    let profiles = match profile(&*method, problem, optimum, &[], &options)? {
        Traced::Profiles(p) => p,
        Traced::BetterOptimum(point) => {
            write(
                &dir.join("profiles.json"),
                &serde_json::to_string_pretty(&serde_json::json!({
                    "better_optimum_found": point,
                }))?,
            )?;
            return Ok(None);
        }
    };
    let json: serde_json::Map<String, serde_json::Value> =
        profiles.iter().map(|p| (p.name.clone(), serde_json::json!(p.record()))).collect();
    write(&dir.join("profiles.json"), &serde_json::to_string_pretty(&json)?)?;
    let title = format!("{name}: profile likelihoods");
    let figure = Profiles::new(title, problem, optimum, options.threshold, &profiles);
    save(&figure, &dir.join("profiles"))?;
    let verdicts: Vec<String> =
        profiles.iter().map(|p| format!("{} {}", p.name, p.label.words())).collect();
    Ok(Some(format!(
        "Profile likelihoods around the fit ({method_name} re-optimising the others): \
         ΔNLL with the pointwise 95 % threshold 1.92 (dashed) and the interval's ends, \
         and below how the other unknowns compensate: each one's shift from the optimum, \
         ln(θ/θ̂) on a log scale, Δθ/max(|θ̂|, |guess|, 1) otherwise. {}.",
        verdicts.join(", ")
    )))
}
