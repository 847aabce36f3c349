//! `sysid._sysid`: the compiled half of the `sysid` Python package (crates/python/python/sysid
//! holds the rest, and the documentation a Python user reads).
//!
//! A [`Problem`] is a PEtab problem, a model file (imported and compiled once) or a system of
//! the benchmark catalogue with its data. Its objective,
//! gradient, Fisher information, weighted residuals and Jacobian are evaluated at a point given
//! on the linear scale (the parameters' values) or on sysid's parameter scale (ln of a value
//! for a log-scaled unknown, the value itself otherwise), as numpy arrays. `fit` runs any
//! method of the registry, from the problem's guess or from N starts, and returns the fit's
//! JSON object of docs/json.md as a string, which the Python side wraps. The GIL is released
//! while the model is integrated. Bad input raises `ValueError`; what the model or the method
//! cannot do raises `sysid.SysidError`, with the command line's message.

use std::borrow::Cow;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::DMatrix;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sysid_core::observer::{IterateReport, TrialReport, observe, observe_trials};
use sysid_core::{Linearization, Problem, Sensitivities, Unknown};
use sysid_montecarlo::{MultistartOptions, Sampling, StartDone};
use sysid_registry::any::{self, AnySystem};
use sysid_registry::{Boxed, Registry, Role, Settings};

create_exception!(
    _sysid,
    SysidError,
    PyException,
    "What a model or a method cannot do: a model that cannot be integrated at the point asked \
     for, a file that cannot be read, a start every method fails from."
);

fn sysid_error(message: impl std::fmt::Display) -> PyErr {
    SysidError::new_err(message.to_string())
}

/// `SysidError` where the fit could not begin at its start, as the command line says it:
/// the values there and why.
fn unusable_start(problem: &Problem<AnySystem>, e: &sysid_core::Estimate) -> PyResult<()> {
    let sysid_core::Termination::StartFailed(failure) = &e.termination else { return Ok(()) };
    Err(sysid_error(match failure.at() {
        Some(at) => format!(
            "the starting guess cannot be used ({}): {failure}",
            sysid_core::format::named_point(&problem.names(), at)
        ),
        None => format!("the starting guess cannot be used: {failure}"),
    }))
}

/// A numpy vector.
type Array1<'py> = Bound<'py, PyArray1<f64>>;
/// A vector argument: a numpy array, or anything numpy's `asarray` makes a 1-D array of
/// floats of (a list, a tuple, integers, a strided view such as a matrix's column). Anything
/// else is refused by what it is (pyo3's own refusal named its Rust type, `PyArray<T, D>`).
struct Vector(Vec<f64>);

impl<'py> FromPyObject<'py> for Vector {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        let refuse = |got: String| {
            PyTypeError::new_err(format!(
                "expected a 1-D array of numbers (a numpy array, a list or a tuple), got {got}"
            ))
        };
        let kind = || ob.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        if ob.is_none() {
            return Err(refuse("None".into()));
        }
        let numpy = ob.py().import("numpy")?;
        // First as it comes, so that what numpy would convert quietly is named: None (NaN
        // as a float) and complex numbers (their imaginary part dropped, with a warning).
        let raw = numpy
            .call_method1("asarray", (ob,))
            .map_err(|_| refuse(format!("a {} that numpy makes no array of", kind())))?;
        // A masked array's masked entries would be taken at whatever value lies under them.
        if numpy.getattr("ma")?.call_method1("is_masked", (ob,))?.extract::<bool>()? {
            return Err(refuse(format!("a {} with masked entries", kind())));
        }
        let dtype: String = raw.getattr("dtype")?.getattr("kind")?.extract()?;
        match dtype.as_str() {
            "c" => return Err(refuse(format!("a {} of complex numbers", kind()))),
            "O" if raw.getattr("ndim")?.extract::<usize>()? == 1 => {
                for (i, entry) in raw.try_iter()?.enumerate() {
                    let entry = entry?;
                    if entry.is_none() {
                        return Err(refuse(format!("a {} whose entry {i} is None", kind())));
                    }
                    // Text held as objects (a pandas Series of str): numpy reads "1.0" as 1.0.
                    if entry.is_instance_of::<pyo3::types::PyString>()
                        || entry.is_instance_of::<pyo3::types::PyBytes>()
                    {
                        return Err(refuse(format!("a {} of text, not numbers", kind())));
                    }
                }
            }
            _ => {}
        }
        let array = numpy
            .call_method1("asarray", (&raw, numpy.getattr("float64")?))
            .map_err(|_| refuse(format!("a {} that is not numbers", kind())))?;
        let ndim: usize = array.getattr("ndim")?.extract()?;
        if ndim != 1 {
            return Err(refuse(match ndim {
                0 => format!("a single {}", kind()),
                _ => format!("a {ndim}-D array of shape {}", array.getattr("shape")?.str()?),
            }));
        }
        // Numbers as text and dates convert too: numpy reads "1.0" as 1.0, and a date as its
        // days since 1970.
        match dtype.as_str() {
            "U" | "S" | "T" => return Err(refuse(format!("a {} of text, not numbers", kind()))),
            "M" | "m" => return Err(refuse(format!("a {} of dates or times", kind()))),
            _ => {}
        }
        let array: PyReadonlyArray1<'py, f64> = array.extract()?;
        Ok(Vector(array.as_array().to_vec()))
    }
}

/// A whole number argument that must be at least `least`, taken as a Python int of any sign
/// so that a negative one is named (pyo3 would raise `OverflowError` without the name).
fn whole(name: &str, value: i128, least: i128) -> PyResult<u64> {
    if value < least {
        return Err(PyValueError::new_err(format!("{name} must be at least {least}, got {value}")));
    }
    u64::try_from(value).map_err(|_| {
        PyValueError::new_err(format!("{name} must be at most {}, got {value}", u64::MAX))
    })
}

/// A seed: any non-negative int below 2⁶⁴.
fn seed(value: i128) -> PyResult<u64> {
    u64::try_from(value).map_err(|_| {
        PyValueError::new_err(format!("seed must be a whole number in [0, 2^64), got {value}"))
    })
}
/// A numpy matrix.
type Array2Py<'py> = Bound<'py, PyArray2<f64>>;

/// The scale a point or a derivative is given on.
#[derive(Clone, Copy, PartialEq)]
enum Scale {
    /// The parameters' values.
    Linear,
    /// sysid's coordinates: ln(value) for a log-scaled unknown, the value otherwise.
    Parameter,
}

