//! The measurements resolved against the system and checked: which state or output each
//! series measures, on what scale, with what noise, on one sorted time grid; a continuous
//! record also as residual rows at the nodes of a composite Gauss–Legendre rule.
//!
//! This module is for the crates that work on a built problem's layout: methods that form
//! residual rows themselves (quasilinearization, multiple shooting) and importers (model
//! files, PEtab). It also holds the traits behind [`Noise::Function`]
//! and [`Setting::Function`](crate::Setting::Function), for σ or a setting that is a function
//! of the unknowns. A user who builds a [`Problem`](crate::Problem) from numbers and names
//! needs none of it.

use std::sync::Arc;

use sysid_ode::{Interpolation, Observable, Record, RecordedOutput, Signal, System};

use crate::data::{Data, Record as Kind, Samples, Series};
use crate::error::ProblemError;
use crate::noise::{Noise, NoiseDistribution, Transform};

pub use crate::experiment::{Planned, SettingFunction, SlotJacobian};
pub use crate::noise::{
    LN_2PI, NOISE_ROW_SHIFT, NoiseArgs, NoiseFunction, NoiseGradient, least_sigma,
};
pub use crate::problem::{QUADRATURE_RTOL, SINGLE_EXPERIMENT};

/// The measurements resolved against the system.
#[derive(Clone, Debug)]
pub(crate) enum Plan {
    Discrete(Sampled),
    Continuous {
        span: (f64, f64),
        outputs: Vec<RecordedOutput>,
        /// The record discretised for least-squares solvers that need a residual vector.
        nodes: Sampled,
    },
}

/// The data in residual form: measured values at discrete times, each with the square root
/// of its weight. Discrete data as given (weight w_o); a continuous record at the nodes of a
/// composite Gauss–Legendre rule (weight w_o times the node's weight), so that
/// Σ (√w (h − b))² is the quadrature of ε.
#[derive(Clone, Debug)]
pub struct Sampled {
    /// All times, sorted, without repeats.
    pub times: Vec<f64>,
    /// One entry per measured quantity.
    pub series: Vec<PlannedSeries>,
}

/// The samples of one measured quantity in residual form.
#[derive(Clone, Debug)]
pub struct PlannedSeries {
    /// What is measured.
    pub observable: Observable,
    /// The scale its residuals are formed on.
    pub transform: Transform,
    /// Its noise's distribution.
    pub distribution: NoiseDistribution,
    /// Its noise.
    pub noise: PlannedNoise,
    /// Its samples.
    pub samples: Vec<Sample>,
}

impl PlannedSeries {
    /// The name of what it measures.
    pub fn name<'a>(&self, signature: &'a sysid_ode::Signature) -> &'a str {
        match self.observable {
            Observable::State(i) => &signature.states()[i],
            Observable::Output(i) => &signature.outputs()[i],
        }
    }

    pub(crate) fn observable_name<S: System>(&self, system: &S) -> String {
        self.name(system.signature()).to_string()
    }
}

/// The noise of a series, resolved against the problem's unknowns.
#[derive(Clone)]
pub enum PlannedNoise {
    /// Relative weights (no noise model): √w of each sample is √(w_o w_m).
    Weights,
    /// σ known: √w = 1/σ.
    Known,
    /// σ_m = s·f_m with s the unknown of declared index `unknown`, eliminated in closed form:
    /// √w = 1/(s f_m) at the current s.
    Scale {
        /// The declared index of s.
        unknown: usize,
        /// f_m, one per sample.
        factors: Vec<f64>,
    },
    /// σ a function of the model and the unknowns, evaluated with each residual.
    Function(Arc<dyn NoiseFunction>),
}

impl std::fmt::Debug for PlannedNoise {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlannedNoise::Weights => write!(f, "Weights"),
            PlannedNoise::Known => write!(f, "Known"),
            PlannedNoise::Scale { unknown, .. } => write!(f, "Scale(unknown {unknown})"),
            PlannedNoise::Function(n) => write!(f, "Function({})", n.describe()),
        }
    }
}

