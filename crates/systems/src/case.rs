//! A catalogue entry: a model with its data, unknowns, start and reference answer.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sysid_core::{Data, Problem, ProblemError, Unknown, format::Expected};
use sysid_ode::{Integrator, Ivp, OdeError, Scheme, System};

/// A published or exact answer a fit must reproduce, with the tolerance that applies.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    /// Estimated values by unknown name.
    pub values: Vec<(&'static str, f64)>,
    /// ε at the answer.
    pub cost: f64,
    /// Relative tolerance a fit is held to.
    pub tolerance: f64,
    /// Where the answer comes from.
    pub source: &'static str,
}

/// Gaussian measurement noise on one measured state.
#[derive(Clone, Debug, PartialEq)]
pub struct Noise {
    /// The measured state.
    pub name: &'static str,
    /// Standard deviation σ; the series gets the weight 1/σ² (Goodman's eq. 32).
    pub sigma: f64,
    /// Whether σ is relative to the true value: sample m then has the standard deviation
    /// σ·|y(t_m)| and the weight 1/(σ·y(t_m))².
    pub relative: bool,
    /// Whether the series is weighted by 1/σ² (eq. 32); unweighted (weight 1) as a user
    /// fitting raw counts would, the cost is then of the order of N σ².
    pub weighted: bool,
}

impl Noise {
    /// Noise of standard deviation σ on every sample of `name`.
    pub fn absolute(name: &'static str, sigma: f64) -> Self {
        Self { name, sigma, relative: false, weighted: true }
    }

    /// Noise of standard deviation σ·|y(t_m)| (σ = 0.01: 1 % of the value).
    pub fn relative(name: &'static str, sigma: f64) -> Self {
        Self { name, sigma, relative: true, weighted: true }
    }

    /// The same noise, fitted with weight 1.
    pub fn unweighted(self) -> Self {
        Self { weighted: false, ..self }
    }
}

/// Where a case's data come from.
#[derive(Clone, Debug)]
pub enum DataSource {
    /// Fixed data: a published table or record.
    Fixed(fn() -> Data),
    /// The truth simulated at `times` (rtol 1e-12, see [`Case::truth_integrator`]) plus
    /// seeded Gaussian noise.
    Synthetic {
        /// Measurement times.
        times: Vec<f64>,
        /// The measured states and their noise.
        noise: Vec<Noise>,
    },
}