impl Scale {
    fn parse(name: &str) -> PyResult<Self> {
        match name {
            "linear" => Ok(Self::Linear),
            "parameter" => Ok(Self::Parameter),
            _ => Err(PyValueError::new_err(format!(
                "scale must be \"linear\" or \"parameter\", not {name:?}"
            ))),
        }
    }
}

/// A parameter estimation problem: a PEtab problem, a model file with its data, or a system of
/// the catalogue.
#[pyclass(name = "Problem", module = "sysid._sysid", frozen)]
struct PyProblem {
    problem: Arc<Problem<AnySystem>>,
    name: String,
}

/// A point's evaluation: the problem with the noise scales at the point's, its linearization
/// at the point's free unknowns, and ∂value/∂coordinate of every parameter (1 on a linear
/// scale, the value on a log scale).
struct Evaluated<'a> {
    /// The problem itself where it has no noise scales; else a copy with the point's.
    problem: Cow<'a, Problem<AnySystem>>,
    lin: Linearization,
    chain: Vec<f64>,
}

impl PyProblem {
    /// The parameters: the free unknowns, then the noise scales (which the fits set in closed
    /// form, and which PEtab and pyPESTO count among the parameters).
    fn parameters(&self) -> Vec<&Unknown> {
        self.problem.parameters()
    }

    /// The coordinates of the point `x` given on `scale`, checked.
    fn coordinates(&self, x: &[f64], scale: Scale) -> PyResult<Vec<f64>> {
        let unknowns = self.parameters();
        if x.len() != unknowns.len() {
            return Err(PyValueError::new_err(format!(
                "x has {} entries; the problem has {} unknowns ({})",
                x.len(),
                unknowns.len(),
                self.parameter_names().join(", ")
            )));
        }
        let free = self.problem.unknowns().len();
        for (i, (u, &v)) in unknowns.iter().zip(x).enumerate() {
            if !v.is_finite() {
                return Err(PyValueError::new_err(format!("x[{}] = {v} is not finite", u.name)));
            }
            // A noise scale is σ; on a linear scale its coordinate is itself.
            if i >= free && !u.log && v <= 0.0 {
                return Err(PyValueError::new_err(format!(
                    "{} = {v}: a noise scale is a σ: it must be positive",
                    u.name
                )));
            }
            if scale == Scale::Linear && u.log && v <= 0.0 {
                return Err(PyValueError::new_err(format!(
                    "{} = {v}: a log-scaled unknown must be positive on the linear scale",
                    u.name
                )));
            }
        }
        Ok(match scale {
            Scale::Linear => unknowns.iter().zip(x).map(|(u, &v)| u.coordinate(v)).collect(),
            Scale::Parameter => x.to_vec(),
        })
    }

    /// The point's values on the linear scale.
    fn values(&self, z: &[f64]) -> Vec<f64> {
        self.parameters().iter().zip(z).map(|(u, &z)| u.value(z)).collect()
    }

    /// The problem at the noise scales of the point z (itself where it has none).
    fn at_scales(&self, z: &[f64]) -> Cow<'_, Problem<AnySystem>> {
        let k = self.problem.unknowns().len();
        match self.problem.scales().is_empty() {
            true => Cow::Borrowed(&*self.problem),
            false => Cow::Owned(self.problem.with_scales(&self.values(z)[k..])),
        }
    }

    /// ∂value/∂coordinate of every parameter at z.
    fn chain(&self, z: &[f64]) -> Vec<f64> {
        self.parameters().iter().zip(z).map(|(u, &z)| u.scale(z)).collect()
    }

    /// The evaluation at x (given on `scale`), the model integrated with its sensitivities
    /// with the GIL released.
    fn evaluate(&self, py: Python<'_>, x: &[f64], scale: Scale) -> PyResult<Evaluated<'_>> {
        let z = self.coordinates(x, scale)?;
        let k = self.problem.unknowns().len();
        let problem = self.at_scales(&z);
        let lin = py
            .allow_threads(|| problem.residuals_and_jacobian(&z[..k]))
            .map_err(|e| sysid_error(format!("the model cannot be evaluated at x: {e}")))?;
        Ok(Evaluated { problem, lin, chain: self.chain(&z) })
    }

    /// The NLL (`priors` false) or the objective at x, and its gradient on `scale`, by the
    /// `sensitivities` asked for (forward, adjoint or auto; docs/methods.md).
    fn value_and_gradient<'py>(
        &self,
        py: Python<'py>,
        x: Vector,
        (scale, sensitivities): (&str, &str),
        priors: bool,
    ) -> PyResult<(f64, Array1<'py>)> {
        let scale = Scale::parse(scale)?;
        let how = match sensitivities {
            "forward" => {
                let e = self.evaluate(py, &x.0, scale)?;
                let value = if priors { e.objective()? } else { e.nll()? };
                return Ok((value, e.gradient(priors, scale).into_pyarray(py)));
            }
            "adjoint" => Sensitivities::Adjoint,
            "auto" => Sensitivities::Auto,
            _ => {
                return Err(PyValueError::new_err(format!(
                    "sensitivities must be \"forward\", \"adjoint\" or \"auto\", not {sensitivities:?}"
                )));
            }
        };
        let z = self.coordinates(&x.0, scale)?;
        let k = self.problem.unknowns().len();
        let problem = self.at_scales(&z);
        let e = py
            .allow_threads(|| problem.nll_gradient(&z[..k], how))
            .map_err(|e| sysid_error(format!("the model cannot be evaluated at x: {e}")))?
            .ok_or_else(|| {
                sysid_error("the problem's data are a continuous record: it has no likelihood")
            })?;
        let (mut value, mut g) = (e.nll, e.gradient);
        if priors {
            value += problem.prior_nll_at(&z[..k]).unwrap_or(0.0);
            g.iter_mut().zip(problem.prior_gradient_at(&z[..k])).for_each(|(g, p)| *g += p);
        }
        if scale == Scale::Linear {
            g.iter_mut().zip(self.chain(&z)).for_each(|(g, c)| *g /= c);
        }
        Ok((value, g.into_pyarray(py)))
    }
}

