//! The problem as argmin sees it: the weighted residual vector r(z) and its Jacobian.
//!
//! argmin asks for r and J separately; both come from one integration with sensitivities
//! and are kept together with the z they belong to, so a request for J at the z whose r was
//! just computed costs nothing (the pairing mistake of argmin issue #342 cannot happen).

use std::sync::Mutex;

use argmin::core::{Error, Jacobian, Operator};
use nalgebra::{DMatrix, DVector};
use sysid_core::{Linearization, Problem};
use sysid_ode::{Counts, OdeError, System};

use crate::bounds::Map;
use crate::options::JacobianSource;

/// One evaluation: r (and J when computed) at argmin's parameters (w; z when unmapped).
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Where, in argmin's coordinates.
    pub z: Vec<f64>,
    /// Weighted residuals.
    pub r: DVector<f64>,
    /// Their Jacobian, if computed.
    pub jacobian: Option<DMatrix<f64>>,
}

impl Evaluation {
    /// As a linearization (requires the Jacobian).
    pub fn linearization(&self) -> Option<Linearization> {
        let j = self.jacobian.as_ref()?;
        Some(Linearization {
            z: self.z.clone(),
            cost: self.r.norm_squared(),
            gradient: j.tr_mul(&self.r),
            normal: j.tr_mul(j),
            residuals: None,
            counts: Counts::default(),
        })
    }
}

/// The state shared with argmin through `&self`.
#[derive(Default)]
struct Shared {
    last: Option<Evaluation>,
    /// Every evaluation with a Jacobian, in order: the source of the iteration history.
    log: Vec<Evaluation>,
    counts: Counts,
    failure: Option<OdeError>,
}

/// The residual operator of a problem for argmin, in the free coordinates w of
/// [`Map`](crate::bounds::Map) (w = z for unbounded unknowns).
pub struct Residuals<'a, S> {
    problem: &'a Problem<S>,
    source: JacobianSource,
    maps: Vec<Map>,
    shared: Mutex<Shared>,
}

impl<'a, S: System> Residuals<'a, S> {
    /// The operator of `problem` with Jacobians from `source`, bounded unknowns mapped to
    /// free coordinates.
    pub fn new(problem: &'a Problem<S>, source: JacobianSource) -> Self {
        let maps = problem.unknowns().list().iter().map(Map::of).collect();
        Self { problem, source, maps, shared: Mutex::new(Shared::default()) }
    }

    /// The same without mapping (w = z), for evaluations in the problem's coordinates.
    pub fn unmapped(problem: &'a Problem<S>, source: JacobianSource) -> Self {
        let maps = vec![Map::Free; problem.unknowns().len()];
        Self { problem, source, maps, shared: Mutex::new(Shared::default()) }
    }

    /// Whether any unknown is mapped (has bounds).
    pub fn is_mapped(&self) -> bool {
        self.maps.iter().any(|m| *m != Map::Free)
    }

    /// z(w).
    pub fn z(&self, w: &[f64]) -> Vec<f64> {
        self.maps.iter().zip(w).map(|(m, &w)| m.z(w)).collect()
    }

    /// w(z).
    pub fn w(&self, z: &[f64]) -> Vec<f64> {
        self.maps.iter().zip(z).map(|(m, &z)| m.w(z)).collect()
    }