/// A benchmark system: everything needed to pose its identification problem.
pub struct Case<S> {
    /// The name used on the command line.
    pub name: &'static str,
    /// One line: what it is.
    pub summary: &'static str,
    /// The unit of time (`s`, or `dimensionless` for models in scaled time).
    pub time_unit: &'static str,
    /// The model.
    pub system: S,
    /// Time of the initial values.
    pub t0: f64,
    /// Known initial values and parameters.
    pub known: Vec<(&'static str, f64)>,
    /// The unknowns with their default starting guesses.
    pub unknowns: Vec<Unknown>,
    /// The integrator the problem uses.
    pub integrator: Integrator,
    /// The data.
    pub data: DataSource,
    /// The true values of the unknowns, where the data are synthetic.
    pub truth: Vec<(&'static str, f64)>,
    /// The answer to reproduce, where one is known.
    pub reference: Option<Reference>,
}

/// The integrator that simulates the truth of non-stiff cases: far tighter than any fit
/// uses.
pub fn truth_integrator() -> Integrator {
    Integrator::dopri5(1e-12, 1e-14)
}

impl<S> Case<S> {
    /// The same case with its system mapped by `f` (to an enum of several system types, say).
    pub fn map_system<T>(self, f: impl FnOnce(S) -> T) -> Case<T> {
        Case {
            name: self.name,
            summary: self.summary,
            time_unit: self.time_unit,
            system: f(self.system),
            t0: self.t0,
            known: self.known,
            unknowns: self.unknowns,
            integrator: self.integrator,
            data: self.data,
            truth: self.truth,
            reference: self.reference,
        }
    }
}

impl<S: System + Clone> Case<S> {
    /// The data for `seed`: the same on every machine (ChaCha8 seeded by `seed`, noise drawn
    /// series after series, in time order).
    pub fn data(&self, seed: u64) -> Result<Data, OdeError> {
        match &self.data {
            DataSource::Fixed(data) => Ok(data()),
            DataSource::Synthetic { times, noise } => {
                let (y0, p) = self.true_point();
                let sol = Ivp::new(&self.system, self.t0, &y0, &p)
                    .solve(&self.truth_integrator(), times)?;
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let sig = self.system.signature();
                let mut data = Data::discrete();
                for n in noise {
                    let i = sig.state(n.name).expect("noise on a state of the system");
                    let normal = Normal::new(0.0, 1.0).expect("the standard normal");
                    let sigma = |m: usize| match n.relative {
                        true => n.sigma * sol.state(m)[i].abs(),
                        false => n.sigma,
                    };
                    let values: Vec<f64> = (0..times.len())
                        .map(|m| sol.state(m)[i] + sigma(m) * normal.sample(&mut rng))
                        .collect();
                    data = match n.relative {
                        true => {
                            let w: Vec<f64> =
                                (0..times.len()).map(|m| 1.0 / (sigma(m) * sigma(m))).collect();
                            data.series_with_weights(n.name, times, &values, &w)
                        }
                        false => {
                            let w = if n.weighted { 1.0 / (n.sigma * n.sigma) } else { 1.0 };
                            data.weighted_series(n.name, w, times, &values)
                        }
                    };
                }
                Ok(data)
            }
        }
    }

    /// The integrator that simulates the truth: [`truth_integrator`], or for a case fitted
    /// with the stiff integrator, Rodas4 at rtol 1e-11 with an absolute tolerance far below
    /// the smallest concentration measured.
    pub fn truth_integrator(&self) -> Integrator {
        match self.integrator.scheme {
            Scheme::Rodas4 | Scheme::Rodas5p | Scheme::Auto | Scheme::Bdf => {
                Integrator::rodas4(1e-11, 1e-18).with_max_steps(10_000_000)
            }
            _ => truth_integrator(),
        }
    }

    /// y(t0) and α at the truth: known values, and the truth (or the reference answer) for the
    /// unknowns.
    pub fn true_point(&self) -> (Vec<f64>, Vec<f64>) {
        let sig = self.system.signature();
        let value = |name: &str| {
            self.known
                .iter()
                .chain(&self.truth)
                .find(|(n, _)| *n == name)
                .map(|p| p.1)
                .or_else(|| {
                    self.reference
                        .as_ref()
                        .and_then(|r| r.values.iter().find(|(n, _)| *n == name).map(|p| p.1))
                })
                .unwrap_or_else(|| panic!("{}: no true value for `{name}`", self.name))
        };
        (
            sig.states().iter().map(|s| value(s)).collect(),
            sig.parameters().iter().map(|s| value(s)).collect(),
        )
    }

    /// The identification problem on the data for `seed`, from the default start.
    pub fn problem(&self, seed: u64) -> Result<Problem<S>, ProblemError> {
        let data = self.data(seed).map_err(|e| ProblemError::Simulation(e.to_string()))?;
        let mut builder = Problem::builder(self.system.clone())
            .t0(self.t0)
            .knowns(&self.known)
            .integrator(self.integrator)
            .data(data);
        for u in &self.unknowns {
            builder = builder.unknown_with(u.clone());
        }
        builder.build()
    }

    /// The reference value or the truth of an unknown, for tables.
    pub fn expected(&self, name: &str) -> Option<f64> {
        let find = |list: &[(&str, f64)]| list.iter().find(|(n, _)| *n == name).map(|p| p.1);
        self.reference.as_ref().and_then(|r| find(&r.values)).or_else(|| find(&self.truth))
    }

    /// What a fit of this case is compared with in tables: the reference answer (with its
    /// cost) if there is one, else the truth; None when neither is known.
    pub fn expectation(&self) -> Option<Expected> {
        let label = match (&self.reference, self.truth.is_empty()) {
            (Some(_), _) => "reference",
            (None, false) => "truth",
            (None, true) => return None,
        };
        let values = self
            .unknowns
            .iter()
            .filter_map(|u| self.expected(&u.name).map(|v| (u.name.clone(), v)))
            .collect();
        let cost = self.reference.as_ref().map(|r| (r.cost, r.source));
        Some(Expected { label, values, cost })
    }

    /// The expected values of all unknowns in order, if every one is known.
    pub fn expected_values(&self) -> Option<Vec<f64>> {
        self.unknowns.iter().map(|u| self.expected(&u.name)).collect()
    }
}

/// `count` evenly spaced times from `start` with step `step` (computed by multiplication, so
/// they are exact multiples of the step).
pub fn grid(start: f64, step: f64, count: usize) -> Vec<f64> {
    (0..count).map(|i| start + step * i as f64).collect()
}
