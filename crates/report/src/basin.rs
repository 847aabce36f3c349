//! Basins of attraction: a grid of starts for two unknowns (the others at the truth), one
//! panel per method. A start that reaches the reference minimum is blue, darker the more
//! iterations it took; one that converges to another minimum is orange with a cross; one
//! that fails is left white. The truth is marked by a black ring.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::chart::{DrawResult, FONT, Figure, tick};

/// The outcome from one start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cell {
    /// Reached the reference minimum in this many iterations.
    Success(usize),
    /// Converged, to another minimum.
    OtherMinimum,
    /// Did not converge (diverged, iteration limit, singular, integration failure).
    Failure,
}

/// One method's map.
#[derive(Clone, Debug)]
pub struct BasinPanel {
    /// The method.
    pub method: String,
    /// `cells[row][col]`: row j is `y[j]`, column i is `x[i]`.
    pub cells: Vec<Vec<Cell>>,
}

/// The basin figure of one system.
#[derive(Clone, Debug)]
pub struct Basin {
    /// The title.
    pub title: String,
    /// The unknowns on the axes.
    pub axes: [String; 2],
    /// Grid values of the first unknown (columns), increasing.
    pub x: Vec<f64>,
    /// Grid values of the second unknown (rows), increasing.
    pub y: Vec<f64>,
    /// The truth of the two unknowns.
    pub truth: (f64, f64),
    /// One panel per method.
    pub panels: Vec<BasinPanel>,
}

/// Blue from light (1 iteration) to dark (`most` iterations).
fn shade(iterations: usize, most: usize) -> RGBColor {
    let f = if most > 1 { (iterations.max(1) - 1) as f64 / (most - 1) as f64 } else { 0.0 };
    let mix = |light: f64, dark: f64| (light + f * (dark - light)).round() as u8;
    RGBColor(mix(170.0, 8.0), mix(205.0, 48.0), mix(240.0, 107.0))
}

/// Cell edges: midpoints between grid values, extended by half a step at the ends.
fn edges(v: &[f64]) -> Vec<f64> {
    if v.len() == 1 {
        return vec![v[0] - 0.5, v[0] + 0.5];
    }
    let mut e = vec![v[0] - 0.5 * (v[1] - v[0])];
    e.extend(v.windows(2).map(|w| 0.5 * (w[0] + w[1])));
    e.push(v[v.len() - 1] + 0.5 * (v[v.len() - 1] - v[v.len() - 2]));
    e
}

impl Figure for Basin {
    fn size(&self) -> (u32, u32) {
        (400 * self.panels.len().max(1) as u32 + 20, 470)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static,
    {
        let root = root.titled(&self.title, (FONT, 22))?;
        let (body, key) = root.split_vertically(root.dim_in_pixel().1 - 36);
        let panels = body.split_evenly((1, self.panels.len().max(1)));
        let (xe, ye) = (edges(&self.x), edges(&self.y));
        let most = self
            .panels
            .iter()
            .flat_map(|p| p.cells.iter().flatten())
            .filter_map(|c| if let Cell::Success(k) = c { Some(*k) } else { None })
            .max()
            .unwrap_or(1);
        for (panel, area) in self.panels.iter().zip(&panels) {
            let total = panel.cells.iter().map(Vec::len).sum::<usize>().max(1);
            let good =
                panel.cells.iter().flatten().filter(|c| matches!(c, Cell::Success(_))).count();
            let caption =
                format!("{}: {:.0} % of starts", panel.method, 100.0 * good as f64 / total as f64);
            let mut chart = ChartBuilder::on(area)
                .caption(caption, (FONT, 16))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(58)
                .build_cartesian_2d(xe[0]..xe[xe.len() - 1], ye[0]..ye[ye.len() - 1])?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc(format!("start of {}", self.axes[0]))
                .y_desc(format!("start of {}", self.axes[1]))
                .x_label_formatter(&|v| tick(*v))
                .y_label_formatter(&|v| tick(*v))
                .label_style((FONT, 12))
                .axis_desc_style((FONT, 14))
                .draw()?;
            for (j, row) in panel.cells.iter().enumerate() {
                for (i, cell) in row.iter().enumerate() {
                    let corners = [(xe[i], ye[j]), (xe[i + 1], ye[j + 1])];
                    match *cell {
                        Cell::Success(k) => {
                            chart.draw_series(std::iter::once(Rectangle::new(
                                corners,
                                shade(k, most).filled(),
                            )))?;
                        }
                        Cell::OtherMinimum => {
                            let orange = RGBColor(230, 159, 0);
                            chart.draw_series(std::iter::once(Rectangle::new(
                                corners,
                                orange.filled(),
                            )))?;
                            chart.draw_series([
                                PathElement::new(vec![corners[0], corners[1]], BLACK.mix(0.6)),
                                PathElement::new(
                                    vec![(xe[i], ye[j + 1]), (xe[i + 1], ye[j])],
                                    BLACK.mix(0.6),
                                ),
                            ])?;
                        }
                        Cell::Failure => {}
                    }
                }
            }
            chart.draw_series(std::iter::once(Circle::new(
                self.truth,
                6,
                ShapeStyle::from(BLACK).stroke_width(2),
            )))?;
        }
        key.draw(&Text::new(
            format!(
                "blue: reaches the reference minimum (light 1 iteration … dark {most}); \
                 orange ×: converges to another minimum; white: fails; ring: truth"
            ),
            (20, 10),
            (FONT, 14),
        ))?;
        Ok(())
    }
}
