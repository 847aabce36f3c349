//! The unknowns z: chosen initial values and parameters, with starting guesses, optional
//! bounds and an optional logarithmic scale.

use serde::{Deserialize, Serialize};

/// ln of the smallest positive normal number: the least coordinate a log-scale value keeps.
const LN_SMALLEST: f64 = -708.396_418_532_264_1;
/// ln of the largest finite number, less a little: the largest coordinate a log-scale value
/// keeps.
const LN_LARGEST: f64 = 709.782_712_893_383_9;

/// One quantity to identify: a parameter, or the initial value of a state (named after the
/// state).
///
/// On a log scale (`log = true`) the method works with ln(value), which keeps the value
/// positive and makes relative changes uniform; estimates and standard errors are reported
/// as values (the standard error by the delta method, value · σ(ln value)).
///
/// Bounds hold inside every method's step (on the log scale as [ln min, ln max]): Goodman's
/// projected Newton step and quasilinearization's least squares solve the step's subproblem
/// within the box ([`minimise_in_box`](crate::method::minimise_in_box)); the argmin baseline maps
/// the unknown to a free coordinate and holds it on its bound where the projected
/// Gauss–Newton model does.
///
/// ```
/// use sysid_core::Unknown;
///
/// let k = Unknown::new("k", 0.5).min(1e-3).max(10.0).log();
/// // The methods move z = ln k; estimates, errors and bounds are reported on k itself.
/// assert_eq!(k.coordinate(0.5), 0.5f64.ln());
/// assert!((k.value(k.coordinate(2.0)) - 2.0).abs() < 1e-15);
/// assert_eq!(k.coordinate_bounds(), (1e-3f64.ln(), 10f64.ln()));
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unknown {
    /// A parameter's name, or a state's name for its initial value.
    pub name: String,
    /// The starting guess (as a value, also on a log scale).
    pub guess: f64,
    /// Lower bound, if any.
    pub min: Option<f64>,
    /// Upper bound, if any.
    pub max: Option<f64>,
    /// Estimate ln(value) instead of the value.
    pub log: bool,
    /// A normal prior, added to the objective (none: the likelihood alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<Prior>,
    /// How multistart draws its starts (none: uniformly on its scale within its bounds).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initialization: Option<Initialization>,
}

/// The distribution multistart draws an unknown's starts from (PEtab's
/// `initializationPriorType` and `initializationPriorParameters`): `distribution` with
/// parameters (a, b) of T(θ), T the identity, ln or log10 (`on`); a draw outside the bounds
/// is moved onto the nearer one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Initialization {
    /// The distribution.
    pub distribution: Distribution,
    /// Its first parameter: the lower end, the mean or the location.
    pub a: f64,
    /// Its second parameter: the upper end, the standard deviation or the scale.
    pub b: f64,
    /// The scale it is on.
    pub on: crate::Transform,
}

/// A distribution of [`Initialization`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Distribution {
    /// Uniform on [a, b].
    Uniform,
    /// Normal with mean a and standard deviation b.
    Normal,
    /// Laplace with location a and scale b.
    Laplace,
}

impl Distribution {
    /// Its name in model files: "uniform", "normal", "laplace".
    pub fn name(self) -> &'static str {
        match self {
            Distribution::Uniform => "uniform",
            Distribution::Normal => "normal",
            Distribution::Laplace => "laplace",
        }
    }
}

impl Initialization {
    /// Whether the parameters describe a distribution: finite, a < b for a uniform one,
    /// b > 0 otherwise.
    pub fn is_valid(&self) -> bool {
        let finite = self.a.is_finite() && self.b.is_finite();
        finite
            && match self.distribution {
                Distribution::Uniform => self.a < self.b,
                Distribution::Normal | Distribution::Laplace => self.b > 0.0,
            }
    }

    /// The value θ at quantile u ∈ (0, 1) of the distribution (of T(θ)).
    pub fn quantile(&self, u: f64) -> f64 {
        use cdflib::traits::ContinuousCdf;
        let (a, b) = (self.a, self.b);
        let u = u.clamp(f64::MIN_POSITIVE, 1.0 - f64::EPSILON);
        let x = match self.distribution {
            Distribution::Uniform => a + u * (b - a),
            Distribution::Normal => cdflib::Normal::new(a, b)
                .inverse_cdf(u)
                .unwrap_or(if u < 0.5 { a - b } else { a + b }),
            Distribution::Laplace => {
                let c = u - 0.5;
                a - b * c.signum() * (1.0 - 2.0 * c.abs()).ln()
            }
        };
        self.on.invert(x)
    }
}

