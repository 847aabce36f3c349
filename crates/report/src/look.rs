//! How each method looks: a colour of the Okabe–Ito palette (the first three chosen to differ in
//! lightness too), a dash pattern and a marker, so lines stay apart in grey print.

use plotters::coord::CoordTranslate;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::chart::DrawResult;

/// The marker of a method's points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Marker {
    /// A filled circle.
    Circle,
    /// A filled triangle.
    Triangle,
    /// A cross.
    Cross,
}

/// Colour, dash pattern and marker of one method.
#[derive(Clone, Copy, Debug)]
pub struct Look {
    /// Line and fill colour.
    pub color: RGBColor,
    /// Dash length and gap in pixels; `None` for a solid line.
    pub dash: Option<(u32, u32)>,
    /// Marker of points.
    pub marker: Marker,
}

/// The look of the method at position `index` of a figure (cycling after four).
pub fn look(index: usize) -> Look {
    const LOOKS: [Look; 8] = [
        // Black, solid, circles.
        Look { color: RGBColor(0, 0, 0), dash: None, marker: Marker::Circle },
        // Vermillion, dashed, triangles.
        Look { color: RGBColor(213, 94, 0), dash: Some((9, 5)), marker: Marker::Triangle },
        // Sky blue, dotted, crosses.
        Look { color: RGBColor(86, 180, 233), dash: Some((3, 4)), marker: Marker::Cross },
        // Bluish green, long dashes.
        Look { color: RGBColor(0, 158, 115), dash: Some((16, 6)), marker: Marker::Circle },
        // Reddish purple, dash-gap, triangles.
        Look { color: RGBColor(204, 121, 167), dash: Some((6, 3)), marker: Marker::Triangle },
        // Blue, solid, crosses.
        Look { color: RGBColor(0, 114, 178), dash: None, marker: Marker::Cross },
        // Orange, long dashes, triangles.
        Look { color: RGBColor(230, 159, 0), dash: Some((16, 6)), marker: Marker::Triangle },
        // Yellow, dotted, circles.
        Look { color: RGBColor(240, 228, 66), dash: Some((3, 4)), marker: Marker::Circle },
    ];
    LOOKS[index % LOOKS.len()]
}

impl Look {
    /// The line style (2 px).
    pub fn stroke(&self) -> ShapeStyle {
        ShapeStyle::from(self.color).stroke_width(2)
    }
}

/// Draws `points` as a line with markers in `look`, with a legend entry `label`.
pub(crate) fn line<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    points: &[(f64, f64)],
    look: Look,
    label: &str,
) -> DrawResult<DB>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate<From = (f64, f64)>,
{
    let stroke = look.stroke();
    let series = match look.dash {
        None => chart.draw_series(LineSeries::new(points.iter().copied(), stroke))?,
        Some((dash, gap)) => {
            chart.draw_series(DashedLineSeries::new(points.iter().copied(), dash, gap, stroke))?
        }
    };
    let series = series.label(label);
    // A short stretch of the line with the marker on it; the composed element's types
    // differ per marker, hence one arm each.
    // A dash longer than the stretch draws a solid line.
    let (dash, gap) = look.dash.unwrap_or((30, 1));
    let path = move || DashedPathElement::new(vec![(0, 0), (24, 0)], dash, gap, stroke);
    match look.marker {
        Marker::Circle => series.legend(move |(x, y)| {
            EmptyElement::at((x, y)) + Circle::new((12, 0), 4, stroke.filled()) + path()
        }),
        Marker::Triangle => series.legend(move |(x, y)| {
            EmptyElement::at((x, y)) + TriangleMarker::new((12, 0), 5, stroke.filled()) + path()
        }),
        Marker::Cross => series.legend(move |(x, y)| {
            EmptyElement::at((x, y)) + Cross::new((12, 0), 4, stroke) + path()
        }),
    };
    let fill = ShapeStyle::from(look.color).filled();
    match look.marker {
        Marker::Circle => chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, fill)))?,
        Marker::Triangle => {
            chart.draw_series(points.iter().map(|&p| TriangleMarker::new(p, 4, fill)))?
        }
        Marker::Cross => chart.draw_series(points.iter().map(|&p| Cross::new(p, 3, stroke)))?,
    };
    Ok(())
}
