//! Integrator choice and tolerances.

use serde::{Deserialize, Serialize};

/// The integration scheme.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scheme {
    /// Dormand–Prince 5(4) (Hairer's DOPRI5): adaptive, error-controlled, dense output of
    /// order 4. With a fixed step it runs without error control (for order studies).
    #[default]
    Dopri5,
    /// Dormand–Prince 8(5,3) (Hairer's DOP853): adaptive, error-controlled (Hairer's blend of
    /// order-5 and order-3 estimates), dense output of order 7 (three more evaluations on a
    /// step where it is wanted). Twelve evaluations a step against DOPRI5's six, but at tight
    /// tolerances far fewer steps: for rtol of 1e-9 and below on problems that are not stiff.
    /// With a fixed step it runs without error control.
    Dop853,
    /// Classical fourth-order Runge–Kutta with a fixed step; cubic Hermite dense output.
    Rk4,
    /// Rodas4 (Hairer & Wanner): a Rosenbrock method of order 4 for stiff systems,
    /// error-controlled, with dense output of order 3 and an exact Jacobian.
    Rodas4,
    /// Rodas5P (Steinebach 2023): a Rosenbrock method of order 5 for stiff systems,
    /// error-controlled (order-4 estimate), with dense output of order 4 and an exact
    /// Jacobian; about half Rodas4's steps at tight tolerances.
    Rodas5p,
    /// DOPRI5 until its steps are limited by stability rather than accuracy (fifteen
    /// accepted steps in a row with h·λ > 2 by Hairer's estimate from the last stages, or
    /// h·|λ|max > 3 with the Jacobian's spectral radius by power iteration, which still sees
    /// the fast modes once they have decayed), then Rodas5P; back to DOPRI5 where h·|λ|max of
    /// Rodas5P's steps stays below 1 (two refreshes of the estimate in a row, 32 accepted
    /// steps), a third of the way to DOPRI5's stability boundary. At rtol ≤
    /// [`AUTO_DOP853_RTOL`] DOP853 takes DOPRI5's place throughout. What imported PEtab
    /// problems use.
    Auto,
    /// Variable-order, variable-step numerical differentiation formulas (orders 1–4, and
    /// BDF5; Shampine & Reichelt's ode15s) for stiff systems: one to three evaluations and
    /// solves a step, the factorised matrix kept over many steps (CVODE's rules for forming it
    /// again), interpolating polynomial of the step's order as dense output. Not with a fixed
    /// step, nor with state events.
    Bdf,
}

/// The rtol at and below which [`Scheme::Auto`] steps explicitly with DOP853 instead of
/// DOPRI5 (Rodas5P where the model is stiff, as above it). DOP853's order 8 pays at tight
/// tolerances (0.4–0.6 of DOPRI5's time at rtol 1e-12 in the `ode` bench's `-tight` runs and
/// on Borghans), not at the default 1e-8 (1.1–1.4 times). A fit's driver integrates at 1e-11
/// only where it refines; Borghans' fit from nominal, which does for most of its 3 000
/// iterations, takes a third of the time. Not higher: at rtol 1e-9, atol 1e-13 DOP853's
/// longer steps hold a state of Fujita's that lies below atol only to atol, and a fit lost
/// its certificate (docs/petab.md, "DOP853 at tight tolerances").
pub const AUTO_DOP853_RTOL: f64 = 1e-11;

/// A state's absolute tolerance is at most STATE_FLOOR·rtol times its given size
/// ([`Ivp::sized`](crate::Ivp::sized), the model's own initial value): a state of size
/// x0_i ≠ 0 is held to min(atol, STATE_FLOOR·rtol·|x0_i|) + rtol·|x_i| (its sensitivities
/// alike, in their columns' units), at rtol 1e-8 to a thousandth of its initial size. See
/// [`Integrator`].
///
/// Not smaller: the floor is a remedy for states that atol does not control at all (Beer's
/// bacteria from 1e-14 under atol 1e-12), not a tolerance of its own. Measured with the
/// floors taken from every integration's start (steady states included) on the PEtab
/// collection at nominal: at 1 (every state held to rtol of its initial size) it moved the
/// NLL of five problems by up to 3e-7 and cost Giordano_Nature2020 (a state at 1.7e-8) 25 %
/// of an evaluation's time; at 100 it still moved Brannmark_JBC2010's (a state at 1.8e-9),
/// whose default fit from nominal then stalled at NLL 141.889 instead of certifying
/// 141.82485; at 1e5 only Raimundez_PCB2020's (1.3e-7), at no cost. With the sizes the
/// model's own initial values, none moves (2026-12-07).
pub const STATE_FLOOR: f64 = 1e5;

/// How to integrate: scheme, tolerances and limits. Plain data with documented defaults.
///
/// Error control (DOPRI5): a step is accepted when
/// sqrt(mean_i (e_i / (atol + rtol·max(|x_i|, |x̂_i|)))²) ≤ 1 over every integrated component,
/// the sensitivities included; a state whose size x0_i ≠ 0 is [given](crate::Ivp::sized) has
/// min(atol, [`STATE_FLOOR`]·rtol·|x0_i|) in place of atol (its sensitivities alike).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Integrator {
    /// The scheme (default DOPRI5).
    pub scheme: Scheme,
    /// Relative tolerance (default 1e-8).
    pub rtol: f64,
    /// Absolute tolerance (default 1e-10).
    pub atol: f64,
    /// A fixed step size: required for RK4; for DOPRI5 it switches error control off.
    pub fixed_step: Option<f64>,
    /// Largest step size allowed (default unlimited; JSON writes unlimited as `null`).
    #[serde(with = "unlimited")]
    pub max_step: f64,
    /// First trial step size (default: Hairer's estimate).
    pub initial_step: Option<f64>,
    /// Step budget for one integration, accepted and rejected steps together (default 100 000).
    pub max_steps: usize,
}