/// How many units of rounding (ε times the scale of the maps between a coordinate z, its
/// value θ and T(θ): [`Unknown::at_kink`]) T(θ) may be from a Laplace prior's location and be
/// on it.
const KINK_ULPS: f64 = 16.0;

/// A prior on an unknown θ, normal or Laplace on the scale `on` (T the identity, ln or
/// log10), as a residual row r of its own whose ½ r² is the negative log-prior less a
/// constant:
///
/// * normal (mean μ, standard deviation σ): r = (T(θ) − μ)/σ, the negative log-prior
///   ½ r² + ln(σ√(2π));
/// * Laplace (location μ, scale b): ½ r² = |T(θ) − μ|/b, r = sign(d)·√(2|d|/b) with
///   d = T(θ) − μ, the negative log-prior ½ r² + ln(2b). Its gradient r·∂r/∂θ = sign(d)·T′(θ)/b
///   is exact away from μ; at μ, where it jumps, the row's slope is taken as 0. The kink
///   is handled like a bound: every bounded step stays on the side of μ it starts from
///   ([`Unknowns::step_box`]), a step that reaches μ stops on it, and from μ an unknown
///   leaves only where the rest of the objective pulls harder than the prior's slope
///   T′(θ)/b (the subgradient condition, which the certificate tests:
///   [`Bound::PriorLocation`](crate::Bound::PriorLocation)).
///
/// The negative log-prior is reported apart from the likelihood.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    /// Its mean (normal) or location (Laplace), on the scale `on`.
    pub mean: f64,
    /// Its standard deviation (normal) or scale b (Laplace), on the scale `on`.
    pub sd: f64,
    /// The scale it is normal (or Laplace) on.
    pub on: crate::Transform,
    /// Normal or Laplace (a uniform prior is a constant within the bounds: no prior).
    #[serde(default = "normal")]
    pub distribution: Distribution,
}

fn normal() -> Distribution {
    Distribution::Normal
}

impl Prior {
    /// A normal prior of mean `mean` and standard deviation `sd` on the scale `on`.
    pub fn normal(mean: f64, sd: f64, on: crate::Transform) -> Self {
        Self { mean, sd, on, distribution: Distribution::Normal }
    }

    /// A Laplace prior of location `location` and scale `b` on the scale `on`.
    pub fn laplace(location: f64, b: f64, on: crate::Transform) -> Self {
        Self { mean: location, sd: b, on, distribution: Distribution::Laplace }
    }

    /// The residual r and its derivative with respect to θ.
    pub fn residual(&self, value: f64) -> (f64, f64) {
        let d = self.on.apply(value) - self.mean;
        let slope = self.on.derivative(value);
        match self.distribution {
            Distribution::Laplace if d == 0.0 => (0.0, 0.0),
            Distribution::Laplace => {
                let r = d.signum() * (2.0 * d.abs() / self.sd).sqrt();
                let dr = slope / (self.sd * r.abs());
                // At the kink (and where |d| is so small that 1/r overflows): slope 0.
                (r, if r != 0.0 && dr.is_finite() { dr } else { 0.0 })
            }
            _ => (d / self.sd, slope / self.sd),
        }
    }

    /// The negative log-prior less ½ r²: ln(sd·√(2π)) (normal), ln(2b) (Laplace).
    pub fn offset(&self) -> f64 {
        match self.distribution {
            Distribution::Laplace => (2.0 * self.sd).ln(),
            _ => self.sd.ln() + 0.5 * crate::noise::LN_2PI,
        }
    }
}

impl Unknown {
    /// An unbounded unknown on a linear scale.
    pub fn new(name: impl Into<String>, guess: f64) -> Self {
        Self {
            name: name.into(),
            guess,
            min: None,
            max: None,
            log: false,
            prior: None,
            initialization: None,
        }
    }
    /// With a lower bound.
    pub fn min(self, min: f64) -> Self {
        Self { min: Some(min), ..self }
    }
    /// With an upper bound.
    pub fn max(self, max: f64) -> Self {
        Self { max: Some(max), ..self }
    }
    /// On a logarithmic scale.
    pub fn log(self) -> Self {
        Self { log: true, ..self }
    }
    /// With a prior.
    pub fn prior(self, prior: Prior) -> Self {
        Self { prior: Some(prior), ..self }
    }
    /// With the distribution multistart draws its starts from.
    pub fn initialization(self, initialization: Initialization) -> Self {
        Self { initialization: Some(initialization), ..self }
    }

