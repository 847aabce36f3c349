//! The waterfall plot of a multistart: every start's final objective, sorted, least first
//! (pyPESTO's and Data2Dynamics' picture of how often a multistart finds its best). The
//! y axis is objective − best + 1 on a log scale, so the best is at 1 and a start within the
//! field's 0.1 of it below the dashed line at 1.1; a filled point converged, a hollow one did
//! not. A start that could not begin is left out.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::chart::{DrawResult, FONT, Figure, decade, log_range};
use crate::look::look;

/// A multistart's waterfall.
#[derive(Clone, Debug)]
pub struct Waterfall {
    /// The title.
    pub title: String,
    /// (objective, converged) of every start that began, in any order.
    pub starts: Vec<(f64, bool)>,
}

impl Waterfall {
    /// The waterfall of `count` starts of `method` on `subject`, from the (objective,
    /// converged) of those that have one: the title says how many are not drawn (a start that
    /// could not begin, or whose objective is not finite), where the count alone said "3
    /// starts" over one point.
    pub fn of_starts(subject: &str, count: usize, method: &str, starts: Vec<(f64, bool)>) -> Self {
        let drawn = starts.iter().filter(|s| s.0.is_finite()).count();
        let missing = match count.saturating_sub(drawn) {
            0 => String::new(),
            n => format!(" ({n} without a finite objective, not drawn)"),
        };
        Self { title: format!("{subject}: {count} starts of {method}{missing}"), starts }
    }

    /// The points: (rank from 1, objective − best + 1, converged), least objective first.
    fn points(&self) -> Vec<(f64, f64, bool)> {
        let mut finite: Vec<(f64, bool)> =
            self.starts.iter().copied().filter(|s| s.0.is_finite()).collect();
        finite.sort_by(|a, b| a.0.total_cmp(&b.0));
        let best = finite.first().map_or(0.0, |s| s.0);
        finite.iter().enumerate().map(|(i, &(v, c))| ((i + 1) as f64, v - best + 1.0, c)).collect()
    }
}

impl Figure for Waterfall {
    fn size(&self) -> (u32, u32) {
        (900, 480)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let points = self.points();
        let n = points.len().max(1) as f64;
        let (lo, hi) = log_range(points.iter().map(|p| p.1).chain([1.0, 1.1]));
        let mut caption = "final objective of every start, sorted (filled: converged; dashed: within 0.1 of the best)".to_string();
        let left_out = self.starts.len() - points.len();
        if left_out > 0 {
            caption += &format!("; {left_out} that could not begin, not drawn");
        }
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, (FONT, 15))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.5..n + 0.5, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("start, sorted by final objective")
            .x_labels(points.len().clamp(1, 12))
            .x_label_formatter(&rank_label)
            .y_desc("objective − best + 1")
            .y_label_formatter(&|v| decade(*v))
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 14))
            .draw()?;
        // Dashed, as the caption says (it was drawn solid).
        chart.draw_series(DashedLineSeries::new(
            [(0.5, 1.1), (n + 0.5, 1.1)],
            6,
            4,
            BLACK.stroke_width(1),
        ))?;
        let color = look(0).color;
        chart.draw_series(LineSeries::new(points.iter().map(|p| (p.0, p.1)), color.mix(0.5)))?;
        for &(x, y, converged) in &points {
            let style = if converged { color.filled() } else { color.stroke_width(2) };
            chart.draw_series(std::iter::once(Circle::new((x, y), 4, style)))?;
        }
        Ok(())
    }
}

/// A tick of the rank axis: the rank where the tick is on one, nothing between (with a few
/// starts the ticks fell at halves, printed rounded: `1 1 1 1 1 2 2 2 2 2`).
fn rank_label(v: &f64) -> String {
    match (v - v.round()).abs() < 1e-9 && *v >= 1.0 {
        true => format!("{v:.0}"),
        false => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rank_axis_is_labelled_at_whole_ranks_only() {
        let labels: Vec<String> = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0].iter().map(rank_label).collect();
        assert_eq!(labels, ["", "1", "", "2", "", "3"]);
    }

    #[test]
    fn the_best_is_at_one_and_the_rest_follow_in_order() {
        let w = Waterfall {
            title: String::new(),
            starts: vec![(5.0, false), (f64::NAN, false), (2.0, true), (2.05, true)],
        };
        let p = w.points();
        assert_eq!(p.len(), 3, "a start that could not begin is left out");
        assert_eq!(p[0], (1.0, 1.0, true));
        assert!((p[1].1 - 1.05).abs() < 1e-12 && p[1].2);
        assert_eq!(p[2], (3.0, 4.0, false));
    }

    #[test]
    fn the_title_says_how_many_starts_are_not_drawn() {
        let all = Waterfall::of_starts("m", 2, "nl2sol", vec![(1.0, true), (2.0, false)]);
        assert_eq!(all.title, "m: 2 starts of nl2sol");
        // Three starts, one with an objective that is not finite and one without any.
        let some =
            Waterfall::of_starts("m", 3, "nl2sol", vec![(1.0, true), (f64::INFINITY, false)]);
        assert_eq!(some.title, "m: 3 starts of nl2sol (2 without a finite objective, not drawn)");
        assert_eq!(some.points().len(), 1);
    }
}
