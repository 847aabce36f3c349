//! State events: where a condition on the state falls through zero the state is reset, and
//! its sensitivities jump with it ([`System::n_events`]). The driver locates the time; this
//! module evaluates the conditions and applies a firing.

use num_dual::Dual64;

use crate::signal::Side;
use crate::system::System;
use crate::wrt::Wrt;

/// Every event's condition at (t, y).
pub(crate) fn conditions<S: System>(sys: &S, t: f64, y: &[f64], p: &[f64], c: &mut [f64]) {
    for (i, c) in c.iter_mut().enumerate() {
        *c = sys.event_condition(i, t, y, p);
    }
}

/// Event `i` fires at τ: y becomes r_i(τ, y, α), the state of x = [y; S row by row] (k
/// columns `wrt`; none for the state alone), and each column jumps by
///
/// S⁺ = R_y S + R_α + (R_y g⁻ − g⁺)·∂τ/∂z,  ∂τ/∂z = −(c_y S + c_α)/(c_y g⁻ + c_t),
///
/// g⁻ and g⁺ the right-hand side before and after the reset, c_i the condition and R the
/// reset's Jacobians ([`Reset`]). `u` is work space for the inputs.
pub(crate) fn fire<S: System>(
    sys: &S,
    i: usize,
    tau: f64,
    (p, wrt, u): (&[f64], &[Wrt], &mut [f64]),
    x: &mut [f64],
) {
    let n = sys.signature().n_states();
    let (y, s) = x.split_at_mut(n);
    if wrt.is_empty() {
        let mut y_new = y.to_vec();
        sys.event_reset(i, tau, y, p, &mut y_new);
        y.copy_from_slice(&y_new);
        return;
    }
    let k = wrt.len();
    let mut reset = Reset::new(sys, i, tau, (y, p, u));
    let old = s.to_vec();
    for (j, w) in wrt.iter().enumerate() {
        let (mut c_z, r_z) = match *w {
            Wrt::Parameter(q) => reset.parameter(sys, q),
            Wrt::InitialValue(_) => (0.0, vec![0.0; n]),
        };
        let column = |b: usize| old[b * k + j];
        c_z += (0..n).map(|b| reset.c_y[b] * column(b)).sum::<f64>();
        let dtau = -c_z / reset.rate;
        for a in 0..n {
            let carried: f64 = (0..n).map(|b| reset.r_y[a * n + b] * column(b)).sum();
            s[a * k + j] = carried + r_z[a] + reset.drift[a] * dtau;
        }
    }
    y.copy_from_slice(&reset.y_new);
}

/// A state event as it fired: which, at τ, from the state before it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Fired {
    pub(crate) event: usize,
    pub(crate) tau: f64,
    pub(crate) before: Vec<f64>,
}

/// The derivatives of event `i`'s firing at τ from the state y⁻ before it: the condition's
/// c_y, the reset's R_y, the rate c_y g⁻ + c_t at which the condition falls and the drift
/// R_y g⁻ − g⁺ (how the state after the event moves as the event moves). The derivatives in
/// y and α are exact (dual numbers); c_t is a central difference (a condition depends on t
/// only where it is a time, so the difference is exact up to rounding).
pub(crate) struct Reset {
    /// r_i(τ, y⁻, α).
    pub(crate) y_new: Vec<f64>,
    pub(crate) c_y: Vec<f64>,
    /// R_y row by row: r_y[a * n + b] = ∂r_a/∂y_b.
    pub(crate) r_y: Vec<f64>,
    pub(crate) rate: f64,
    pub(crate) drift: Vec<f64>,
    yd: Vec<Dual64>,
    pd: Vec<Dual64>,
    event: usize,
    tau: f64,
}

impl Reset {
    pub(crate) fn new<S: System>(
        sys: &S,
        i: usize,
        tau: f64,
        (y, p, u): (&[f64], &[f64], &mut [f64]),
    ) -> Self {
        let n = y.len();
        let mut y_new = y.to_vec();
        sys.event_reset(i, tau, y, p, &mut y_new);
        let mut rhs = |y: &[f64]| {
            let mut g = vec![0.0; n];
            sys.input_values(tau, Side::After, u);
            sys.rhs(tau, y, p, u, &mut g);
            g
        };
        let (g_before, g_after) = (rhs(y), rhs(&y_new));
        let mut reset = Self {
            y_new,
            c_y: vec![0.0; n],
            r_y: vec![0.0; n * n],
            rate: 0.0,
            drift: Vec::new(),
            yd: y.iter().map(|&v| Dual64::from_re(v)).collect(),
            pd: p.iter().map(|&v| Dual64::from_re(v)).collect(),
            event: i,
            tau,
        };
        // c_y and R_y by one dual-number evaluation per state.
        for b in 0..n {
            reset.yd[b].eps = 1.0;
            let (c, r) = reset.seeded(sys);
            reset.yd[b].eps = 0.0;
            reset.c_y[b] = c;
            for (a, r) in r.iter().enumerate() {
                reset.r_y[a * n + b] = *r;
            }
        }
        let h = 1e-6 * tau.abs().max(1.0);
        let c_t = (sys.event_condition(i, tau + h, y, p) - sys.event_condition(i, tau - h, y, p))
            / (2.0 * h);
        reset.rate = reset.c_y.iter().zip(&g_before).map(|(c, g)| c * g).sum::<f64>() + c_t;
        reset.drift = (0..n)
            .map(|a| (0..n).map(|b| reset.r_y[a * n + b] * g_before[b]).sum::<f64>() - g_after[a])
            .collect();
        reset
    }

    /// The condition's and the reset's derivatives in parameter q: (c_α, R_α).
    pub(crate) fn parameter<S: System>(&mut self, sys: &S, q: usize) -> (f64, Vec<f64>) {
        self.pd[q].eps = 1.0;
        let out = self.seeded(sys);
        self.pd[q].eps = 0.0;
        out
    }

    fn seeded<S: System>(&self, sys: &S) -> (f64, Vec<f64>) {
        let mut out = self.yd.clone();
        sys.event_reset(self.event, self.tau, &self.yd, &self.pd, &mut out);
        let c = sys.event_condition(self.event, self.tau, &self.yd, &self.pd).eps;
        (c, out.iter().map(|v| v.eps).collect())
    }
}

/// Locates where condition `c` (of the time) falls through zero in (a, b], given c(a) > 0 ≥
/// c(b): the Illinois variant of regula falsi, to a few units in the last place of the
/// time. Returns the earliest time at which c ≤ 0 that it found.
pub(crate) fn locate(
    mut c: impl FnMut(f64) -> f64,
    (a, b): (f64, f64),
    (ca, cb): (f64, f64),
) -> f64 {
    let (mut a, mut b, mut ca, mut cb) = (a, b, ca, cb);
    // Which end was kept last time: halve its value when kept twice (Illinois).
    let mut kept = 0i8;
    for _ in 0..200 {
        if (b - a).abs() <= 4.0 * f64::EPSILON * a.abs().max(b.abs()).max(f64::MIN_POSITIVE) {
            break;
        }
        let mut m = b - cb * (b - a) / (cb - ca);
        if !(m > a.min(b) && m < a.max(b)) {
            m = 0.5 * (a + b);
        }
        let cm = c(m);
        if cm > 0.0 {
            (a, ca) = (m, cm);
            if kept == 1 {
                cb *= 0.5;
            }
            kept = 1;
        } else {
            (b, cb) = (m, cm);
            if kept == -1 {
                ca *= 0.5;
            }
            kept = -1;
        }
    }
    b
}