    /// The coordinate z of a value.
    pub fn coordinate(&self, value: f64) -> f64 {
        if self.log { value.ln() } else { value }
    }
    /// The value of a coordinate z. On a log scale the value is a positive normal number
    /// whatever z is: a coordinate that runs off towards ±∞ (a rate driven to 0) gives the
    /// smallest or largest one, never 0 or ∞ (the certificate then finds the unknown
    /// undetermined: the model no longer responds to it).
    pub fn value(&self, z: f64) -> f64 {
        if !self.log {
            return z;
        }
        // exp(ln b) may round to a neighbour of b: a coordinate on its bound, or past it by
        // rounding, is the bound's value itself. One further past is its own value (`sysid
        // evaluate --set` beyond a bound evaluates there, not on the bound).
        let (lo, hi) = self.coordinate_bounds();
        let near = |b: f64| (z - b).abs() <= 1e-12 * b.abs().max(1.0);
        match (self.min, self.max) {
            (Some(min), _) if z <= lo && near(lo) => min.max(f64::MIN_POSITIVE),
            (_, Some(max)) if z >= hi && near(hi) => max.min(f64::MAX),
            _ => z.clamp(LN_SMALLEST, LN_LARGEST).exp(),
        }
    }
    /// d value / d z: 1, or the value itself on a log scale.
    pub fn scale(&self, z: f64) -> f64 {
        if self.log { self.value(z) } else { 1.0 }
    }
    /// The scale of the coordinate at z, by which the certificate tells a flat unknown
    /// (docs of [`Certificate`](crate::Certificate)): 1 on a log scale (an e-fold of the
    /// value); on a linear scale the larger of |z|, |guess| and 1 (a generous scale, so that
    /// a linear unknown of small magnitude is not called flat).
    pub fn coordinate_scale(&self, z: f64) -> f64 {
        if self.log { 1.0 } else { z.abs().max(self.guess.abs()).max(1.0) }
    }

    /// The coordinate z_k of its Laplace prior's location μ, where the prior |T(θ) − μ|/b
    /// has its kink, when the location is a value the unknown can take within its bounds
    /// (`None` without a Laplace prior).
    pub fn kink(&self) -> Option<f64> {
        let prior = self.prior.filter(|p| p.distribution == Distribution::Laplace)?;
        let theta = prior.on.invert(prior.mean);
        if !theta.is_finite() || (self.log && theta <= 0.0) {
            return None;
        }
        let z = self.coordinate(theta);
        let (lo, hi) = self.coordinate_bounds();
        (z.is_finite() && lo <= z && z <= hi).then_some(z)
    }

    /// Whether z is on the kink of its Laplace prior ([`kink`](Self::kink)) to rounding: d =
    /// T(θ(z)) − μ is within [`KINK_ULPS`]·ε·(|μ| + |dT/dz·z|) of 0, the rounding of T and of
    /// the maps between z and θ (0 exactly where the location is 0 on the unknown's own
    /// scale). The prior's row is then r = 0 with slope 0
    /// ([`prior_residual`](Self::prior_residual)): one test for the step, the certificate and
    /// the row.
    pub fn at_kink(&self, z: f64) -> bool {
        let Some(prior) = self.prior.filter(|p| p.distribution == Distribution::Laplace) else {
            return false;
        };
        if self.kink().is_none() {
            return false;
        }
        let theta = self.value(z);
        let d = prior.on.apply(theta) - prior.mean;
        let rounding = prior.mean.abs() + (prior.on.derivative(theta) * self.scale(z) * z).abs();
        d.abs() <= KINK_ULPS * f64::EPSILON * rounding
    }

