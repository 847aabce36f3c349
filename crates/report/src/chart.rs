//! What every figure shares: the [`Figure`] trait, [`save`] to PNG and SVG, the embedded font,
//! and the helpers for axes and tick labels.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

/// A figure that can draw itself on any plotters backend.
pub trait Figure {
    /// Size in pixels of the PNG (and of the SVG's view box).
    fn size(&self) -> (u32, u32);

    /// Draws the figure on `root`, which is already filled white.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>
    where
        DB::ErrorType: 'static;
}

/// The result of drawing on backend `DB`.
pub type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A figure that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct ReportError {
    /// The file being written.
    pub path: PathBuf,
    /// What went wrong.
    pub message: String,
}

/// The two files [`save`] writes for `stem`: `<stem>.png` and `<stem>.svg`.
pub fn figure_paths(stem: &Path) -> [PathBuf; 2] {
    // A stem's own dots stay (`seed1.rho0.5` was written as `seed1.rho0.png`, so that a sweep
    // overwrote its figures); a `.png` or `.svg` given is the figure's.
    let given = stem.extension().and_then(|e| e.to_str());
    let base = match given {
        Some(e) if e.eq_ignore_ascii_case("png") || e.eq_ignore_ascii_case("svg") => {
            stem.with_extension("")
        }
        _ => stem.to_path_buf(),
    };
    ["png", "svg"].map(|e| {
        let mut name = base.clone().into_os_string();
        name.push(".");
        name.push(e);
        PathBuf::from(name)
    })
}

/// Writes `figure` to `<stem>.png` and `<stem>.svg` and returns the two paths. A file that
/// cannot be created is reported with the system's reason, before anything is drawn.
pub fn save(figure: &impl Figure, stem: &Path) -> Result<[PathBuf; 2], ReportError> {
    init_fonts();
    let [png, svg] = figure_paths(stem);
    for path in [&png, &svg] {
        std::fs::File::create(path).map_err(|e| ReportError {
            path: path.clone(),
            message: format!("cannot be written: {e}"),
        })?;
    }
    let fail = |path: &Path| {
        let path = path.to_path_buf();
        move |e: String| ReportError { path, message: e }
    };
    {
        let root = BitMapBackend::new(&png, figure.size()).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string()).map_err(fail(&png))?;
        figure.draw(&root).map_err(|e| e.to_string()).map_err(fail(&png))?;
        root.present().map_err(|e| e.to_string()).map_err(fail(&png))?;
    }
    {
        let root = SVGBackend::new(&svg, figure.size()).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string()).map_err(fail(&svg))?;
        figure.draw(&root).map_err(|e| e.to_string()).map_err(fail(&svg))?;
        root.present().map_err(|e| e.to_string()).map_err(fail(&svg))?;
    }
    Ok([png, svg])
}

/// The font family every figure uses.
pub(crate) const FONT: &str = "sans-serif";

/// Registers DejaVu Sans under the family names plotters asks for (once per process).
fn init_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        for family in ["sans-serif", "serif", "monospace"] {
            // The fonts are compiled in and valid; a failure would leave text undrawn, and
            // drawing then reports `FontUnavailable` with the figure's path.
            let _ =
                plotters::style::register_font(family, FontStyle::Normal, dejavu::sans::regular());
            let _ = plotters::style::register_font(family, FontStyle::Bold, dejavu::sans::bold());
        }
    });
}

/// The x-axis labels of a chart with one column per name at x = 0, 1, …: the name at a whole
/// x, nothing between.
pub(crate) fn column_labels(names: Vec<String>) -> impl Fn(&f64) -> String {
    move |v: &f64| {
        let i = v.round();
        if (v - i).abs() < 1e-9 && i >= 0.0 && (i as usize) < names.len() {
            names[i as usize].clone()
        } else {
            String::new()
        }
    }
}

/// `[lo, hi]` widened by `margin` of its width on each side (a width of 0 becomes ±1 or
/// ±10 % of the value), never empty.
pub(crate) fn padded(lo: f64, hi: f64, margin: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let width = hi - lo;
    if width > 0.0 {
        (lo - margin * width, hi + margin * width)
    } else {
        let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        (lo - d, hi + d)
    }
}