impl Evaluated<'_> {
    fn rows(&self) -> &sysid_core::WeightedResiduals {
        self.lin.residuals.as_ref().expect("discrete data have residual rows")
    }

    /// The negative log-likelihood.
    fn nll(&self) -> PyResult<f64> {
        self.problem.nll(&self.lin).ok_or_else(|| {
            sysid_error("the problem's data are a continuous record: it has no likelihood")
        })
    }

    /// The objective: the NLL plus the priors' term.
    fn objective(&self) -> PyResult<f64> {
        Ok(self.nll()? + self.problem.prior_nll(&self.lin).unwrap_or(0.0))
    }

    /// The gradient of the NLL (`priors` false) or of the objective, with respect to the
    /// parameters on `scale`.
    fn gradient(&self, priors: bool, scale: Scale) -> Vec<f64> {
        let g = self.problem.objective_gradient(&self.lin, priors);
        match scale {
            Scale::Parameter => g,
            Scale::Linear => g.iter().zip(&self.chain).map(|(g, c)| g / c).collect(),
        }
    }

    /// The Fisher information of the objective on `scale`: JᵀJ (or the exact information
    /// where σ depends on the unknowns) for the free unknowns, 2·n_s/s² for a noise scale s
    /// of n_s samples (a normal's information about its σ), 0 between the two.
    fn fisher(&self, scale: Scale) -> PyResult<DMatrix<f64>> {
        let k = self.lin.normal.nrows();
        let sigma = self.problem.scale_values();
        let mut f = DMatrix::zeros(k + sigma.len(), k + sigma.len());
        f.view_mut((0, 0), (k, k)).copy_from(&self.lin.normal);
        for (g, n) in self.problem.scale_samples().iter().enumerate() {
            let c = self.chain[k + g];
            f[(k + g, k + g)] = 2.0 * *n as f64 * (c / sigma[g]).powi(2);
        }
        if scale == Scale::Linear {
            // On the parameter scale an unknown's information is c² times its own (c = dθ/dz,
            // θ itself on a log scale): where that underflowed, the value cannot be had back
            // from it (it was NaN at θ = 1e-200).
            if let Some(rows) = self.lin.residuals.as_ref() {
                for i in 0..k {
                    let seen = rows.jacobian.column(i).iter().any(|v| *v != 0.0);
                    if seen && f[(i, i)].abs() < f64::MIN_POSITIVE {
                        return Err(PyValueError::new_err(format!(
                            "the Fisher information about `{}` cannot be had on the linear scale here: on the parameter scale it is (dθ/dz)² times as large, dθ/dz = {}, and underflows (scale=\"parameter\" gives it as it is)",
                            self.problem.names()[i],
                            sysid_core::format::shortest(self.chain[i]),
                        )));
                    }
                }
            }
            for i in 0..f.nrows() {
                for j in 0..f.ncols() {
                    f[(i, j)] = f[(i, j)] / self.chain[i] / self.chain[j];
                }
            }
        }
        Ok(f)
    }

    /// The weighted residuals and their Jacobian on `scale`: ∂r/∂s = −r/s for a noise
    /// scale's rows.
    fn jacobian(&self, scale: Scale) -> DMatrix<f64> {
        let rows = self.rows();
        let k = rows.jacobian.ncols();
        let sigma = self.problem.scale_values();
        let mut j = DMatrix::zeros(rows.r.len(), k + sigma.len());
        j.view_mut((0, 0), (rows.r.len(), k)).copy_from(&rows.jacobian);
        for (i, s) in self.problem.scale_rows().into_iter().enumerate() {
            if let Some(s) = s {
                j[(i, k + s)] = -rows.r[i] / sigma[s] * self.chain[k + s];
            }
        }
        if scale == Scale::Linear {
            for (col, c) in self.chain.iter().enumerate() {
                j.column_mut(col).unscale_mut(*c);
            }
        }
        j
    }
}

/// The settings every method shares, with the driver's budgets and tolerance where given.
fn settings(
    max_iterations: Option<usize>,
    gtol: Option<f64>,
    max_integrations: Option<u64>,
    max_seconds: Option<f64>,
    coarse_first: bool,
) -> PyResult<Settings> {
    let mut settings = Settings::default();
    if let Some(n) = max_iterations {
        settings.driver.max_iterations = n;
    }
    settings.driver.gtol = gtol;
    settings.driver.max_integrations = max_integrations;
    settings.driver.max_seconds = max_seconds;
    settings.driver.coarse_first = coarse_first;
    settings.validate().map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(settings)
}

/// The registry's method `name` (the default when None), built with `settings`.
fn build(name: Option<&str>, settings: &Settings) -> PyResult<Boxed<AnySystem>> {
    Registry::standard()
        .build(name.unwrap_or(Role::Default.method()), settings)
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

fn matrix<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]).into_pyarray(py)
}

#[pymethods]
impl PyProblem {
    /// Imports a PEtab problem from its YAML file.
    #[staticmethod]
    fn from_petab(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let model = py.allow_threads(|| sysid_petab::import(&path)).map_err(sysid_error)?.model;
        let problem = any::model_problem(model.problem(None).map_err(sysid_error)?);
        Ok(Self { problem: Arc::new(problem), name: path.display().to_string() })
    }

    /// Reads a model file (TOML), with its data from `data` (a CSV file) or from the file's
    /// own `[data]` table.
    #[staticmethod]
    #[pyo3(signature = (path, data=None))]
    fn from_model(py: Python<'_>, path: PathBuf, data: Option<PathBuf>) -> PyResult<Self> {
        let model = py.allow_threads(|| sysid_model::Model::load(&path)).map_err(sysid_error)?;
        let problem = any::model_problem(model.problem(data.as_deref()).map_err(sysid_error)?);
        Ok(Self { problem: Arc::new(problem), name: path.display().to_string() })
    }

    /// A system of the benchmark catalogue (`sysid systems` names them) with its data: the
    /// published record, or synthetic data drawn with `seed` (the command line's `--seed`).
    #[staticmethod]
    #[pyo3(signature = (name, seed=1))]
    fn from_catalogue(py: Python<'_>, name: &str, seed: i128) -> PyResult<Self> {
        let seed = self::seed(seed)?;
        let case = any::case(name).ok_or_else(|| {
            PyValueError::new_err(format!(
                "unknown system {name:?} (systems: {})",
                sysid_systems::NAMES.join(", ")
            ))
        })?;
        let problem = py
            .allow_threads(|| case.problem(seed))
            .map_err(|e| sysid_error(format!("system {name}: {e}")))?;
        Ok(Self { problem: Arc::new(problem), name: name.to_string() })
    }

