//! Minima: per method, the distinct minima that its multistart fits converged to, as circles
//! at their cost ε (log scale) with an area that grows with the number of starts that reached
//! each; the least cost any method found is the dashed line.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::chart::{DrawResult, FONT, Figure, column_labels, decade, log_range};
use crate::look::look;

/// One method's multistart.
#[derive(Clone, Debug)]
pub struct MethodMinima {
    /// The method.
    pub method: String,
    /// The starts.
    pub starts: usize,
    /// (ε, starts that reached it) of each distinct minimum.
    pub minima: Vec<(f64, usize)>,
}

/// The minima figure of one system.
#[derive(Clone, Debug)]
pub struct Minima {
    /// The title.
    pub title: String,
    /// One column per method.
    pub methods: Vec<MethodMinima>,
}

impl Figure for Minima {
    fn size(&self) -> (u32, u32) {
        (1000, 420)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let m = self.methods.len();
        let name_of = column_labels(self.methods.iter().map(|b| b.method.clone()).collect());
        let costs = || self.methods.iter().flat_map(|b| b.minima.iter().map(|p| p.0));
        let (lo, hi) = log_range(costs());
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "distinct minima of the converged starts (area: starts that reached it)",
                (FONT, 15),
            )
            .margin(12)
            .x_label_area_size(34)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5..m as f64 - 0.5, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * m + 1)
            .x_label_formatter(&name_of)
            .y_label_formatter(&|v| decade(*v))
            .y_desc("cost ε")
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 14))
            .draw()?;
        if let Some(best) = costs().filter(|c| *c > 0.0).reduce(f64::min) {
            let dashes = (0..2 * m).map(|k| {
                let x = -0.5 + k as f64 * 0.5;
                PathElement::new(vec![(x, best), (x + 0.3, best)], BLACK.stroke_width(1))
            });
            chart.draw_series(dashes)?;
        }
        for (i, b) in self.methods.iter().enumerate() {
            let x = i as f64;
            let color = look(i).color;
            for &(cost, count) in b.minima.iter().filter(|p| p.0 > 0.0) {
                let share = count as f64 / b.starts.max(1) as f64;
                let radius = (4.0 + 22.0 * share.sqrt()).round() as i32;
                chart.draw_series([
                    Circle::new((x, cost), radius, color.mix(0.6).filled()),
                    Circle::new((x, cost), radius, BLACK.stroke_width(1)),
                ])?;
                chart.draw_series(std::iter::once(Text::new(
                    format!("{count}"),
                    (x + 0.12, cost),
                    (FONT, 13),
                )))?;
            }
        }
        Ok(())
    }
}
