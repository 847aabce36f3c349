//! Convergence from one start: the cost against the iteration (log scale), one line per
//! method, and beside it the norm of each step.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::chart::{DrawResult, FONT, Figure, decade, log_range};
use crate::look::{line, look};

/// One method's iteration history.
#[derive(Clone, Debug)]
pub struct History {
    /// The method.
    pub method: String,
    /// (iteration, ε) of each iterate, the start at iteration 0.
    pub costs: Vec<(usize, f64)>,
    /// (iteration, ‖Δz‖) of each step taken.
    pub steps: Vec<(usize, f64)>,
}

/// The convergence figure of one system.
#[derive(Clone, Debug)]
pub struct Convergence {
    /// The title (system and start).
    pub title: String,
    /// One history per method.
    pub methods: Vec<History>,
}

/// Values this small are drawn on the bottom edge of a log axis rather than dropped.
const FLOOR: f64 = 1e-30;

impl Figure for Convergence {
    fn size(&self) -> (u32, u32) {
        (1100, 440)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let panels = root.split_evenly((1, 2));
        let last = self
            .methods
            .iter()
            .flat_map(|m| m.costs.iter().chain(&m.steps).map(|p| p.0))
            .max()
            .unwrap_or(1)
            .max(1);
        let draw_panel = |area: &DrawingArea<DB, Shift>,
                          caption: &str,
                          y_desc: &str,
                          pick: &dyn Fn(&History) -> &[(usize, f64)]|
         -> DrawResult<DB> {
            let (lo, hi) = log_range(self.methods.iter().flat_map(|m| pick(m).iter().map(|p| p.1)));
            let lo = lo.max(FLOOR);
            let mut chart = ChartBuilder::on(area)
                .caption(caption, (FONT, 17))
                .margin(12)
                .x_label_area_size(42)
                .y_label_area_size(64)
                .build_cartesian_2d(-0.2..last as f64 + 0.2, (lo..hi).log_scale())?;
            chart
                .configure_mesh()
                .x_desc("iteration")
                .y_desc(y_desc)
                .x_label_formatter(&|v| {
                    if (v - v.round()).abs() < 1e-9 {
                        format!("{}", v.round())
                    } else {
                        String::new()
                    }
                })
                .y_label_formatter(&|v| decade(*v))
                .label_style((FONT, 13))
                .axis_desc_style((FONT, 15))
                .draw()?;
            for (i, m) in self.methods.iter().enumerate() {
                let points: Vec<(f64, f64)> =
                    pick(m).iter().map(|&(k, v)| (k as f64, v.max(lo))).collect();
                line(&mut chart, &points, look(i), &m.method)?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font((FONT, 14))
                .draw()?;
            Ok(())
        };
        draw_panel(&panels[0], "cost", "ε = Σ w r² (weighted, dimensionless)", &|m| &m.costs)?;
        draw_panel(&panels[1], "step", "‖Δz‖ (step in the unknowns)", &|m| &m.steps)?;
        Ok(())
    }
}
