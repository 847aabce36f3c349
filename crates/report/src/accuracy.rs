//! Accuracy over a Monte-Carlo study: per unknown, the estimates of the successful trials
//! of each method as a box (quartiles, whiskers at 2.5 % and 97.5 %) over the points
//! themselves, the truth as a dashed line and the Cramér–Rao band truth ± σ_CRB shaded.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::chart::{DrawResult, FONT, Figure, padded, tick};
use crate::look::look;

/// The estimates of one unknown.
#[derive(Clone, Debug)]
pub struct Spread {
    /// The unknown.
    pub name: String,
    /// Its true value.
    pub truth: f64,
    /// The Cramér–Rao standard deviation at the truth.
    pub crb_sd: Option<f64>,
    /// The estimates of each method over its successful trials (in the order of
    /// [`Accuracy::methods`]).
    pub estimates: Vec<Vec<f64>>,
}

/// The accuracy figure of one study.
#[derive(Clone, Debug)]
pub struct Accuracy {
    /// The title.
    pub title: String,
    /// The methods, in the order of [`Spread::estimates`].
    pub methods: Vec<String>,
    /// One panel per unknown.
    pub unknowns: Vec<Spread>,
}

/// The q-quantile of sorted values (linear interpolation).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let x = q * (sorted.len() - 1) as f64;
    let (i, f) = (x.floor() as usize, x - x.floor());
    if i + 1 < sorted.len() { sorted[i] + f * (sorted[i + 1] - sorted[i]) } else { sorted[i] }
}

/// A jitter in [−1, 1] that depends only on the point's index (the figure is reproducible).
fn jitter(k: usize) -> f64 {
    // The golden-ratio sequence fills the interval evenly.
    2.0 * ((k as f64 * 0.618_033_988_749_895) % 1.0) - 1.0
}

impl Figure for Accuracy {
    fn size(&self) -> (u32, u32) {
        let cols = self.unknowns.len().clamp(1, 3) as u32;
        let rows = self.unknowns.len().div_ceil(3).max(1) as u32;
        (380 * cols + 40, 360 * rows + 50)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let cols = self.unknowns.len().clamp(1, 3);
        let rows = self.unknowns.len().div_ceil(3).max(1);
        let panels = root.split_evenly((rows, cols));
        let m = self.methods.len();
        for (spread, area) in self.unknowns.iter().zip(&panels) {
            let crb = spread.crb_sd.unwrap_or(0.0);
            let all = spread.estimates.iter().flatten().copied();
            let (lo, hi) = all
                .chain([spread.truth - 2.0 * crb, spread.truth + 2.0 * crb])
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
            let (lo, hi) = padded(lo, hi, 0.06);
            let caption = match spread.crb_sd {
                Some(sd) => {
                    format!("{} (truth {}, σ_CRB {})", spread.name, tick(spread.truth), tick(sd))
                }
                None => format!("{} (truth {})", spread.name, tick(spread.truth)),
            };
            let mut chart = ChartBuilder::on(area)
                .caption(caption, (FONT, 16))
                .margin(10)
                .x_label_area_size(34)
                .y_label_area_size(70)
                .build_cartesian_2d(-0.5..m as f64 - 0.5, lo..hi)?;
            let names = self.methods.clone();
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(2 * m + 1)
                .x_label_formatter(&|v| {
                    let i = v.round();
                    if (v - i).abs() < 1e-9 && i >= 0.0 && (i as usize) < names.len() {
                        names[i as usize].clone()
                    } else {
                        String::new()
                    }
                })
                .y_label_formatter(&|v| tick(*v))
                .light_line_style(TRANSPARENT)
                .y_desc(format!("estimate of {}", spread.name))
                .label_style((FONT, 12))
                .axis_desc_style((FONT, 14))
                .draw()?;
            if crb > 0.0 {
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(-0.5, spread.truth - crb), (m as f64 - 0.5, spread.truth + crb)],
                    RGBColor(200, 200, 200).mix(0.6).filled(),
                )))?;
            }
            chart.draw_series(DashedLineSeries::new(
                [(-0.5, spread.truth), (m as f64 - 0.5, spread.truth)],
                8,
                5,
                BLACK.stroke_width(1),
            ))?;
            for (i, estimates) in spread.estimates.iter().enumerate() {
                if estimates.is_empty() {
                    continue;
                }
                let look = look(i);
                let x = i as f64;
                let mut sorted = estimates.clone();
                sorted.sort_by(f64::total_cmp);
                let points = estimates.iter().enumerate().map(|(k, &v)| {
                    Circle::new((x + 0.28 * jitter(k), v), 2, look.color.mix(0.35).filled())
                });
                chart.draw_series(points)?;
                let q = |p| quantile(&sorted, p);
                let stroke = ShapeStyle::from(BLACK).stroke_width(2);
                chart.draw_series([
                    PathElement::new(vec![(x, q(0.025)), (x, q(0.25))], stroke),
                    PathElement::new(vec![(x, q(0.75)), (x, q(0.975))], stroke),
                    PathElement::new(vec![(x - 0.2, q(0.5)), (x + 0.2, q(0.5))], stroke),
                ])?;
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(x - 0.2, q(0.25)), (x + 0.2, q(0.75))],
                    stroke,
                )))?;
            }
        }
        Ok(())
    }
}
