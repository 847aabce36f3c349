//! Measurements: discrete samples of states or outputs (Goodman 1966, eq. 2, 32) or a
//! continuous record (eq. 16–17), each measured quantity with its weight w_o = 1/σ_o².

use std::sync::Arc;

use crate::noise::{Noise, NoiseDistribution, Transform};

/// Measured values of one quantity.
#[derive(Clone)]
pub enum Samples {
    /// Values at times (strictly increasing). In a continuous record they are joined by
    /// straight lines.
    Points {
        /// Sample times.
        times: Vec<f64>,
        /// Measured values b_{o,m}.
        values: Vec<f64>,
    },
    /// A record known as a function of time (continuous data only).
    Function(Arc<dyn Fn(f64) -> f64 + Send + Sync>),
}

impl std::fmt::Debug for Samples {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Samples::Points { times, .. } => write!(f, "Points({} samples)", times.len()),
            Samples::Function(_) => write!(f, "Function"),
        }
    }
}

/// The measurements of one quantity: a state or output, its weight and its samples.
#[derive(Clone, Debug)]
pub struct Series {
    /// A state or output name.
    pub name: String,
    /// Weight w_o of the series (eq. 32: the reciprocal of the noise variance).
    pub weight: f64,
    /// The measured values.
    pub samples: Samples,
    /// Per-sample weights w_{o,m} multiplying w_o, for noise whose variance changes from
    /// sample to sample (relative noise); discrete data only. `None`: all 1.
    pub sample_weights: Option<Vec<f64>>,
    /// The noise model (discrete data only). `None`: the weights above are relative weights
    /// (σ = 1/√w for the likelihood, the covariance scaled by the residual variance).
    pub noise: Option<Noise>,
    /// The scale the residuals are formed on (discrete data only).
    pub transform: Transform,
    /// The noise's distribution (discrete data with a noise model only; default normal).
    pub distribution: NoiseDistribution,
}

/// Whether the data are samples or a continuous record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Record {
    /// Samples at discrete times: ε = Σ_o w_o Σ_m r_{o,m}² (eq. 3, 32).
    Discrete,
    /// A continuous record over [t_lo, t_hi]: ε = Σ_o w_o ∫ r_o² dt (eq. 17).
    Continuous {
        /// Start of the record.
        t_lo: f64,
        /// End of the record.
        t_hi: f64,
    },
}

/// The measurements of a problem.
///
/// ```
/// use sysid_core::{Data, Noise, Transform};
///
/// let (t, b) = ([1.0, 2.0, 3.0], [0.9, 0.8, 0.7]);
/// // Weighted least squares: ε = Σ w (x(t) − b)², here w = 4 = 1/σ² for σ = 0.5.
/// let wls = Data::discrete().weighted_series("x", 4.0, &t, &b);
/// assert_eq!(wls.n_observations(), Some(3));
/// // The likelihood with σ = 0.1 known: the fit reports the negative log-likelihood too.
/// let known = Noise::Known(vec![0.1; 3]);
/// let likelihood = Data::discrete().series_with_noise("x", &t, &b, known, Transform::Lin);
/// assert!(likelihood.has_noise_model() && !wls.has_noise_model());
/// // A continuous record over [0, 3]: ε = ∫ (x(t) − b(t))² dt, b joined by straight lines.
/// // Its samples count as the observations of the degrees of freedom N − k.
/// let record = Data::continuous(0.0, 3.0).series("x", &[0.0, 1.5, 3.0], &[1.0, 0.8, 0.7]);
/// assert_eq!(record.n_observations(), Some(3));
/// ```
#[derive(Clone, Debug)]
pub struct Data {
    /// Discrete or continuous.
    pub record: Record,
    /// One entry per measured quantity.
    pub series: Vec<Series>,
}

impl Data {
    /// Discrete data; add series with [`series`](Self::series).
    pub fn discrete() -> Self {
        Self { record: Record::Discrete, series: Vec::new() }
    }

    /// A continuous record over [t_lo, t_hi]; add series with [`series`](Self::series) (joined
    /// by straight lines) or [`function`](Self::function).
    pub fn continuous(t_lo: f64, t_hi: f64) -> Self {
        Self { record: Record::Continuous { t_lo, t_hi }, series: Vec::new() }
    }

    /// Adds samples of `name` with weight 1.
    pub fn series(self, name: &str, times: &[f64], values: &[f64]) -> Self {
        self.weighted_series(name, 1.0, times, values)
    }

    /// Adds samples of `name` with weight w.
    pub fn weighted_series(
        mut self,
        name: &str,
        weight: f64,
        times: &[f64],
        values: &[f64],
    ) -> Self {
        self.series.push(Series {
            name: name.into(),
            weight,
            samples: Samples::Points { times: times.to_vec(), values: values.to_vec() },
            sample_weights: None,
            noise: None,
            transform: Transform::Lin,
            distribution: NoiseDistribution::Normal,
        });
        self
    }

    /// Adds samples of `name` with a noise model, residuals on the scale `transform`.
    pub fn series_with_noise(
        mut self,
        name: &str,
        times: &[f64],
        values: &[f64],
        noise: Noise,
        transform: Transform,
    ) -> Self {
        self.series.push(Series {
            name: name.into(),
            weight: 1.0,
            samples: Samples::Points { times: times.to_vec(), values: values.to_vec() },
            sample_weights: None,
            noise: Some(noise),
            transform,
            distribution: NoiseDistribution::Normal,
        });
        self
    }

    /// Adds samples of `name` with one weight per sample, w_m = 1/σ_m² for noise of standard
    /// deviation σ_m (discrete data only): ε gains Σ_m w_m (h(t_m) − b_m)².
    pub fn series_with_weights(
        mut self,
        name: &str,
        times: &[f64],
        values: &[f64],
        weights: &[f64],
    ) -> Self {
        self.series.push(Series {
            name: name.into(),
            weight: 1.0,
            samples: Samples::Points { times: times.to_vec(), values: values.to_vec() },
            sample_weights: Some(weights.to_vec()),
            noise: None,
            transform: Transform::Lin,
            distribution: NoiseDistribution::Normal,
        });
        self
    }

    /// Adds a record of `name` given as a function of time, with weight w.
    pub fn function(
        mut self,
        name: &str,
        weight: f64,
        b: impl Fn(f64) -> f64 + Send + Sync + 'static,
    ) -> Self {
        self.series.push(Series {
            name: name.into(),
            weight,
            samples: Samples::Function(Arc::new(b)),
            sample_weights: None,
            noise: None,
            transform: Transform::Lin,
            distribution: NoiseDistribution::Normal,
        });
        self
    }

    /// Whether any series has a noise model (then the likelihood is the objective and the
    /// covariance is the inverse Fisher information, not scaled by the residual variance).
    pub fn has_noise_model(&self) -> bool {
        self.series.iter().any(|s| s.noise.is_some())
    }

    /// Number of measured values: all samples of discrete data, the samples inside the span of
    /// a continuous record; `None` when a record is a function.
    pub fn n_observations(&self) -> Option<usize> {
        self.series
            .iter()
            .map(|s| match (&s.samples, self.record) {
                (Samples::Points { values, .. }, Record::Discrete) => Some(values.len()),
                (Samples::Points { times, .. }, Record::Continuous { t_lo, t_hi }) => {
                    Some(times.iter().filter(|t| (t_lo..=t_hi).contains(*t)).count())
                }
                (Samples::Function(_), _) => None,
            })
            .sum()
    }
}