/// Decades spanning the positive values of `values` (one decade when there are none), for
/// a log axis.
pub(crate) fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (0.1, 1.0);
    }
    let lo = 10f64.powf(lo.log10().floor());
    let hi = 10f64.powf(hi.log10().ceil());
    let hi = if hi > lo { hi } else { lo * 10.0 };
    // Widened by a hair: plotters puts its first tick at 10^ceil(log10 lo), and 0.1 comes out
    // of powf as 10^−0.99999…, which would lose the bottom decade's ticks.
    (lo * (1.0 - 1e-9), hi * (1.0 + 1e-9))
}

/// A number for a tick label: short, exponent form outside [1e-3, 1e4) with up to four
/// significant digits (so that 1e4 and 1.05e4 stay apart).
pub(crate) fn tick(v: f64) -> String {
    let a = v.abs();
    // Ticks are computed in floating point: a zero comes out as ±1e-17 or so.
    if a < 1e-12 {
        "0".into()
    } else if (1e-3..1e4).contains(&a) {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        let s = format!("{v:.3e}");
        let (mantissa, exponent) = s.split_once('e').expect("exponent form");
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        format!("{mantissa}e{exponent}")
    }
}

/// A label for a log-axis tick: powers of ten only.
pub(crate) fn decade(v: f64) -> String {
    let e = v.log10();
    if (e - e.round()).abs() < 1e-6 { format!("1e{}", e.round() as i32) } else { String::new() }
}

/// A label for a log-axis tick over few decades: 1, 2 and 5 times a power of ten.
pub(crate) fn one_two_five(v: f64) -> String {
    let e = v.log10().floor();
    let mantissa = v / 10f64.powf(e);
    if [1.0, 2.0, 5.0].iter().any(|m| (mantissa - m).abs() < 1e-6) {
        tick(v)
    } else {
        String::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_figures_stem_keeps_its_dots() {
        let paths = |s: &str| figure_paths(Path::new(s)).map(|p| p.display().to_string());
        assert_eq!(paths("wf/seed1.rho0.5"), ["wf/seed1.rho0.5.png", "wf/seed1.rho0.5.svg"]);
        assert_eq!(paths("w"), ["w.png", "w.svg"]);
        assert_eq!(paths("w.png"), ["w.png", "w.svg"]);
        assert_eq!(paths("w.SVG"), ["w.png", "w.svg"]);
    }

    #[test]
    fn ranges_and_ticks() {
        assert_eq!(padded(1.0, 1.0, 0.05), (0.9, 1.1));
        assert_eq!(padded(0.0, 0.0, 0.05), (-1.0, 1.0));
        let close = |(a, b): (f64, f64), (c, d): (f64, f64)| {
            assert!((a / c - 1.0).abs() < 1e-8 && (b / d - 1.0).abs() < 1e-8, "{a} {b}")
        };
        close(log_range([3e-5, 0.2, 0.0, f64::NAN].into_iter()), (1e-5, 1.0));
        close(log_range([1.0].into_iter()), (1.0, 10.0));
        // The first tick plotters computes, 10^ceil(log10 lo), is the bottom decade itself.
        let (lo, _) = log_range([0.6, 1.4].into_iter());
        assert_eq!((lo.ln() / 10f64.ln()).ceil() as i32, -1);
        assert_eq!(tick(0.25), "0.25");
        assert_eq!(tick(32.5), "32.5");
        assert_eq!(tick(3e7), "3e7");
        assert_eq!(tick(2.5e7), "2.5e7");
        assert_eq!(tick(1.05e4), "1.05e4");
        assert_eq!(tick(-1.2345e-5), "-1.234e-5");
        assert_eq!(decade(1e-3), "1e-3");
        assert_eq!(decade(2e-3), "");
        assert_eq!(tick(-6e-17), "0");
        assert_eq!(one_two_five(20.0), "20");
        assert_eq!(one_two_five(0.5), "0.5");
        assert_eq!(one_two_five(3.0), "");
    }
}