    /// The same problem integrated with other tolerances or another scheme (`fixed_step`: a
    /// fixed step size, which `rk4` needs, and which turns error control off for `dopri5` and
    /// `dop853`).
    #[pyo3(signature = (rtol=None, atol=None, scheme=None, fixed_step=None))]
    fn with_integrator(
        &self,
        rtol: Option<f64>,
        atol: Option<f64>,
        scheme: Option<&str>,
        fixed_step: Option<f64>,
    ) -> PyResult<Self> {
        let mut integrator = *self.problem.integrator();
        if let Some(rtol) = rtol {
            integrator.rtol = rtol;
        }
        if let Some(atol) = atol {
            integrator.atol = atol;
        }
        if let Some(scheme) = scheme {
            integrator.scheme =
                serde_json::from_value(serde_json::Value::from(scheme)).map_err(|_| {
                    PyValueError::new_err(format!(
                        "unknown scheme {scheme:?} (schemes: dopri5, dop853, rk4, rodas4, rodas5p, bdf, auto)"
                    ))
                })?;
            // A fixed step belongs to the scheme it was given for.
            integrator.fixed_step = None;
        }
        if fixed_step.is_some() {
            integrator.fixed_step = fixed_step;
        }
        integrator.validate().map_err(|e| PyValueError::new_err(e.to_string()))?;
        let problem = (*self.problem)
            .clone()
            .with_integrator(integrator)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(Self { problem: Arc::new(problem), name: self.name.clone() })
    }

    /// The file the problem was read from, or the catalogue system's name.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The parameters' names, in the order of every array: the unknowns, then the noise
    /// scales.
    #[getter]
    fn parameter_names(&self) -> Vec<String> {
        self.parameters().iter().map(|u| u.name.clone()).collect()
    }