    /// Its prior's row r and ∂r/∂θ at `value`: [`Prior::residual`], with r = 0 and slope 0 on
    /// the kink of a Laplace prior ([`at_kink`](Self::at_kink) at the value's coordinate);
    /// `None` without a prior.
    pub fn prior_residual(&self, value: f64) -> Option<(f64, f64)> {
        let prior = self.prior?;
        Some(match self.at_kink(self.coordinate(value)) {
            true => (0.0, 0.0),
            false => prior.residual(value),
        })
    }

    /// The slope of its Laplace prior's ½ r² = |T(θ) − μ|/b along the coordinate on either
    /// side of the kink, |T′(θ)·dθ/dz|/b at z: the least pull of the rest of the objective's
    /// half gradient that moves the unknown off its prior's location (0 without a Laplace
    /// prior).
    pub fn kink_slope(&self, z: f64) -> f64 {
        match self.prior {
            Some(p) if p.distribution == Distribution::Laplace => {
                let theta = self.value(z);
                (p.on.derivative(theta) * self.scale(z) / p.sd).abs()
            }
            _ => 0.0,
        }
    }

    /// The bounds in coordinates.
    pub fn coordinate_bounds(&self) -> (f64, f64) {
        let lo = self.min.map_or(f64::NEG_INFINITY, |v| if self.log { v.ln() } else { v });
        let hi = self.max.map_or(f64::INFINITY, |v| if self.log { v.ln() } else { v });
        (lo, hi)
    }

    /// Checks guess, bounds and scale; returns a message for the first problem.
    pub(crate) fn validate(&self) -> Result<(), String> {
        if !self.guess.is_finite() {
            return Err(format!("the guess {} is not a finite number", self.guess));
        }
        for (what, b) in [("min", self.min), ("max", self.max)] {
            if let Some(v) = b
                && v.is_nan()
            {
                return Err(format!("{what} is not a number"));
            }
        }
        if self.log {
            if self.guess <= 0.0 {
                return Err(format!(
                    "a log-scale unknown needs a positive guess, got {}",
                    self.guess
                ));
            }
            if let Some(m) = self.min
                && m <= 0.0
            {
                return Err(format!("a log-scale unknown needs a positive min, got {m}"));
            }
        }
        if let Some(i) = &self.initialization
            && !i.is_valid()
        {
            return Err(format!(
                "an initialization needs finite parameters, a < b for a uniform one and b > 0 otherwise: got {} with a = {}, b = {}",
                i.distribution.name(),
                i.a,
                i.b
            ));
        }
        if let Some(p) = &self.prior {
            if p.distribution == Distribution::Uniform {
                return Err("a prior is normal or laplace (a uniform one is the bounds)".into());
            }
            if !(p.mean.is_finite() && p.sd > 0.0 && p.sd.is_finite()) {
                return Err(format!(
                    "a prior needs a finite mean and a positive sd, got mean {} and sd {}",
                    p.mean, p.sd
                ));
            }
            if p.on != crate::Transform::Lin && !self.log && !self.min.is_some_and(|m| m > 0.0) {
                return Err(format!(
                    "a prior on the {} scale needs a positive unknown: a log scale or a positive min",
                    p.on.name()
                ));
            }
        }
        let (lo, hi) = (self.min.unwrap_or(f64::NEG_INFINITY), self.max.unwrap_or(f64::INFINITY));
        if lo >= hi {
            return Err(format!("min {lo} is not below max {hi}"));
        }
        if !(lo..=hi).contains(&self.guess) {
            return Err(format!("the guess {} lies outside [{lo}, {hi}]", self.guess));
        }
        Ok(())
    }
}

/// The free unknowns of a problem, in order: what the methods move.
#[derive(Clone, Debug, PartialEq)]
pub struct Unknowns {
    list: Vec<Unknown>,
}

