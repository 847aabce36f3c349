//! The problem as argmin sees it: the weighted residual vector r(w) and its Jacobian, in the
//! free coordinates w of [`Map`] of the unknowns not held on a bound.
//!
//! Every evaluation is made and remembered in the problem's coordinates z (Jacobian ∂r/∂z
//! over all unknowns) and mapped to argmin's w on request, so a request for J at the point
//! whose r was just computed costs nothing (the pairing mistake of argmin issue #342 cannot
//! happen), and changing which unknowns are held does not invalidate it. Every integration
//! goes through the driver's [`Evaluations`], so the line search's trial points count against
//! the fit's integration budget.

use std::cell::RefCell;

use argmin::core::{CostFunction, Error, Gradient, Jacobian, Operator};
use nalgebra::{DMatrix, DVector};
use sysid_core::{Failure, Linearization, method::Evaluations};
use sysid_ode::System;

use crate::bounds::Map;
use crate::options::JacobianSource;

/// One evaluation at coordinates z.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Where.
    pub z: Vec<f64>,
    /// Weighted residuals (infinite where the model could not be evaluated, so that a line
    /// search backs off).
    pub r: DVector<f64>,
    /// ∂r/∂z over all unknowns, if computed (sensitivities, or forward differences).
    pub jacobian: Option<DMatrix<f64>>,
    /// The model's linearization at z from its sensitivities.
    pub linearization: Option<Linearization>,
}

impl Evaluation {
    /// Whether the model could be evaluated here.
    pub fn is_finite(&self) -> bool {
        self.r.iter().all(|v| v.is_finite())
    }
}

/// What the operator remembers between argmin's calls within one fit.
#[derive(Default)]
pub struct Cache {
    /// The last evaluation.
    pub last: Option<Evaluation>,
    /// The first failure met since it was last taken.
    pub failure: Option<Failure>,
}

impl Cache {
    /// The evaluation at exactly z, if it is the last one.
    pub fn at(&self, z: &[f64]) -> Option<&Evaluation> {
        self.last.as_ref().filter(|e| e.z == z)
    }
}

/// argmin's coordinates: the unknowns not held on a bound, each through its map.
#[derive(Clone, Debug)]
pub struct Space {
    /// The map of every unknown.
    pub maps: Vec<Map>,
    /// The value each held unknown is held at (its bound), `None` for a free one.
    pub held: Vec<Option<f64>>,
    /// w of every unknown (the held ones' entries are unused).
    pub w: Vec<f64>,
}

impl Space {
    /// The free unknowns' indices.
    pub fn free(&self) -> Vec<usize> {
        (0..self.maps.len()).filter(|&i| self.held[i].is_none()).collect()
    }
    /// The free unknowns' w.
    pub fn free_w(&self) -> Vec<f64> {
        self.free().iter().map(|&i| self.w[i]).collect()
    }
    /// Sets the free unknowns' w.
    pub fn set_free_w(&mut self, w: &[f64]) {
        for (&i, &v) in self.free().iter().zip(w) {
            self.w[i] = v;
        }
    }
    /// z for the free unknowns at `free_w` (the held ones at their bounds).
    pub fn z(&self, free_w: &[f64]) -> Vec<f64> {
        let mut z: Vec<f64> = self
            .maps
            .iter()
            .zip(&self.w)
            .zip(&self.held)
            .map(|((m, &w), h)| h.unwrap_or(m.z(w)))
            .collect();
        for (&i, &w) in self.free().iter().zip(free_w) {
            z[i] = self.maps[i].z(w);
        }
        z
    }
    /// z at the current w.
    pub fn current_z(&self) -> Vec<f64> {
        self.z(&self.free_w())
    }
    /// Whether another unknown is held, or one at another value, than in `other`.
    pub fn holds_otherwise(&self, other: &Space) -> bool {
        self.held.iter().zip(&other.held).any(|(a, b)| !same_hold(*a, *b))
    }
    /// Moves to z, on the way from a point of `before` to one of `self`: the unknowns both
    /// hold at the same value stay held, every other one is free at its z.
    pub fn hold_between(&mut self, before: &Space, z: &[f64]) {
        for (i, &zi) in z.iter().enumerate() {
            if self.held[i].is_none() || !same_hold(self.held[i], before.held[i]) {
                self.held[i] = None;
                self.w[i] = self.maps[i].w(zi);
            }
        }
    }
}

/// Whether two unknowns' holds are the same: both free, or both held at the same value.
fn same_hold(a: Option<f64>, b: Option<f64>) -> bool {
    a.map(f64::to_bits) == b.map(f64::to_bits)
}

/// The residual operator handed to argmin for one iteration.
pub struct Residuals<'a, S> {
    /// The fit's counted, budgeted evaluations.
    pub ev: &'a Evaluations<'a, S>,
    /// Where the Jacobian comes from.
    pub source: JacobianSource,
    /// argmin's coordinates.
    pub space: &'a Space,
    /// Typical magnitudes of the coordinates (from the start), for difference steps.
    pub typical: &'a [f64],
    /// The evaluations remembered.
    pub cache: &'a RefCell<Cache>,
}

