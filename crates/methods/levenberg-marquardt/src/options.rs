//! Options of Levenberg–Marquardt.

use serde::{Deserialize, Serialize};
use sysid_core::{Driven, DriverOptions, OptionsError};

/// The curvature of the model a step minimises: m_λ's A.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Hessian {
    /// A = JᵀWJ, the Gauss–Newton matrix every method shares: exact where the residuals
    /// vanish, and it leaves out Σ rᵢ∇²rᵢ, which large residuals make matter.
    #[default]
    GaussNewton,
    /// Fletcher and Xu's hybrid (IMA J. Numer. Anal. 7, 1987, 371–389): JᵀWJ while ε falls
    /// fast, else A = ∂U/∂z, half the full Hessian of ε, from forward differences of U (the
    /// sensitivities' gradient; k more linearizations per iterate, [`sysid_core::method::differenced_hessian`]).
    Hybrid,
    /// Dennis, Gay and Welsch's adaptive model (NL2SOL; ACM TOMS 7, 1981, 348–368): JᵀWJ,
    /// or JᵀWJ + S with S a secant approximation of Σ rᵢ∇²rᵢ updated from the gradients at
    /// the ends of every accepted step (no extra integration), whichever of the two
    /// predicted the last step's decrease better.
    Adaptive,
}

/// Options with MINPACK's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevenbergMarquardtOptions {
    /// The iteration's budgets and tolerances, shared by every method ([`DriverOptions`]).
    pub driver: DriverOptions,
    /// The first trust-region radius is this multiple of ‖D z₀‖ (or this, when it is 0):
    /// MINPACK's `factor`, default 100.
    pub factor: f64,
    /// Most trial steps rejected in a row before the iteration stops with no descent
    /// (default 30; each halves the radius at least).
    pub max_rejections: usize,
    /// The curvature of the step's model: JᵀWJ (Levenberg–Marquardt proper, the default), or
    /// Fletcher and Xu's switch between it and the full Hessian of ε (`hybrid-newton`).
    #[serde(default)]
    pub hessian: Hessian,
    /// Bend each step along the valley by Transtrum and Sethna's geodesic acceleration (two
    /// plain integrations per iterate and one per further trial; [`sysid_core::method::Geodesic`]).
    /// Default off: measured on the PEtab problems it costs 2–3 times the time for the same
    /// share of starts reaching the best value (docs/methods.md).
    #[serde(default)]
    pub geodesic: bool,
    /// While many trials are rejected ([`SCREEN_FROM`](crate::SCREEN_FROM) of the recent
    /// ones), integrate each trial plain first and with sensitivities only where that does not
    /// reject it (default on). It changes what a fit costs, not the points it visits.
    #[serde(default = "on")]
    pub screen: bool,
    /// While the fit crawls (its cost fell by less than [`CRAWL_FALL`](crate::CRAWL_FALL)
    /// of ε over the last [`CRAWL_WINDOW`](crate::CRAWL_WINDOW) iterations), correct a
    /// rejected trial by a chord step with the iterate's Jacobian and judge the corrected
    /// point instead (one more linearization per corrected trial; docs/methods.md). Default
    /// off; `nl2sol` turns it on.
    #[serde(default)]
    pub correct: bool,
}

fn on() -> bool {
    true
}

impl Default for LevenbergMarquardtOptions {
    fn default() -> Self {
        Self {
            driver: DriverOptions::default(),
            factor: 100.0,
            max_rejections: 30,
            hessian: Hessian::GaussNewton,
            geodesic: false,
            screen: true,
            correct: false,
        }
    }
}

impl LevenbergMarquardtOptions {
    /// The same options with the first radius `factor`·‖D z₀‖.
    pub fn with_factor(self, factor: f64) -> Self {
        Self { factor, ..self }
    }

    /// The same options with at most `max_rejections` trial steps rejected in a row.
    pub fn with_max_rejections(self, max_rejections: usize) -> Self {
        Self { max_rejections, ..self }
    }

    /// The same options with another model curvature.
    pub fn with_hessian(self, hessian: Hessian) -> Self {
        Self { hessian, ..self }
    }

    /// The same options with geodesic acceleration on or off.
    pub fn with_geodesic(self, geodesic: bool) -> Self {
        Self { geodesic, ..self }
    }

    /// The same options with the screening of trials on or off.
    pub fn with_screen(self, screen: bool) -> Self {
        Self { screen, ..self }
    }

    /// The same options with the crawl's corrector on or off.
    pub fn with_correct(self, correct: bool) -> Self {
        Self { correct, ..self }
    }

    /// Checks the method's own options (the driver's are checked by
    /// [`drive`](sysid_core::method::drive), once).
    pub fn validate(&self) -> Result<(), OptionsError> {
        OptionsError::positive("factor", self.factor)
    }
}

impl Driven for LevenbergMarquardtOptions {
    fn driver_mut(&mut self) -> &mut DriverOptions {
        &mut self.driver
    }
}