impl Unknowns {
    pub(crate) fn new(list: Vec<Unknown>) -> Self {
        Self { list }
    }
    /// Number of unknowns k.
    pub fn len(&self) -> usize {
        self.list.len()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }
    /// The unknowns in order.
    pub fn list(&self) -> &[Unknown] {
        &self.list
    }
    /// Their names in order.
    pub fn names(&self) -> Vec<String> {
        self.list.iter().map(|u| u.name.clone()).collect()
    }
    /// The starting guesses, as values.
    pub fn guesses(&self) -> Vec<f64> {
        self.list.iter().map(|u| u.guess).collect()
    }
    /// Coordinates z of values.
    pub fn coordinates(&self, values: &[f64]) -> Vec<f64> {
        self.list.iter().zip(values).map(|(u, &v)| u.coordinate(v)).collect()
    }
    /// Values of coordinates z.
    pub fn values(&self, z: &[f64]) -> Vec<f64> {
        self.list.iter().zip(z).map(|(u, &z)| u.value(z)).collect()
    }
    /// The box of corrections δ that keep z + δ within the bounds: (lo − z, hi − z), infinite
    /// where an unknown has no bound. Every bounded step minimises its model over it.
    ///
    /// The kink z_k of a Laplace prior ([`Unknown::kink`]) is a bound of the side the
    /// unknown is on: a step from z > z_k goes no lower than z_k, and one from below no
    /// higher (the prior's Gauss–Newton row, r ∝ √|d|, would otherwise step to the mirror
    /// point −d and back). On the kink, with `gradient` the half gradient g there (the
    /// prior's row has slope 0 on it, so g is the rest of the objective's), the unknown is
    /// held while |g_i| is at most the prior's slope ([`Unknown::kink_slope`]: no side
    /// descends), and otherwise may move only to the side −g_i points at.
    pub fn step_box(&self, z: &[f64], gradient: &[f64]) -> (Vec<f64>, Vec<f64>) {
        self.list
            .iter()
            .zip(z.iter().zip(gradient))
            .map(|(u, (&z, &g))| {
                let (mut lo, mut hi) = u.coordinate_bounds();
                if let Some(kink) = u.kink() {
                    if u.at_kink(z) {
                        if g.abs() <= u.kink_slope(z) {
                            (lo, hi) = (z, z);
                        } else if g > 0.0 {
                            hi = z;
                        } else {
                            lo = z;
                        }
                    } else if z > kink {
                        lo = lo.max(kink);
                    } else {
                        hi = hi.min(kink);
                    }
                }
                (lo - z, hi - z)
            })
            .unzip()
    }
    /// The half gradient of the objective as a step from z sees it: on the kink of a Laplace
    /// prior, whose row has slope 0 there, the rest of the gradient g_i is lowered by the
    /// prior's slope w_i on the side it opens ([`step_box`](Self::step_box)): g_i − sign(g_i)·w_i
    /// where |g_i| > w_i, 0 where the unknown is held. A quadratic model with it predicts the
    /// first-order change of a step off the kink exactly (the prior's |d|/b grows by w_i·|δ_i|).
    /// `None` where no unknown is on its kink.
    pub fn one_sided(&self, z: &[f64], gradient: &[f64]) -> Option<Vec<f64>> {
        let mut out = gradient.to_vec();
        let mut any = false;
        for ((u, &z), g) in self.list.iter().zip(z).zip(out.iter_mut()) {
            if u.at_kink(z) {
                any = true;
                let w = u.kink_slope(z);
                *g = if g.abs() <= w { 0.0 } else { *g - g.signum() * w };
            }
        }
        any.then_some(out)
    }

