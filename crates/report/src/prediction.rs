//! Fit and prediction: per measured quantity, the data, the fitted trajectory and its 95 %
//! band from the linearised covariance, continued past the last datum (dotted line).

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::chart::{DrawResult, FONT, Figure, padded, tick};

/// One measured quantity.
#[derive(Clone, Debug)]
pub struct PredictionPanel {
    /// What is measured (state or output name).
    pub name: String,
    /// The data (t, value).
    pub data: Vec<(f64, f64)>,
    /// The fitted trajectory: (t, value, 95 % half-width if known).
    pub curve: Vec<(f64, f64, Option<f64>)>,
}

/// The fit-and-prediction figure of one system.
#[derive(Clone, Debug)]
pub struct Prediction {
    /// The title.
    pub title: String,
    /// Label of the time axis, with its unit.
    pub time_label: String,
    /// The end of the data: the prediction starts here.
    pub data_end: f64,
    /// A logarithmic time axis (for data spaced over decades; every time must be positive).
    pub log_time: bool,
    /// One panel per measured quantity.
    pub panels: Vec<PredictionPanel>,
}

impl Figure for Prediction {
    fn size(&self) -> (u32, u32) {
        (1000, 300 * self.panels.len().max(1) as u32 + 50)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let areas = root.split_evenly((self.panels.len().max(1), 1));
        let fit_color = RGBColor(0, 0, 0);
        let band_color = RGBColor(86, 180, 233);
        // On a log axis the chart's x is log10 t, labelled at whole decades.
        let x = |t: f64| if self.log_time { t.log10() } else { t };
        let x_label = |v: &f64| match self.log_time {
            true if (v - v.round()).abs() < 1e-9 => tick(10f64.powf(v.round())),
            true => String::new(),
            false => tick(*v),
        };
        for (panel, area) in self.panels.iter().zip(&areas) {
            let ts = panel.curve.iter().map(|c| x(c.0)).chain(panel.data.iter().map(|d| x(d.0)));
            let (t_lo, t_hi) =
                ts.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| (a.min(t), b.max(t)));
            let ys = panel
                .curve
                .iter()
                .flat_map(|&(_, y, h)| [y - h.unwrap_or(0.0), y + h.unwrap_or(0.0)])
                .chain(panel.data.iter().map(|d| d.1));
            let (y_lo, y_hi) =
                ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| (a.min(y), b.max(y)));
            let (y_lo, y_hi) = padded(y_lo, y_hi, 0.05);
            // Room above the curves for the legend.
            let y_hi = y_hi + 0.4 * (y_hi - y_lo);
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(38)
                .y_label_area_size(70)
                .build_cartesian_2d(t_lo..t_hi, y_lo..y_hi)?;
            chart
                .configure_mesh()
                .x_desc(&self.time_label)
                .y_desc(&panel.name)
                .x_label_formatter(&x_label)
                .y_label_formatter(&|v| tick(*v))
                .label_style((FONT, 12))
                .axis_desc_style((FONT, 14))
                .light_line_style(WHITE)
                .draw()?;
            // The band as one polygon: upper edge forwards, lower edge back.
            let band: Vec<(f64, f64)> = panel
                .curve
                .iter()
                .filter_map(|&(t, y, h)| h.map(|h| (x(t), y + h)))
                .chain(panel.curve.iter().rev().filter_map(|&(t, y, h)| h.map(|h| (x(t), y - h))))
                .collect();
            if !band.is_empty() {
                chart
                    .draw_series(std::iter::once(Polygon::new(
                        band,
                        band_color.mix(0.45).filled(),
                    )))?
                    .label("95 % band (linearised covariance)")
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 24, y + 5)], band_color.mix(0.45).filled())
                    });
            }
            let fitted: Vec<(f64, f64)> = panel
                .curve
                .iter()
                .filter(|c| c.0 <= self.data_end)
                .map(|&(t, y, _)| (x(t), y))
                .collect();
            let predicted: Vec<(f64, f64)> = panel
                .curve
                .iter()
                .filter(|c| c.0 >= self.data_end)
                .map(|&(t, y, _)| (x(t), y))
                .collect();
            let stroke = ShapeStyle::from(fit_color).stroke_width(2);
            chart
                .draw_series(LineSeries::new(fitted, stroke))?
                .label("fit")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], stroke));
            chart
                .draw_series(DashedLineSeries::new(predicted, 3, 4, stroke))?
                .label("prediction")
                .legend(move |(x, y)| {
                    DashedPathElement::new(vec![(x, y), (x + 24, y)], 3, 4, stroke)
                });
            let dot = RGBColor(213, 94, 0);
            chart
                .draw_series(
                    panel.data.iter().map(|&(t, v)| Circle::new((x(t), v), 2, dot.filled())),
                )?
                .label("data")
                .legend(move |(x, y)| Circle::new((x + 12, y), 3, dot.filled()));
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(x(self.data_end), y_lo), (x(self.data_end), y_hi)],
                BLACK.mix(0.4),
            )))?;
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font((FONT, 13))
                .draw()?;
        }
        Ok(())
    }
}