    /// The parameters' starting values (PEtab's nominal values), on the linear scale.
    #[getter]
    fn nominal<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.parameters().iter().map(|u| u.guess).collect::<Vec<_>>().into_pyarray(py)
    }

    /// (lower, upper) on the linear scale; ±inf where there is no bound, but 0 below a
    /// log-scaled parameter without one (its value is positive: −inf on the parameter scale).
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> (Array1<'py>, Array1<'py>) {
        let list = self.parameters();
        let least = |u: &Unknown| if u.log { 0.0 } else { f64::NEG_INFINITY };
        let lo: Vec<f64> = list.iter().map(|u| u.min.unwrap_or_else(|| least(u))).collect();
        let hi: Vec<f64> = list.iter().map(|u| u.max.unwrap_or(f64::INFINITY)).collect();
        (lo.into_pyarray(py), hi.into_pyarray(py))
    }

    /// Each parameter's scale: "log" (estimated as ln of its value; PEtab's log and log10
    /// both) or "lin".
    #[getter]
    fn scales(&self) -> Vec<&'static str> {
        self.parameters().iter().map(|u| if u.log { "log" } else { "lin" }).collect()
    }

    /// The names of the experiments (PEtab's simulation conditions), in order.
    #[getter]
    fn experiments(&self) -> Vec<String> {
        self.problem.experiments().iter().map(|e| e.name().to_string()).collect()
    }

    /// The point `x` on the parameter scale.
    fn to_parameter_scale<'py>(
        &self,
        py: Python<'py>,
        x: Vector,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(self.coordinates(&x.0, Scale::Linear)?.into_pyarray(py))
    }

    /// The point `z` (on the parameter scale) on the linear scale.
    fn to_linear_scale<'py>(
        &self,
        py: Python<'py>,
        z: Vector,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let z = self.coordinates(&z.0, Scale::Parameter)?;
        Ok(self.values(&z).into_pyarray(py))
    }

    /// The negative log-likelihood at x (priors excluded, as the fit JSON's `nll`).
    #[pyo3(signature = (x, scale="linear"))]
    fn nll(&self, py: Python<'_>, x: Vector, scale: &str) -> PyResult<f64> {
        self.evaluate(py, &x.0, Scale::parse(scale)?)?.nll()
    }

    /// The negative log-likelihood at x and its gradient on `scale`. `sensitivities`: "auto" (each experiment by whichever of forward
    /// sensitivities and the adjoint did less work at its first gradient, which computes both),
    /// "forward" or "adjoint" (docs/methods.md#adjoint-gradients).
    #[pyo3(signature = (x, scale="linear", sensitivities="auto"))]
    fn nll_and_gradient<'py>(
        &self,
        py: Python<'py>,
        x: Vector,
        scale: &str,
        sensitivities: &str,
    ) -> PyResult<(f64, Array1<'py>)> {
        self.value_and_gradient(py, x, (scale, sensitivities), false)
    }

    /// The objective the fits minimise at x: the NLL plus the priors' negative log-density
    /// where the problem has priors (what pyPESTO minimises), the NLL otherwise.
    #[pyo3(signature = (x, scale="linear"))]
    fn objective(&self, py: Python<'_>, x: Vector, scale: &str) -> PyResult<f64> {
        self.evaluate(py, &x.0, Scale::parse(scale)?)?.objective()
    }

    /// The objective and its gradient on `scale`. `sensitivities`: "auto" (each experiment by whichever of forward
    /// sensitivities and the adjoint did less work at its first gradient, which computes both),
    /// "forward" or "adjoint" (docs/methods.md#adjoint-gradients).
    #[pyo3(signature = (x, scale="linear", sensitivities="auto"))]
    fn objective_and_gradient<'py>(
        &self,
        py: Python<'py>,
        x: Vector,
        scale: &str,
        sensitivities: &str,
    ) -> PyResult<(f64, Array1<'py>)> {
        self.value_and_gradient(py, x, (scale, sensitivities), true)
    }

    /// The Fisher information of the objective at x on `scale`: the Gauss–Newton
    /// approximation of its Hessian (JᵀJ of the weighted residuals, or the exact Fisher
    /// information where σ depends on the unknowns; the priors' rows included), with each
    /// noise scale's own information 2·n/s².
    #[pyo3(signature = (x, scale="linear"))]
    fn fisher<'py>(
        &self,
        py: Python<'py>,
        x: Vector,
        scale: &str,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let scale = Scale::parse(scale)?;
        Ok(matrix(py, &self.evaluate(py, &x.0, scale)?.fisher(scale)?))
    }

    /// The weighted residuals r and their Jacobian ∂r/∂x on `scale`: a row per measurement,
    /// then a row per measurement whose σ is a function of the unknowns, then a row per
    /// prior. ½‖r‖² is the objective less terms that depend on the noise scales and σ
    /// functions alone (constant where there are none).
    #[pyo3(signature = (x, scale="linear"))]
    fn residuals_and_jacobian<'py>(
        &self,
        py: Python<'py>,
        x: Vector,
        scale: &str,
    ) -> PyResult<(Array1<'py>, Array2Py<'py>)> {
        let scale = Scale::parse(scale)?;
        let e = self.evaluate(py, &x.0, scale)?;
        let r: Vec<f64> = e.rows().r.iter().copied().collect();
        Ok((r.into_pyarray(py), matrix(py, &e.jacobian(scale))))
    }

    /// Every state of experiment `experiment` (an index or a name) at `times`, at x (the
    /// nominal values when None): a dict of state name to array.
    #[pyo3(signature = (times, x=None, experiment=None, scale="linear"))]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        times: Vector,
        x: Option<Vector>,
        experiment: Option<Bound<'py, PyAny>>,
        scale: &str,
    ) -> PyResult<Bound<'py, PyDict>> {
        let scale = Scale::parse(scale)?;
        let z = match &x {
            Some(x) => self.coordinates(&x.0, scale)?,
            None => self.parameters().iter().map(|u| u.coordinate(u.guess)).collect(),
        };
        let k = self.problem.unknowns().len();
        let values = self.problem.unknowns().values(&z[..k]);
        let names = self.experiments();
        let index = match experiment {
            None => 0,
            // A bool is an int to Python (True was experiment 1): refused as neither.
            Some(e) if e.is_instance_of::<pyo3::types::PyBool>() => {
                return Err(PyTypeError::new_err(format!(
                    "experiment is an index or a name, got a bool: {}",
                    e.str().map(|s| s.to_string()).unwrap_or_default()
                )));
            }
            Some(e) => match e.extract::<i128>() {
                Ok(i) if usize::try_from(i).is_ok_and(|i| i < names.len()) => i as usize,
                Ok(i) => {
                    return Err(PyValueError::new_err(format!(
                        "experiment {i}: the problem has {} experiments",
                        names.len()
                    )));
                }
                Err(_) => {
                    let name: String = e.extract().map_err(|_| {
                        let kind = e.get_type().name().map(|n| n.to_string()).unwrap_or_default();
                        PyTypeError::new_err(format!(
                            "experiment is an index or a name, got a {kind}: {}",
                            e.repr().map(|r| r.to_string()).unwrap_or_default()
                        ))
                    })?;
                    names.iter().position(|n| *n == name).ok_or_else(|| {
                        PyValueError::new_err(format!(
                            "no experiment {name:?} (experiments: {})",
                            names.join(", ")
                        ))
                    })?
                }
            },
        };
        let times = times.0;
        if let Some(t) = times.iter().find(|t| !t.is_finite()) {
            return Err(PyValueError::new_err(format!("times: {t} is not finite")));
        }
        if times.windows(2).any(|w| w[1] < w[0]) {
            return Err(PyValueError::new_err("times must be in increasing order"));
        }
        let problem = &self.problem;
        let states = py
            .allow_threads(|| problem.trajectory(index, &values, None, &times))
            .map_err(|e| sysid_error(format!("the model cannot be integrated at x: {e}")))?;
        let out = PyDict::new(py);
        for s in states {
            out.set_item(s.name, s.values.into_pyarray(py))?;
        }
        Ok(out)
    }

    /// Fits the problem: a `sysid.FitResult` over the fit's JSON object (docs/json.md).
    ///
    /// `max_iterations`: by default 3000 for one fit, 1000 for each start of `starts`.
    ///
    /// `progress`, a callable, is called while the fit runs with a dict: for a single fit
    /// at each iterate (`iteration`, `objective`, `cost`, `optimality`, `coarse`), with
    /// `starts` as each start ends (`start`, `done`, `total`, `objective`, `converged`).
    /// An exception it raises stops the fit at its next iteration (a multistart's running
    /// starts so, and begins no other), and the fit raises it then, with the fit as it
    /// stood as the exception's `result`. Ctrl-C (KeyboardInterrupt) stops it the same way.
    ///
    /// `trials`, a callable, is called with a dict for every trial step a trust-region
    /// method judges in a single fit (the keys of docs/json.md's trial lines: `method`,
    /// `model`, `from`, `radius`, `step`, `lambda`, `predicted`, `actual`, `ratio`,
    /// `accepted`); an exception it raises stops the fit as `progress`'s does. Not with
    /// `starts`.
    #[pyo3(signature = (method=None, starts=None, seed=1, sampling="uniform", include_nominal=true, max_iterations=None, gtol=None, max_integrations=None, max_seconds=None, fix=None, start=None, coarse_first=true, progress=None, trials=None))]
    #[allow(clippy::too_many_arguments)]
    fn fit<'py>(
        &self,
        py: Python<'py>,
        method: Option<&str>,
        starts: Option<i128>,
        seed: i128,
        sampling: &str,
        include_nominal: bool,
        max_iterations: Option<i128>,
        gtol: Option<f64>,
        max_integrations: Option<i128>,
        max_seconds: Option<f64>,
        fix: Option<std::collections::BTreeMap<String, f64>>,
        start: Option<std::collections::BTreeMap<String, f64>>,
        coarse_first: bool,
        progress: Option<Py<PyAny>>,
        trials: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        for (name, callback) in [("progress", &progress), ("trials", &trials)] {
            if let Some(c) = callback
                && !c.bind(py).is_callable()
            {
                return Err(PyTypeError::new_err(format!("{name} must be a callable (or None)")));
            }
        }
        let starts = starts.map(|n| whole("starts", n, 1)).transpose()?.map(|n| n as usize);
        if trials.is_some() && starts.is_some() {
            return Err(PyValueError::new_err(
                "trials hears one fit, and the starts of a multistart run side by side: fit a start alone from its start values (start=)",
            ));
        }
        let seed = self::seed(seed)?;
        let max_iterations =
            max_iterations.map(|n| whole("max_iterations", n, 0)).transpose()?.map(|n| n as usize);
        let max_integrations =
            max_integrations.map(|n| whole("max_integrations", n, 1)).transpose()?;
        // Each start of a multistart has its own budget where none is named.
        let max_iterations =
            max_iterations.or(starts.is_some().then_some(sysid_core::START_MAX_ITERATIONS));
        let settings = settings(max_iterations, gtol, max_integrations, max_seconds, coarse_first)?;
        let method = build(method, &settings)?;
        let fix: Vec<(String, f64)> = fix.unwrap_or_default().into_iter().collect();
        let start: Vec<(String, f64)> = start.unwrap_or_default().into_iter().collect();
        if let Some((name, _)) = start.iter().find(|(n, _)| fix.iter().any(|(f, _)| f == n)) {
            return Err(PyValueError::new_err(format!(
                "{name} is in both fix and start: a fixed unknown does not move"
            )));
        }
        let problem = match fix.is_empty() && start.is_empty() {
            false => Arc::new(
                (*self.problem)
                    .clone()
                    .with_fixed(&fix)
                    .map_err(|e| PyValueError::new_err(format!("fix: {e}")))?
                    .with_start(&start)
                    .map_err(|e| PyValueError::new_err(format!("start: {e}")))?,
            ),
            true => Arc::clone(&self.problem),
        };
        let sampling = match sampling {
            "uniform" => Sampling::Uniform,
            "latin-hypercube" => Sampling::LatinHypercube,
            _ => {
                return Err(PyValueError::new_err(format!(
                    "sampling must be \"uniform\" or \"latin-hypercube\", not {sampling:?}"
                )));
            }
        };
        if starts.is_none() && !include_nominal {
            return Err(PyValueError::new_err(
                "include_nominal=False is for a multistart: give starts=N (one fit begins at the nominal point or at start=)",
            ));
        }
        if starts.is_some() && !include_nominal && !start.is_empty() {
            return Err(PyValueError::new_err(
                "start sets the first start of the multistart, which include_nominal=False draws instead: give one of them",
            ));
        }
        let options = match starts {
            None => None,
            Some(n) => {
                let options = MultistartOptions {
                    starts: n,
                    seed,
                    sampling,
                    guess: include_nominal,
                    ..MultistartOptions::default()
                };
                options.validate().map_err(|e| PyValueError::new_err(e.to_string()))?;
                Some(options)
            }
        };
        let raised = Arc::new(Raised::default());
        let outcome = interruptible(py, &raised, || match &options {
            None => {
                heard(progress, &raised, None, || traced(trials, &raised, || method.fit(&problem)))
                    .map(|e| (e, None))
            }
            Some(options) => {
                let told = |s: StartDone| {
                    if let Some(callback) = &progress {
                        tell(callback, &raised, |d| {
                            d.set_item("start", s.start)?;
                            d.set_item("done", s.done)?;
                            d.set_item("total", s.total)?;
                            d.set_item("objective", s.objective)?;
                            d.set_item("converged", s.converged)
                        });
                    }
                };
                sysid_montecarlo::multistart_observed(&*method, &problem, options, &told)
                    .map(|run| (run.best, Some(run.starts)))
            }
        });
        let result = |(estimate, starts)| fit_result(py, &problem, &self.name, estimate, starts);
        if let Some(error) = raised.take() {
            return Err(with_result(py, error, outcome.ok().map(result)));
        }
        result(outcome.map_err(sysid_error)?)
    }

    /// Profile likelihoods around the fit `method` reaches from the nominal point: each
    /// unknown of `only` (names; every free unknown by default) held along a path while the
    /// others are fitted again, to where ΔNLL crosses the 95 % threshold (χ²₁/2, or χ²ₖ/2
    /// with `simultaneous`). A `sysid.ProfileResult` over the JSON object of `sysid profile
    /// --format json` (docs/json.md).
    ///
    /// `progress`, a callable, is called while it runs with a dict: `stage` "optimum" with
    /// the fit's iterates (as `fit` tells them), then `stage` "point" as each point of a
    /// profile is fitted (`unknown`, `value`, `objective` and `rise`, ΔNLL from the
    /// optimum), `stage` "traced" as each profile is traced (`unknown`, `done`, `total`),
    /// and `stage` "better" where a profile found a lower point (`objective`, the NLL
    /// there, and `was`). Points and profiles are told from the threads that fit them. An
    /// exception it raises, or Ctrl-C, stops the run and is raised with what it had as its
    /// `result` (profiles not done labelled `stopped`).
    #[pyo3(signature = (method=None, only=None, simultaneous=false, max_points=60, max_iterations=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn profile<'py>(
        &self,
        py: Python<'py>,
        method: Option<&str>,
        only: Option<Bound<'py, PyAny>>,
        simultaneous: bool,
        max_points: i128,
        max_iterations: Option<i128>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        if let Some(p) = &progress
            && !p.bind(py).is_callable()
        {
            return Err(PyTypeError::new_err("progress must be a callable (or None)"));
        }
        // A profile re-optimises the others at every point: at least one of each.
        let max_points = whole("max_points", max_points, 1)? as usize;
        let max_iterations =
            max_iterations.map(|n| whole("max_iterations", n, 1)).transpose()?.map(|n| n as usize);
        let settings = settings(max_iterations, None, None, None, true)?;
        let method = build(method, &settings)?;
        let names = self.problem.names();
        let mut which = Vec::new();
        let only: Vec<String> = match only {
            None => Vec::new(),
            Some(o) if o.is_instance_of::<pyo3::types::PyString>() => {
                return Err(PyTypeError::new_err(format!(
                    "only takes a list of names, got the name {}: write only=[{}]",
                    o.repr()?,
                    o.repr()?
                )));
            }
            Some(o) => o.extract().map_err(|_| {
                PyTypeError::new_err(format!(
                    "only takes a list of names, got {}",
                    o.repr().map(|r| r.to_string()).unwrap_or_default()
                ))
            })?,
        };
        for n in only {
            let i = names.iter().position(|x| *x == n).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "only: {n:?} is not a profiled unknown (unknowns: {}; noise scales set in closed form are not profiled)",
                    names.join(", ")
                ))
            })?;
            if which.contains(&i) {
                return Err(PyValueError::new_err(format!("only: {n:?} is named twice")));
            }
            which.push(i);
        }
        let threshold = sysid_profile::threshold_95(simultaneous.then_some(names.len()));
        let options = sysid_profile::ProfileOptions {
            max_steps: max_points,
            threshold,
            ..Default::default()
        };
        let problem = &self.problem;
        let raised = Arc::new(Raised::default());
        let hears_optimum = progress.as_ref().map(|p| p.clone_ref(py));
        let optimum = interruptible(py, &raised, || {
            heard(hears_optimum, &raised, Some("optimum"), || method.fit(problem))
        });
        if let Some(error) = raised.take() {
            // Stopped while the optimum was fitted: no profile yet, but the fit so far.
            let fit = |optimum| fit_result(py, problem, &self.name, optimum, None);
            return Err(with_result(py, error, optimum.ok().map(fit)));
        }
        let optimum = optimum.map_err(sysid_error)?;
        // No profile from a start every fit fails from (its NLLs were all NaN).
        unusable_start(problem, &optimum)?;
        let profiled = interruptible(py, &raised, || {
            let told = |p: sysid_profile::Progress<'_>| {
                let Some(callback) = &progress else { return };
                tell(callback, &raised, |d| match p {
                    sysid_profile::Progress::Point { unknown, point, rise } => {
                        d.set_item("stage", "point")?;
                        d.set_item("unknown", &names[unknown])?;
                        d.set_item("value", point.value)?;
                        d.set_item("objective", point.nll)?;
                        d.set_item("rise", rise)
                    }
                    sysid_profile::Progress::Traced { unknown, done, total } => {
                        d.set_item("stage", "traced")?;
                        d.set_item("unknown", &names[unknown])?;
                        d.set_item("done", done)?;
                        d.set_item("total", total)
                    }
                    sysid_profile::Progress::Better { point, was } => {
                        d.set_item("stage", "better")?;
                        d.set_item("objective", point.nll)?;
                        d.set_item("was", was)
                    }
                });
            };
            sysid_profile::profile_from_optimum(&*method, problem, optimum, &which, &options, &told)
        });
        let result = |profiled: sysid_profile::Profiled| {
            let json = serde_json::to_string(&profiled.record(&self.name, threshold))
                .expect("a profile record serialises");
            py.import("sysid._result")?.getattr("ProfileResult")?.call1((json,))
        };
        if let Some(error) = raised.take() {
            return Err(with_result(py, error, profiled.ok().map(result)));
        }
        result(profiled.map_err(sysid_error)?)
    }

    /// For scripts/python/overhead.py: the seconds per evaluation of what a Rust program calls
    /// for the NLL and its gradient at the point `z` on the parameter scale (its noise scales
    /// taken as the problem holds them), `repeat` times in a loop without Python, so that the
    /// binding's cost is measured against it in the same process.
    fn _rust_seconds_per_evaluation(
        &self,
        py: Python<'_>,
        z: Vector,
        repeat: usize,
    ) -> PyResult<f64> {
        let mut z = self.coordinates(&z.0, Scale::Parameter)?;
        z.truncate(self.problem.unknowns().len());
        let problem = &self.problem;
        py.allow_threads(|| {
            let start = std::time::Instant::now();
            for _ in 0..repeat.max(1) {
                let lin = problem.residuals_and_jacobian(&z)?;
                std::hint::black_box((problem.nll(&lin), &lin.gradient));
            }
            Ok(start.elapsed().as_secs_f64() / repeat.max(1) as f64)
        })
        .map_err(|e: sysid_ode::OdeError| sysid_error(e))
    }

    fn __repr__(&self) -> String {
        // The parameters are the unknowns and the noise scales, as `parameter_names` has them.
        let scales = self.problem.scales().len();
        format!(
            "sysid.Problem({:?}: {} parameters ({} unknowns, {} noise scale{}), {} experiment{})",
            self.name,
            self.parameters().len(),
            self.problem.unknowns().len(),
            scales,
            if scales == 1 { "" } else { "s" },
            self.problem.experiments().len(),
            if self.problem.experiments().len() == 1 { "" } else { "s" }
        )
    }
}

