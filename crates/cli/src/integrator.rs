//! `--integrator`, `--rtol`, `--atol`, `--step`: the integrator a problem is solved with.

use clap::{Args, ValueEnum};
use sysid_core::Problem;
use sysid_ode::{Integrator, Scheme, System};

/// The integration scheme, by its command-line name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SchemeArg {
    /// Dormand–Prince 5(4), adaptive (explicit; the default for non-stiff systems).
    Dopri5,
    /// Classical Runge–Kutta 4 with the fixed step --fixed-step (explicit).
    Rk4,
    /// Rodas4, a Rosenbrock method of order 4 with exact Jacobians (implicit, for stiff
    /// systems).
    Rodas4,
    /// DOPRI5, switching to Rodas4 when the steps become limited by stability.
    Auto,
}

impl From<SchemeArg> for Scheme {
    fn from(s: SchemeArg) -> Self {
        match s {
            SchemeArg::Dopri5 => Scheme::Dopri5,
            SchemeArg::Rk4 => Scheme::Rk4,
            SchemeArg::Rodas4 => Scheme::Rodas4,
            SchemeArg::Auto => Scheme::Auto,
        }
    }
}

/// Integrator settings that replace the system's or model file's where given.
#[derive(Args, Debug, Clone, Copy, Default)]
pub struct IntegratorArgs {
    /// Integration scheme (default: the system's or model file's).
    #[arg(long, value_enum, value_name = "SCHEME")]
    pub integrator: Option<SchemeArg>,
    /// Relative tolerance of the integrator (default: the system's).
    #[arg(long, value_name = "RTOL", allow_negative_numbers = true)]
    pub rtol: Option<f64>,
    /// Absolute tolerance of the integrator (default: the system's).
    #[arg(long, value_name = "ATOL", allow_negative_numbers = true)]
    pub atol: Option<f64>,
    /// A fixed step size (required by rk4; turns error control off for the others).
    #[arg(long = "fixed-step", value_name = "H", allow_negative_numbers = true)]
    pub fixed_step: Option<f64>,
    /// Step budget of one integration (default 100000).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub max_steps: Option<usize>,
}

impl IntegratorArgs {
    /// `integrator` with the settings given on the command line.
    pub fn apply_to(&self, integrator: Integrator) -> anyhow::Result<Integrator> {
        self.validate()?;
        let mut out = integrator;
        if let Some(scheme) = self.integrator {
            out.scheme = scheme.into();
            // A fixed step belongs to the scheme it was given for.
            out.fixed_step = None;
        }
        out.rtol = self.rtol.unwrap_or(out.rtol);
        out.atol = self.atol.unwrap_or(out.atol);
        if self.fixed_step.is_some() {
            out.fixed_step = self.fixed_step;
        }
        out.max_steps = self.max_steps.unwrap_or(out.max_steps);
        if out.scheme == Scheme::Rk4 && out.fixed_step.is_none() {
            anyhow::bail!("--integrator rk4 needs a step size: add --fixed-step H");
        }
        out.validate().map_err(|e| anyhow::anyhow!("integrator: {e}"))?;
        Ok(out)
    }

    /// Checks each value given, naming its option (the combination with the system's or
    /// model file's settings is checked once applied).
    fn validate(&self) -> anyhow::Result<()> {
        if let Some(rtol) = self.rtol
            && !(rtol > 0.0 && rtol.is_finite())
        {
            anyhow::bail!("--rtol must be positive, got {rtol}");
        }
        if let Some(atol) = self.atol
            && !(atol >= 0.0 && atol.is_finite())
        {
            anyhow::bail!("--atol must be non-negative, got {atol}");
        }
        if let Some(h) = self.fixed_step
            && !(h > 0.0 && h.is_finite())
        {
            anyhow::bail!("--fixed-step must be positive, got {h}");
        }
        if self.max_steps == Some(0) {
            anyhow::bail!("--max-steps must be at least 1");
        }
        Ok(())
    }

    /// The problem with its integrator changed as given on the command line.
    pub fn apply<S: System>(&self, problem: Problem<S>) -> anyhow::Result<Problem<S>> {
        if self.integrator.is_none()
            && self.rtol.is_none()
            && self.atol.is_none()
            && self.fixed_step.is_none()
            && self.max_steps.is_none()
        {
            return Ok(problem);
        }
        let integrator = self.apply_to(*problem.integrator())?;
        Ok(problem.with_integrator(integrator)?)
    }
}
