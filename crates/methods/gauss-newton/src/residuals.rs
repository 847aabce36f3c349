//! The problem as argmin sees it: the weighted residual vector r(w) and its Jacobian, in
//! the free coordinates w of [`Map`] (w = z for unbounded unknowns).
//!
//! argmin asks for r and J separately; with sensitivities both come from one integration and
//! are kept together with the w they belong to, so a request for J at the w whose r was just
//! computed costs nothing (the pairing mistake of argmin issue #342 cannot happen). Every
//! integration goes through the driver's [`Evaluations`], so the line search's trial points
//! count against the fit's integration budget.

use std::cell::RefCell;

use argmin::core::{Error, Jacobian, Operator};
use nalgebra::{DMatrix, DVector};
use sysid_core::{Evaluations, Failure, Linearization};
use sysid_ode::System;

use crate::bounds::Map;
use crate::options::JacobianSource;

/// One evaluation at argmin's parameters w.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Where, in argmin's coordinates.
    pub w: Vec<f64>,
    /// Weighted residuals (infinite where the model could not be evaluated, so that a line
    /// search backs off).
    pub r: DVector<f64>,
    /// ∂r/∂w, if computed.
    pub jacobian: Option<DMatrix<f64>>,
    /// The model's linearization at z(w) in the problem's coordinates (with sensitivities).
    pub linearization: Option<Linearization>,
}

/// What the operator remembers between argmin's calls within one fit.
#[derive(Default)]
pub struct Cache {
    /// The last evaluation.
    pub last: Option<Evaluation>,
    /// The first failure met since the last [`take_failure`](Cache::take_failure).
    pub failure: Option<Failure>,
}

impl Cache {
    /// The evaluation at exactly w, if it is the last one.
    pub fn at(&self, w: &[f64]) -> Option<&Evaluation> {
        self.last.as_ref().filter(|e| e.w == w)
    }
    /// The failure met, if any, forgetting it.
    pub fn take_failure(&mut self) -> Option<Failure> {
        self.failure.take()
    }
}

/// The residual operator handed to argmin for one iteration.
pub struct Residuals<'a, S> {
    /// The fit's counted, budgeted evaluations.
    pub ev: &'a Evaluations<'a, S>,
    /// Where the Jacobian comes from.
    pub source: JacobianSource,
    /// The change of variables per unknown.
    pub maps: &'a [Map],
    /// The evaluations remembered.
    pub cache: &'a RefCell<Cache>,
}

impl<S: System> Residuals<'_, S> {
    /// z(w).
    pub fn z(&self, w: &[f64]) -> Vec<f64> {
        self.maps.iter().zip(w).map(|(m, &w)| m.z(w)).collect()
    }

    /// The evaluation at w (with the Jacobian when the source gives it for free), reusing
    /// the last one when it was at w. A used-up budget is an error; a point where the model
    /// cannot be evaluated gets infinite residuals and its failure is remembered.
    pub fn evaluate(&self, w: &[f64]) -> Result<Evaluation, Failure> {
        if let Some(e) = self.cache.borrow().at(w) {
            return Ok(e.clone());
        }
        let z = self.z(w);
        let outcome = match self.source {
            JacobianSource::Sensitivities => {
                self.ev.residuals_and_jacobian(&z).map(|lin| self.with_sensitivities(w, lin))
            }
            JacobianSource::FiniteDifferences => self.ev.residuals(&z).map(|r| Evaluation {
                w: w.to_vec(),
                r,
                jacobian: None,
                linearization: None,
            }),
        };
        let evaluation = match outcome {
            Ok(e) => e,
            Err(budget @ Failure::Budget { .. }) => return Err(budget),
            Err(failure) => {
                self.cache.borrow_mut().failure.get_or_insert(failure);
                Evaluation {
                    w: w.to_vec(),
                    r: DVector::from_element(self.ev.problem().n_residuals(), f64::INFINITY),
                    jacobian: None,
                    linearization: None,
                }
            }
        };
        self.cache.borrow_mut().last = Some(evaluation.clone());
        Ok(evaluation)
    }

    fn with_sensitivities(&self, w: &[f64], lin: Linearization) -> Evaluation {
        let rows = lin.residuals.as_ref().expect("the residual form has residuals");
        let mut jacobian = rows.jacobian.clone();
        for (j, (m, &wj)) in self.maps.iter().zip(w).enumerate() {
            if *m != Map::Free {
                jacobian.column_mut(j).scale_mut(m.dz_dw(wj));
            }
        }
        Evaluation {
            w: w.to_vec(),
            r: rows.r.clone(),
            jacobian: Some(jacobian),
            linearization: Some(lin),
        }
    }

    /// J at w: from the evaluation there, or by forward differences
    /// (r(w + h_j e_j) − r(w)) / h_j, h_j = √η · max(|w_j|, 1), η = max(rtol, machine ε).
    pub fn jacobian_at(&self, w: &[f64]) -> Result<DMatrix<f64>, Failure> {
        let evaluation = self.evaluate(w)?;
        if let Some(j) = evaluation.jacobian {
            return Ok(j);
        }
        if !evaluation.r.iter().all(|v| v.is_finite()) {
            return Err(self.failure_at(w));
        }
        let r = evaluation.r.clone();
        let eta = self.ev.problem().integrator().rtol.max(f64::EPSILON);
        let mut jacobian = DMatrix::zeros(r.len(), w.len());
        for j in 0..w.len() {
            let h = eta.sqrt() * w[j].abs().max(1.0);
            let mut shifted = w.to_vec();
            shifted[j] += h;
            let rj = self.ev.residuals(&self.z(&shifted))?;
            // The step actually taken, as represented in floating point.
            let h = shifted[j] - w[j];
            jacobian.set_column(j, &((rj - &r) / h));
        }
        let mut cache = self.cache.borrow_mut();
        if let Some(last) = cache.last.as_mut().filter(|e| e.w == w) {
            last.jacobian = Some(jacobian.clone());
        }
        Ok(jacobian)
    }

    /// The failure remembered for a point whose residuals are infinite.
    pub fn failure_at(&self, w: &[f64]) -> Failure {
        self.cache.borrow_mut().take_failure().unwrap_or_else(|| Failure::NonFinite {
            what: "the residuals".into(),
            at: self.ev.problem().unknowns().values(&self.z(w)),
        })
    }
}

fn to_error(failure: Failure) -> Error {
    Error::msg(failure.to_string())
}

impl<S: System> Operator for &Residuals<'_, S> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;
    fn apply(&self, w: &Self::Param) -> Result<Self::Output, Error> {
        self.evaluate(w.as_slice()).map(|e| e.r).map_err(|f| self.remember(f))
    }
}

impl<S: System> Jacobian for &Residuals<'_, S> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;
    fn jacobian(&self, w: &Self::Param) -> Result<Self::Jacobian, Error> {
        self.jacobian_at(w.as_slice()).map_err(|f| self.remember(f))
    }
}

impl<S: System> Residuals<'_, S> {
    /// Keeps a failure that ends argmin's iteration, for the driver to report.
    fn remember(&self, failure: Failure) -> Error {
        let error = to_error(failure.clone());
        self.cache.borrow_mut().failure = Some(failure);
        error
    }
}