    /// z + s·δ, on the bounds exactly where it reaches them (a δ from [`step_box`] keeps z
    /// inside; this only removes rounding).
    ///
    /// [`step_box`]: Self::step_box
    pub fn moved(&self, z: &[f64], delta: &[f64], s: f64) -> Vec<f64> {
        let mut out: Vec<f64> = z.iter().zip(delta).map(|(z, d)| z + s * d).collect();
        // A step that the kink of a Laplace prior bounds ends on it: past it, or short of it
        // by the rounding of z + (z_k − z), is rounding.
        for ((u, &from), to) in self.list.iter().zip(z).zip(out.iter_mut()) {
            let Some(kink) = u.kink() else { continue };
            if u.at_kink(from) {
                continue;
            }
            let crossed = (from - kink).signum() != (*to - kink).signum();
            let rounding = 4.0 * f64::EPSILON * (from.abs() + kink.abs());
            if crossed || (*to - kink).abs() <= rounding {
                *to = kink;
            }
        }
        self.project(&mut out);
        out
    }
    /// Moves coordinates onto the bounds they are outside of (rounding, or a start given
    /// outside); returns whether any moved. A coordinate on the kink of its Laplace prior to
    /// rounding ([`Unknown::at_kink`]: a step that stopped there) is put on it exactly.
    pub fn project(&self, z: &mut [f64]) -> bool {
        let mut clipped = false;
        for (u, zi) in self.list.iter().zip(z.iter_mut()) {
            let (lo, hi) = u.coordinate_bounds();
            let c = zi.clamp(lo, hi);
            clipped |= *zi < lo || *zi > hi;
            *zi = match u.kink() {
                Some(kink) if u.at_kink(c) => kink,
                _ => c,
            };
        }
        clipped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A log-scale coordinate run off towards ±∞ (a step in a flat direction) still gives a
    /// positive normal value, never 0 or ∞; within range the value is exp(z) to the bit.
    #[test]
    fn a_log_scale_value_is_never_zero_or_infinite() {
        let u = Unknown::new("k", 1.0).log();
        for z in [-1e4, -746.0, -708.5, 709.9, 1e4] {
            let v = u.value(z);
            assert!(v >= f64::MIN_POSITIVE && v.is_finite(), "z = {z}: {v}");
            assert_eq!(u.scale(z).to_bits(), v.to_bits());
        }
        assert_eq!(u.value(-3.5).to_bits(), (-3.5f64).exp().to_bits());
        assert_eq!(Unknown::new("x", 0.0).value(-1e4).to_bits(), (-1e4f64).to_bits());
    }

    /// A log-scale unknown on its bound reports the bound itself: exp(ln 1e-5) rounds to
    /// 9.999999999999997e-6, which an importer reading the estimate back refuses as outside
    /// [1e-5, 1000].
    #[test]
    fn a_log_scale_value_on_its_bound_is_the_bound() {
        let (lo, hi) = (1e-5_f64, 1e3_f64);
        assert!(lo.ln().exp() < lo, "the rounding this guards against");
        let u = Unknown::new("k", 1.0).min(lo).max(hi).log();
        let (zlo, zhi) = u.coordinate_bounds();
        assert_eq!(u.value(zlo).to_bits(), lo.to_bits());
        assert_eq!(u.value(zhi).to_bits(), hi.to_bits());
        for b in [1e-10_f64, 3e-7, 0.1, 7.0, 1e5, 1e8] {
            let u = Unknown::new("k", 1.0).min(b).max(b * 10.0).log();
            let (zlo, zhi) = u.coordinate_bounds();
            assert!(u.value(zlo) >= b && u.value(zhi) <= b * 10.0, "{b}");
        }
    }

    /// A Laplace prior's ½ r² is |T(θ) − μ|/b, and r·∂r/∂θ its derivative (against central
    /// differences, to 1e-8 relative), on either side of μ and on a log10 scale; at μ the
    /// row's slope is 0.
    #[test]
    fn a_laplace_prior_is_its_absolute_deviation() {
        for (p, theta) in [
            (Prior::laplace(1.0, 3.0, crate::Transform::Lin), 2.5),
            (Prior::laplace(1.0, 3.0, crate::Transform::Lin), -0.5),
            (Prior::laplace(0.2, 0.5, crate::Transform::Log10), 0.9),
            (Prior::laplace(0.2, 0.5, crate::Transform::Log10), 3.0),
        ] {
            let half_square = |v: f64| 0.5 * p.residual(v).0.powi(2);
            let (r, dr) = p.residual(theta);
            let d = p.on.apply(theta) - p.mean;
            assert!((half_square(theta) - d.abs() / p.sd).abs() <= 1e-14, "{p:?} at {theta}");
            let h = 1e-6 * theta.abs();
            let numeric = (half_square(theta + h) - half_square(theta - h)) / (2.0 * h);
            assert!((r * dr - numeric).abs() <= 1e-8 * numeric.abs(), "{p:?} at {theta}");
            assert!((p.offset() - (2.0 * p.sd).ln()).abs() <= 1e-15);
        }
        let (r, dr) = Prior::laplace(1.0, 3.0, crate::Transform::Lin).residual(1.0);
        assert!(r == 0.0 && dr == 0.0, "{r} {dr}");
        let (r, dr) = Prior::normal(1.0, 3.0, crate::Transform::Lin).residual(2.5);
        assert!((r - 0.5).abs() <= 1e-15 && (dr - 1.0 / 3.0).abs() <= 1e-15);
    }

    /// A Laplace prior's kink is a bound of the side an unknown is on, and on the kink the
    /// unknown is held while the rest of the gradient is within the prior's slope, else let
    /// go towards −g only. On a log coordinate with a log10 prior the kink is ln 10^μ, whose
    /// value rounds, yet gives r = 0; a coordinate a rounding away is put on it.
    #[test]
    fn a_laplace_kink_bounds_the_step_on_the_side_it_starts() {
        let u = Unknown::new("c", 0.5).min(-3.0).max(3.0).prior(Prior::laplace(
            0.0,
            2.0,
            crate::Transform::Lin,
        ));
        let list = Unknowns::new(vec![u.clone()]);
        assert_eq!(u.kink(), Some(0.0));
        assert_eq!(u.kink_slope(0.7).to_bits(), 0.5f64.to_bits());
        assert_eq!(list.step_box(&[0.7], &[1.0]), (vec![-0.7], vec![2.3]));
        assert_eq!(list.step_box(&[-0.7], &[1.0]), (vec![-2.3], vec![0.7]));
        // On it: |g| ≤ 1/b holds it; beyond, only the descending side is open.
        assert_eq!(list.step_box(&[0.0], &[0.4]), (vec![0.0], vec![0.0]));
        assert_eq!(list.step_box(&[0.0], &[0.6]), (vec![-3.0], vec![0.0]));
        assert_eq!(list.step_box(&[0.0], &[-0.6]), (vec![0.0], vec![3.0]));
        // Without a Laplace prior, or with its location outside the bounds: the bounds alone.
        let plain = Unknowns::new(vec![Unknown::new("c", 0.5).min(-3.0).max(3.0)]);
        assert_eq!(plain.step_box(&[0.7], &[1.0]), (vec![-3.7], vec![2.3]));
        let outside = Unknown::new("c", 0.5).min(1.0).max(3.0).prior(Prior::laplace(
            0.0,
            2.0,
            crate::Transform::Lin,
        ));
        assert_eq!(outside.kink(), None);

        let k =
            Unknown::new("k", 1.0).log().prior(Prior::laplace(-1.3, 0.5, crate::Transform::Log10));
        let zk = k.kink().expect("a kink");
        assert_eq!(zk.to_bits(), (10f64.powf(-1.3)).ln().to_bits());
        assert_eq!(k.prior_residual(k.value(zk)), Some((0.0, 0.0)));
        let list = Unknowns::new(vec![k.clone()]);
        let mut z = [zk + 2.0 * f64::EPSILON * zk.abs()];
        assert!(z[0].to_bits() != zk.to_bits() && k.at_kink(z[0]));
        list.project(&mut z);
        assert_eq!(z[0].to_bits(), zk.to_bits());
        // A step that the kink bounds ends on it exactly, from afar (z + (z_k − z) rounds) or
        // past it by rounding.
        let c = Unknown::new("c", 0.5).prior(Prior::laplace(0.1, 2.0, crate::Transform::Lin));
        let list = Unknowns::new(vec![c.clone()]);
        for from in [1000.3, 37.7, -5.0] {
            let to = list.moved(&[from], &[0.1 - from], 1.0);
            assert_eq!(to[0].to_bits(), 0.1f64.to_bits(), "from {from}");
        }
        // The gradient a step sees on the kink: lowered by the prior's slope 0.5 on the open
        // side, 0 where held; none off the kink.
        assert_eq!(list.one_sided(&[0.1], &[0.6]).map(|g| (g[0] * 1e12).round()), Some(1e11));
        assert_eq!(list.one_sided(&[0.1], &[-0.6]).map(|g| (g[0] * 1e12).round()), Some(-1e11));
        assert_eq!(list.one_sided(&[0.1], &[0.4]).map(|g| g[0].to_bits()), Some(0));
        assert!(list.one_sided(&[0.2], &[0.6]).is_none());
        // At a location 0 the test is exact: a value of 1e-15 keeps its prior's row.
        let tiny =
            Unknown::new("c", 1e-15).prior(Prior::laplace(0.0, 1e-16, crate::Transform::Lin));
        assert!(tiny.at_kink(0.0) && !tiny.at_kink(1e-15));
        assert!(tiny.prior_residual(1e-15).is_some_and(|(r, _)| r > 0.0));
        let mut far = [zk + 1e-9];
        list.project(&mut far);
        assert_eq!(far[0].to_bits(), (zk + 1e-9).to_bits(), "only rounding is put on the kink");
    }
}