    /// The first integration failure, if any (a run that converged may have met failures at
    /// rejected trial points).
    pub fn failure(&self) -> Option<OdeError> {
        self.lock().failure.clone()
    }
    /// Work of all integrations so far.
    pub fn counts(&self) -> Counts {
        self.lock().counts
    }
    /// The evaluation with a Jacobian at exactly z, if one was made.
    pub fn evaluation_at(&self, z: &[f64]) -> Option<Evaluation> {
        self.lock().log.iter().rev().find(|e| e.z == z).cloned()
    }
    /// The most recent evaluation with a Jacobian.
    pub fn last_with_jacobian(&self) -> Option<Evaluation> {
        self.lock().log.last().cloned()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Shared> {
        self.shared.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    fn fail(&self, e: OdeError) -> Error {
        let message = e.to_string();
        self.lock().failure.get_or_insert(e);
        Error::msg(message)
    }

    /// r at z, reusing the last evaluation when it was at z.
    fn residuals(&self, z: &[f64]) -> Result<DVector<f64>, Error> {
        if let Some(last) = self.lock().last.as_ref().filter(|e| e.z == z) {
            return Ok(last.r.clone());
        }
        let outcome = match self.source {
            JacobianSource::Sensitivities => self.with_sensitivities(z),
            JacobianSource::FiniteDifferences => match self.problem.residuals(&self.z(z)) {
                Ok((r, counts)) => {
                    self.lock().counts += counts;
                    Ok(Evaluation { z: z.to_vec(), r, jacobian: None })
                }
                Err(e) => Err(self.fail(e)),
            },
        };
        // Where the model cannot be integrated the cost is infinite: argmin's line search
        // then backs off instead of aborting. The failure is kept, and reported if the run
        // ends on it; no result ever carries the infinite cost.
        let evaluation = outcome.unwrap_or_else(|_| Evaluation {
            z: z.to_vec(),
            r: DVector::from_element(self.problem.n_residuals(), f64::INFINITY),
            jacobian: None,
        });
        let r = evaluation.r.clone();
        self.lock().last = Some(evaluation);
        Ok(r)
    }

    fn with_sensitivities(&self, w: &[f64]) -> Result<Evaluation, Error> {
        let lin = self.problem.residuals_and_jacobian(&self.z(w)).map_err(|e| self.fail(e))?;
        let rows = lin.residuals.expect("the residual form has residuals");
        let mut jacobian = rows.jacobian;
        for (j, (m, &wj)) in self.maps.iter().zip(w).enumerate() {
            if *m != Map::Free {
                jacobian.column_mut(j).scale_mut(m.dz_dw(wj));
            }
        }
        let evaluation = Evaluation { z: w.to_vec(), r: rows.r, jacobian: Some(jacobian) };
        let mut shared = self.lock();
        shared.counts += lin.counts;
        shared.log.push(evaluation.clone());
        Ok(evaluation)
    }

    /// J at z.
    fn jacobian_at(&self, z: &[f64]) -> Result<DMatrix<f64>, Error> {
        if let Some(j) =
            self.lock().last.as_ref().filter(|e| e.z == z).and_then(|e| e.jacobian.clone())
        {
            return Ok(j);
        }
        let evaluation = match self.source {
            JacobianSource::Sensitivities => self.with_sensitivities(z)?,
            JacobianSource::FiniteDifferences => self.finite_differences(z)?,
        };
        let j = evaluation.jacobian.clone().expect("a Jacobian was computed");
        self.lock().last = Some(evaluation);
        Ok(j)
    }

    /// Forward differences: (r(z + h_j e_j) − r(z)) / h_j.
    pub fn finite_differences(&self, z: &[f64]) -> Result<Evaluation, Error> {
        let r = self.residuals(z)?;
        let eta = self.problem.integrator().rtol.max(f64::EPSILON);
        let mut jacobian = DMatrix::zeros(r.len(), z.len());
        for j in 0..z.len() {
            let h = eta.sqrt() * z[j].abs().max(1.0);
            let mut shifted = z.to_vec();
            shifted[j] += h;
            let (rj, counts) =
                self.problem.residuals(&self.z(&shifted)).map_err(|e| self.fail(e))?;
            self.lock().counts += counts;
            // The step actually taken, as represented in floating point.
            let h = shifted[j] - z[j];
            jacobian.set_column(j, &((rj - &r) / h));
        }
        let evaluation = Evaluation { z: z.to_vec(), r, jacobian: Some(jacobian) };
        self.lock().log.push(evaluation.clone());
        Ok(evaluation)
    }
}

impl<S: System> Operator for &Residuals<'_, S> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;
    fn apply(&self, z: &Self::Param) -> Result<Self::Output, Error> {
        self.residuals(z.as_slice())
    }
}

impl<S: System> Jacobian for &Residuals<'_, S> {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;
    fn jacobian(&self, z: &Self::Param) -> Result<Self::Jacobian, Error> {
        self.jacobian_at(z.as_slice())
    }
}