impl<S: System> Residuals<'_, S> {
    /// The evaluation at z, reusing the last one when it was at z. A used-up budget is an
    /// error; a point where the model cannot be evaluated gets infinite residuals and its
    /// failure is remembered.
    pub fn evaluate(&self, z: &[f64]) -> Result<Evaluation, Failure> {
        if let Some(e) = self.cache.borrow().at(z) {
            return Ok(e.clone());
        }
        let outcome = match self.source {
            JacobianSource::Sensitivities => self.ev.residuals_and_jacobian(z).map(|lin| {
                let rows = lin.residuals.as_ref().expect("the residual form has residuals");
                Evaluation {
                    z: z.to_vec(),
                    r: rows.r.clone(),
                    jacobian: Some(rows.jacobian.clone()),
                    linearization: Some(lin),
                }
            }),
            JacobianSource::FiniteDifferences => self.ev.residuals(z).map(|r| Evaluation {
                z: z.to_vec(),
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
                    z: z.to_vec(),
                    r: DVector::from_element(self.ev.problem().n_residuals(), f64::INFINITY),
                    jacobian: None,
                    linearization: None,
                }
            }
        };
        self.cache.borrow_mut().last = Some(evaluation.clone());
        Ok(evaluation)
    }

    /// The evaluation at z with ∂r/∂z: from the sensitivities, or by forward differences in
    /// the coordinate each unknown is estimated in (ln for a log scale),
    /// (r(z + h_j e_j) − r(z)) / h_j with h_j = √ε_mach · max(|z_j|, typical_j), backwards
    /// where the forward step would leave the bounds.
    pub fn with_jacobian(&self, z: &[f64]) -> Result<Evaluation, Failure> {
        let mut evaluation = self.evaluate(z)?;
        if evaluation.jacobian.is_some() || !evaluation.is_finite() {
            return Ok(evaluation);
        }
        let unknowns = self.ev.problem().unknowns().list();
        let r = &evaluation.r;
        let mut jacobian = DMatrix::zeros(r.len(), z.len());
        for j in 0..z.len() {
            let h = f64::EPSILON.sqrt() * z[j].abs().max(self.typical[j]);
            let (_, hi) = unknowns[j].coordinate_bounds();
            let mut shifted = z.to_vec();
            shifted[j] = if z[j] + h <= hi { z[j] + h } else { z[j] - h };
            let rj = self.ev.residuals(&shifted)?;
            // The step actually taken, as represented in floating point.
            let h = shifted[j] - z[j];
            jacobian.set_column(j, &((rj - r) / h));
        }
        evaluation.jacobian = Some(jacobian);
        let mut cache = self.cache.borrow_mut();
        if let Some(last) = cache.last.as_mut().filter(|e| e.z == z) {
            last.jacobian.clone_from(&evaluation.jacobian);
        }
        Ok(evaluation)
    }

    /// The failure remembered for a point whose residuals are infinite.
    pub fn failure_at(&self, z: &[f64]) -> Failure {
        self.cache.borrow_mut().failure.take().unwrap_or_else(|| Failure::NonFinite {
            what: "the residuals are not finite".into(),
            at: self.ev.problem().unknowns().values(z),
        })
    }

    /// ∂r/∂w of the free unknowns at free w: ∂r/∂z times dz/dw.
    fn jacobian_w(&self, w: &[f64]) -> Result<DMatrix<f64>, Failure> {
        let z = self.space.z(w);
        let e = self.with_jacobian(&z)?;
        let Some(jz) = e.jacobian else { return Err(self.failure_at(&z)) };
        let free = self.space.free();
        let mut jw = jz.select_columns(&free);
        for (c, (&i, &wi)) in free.iter().zip(w).enumerate() {
            jw.column_mut(c).scale_mut(self.space.maps[i].dz_dw(wi));
        }
        Ok(jw)
    }

    /// Keeps a failure that ends argmin's iteration, for the driver to report.
    fn remember(&self, failure: Failure) -> Error {
        let error = Error::msg(failure.to_string());
        self.cache.borrow_mut().failure = Some(failure);
        error
    }
}

impl<S: System> Operator for &Residuals<'_, S> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;
    fn apply(&self, w: &Self::Param) -> Result<Self::Output, Error> {
        self.evaluate(&self.space.z(w.as_slice())).map(|e| e.r).map_err(|f| self.remember(f))
    }
}

impl<S: System> Jacobian for &Residuals<'_, S> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;
    fn jacobian(&self, w: &Self::Param) -> Result<Self::Jacobian, Error> {
        self.jacobian_w(w.as_slice()).map_err(|f| self.remember(f))
    }
}

/// The line search's view: the cost ½‖r‖² and its gradient Jᵀr, consistent with each
/// other (argmin's own Gauss–Newton line search pairs ‖r‖ with the gradient of ½‖r‖², which
/// rejects every step once ‖r‖ is large).
pub struct HalfSquares<'a, S>(pub &'a Residuals<'a, S>);

impl<S: System> CostFunction for HalfSquares<'_, S> {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, w: &Self::Param) -> Result<f64, Error> {
        let r = Operator::apply(&self.0, w)?;
        Ok(0.5 * r.norm_squared())
    }
}

impl<S: System> Gradient for HalfSquares<'_, S> {
    type Param = DVector<f64>;
    type Gradient = DVector<f64>;
    fn gradient(&self, w: &Self::Param) -> Result<Self::Gradient, Error> {
        let r = Operator::apply(&self.0, w)?;
        let j = Jacobian::jacobian(&self.0, w)?;
        Ok(j.tr_mul(&r))
    }
}