/// The first exception a run met (its progress callback's, or a signal's such as Ctrl-C's
/// KeyboardInterrupt), raised once the run returns, and the flag that asks the run to stop at
/// its next iteration ([`sysid_core::observer::stop_when`]), set with it.
#[derive(Default)]
struct Raised {
    error: Mutex<Option<PyErr>>,
    stop: Arc<AtomicBool>,
}

impl Raised {
    /// Keeps `e` (unless an earlier exception is kept) and asks the run to stop.
    fn keep(&self, e: PyErr) {
        self.lock().get_or_insert(e);
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Whether an exception is kept.
    fn is_set(&self) -> bool {
        self.lock().is_some()
    }

    /// The exception kept, if any.
    fn take(&self) -> Option<PyErr> {
        self.lock().take()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Option<PyErr>> {
        self.error.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The `sysid.FitResult` of `estimate`, a fit of `problem` called `name`, with a
/// multistart's `starts` where there are some; an error where the start was unusable.
fn fit_result<'py>(
    py: Python<'py>,
    problem: &Problem<AnySystem>,
    name: &str,
    estimate: sysid_core::Estimate,
    starts: Option<sysid_montecarlo::multistart::Starts>,
) -> PyResult<Bound<'py, PyAny>> {
    unusable_start(problem, &estimate)?;
    let mut value = serde_json::to_value(estimate.record(name)).expect("a fit record serialises");
    if let (Some(s), Some(map)) = (starts, value.as_object_mut()) {
        map.insert("starts".into(), serde_json::to_value(s).expect("starts serialise"));
    }
    py.import("sysid._result")?.getattr("FitResult")?.call1((value.to_string(),))
}

/// `error`, the exception that stopped a run (Ctrl-C's KeyboardInterrupt, or one its
/// `progress` callback raised), with what the run had when it stopped as its `result`
/// attribute: a fit's best point (termination `interrupted`), a multistart's starts, the
/// profiles with the points traced before the stop. Where the run returned nothing usable
/// (`result` None, or an error building it), or where the exception has a `result` of its
/// own (a user's exception class), `error` is raised as it was. A note added to the
/// exception says where the result is, so a traceback tells the user.
fn with_result<'py>(
    py: Python<'py>,
    error: PyErr,
    result: Option<PyResult<Bound<'py, PyAny>>>,
) -> PyErr {
    let Some(Ok(result)) = result else { return error };
    let value = error.value(py);
    // An exception whose class refuses attributes (__slots__) is raised without it.
    if !value.hasattr("result").unwrap_or(true) && value.setattr("result", &result).is_ok() {
        let kind = result.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        let _ = value.call_method1(
            "add_note",
            (format!("sysid: the run stopped here; what it had is this exception's .result (a sysid.{kind})"),),
        );
    }
    error
}

/// How often the Python thread looks for signals while a run works.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// The stack of the thread a run works on: the main thread's usual 8 MiB, not a spawned
/// thread's 2 MiB.
const RUN_STACK: usize = 8 << 20;

/// Runs `work` (a fit, a multistart, profiles) on a thread of its own while this thread,
/// Python's main one, waits for it without the GIL and looks for signals every
/// [`SIGNAL_POLL`]: a signal handler's exception (Ctrl-C's KeyboardInterrupt) is kept in
/// `raised`, which asks the work to stop at its next iteration; the caller raises it once
/// `work` has returned. (Run on Python's thread, the work heard Ctrl-C only when it returned:
/// the handlers run only there, between Python's own instructions.) Called from any other
/// thread (a fit that a progress callback starts runs on the calling run's threads), `work`
/// runs in place, where signals are not heard: it stops with the run that called it, and
/// on `raised`'s flag.
fn interruptible<R: Send>(py: Python<'_>, raised: &Raised, work: impl FnOnce() -> R + Send) -> R {
    let flag = Arc::clone(&raised.stop);
    if !on_main_thread(py) {
        return py.allow_threads(|| sysid_core::observer::stop_when(flag, work));
    }
    let outer = sysid_core::observer::current_stop();
    std::thread::scope(|scope| {
        let (done, finished) = std::sync::mpsc::channel::<()>();
        // In a mutex only so that the wait, made without the GIL, may borrow it.
        let finished = Mutex::new(finished);
        let worker = std::thread::Builder::new()
            .name("sysid-run".into())
            .stack_size(RUN_STACK)
            .spawn_scoped(scope, move || {
                let out = sysid_core::observer::stop_within(outer, || {
                    sysid_core::observer::stop_when(flag, work)
                });
                // The receiver may be gone only if this thread outlives the wait, which it
                // does not.
                let _ = done.send(());
                out
            })
            .expect("a thread for the run");
        loop {
            let waited = py.allow_threads(|| {
                finished.lock().unwrap_or_else(|e| e.into_inner()).recv_timeout(SIGNAL_POLL)
            });
            match waited {
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                // Done, or the worker panicked (its sender dropped): join says which.
                _ => break,
            }
            if let Err(e) = py.check_signals() {
                raised.keep(e);
            }
        }
        worker.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

/// Whether this is Python's main thread, the one its signal handlers run on.
fn on_main_thread(py: Python<'_>) -> bool {
    let main = || -> PyResult<bool> {
        let threading = py.import("threading")?;
        Ok(threading.call_method0("current_thread")?.is(&threading.call_method0("main_thread")?))
    };
    main().unwrap_or(false)
}

/// Calls `callback` with a dict that `fill` fills, unless an earlier call raised; the
/// first exception is kept in `raised`, which stops the run at its next iteration, for the
/// run to raise when it returns. The lock is not held while the callback runs (a callback
/// may itself fit, on these threads).
fn tell(
    callback: &Py<PyAny>,
    raised: &Raised,
    fill: impl FnOnce(&Bound<'_, PyDict>) -> PyResult<()>,
) {
    if raised.is_set() {
        return;
    }
    let outcome = Python::with_gil(|py| {
        let d = PyDict::new(py);
        fill(&d).and_then(|()| callback.call1(py, (d,)).map(drop))
    });
    if let Err(e) = outcome {
        raised.keep(e);
    }
}

/// `fit`, run on this thread with each iterate it records told to `callback` (where there
/// is one) as a dict: `stage` where given, `iteration`, `objective`, `cost`, `optimality`,
/// `coarse`.
fn heard<R>(
    callback: Option<Py<PyAny>>,
    raised: &Arc<Raised>,
    stage: Option<&'static str>,
    fit: impl FnOnce() -> R,
) -> R {
    let Some(callback) = callback else { return fit() };
    let raised = Arc::clone(raised);
    let told = move |it: &IterateReport<'_>| {
        tell(&callback, &raised, |d| {
            if let Some(stage) = stage {
                d.set_item("stage", stage)?;
            }
            d.set_item("iteration", it.iteration)?;
            d.set_item("objective", it.objective)?;
            d.set_item("cost", it.cost)?;
            d.set_item("optimality", it.optimality)?;
            d.set_item("coarse", it.coarse)
        })
    };
    observe(told, fit)
}

/// `fit`, run on this thread with each trial step a trust-region method judges in it told
/// to `callback` (where there is one) as a dict of the keys of docs/json.md's trial lines
/// (`actual` and `ratio` None where the trial could not be integrated).
fn traced<R>(callback: Option<Py<PyAny>>, raised: &Arc<Raised>, fit: impl FnOnce() -> R) -> R {
    let Some(callback) = callback else { return fit() };
    let raised = Arc::clone(raised);
    let told = move |t: &TrialReport<'_>| {
        tell(&callback, &raised, |d| {
            d.set_item("method", t.method)?;
            d.set_item("model", t.model)?;
            d.set_item("from", t.from)?;
            d.set_item("radius", t.radius)?;
            d.set_item("step", t.step)?;
            d.set_item("lambda", t.lambda)?;
            d.set_item("predicted", t.predicted)?;
            d.set_item("actual", t.actual.is_finite().then_some(t.actual))?;
            d.set_item("ratio", t.ratio.is_finite().then_some(t.ratio))?;
            d.set_item("accepted", t.accepted)
        })
    };
    observe_trials(told, fit)
}

/// The method names `fit` accepts, in the registry's order, the default first.
#[pyfunction]
fn methods() -> Vec<&'static str> {
    let mut names = Registry::<AnySystem>::standard().names();
    let default = Role::Default.method();
    names.retain(|n| *n != default);
    names.insert(0, default);
    names
}

#[pymodule]
fn _sysid(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyProblem>()?;
    m.add("SysidError", m.py().get_type::<SysidError>())?;
    m.add_function(wrap_pyfunction!(methods, m)?)?;
    Ok(())
}