/// An upper limit that may be infinite, written `null` in JSON (which has no infinity) and
/// read back as +∞.
mod unlimited {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(value: &f64, s: S) -> Result<S::Ok, S::Error> {
        if value.is_finite() { s.serialize_some(value) } else { s.serialize_none() }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

impl Default for Integrator {
    fn default() -> Self {
        Self {
            scheme: Scheme::Dopri5,
            rtol: 1e-8,
            atol: 1e-10,
            fixed_step: None,
            max_step: f64::INFINITY,
            initial_step: None,
            max_steps: 100_000,
        }
    }
}

impl Integrator {
    /// DOPRI5 with the given tolerances.
    pub fn dopri5(rtol: f64, atol: f64) -> Self {
        Self { rtol, atol, ..Self::default() }
    }

    /// Rodas4 (stiff) with the given tolerances.
    pub fn rodas4(rtol: f64, atol: f64) -> Self {
        Self { scheme: Scheme::Rodas4, rtol, atol, ..Self::default() }
    }

    /// DOP853 (order 8, for tight tolerances) with the given tolerances.
    pub fn dop853(rtol: f64, atol: f64) -> Self {
        Self { scheme: Scheme::Dop853, rtol, atol, ..Self::default() }
    }

    /// Rodas5P (stiff, order 5) with the given tolerances.
    pub fn rodas5p(rtol: f64, atol: f64) -> Self {
        Self { scheme: Scheme::Rodas5p, rtol, atol, ..Self::default() }
    }

    /// The automatic choice (DOPRI5, switching to Rodas5P when stiffness is detected).
    pub fn auto(rtol: f64, atol: f64) -> Self {
        Self { scheme: Scheme::Auto, rtol, atol, ..Self::default() }
    }

    /// The multistep scheme (stiff, orders 1 to 5) with the given tolerances.
    pub fn bdf(rtol: f64, atol: f64) -> Self {
        Self { scheme: Scheme::Bdf, rtol, atol, ..Self::default() }
    }

    /// RK4 with a fixed step h.
    pub fn rk4(h: f64) -> Self {
        Self { scheme: Scheme::Rk4, fixed_step: Some(h), ..Self::default() }
    }

    /// The same integrator with another step budget.
    pub fn with_max_steps(self, max_steps: usize) -> Self {
        Self { max_steps, ..self }
    }

    /// The same integrator with a fixed step (no error control).
    pub fn with_fixed_step(self, h: f64) -> Self {
        Self { fixed_step: Some(h), ..self }
    }

    /// Checks the settings; returns the first setting that cannot be used, by name.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        let bad = |name, problem: String| Err(InvalidSetting { name, problem });
        if !(self.rtol > 0.0 && self.rtol < 1.0) {
            return bad(
                "rtol",
                format!(
                    "must be positive and below 1 (a relative error of 100 % or more controls nothing), got {}",
                    shortest(self.rtol)
                ),
            );
        }
        if self.rtol < MIN_RTOL {
            return bad(
                "rtol",
                format!(
                    "must be at least {MIN_RTOL:e}: below it the rounding of double precision (1.1e-16 per operation, accumulating over the steps) is larger than the error asked for, got {:e}",
                    self.rtol
                ),
            );
        }
        if !(self.atol >= 0.0 && self.atol.is_finite()) {
            return bad(
                "atol",
                format!("must be a finite non-negative number, got {}", shortest(self.atol)),
            );
        }
        if let Some(h) = self.fixed_step
            && !(h > 0.0 && h.is_finite())
        {
            return bad("fixed_step", format!("must be positive, got {}", shortest(h)));
        }
        if let Some(h) = self.initial_step
            && !(h > 0.0 && h.is_finite())
        {
            return bad("initial_step", format!("must be positive, got {}", shortest(h)));
        }
        if self.scheme == Scheme::Auto && self.fixed_step.is_some() {
            return bad(
                "fixed_step",
                "cannot be used with the automatic choice of scheme, which needs error control"
                    .into(),
            );
        }
        if self.scheme == Scheme::Bdf && self.fixed_step.is_some() {
            return bad(
                "fixed_step",
                "cannot be used with BDF, whose order and step follow its error estimates".into(),
            );
        }
        if self.scheme == Scheme::Rk4 && self.fixed_step.is_none() {
            return bad("fixed_step", "is needed by RK4, which has no error control".into());
        }
        if self.max_step.is_nan() || self.max_step <= 0.0 {
            return bad("max_step", format!("must be positive, got {}", self.max_step));
        }
        if self.max_steps == 0 {
            return bad("max_steps", "must be at least 1".into());
        }
        Ok(())
    }
}

/// `v` as an error quotes it: exponent form outside [1e-4, 1e9) (`-1e-8`, not
/// `-0.00000001`).
fn shortest(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && a.is_finite() && !(1e-4..1e9).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// The smallest relative tolerance an integration accepts (Hairer's DOPRI5 refuses anything
/// at or below 10 × the unit round-off, 2.2e-16).
pub const MIN_RTOL: f64 = 1e-14;

/// An integrator setting that cannot be used: its name (the field of [`Integrator`]) as data,
/// so that a caller can name it as its user spells it (`--rtol`, `[integrator] rtol`), and
/// what is wrong with it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InvalidSetting {
    /// The field: `rtol`, `atol`, `fixed_step`, `max_step` or `max_steps`.
    pub name: &'static str,
    /// What is wrong, without the name: "must be positive, got -1".
    pub problem: String,
}

impl std::fmt::Display for InvalidSetting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}", self.name, self.problem)
    }
}

impl std::error::Error for InvalidSetting {}
