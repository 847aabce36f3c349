//! The sysid comparison report: the engine that runs the catalogue through the registry's
//! methods and writes it ([`write_report`]: fits from the default start, Monte-Carlo studies,
//! basin maps, predictions, the benchmark section from criterion's results, and the
//! README.md whose every sentence comes from the numbers next to it), and its figures, drawn
//! with plotters into PNG and SVG.
//!
//! Each figure is a plain data structure ([`Convergence`], [`Accuracy`], [`Basin`],
//! [`Prediction`], [`Cost`]) that knows how to draw itself on any plotters backend;
//! [`save`] writes it as `<stem>.png` and `<stem>.svg`. Nothing here runs a method: the
//! caller fills the structures from fits and studies, so the figures can be redrawn from the
//! data files the report writes next to them.
//!
//! Fonts: DejaVu Sans, compiled into the binary (the `dejavu` crate) and rendered by
//! `ab_glyph`; no system font library is used. Colours come from the Okabe–Ito palette and
//! each method also has its own dash pattern and marker, so the figures stay readable in grey
//! print.

//!
//! The crate's rooms: `chart` (what every figure shares) under the figures (`accuracy`,
//! `basin`, `convergence`, `cost`, `minima`, `prediction`, with `look` for their colours and
//! markers); `run` runs the catalogue and hands each system's numbers to `markdown`, which
//! writes the README (with `bench` for the benchmark section); `manifest` keeps the files a
//! report owns in its directory; `options` says what a report covers; `scaling` measures and
//! draws how the cost of one NLL + gradient grows over a collection of PEtab problems
//! ([`write_scaling`], its own directory).

mod accuracy;
mod basin;
mod bench;
mod chart;
mod convergence;
mod cost;
mod look;
mod manifest;
mod markdown;
mod minima;
mod options;
mod petab;
mod prediction;
mod profiles;
mod run;
mod scaling;
mod waterfall;

pub use accuracy::{Accuracy, Spread};
pub use basin::{Basin, BasinPanel, Cell};
pub use chart::{DrawResult, Figure, ReportError, figure_paths, save};
pub use convergence::{Convergence, History};
pub use cost::{Cost, CostBar};
pub use look::{Look, look};
pub use minima::{MethodMinima, Minima};
pub use options::{CATALOGUE_ITERATIONS, Observer, PETAB_START_SECONDS, Quiet, ReportOptions};
pub use prediction::{Prediction, PredictionPanel};
pub use profiles::{ProfilePanel, Profiles};
pub use run::write_report;
pub use scaling::{Measured, Scaling, ScalingOptions, power_law, write_scaling};
pub use waterfall::Waterfall;