/// One measured value: row √w (T(h(t)) − T(b)) of the residual vector.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    /// Index into [`Sampled::times`].
    pub index: usize,
    /// The measured value on the series' scale, T(b).
    pub value: f64,
    /// The measured value b itself.
    pub measured: f64,
    /// √w = 1/σ (unused for a noise function).
    pub sqrt_weight: f64,
}

impl Plan {
    /// The data in residual form.
    pub(crate) fn sampled(&self) -> &Sampled {
        match self {
            Plan::Discrete(sampled) => sampled,
            Plan::Continuous { nodes, .. } => nodes,
        }
    }

    /// The span of the data (the record's span for continuous data).
    pub(crate) fn span(&self) -> (f64, f64) {
        match self {
            Plan::Discrete(s) => (s.times[0], s.times[s.times.len() - 1]),
            Plan::Continuous { span, .. } => *span,
        }
    }
}

/// Panels per record span of a record given as a function, in its residual form.
pub(crate) const RESIDUAL_PANELS: usize = 256;

// Gauss–Legendre, 4 points on [−1, 1].
const GL4: [(f64, f64); 4] = [
    (-0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
    (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
];

/// Resolves and checks the measurements; `unknown` gives the declared index of an unknown by
/// name (for noise scales).
pub(crate) fn plan<S: System>(
    system: &S,
    data: &Data,
    unknown: &dyn Fn(&str) -> Option<usize>,
) -> Result<Plan, ProblemError> {
    if data.series.is_empty() {
        return Err(ProblemError::NoData);
    }
    let mut seen = std::collections::HashSet::new();
    let mut resolved = Vec::with_capacity(data.series.len());
    for s in &data.series {
        if !seen.insert(&s.name) {
            return Err(ProblemError::InvalidSeries {
                name: s.name.clone(),
                message: "given twice".into(),
            });
        }
        resolved.push(resolve(system, data, s)?);
    }
    match data.record {
        Kind::Discrete => plan_discrete(data, &resolved, unknown),
        Kind::Continuous { t_lo, t_hi } => plan_continuous(data, &resolved, (t_lo, t_hi)),
    }
}

/// The state or output series `s` measures, after checking its weights and samples.
fn resolve<S: System>(system: &S, data: &Data, s: &Series) -> Result<Observable, ProblemError> {
    let sig = system.signature();
    let invalid = |message: String| ProblemError::InvalidSeries { name: s.name.clone(), message };
    let observable = sig.observable(&s.name).ok_or_else(|| ProblemError::UnknownSeries {
        name: s.name.clone(),
        observable: sig
            .states()
            .iter()
            .chain(sig.outputs())
            .cloned()
            .collect::<Vec<_>>()
            .join(", "),
    })?;
    if !(s.weight > 0.0 && s.weight.is_finite()) {
        return Err(invalid(format!("the weight must be positive and finite, got {}", s.weight)));
    }
    if let Samples::Points { times, values } = &s.samples {
        if times.len() != values.len() {
            return Err(invalid(format!("{} times but {} values", times.len(), values.len())));
        }
        if times.is_empty() {
            return Err(invalid("no samples".into()));
        }
        if let Some(i) = times.iter().position(|t| !t.is_finite()) {
            return Err(invalid(format!("time {i} is {}", times[i])));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(invalid(format!("value at t = {} is {}", times[i], values[i])));
        }
        // Discrete samples may repeat a time (replicates); a record's points may not.
        let back = |w: &[f64]| match data.record {
            Kind::Discrete => w[1] < w[0],
            _ => w[1] <= w[0],
        };
        if let Some(i) = times.windows(2).position(back) {
            let what = match data.record {
                Kind::Discrete => "times must not decrease",
                _ => "times must increase",
            };
            return Err(invalid(format!("{what}: {} follows {}", times[i + 1], times[i])));
        }
    }
    if let Some(weights) = &s.sample_weights {
        let count = match &s.samples {
            Samples::Points { values, .. } => values.len(),
            Samples::Function(_) => 0,
        };
        if weights.len() != count {
            return Err(invalid(format!("{} sample weights for {count} samples", weights.len())));
        }
        if let Some(i) = weights.iter().position(|w| !(*w > 0.0 && w.is_finite())) {
            return Err(invalid(format!(
                "sample weight {i} must be positive and finite, got {}",
                weights[i]
            )));
        }
        if data.record != Kind::Discrete {
            return Err(invalid("per-sample weights need discrete data".into()));
        }
    }
    if (s.noise.is_some() || s.transform != Transform::Lin) && data.record != Kind::Discrete {
        return Err(invalid("a noise model or a log scale needs discrete data".into()));
    }
    if s.distribution == NoiseDistribution::Laplace {
        match &s.noise {
            None => {
                return Err(invalid(
                    "laplace noise needs a noise model: its σ, the Laplace scale b".into(),
                ));
            }
            Some(Noise::Scale { .. }) => {
                return Err(invalid(
                    "laplace noise with a σ scale set in closed form (the normal one's) is not supported"
                        .into(),
                ));
            }
            _ => {}
        }
    }
    if let Samples::Points { times, values } = &s.samples {
        if s.transform != Transform::Lin
            && let Some(i) = values.iter().position(|v| *v <= 0.0)
        {
            return Err(invalid(format!(
                "the {} scale needs positive measurements: {} at t = {}",
                s.transform.name(),
                values[i],
                times[i]
            )));
        }
        let per_sample = |what: &str, list: &[f64]| {
            if list.len() != values.len() {
                return Err(invalid(format!("{} {what} for {} samples", list.len(), values.len())));
            }
            match list.iter().position(|v| !(*v > 0.0 && v.is_finite())) {
                Some(i) => Err(invalid(format!(
                    "{what} at t = {} must be positive and finite, got {}",
                    times[i], list[i]
                ))),
                None => Ok(()),
            }
        };
        match &s.noise {
            Some(Noise::Known(sigma)) => per_sample("σ", sigma)?,
            Some(Noise::Scale { factors, .. }) => per_sample("σ factors", factors)?,
            _ => {}
        }
    }
    Ok(observable)
}

/// Discrete data: one residual row per sample.
fn plan_discrete(
    data: &Data,
    resolved: &[Observable],
    unknown: &dyn Fn(&str) -> Option<usize>,
) -> Result<Plan, ProblemError> {
    let mut points = Vec::with_capacity(data.series.len());
    let mut noises = Vec::with_capacity(data.series.len());
    for s in &data.series {
        match &s.samples {
            Samples::Points { times, values } => {
                let sqrt_weight = |m: usize| match (&s.noise, &s.sample_weights) {
                    (Some(Noise::Known(sigma)), _) => 1.0 / sigma[m],
                    (Some(_), _) => f64::NAN,
                    (None, Some(w)) => (s.weight * w[m]).sqrt(),
                    (None, None) => s.weight.sqrt(),
                };
                points.push(
                    times
                        .iter()
                        .zip(values)
                        .enumerate()
                        .map(|(m, (&t, &v))| (t, v, sqrt_weight(m)))
                        .collect(),
                );
                noises.push((
                    (s.transform, s.distribution),
                    match &s.noise {
                        None => PlannedNoise::Weights,
                        Some(Noise::Known(_)) => PlannedNoise::Known,
                        Some(Noise::Scale { unknown: name, factors }) => PlannedNoise::Scale {
                            unknown: unknown(name).ok_or_else(|| ProblemError::InvalidSeries {
                                name: s.name.clone(),
                                message: format!("its σ scale `{name}` is not an unknown"),
                            })?,
                            factors: factors.clone(),
                        },
                        Some(Noise::Function(f)) => PlannedNoise::Function(f.clone()),
                    },
                ));
            }
            Samples::Function(_) => {
                return Err(ProblemError::InvalidSeries {
                    name: s.name.clone(),
                    message: "a record given as a function needs continuous data".into(),
                });
            }
        }
    }
    Ok(Plan::Discrete(gather(resolved, points, noises)))
}

/// A continuous record over `(t_lo, t_hi)`: the record itself for the integrals, and its
/// residual form at Gauss–Legendre nodes.
fn plan_continuous(
    data: &Data,
    resolved: &[Observable],
    (t_lo, t_hi): (f64, f64),
) -> Result<Plan, ProblemError> {
    if !(t_lo.is_finite() && t_hi.is_finite() && t_lo < t_hi) {
        return Err(ProblemError::InvalidValue {
            what: format!("record span [{t_lo}, {t_hi}]"),
            value: t_hi - t_lo,
        });
    }
    let outputs = data
        .series
        .iter()
        .zip(resolved)
        .map(|(s, &observable)| {
            let record = match &s.samples {
                Samples::Points { times, values } => Record::Samples(
                    Signal::new(times.clone(), values.clone(), Interpolation::Linear).map_err(
                        |e| ProblemError::InvalidSeries {
                            name: s.name.clone(),
                            message: e.to_string(),
                        },
                    )?,
                ),
                Samples::Function(f) => Record::Function(f.clone()),
            };
            Ok(RecordedOutput { observable, weight: s.weight, record })
        })
        .collect::<Result<Vec<_>, ProblemError>>()?;
    let points = outputs.iter().map(|o| record_nodes(o, (t_lo, t_hi))).collect();
    let noises =
        vec![((Transform::Lin, NoiseDistribution::Normal), PlannedNoise::Weights); resolved.len()];
    let nodes = gather(resolved, points, noises);
    Ok(Plan::Continuous { span: (t_lo, t_hi), outputs, nodes })
}

/// Gathers per-series (time, value, √weight) points on one sorted time grid.
fn gather(
    observables: &[Observable],
    points: Vec<Vec<(f64, f64, f64)>>,
    noises: Vec<((Transform, NoiseDistribution), PlannedNoise)>,
) -> Sampled {
    let mut times: Vec<f64> = points.iter().flatten().map(|p| p.0).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let series = observables
        .iter()
        .zip(points)
        .zip(noises)
        .map(|((&observable, pts), ((transform, distribution), noise))| PlannedSeries {
            observable,
            transform,
            distribution,
            noise,
            samples: pts
                .into_iter()
                .map(|(t, measured, sqrt_weight)| Sample {
                    index: times.partition_point(|x| *x < t),
                    value: transform.apply(measured),
                    measured,
                    sqrt_weight,
                })
                .collect(),
        })
        .collect();
    Sampled { times, series }
}

/// A record as residual rows: b at the nodes of a composite 4-point Gauss–Legendre rule,
/// each with the square root of w_o times its quadrature weight.
fn record_nodes(output: &RecordedOutput, (t_lo, t_hi): (f64, f64)) -> Vec<(f64, f64, f64)> {
    let mut breaks = vec![t_lo];
    match &output.record {
        Record::Samples(s) => breaks.extend(s.times().iter().filter(|&&t| t > t_lo && t < t_hi)),
        Record::Function(_) => {
            let h = (t_hi - t_lo) / RESIDUAL_PANELS as f64;
            breaks.extend((1..RESIDUAL_PANELS).map(|i| t_lo + h * i as f64));
        }
    }
    breaks.push(t_hi);
    let mut nodes = Vec::with_capacity(4 * breaks.len());
    for panel in breaks.windows(2) {
        let (c, r) = (0.5 * (panel[0] + panel[1]), 0.5 * (panel[1] - panel[0]));
        for (x, w) in GL4 {
            let t = c + r * x;
            nodes.push((t, output.record.value(t), (output.weight * w * r).sqrt()));
        }
    }
    nodes
}
