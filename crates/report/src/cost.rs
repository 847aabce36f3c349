//! Cost: per method, the median time per fit as a bar with the 90th percentile marked, and
//! the success rate as a bar with its Wilson 95 % interval.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::chart::{DrawResult, FONT, Figure, column_labels, log_range, one_two_five};
use crate::look::look;

/// One method's cost.
#[derive(Clone, Debug)]
pub struct CostBar {
    /// The method.
    pub method: String,
    /// Median time per fit, ms.
    pub median_ms: f64,
    /// 90th percentile of the time per fit, ms.
    pub p90_ms: f64,
    /// Successful trials / trials.
    pub success: f64,
    /// Wilson 95 % interval of the success rate.
    pub interval: [f64; 2],
}

/// The cost figure of one study.
#[derive(Clone, Debug)]
pub struct Cost {
    /// The title.
    pub title: String,
    /// One bar per method.
    pub methods: Vec<CostBar>,
}

impl Figure for Cost {
    fn size(&self) -> (u32, u32) {
        (1000, 400)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let panels = root.split_evenly((1, 2));
        let m = self.methods.len();
        let name_of = column_labels(self.methods.iter().map(|b| b.method.clone()).collect());
        let (lo, hi) = log_range(self.methods.iter().flat_map(|b| [b.median_ms, b.p90_ms]));
        let mut time = ChartBuilder::on(&panels[0])
            .caption("time per fit (bar: median, tick: 90th percentile)", (FONT, 15))
            .margin(12)
            .x_label_area_size(34)
            .y_label_area_size(64)
            .build_cartesian_2d(-0.5..m as f64 - 0.5, (lo..hi).log_scale())?;
        time.configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * m + 1)
            .x_label_formatter(&name_of)
            .y_labels(30)
            .y_label_formatter(&|v| one_two_five(*v))
            .light_line_style(TRANSPARENT)
            .y_desc("ms per fit")
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 14))
            .draw()?;
        for (i, b) in self.methods.iter().enumerate() {
            let x = i as f64;
            let color = look(i).color;
            time.draw_series(std::iter::once(Rectangle::new(
                [(x - 0.3, lo), (x + 0.3, b.median_ms.max(lo))],
                color.mix(0.8).filled(),
            )))?;
            time.draw_series(std::iter::once(Rectangle::new(
                [(x - 0.3, lo), (x + 0.3, b.median_ms.max(lo))],
                BLACK.stroke_width(1),
            )))?;
            let stroke = ShapeStyle::from(BLACK).stroke_width(3);
            time.draw_series([
                PathElement::new(vec![(x, b.median_ms.max(lo)), (x, b.p90_ms.max(lo))], BLACK),
                PathElement::new(vec![(x - 0.15, b.p90_ms), (x + 0.15, b.p90_ms)], stroke),
            ])?;
        }
        let mut rate = ChartBuilder::on(&panels[1])
            .caption("success rate (whisker: Wilson 95 % interval)", (FONT, 15))
            .margin(12)
            .x_label_area_size(34)
            .y_label_area_size(54)
            .build_cartesian_2d(-0.5..m as f64 - 0.5, 0.0..105.0)?;
        rate.configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * m + 1)
            .x_label_formatter(&name_of)
            .y_labels(11)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .light_line_style(TRANSPARENT)
            .y_desc("successful trials, %")
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 14))
            .draw()?;
        for (i, b) in self.methods.iter().enumerate() {
            let x = i as f64;
            let color = look(i).color;
            let corners = [(x - 0.3, 0.0), (x + 0.3, 100.0 * b.success)];
            rate.draw_series(std::iter::once(Rectangle::new(corners, color.mix(0.8).filled())))?;
            rate.draw_series(std::iter::once(Rectangle::new(corners, BLACK.stroke_width(1))))?;
            let [a, c] = b.interval.map(|v| 100.0 * v);
            rate.draw_series([
                PathElement::new(vec![(x, a), (x, c)], BLACK.stroke_width(2)),
                PathElement::new(vec![(x - 0.1, a), (x + 0.1, a)], BLACK.stroke_width(2)),
                PathElement::new(vec![(x - 0.1, c), (x + 0.1, c)], BLACK.stroke_width(2)),
            ])?;
        }
        Ok(())
    }
}
