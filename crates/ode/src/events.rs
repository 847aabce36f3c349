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
/// reset's Jacobians. The derivatives in y and α are exact (dual numbers); c_t is a central
/// difference (a condition depends on t only where it is a time, so the difference is
/// exact up to rounding). `u` is work space for the inputs.
pub(crate) fn fire<S: System>(
    sys: &S,
    i: usize,
    tau: f64,
    (p, wrt, u): (&[f64], &[Wrt], &mut [f64]),
    x: &mut [f64],
) {
    let n = sys.signature().n_states();
    let (y, s) = x.split_at_mut(n);
    let mut y_new = y.to_vec();
    sys.event_reset(i, tau, y, p, &mut y_new);
    if wrt.is_empty() {
        y.copy_from_slice(&y_new);
        return;
    }
    let k = wrt.len();
    let rhs = |y: &[f64], u: &mut [f64]| {
        let mut g = vec![0.0; n];
        sys.input_values(tau, Side::After, u);
        sys.rhs(tau, y, p, u, &mut g);
        g
    };
    let (g_before, g_after) = (rhs(y, u), rhs(&y_new, u));
    // c_y, c_α and R_y, R_α by one dual-number evaluation per state and per parameter.
    let mut yd: Vec<Dual64> = y.iter().map(|&v| Dual64::from_re(v)).collect();
    let mut pd: Vec<Dual64> = p.iter().map(|&v| Dual64::from_re(v)).collect();
    let mut out = vec![Dual64::from_re(0.0); n];
    let mut seeded = |yd: &[Dual64], pd: &[Dual64]| {
        out.copy_from_slice(yd);
        sys.event_reset(i, tau, yd, pd, &mut out);
        (sys.event_condition(i, tau, yd, pd).eps, out.iter().map(|v| v.eps).collect::<Vec<_>>())
    };
    let mut c_y = vec![0.0; n];
    // R_y row by row: r_y[a * n + b] = ∂r_a/∂y_b.
    let mut r_y = vec![0.0; n * n];
    for b in 0..n {
        yd[b].eps = 1.0;
        let (c, r) = seeded(&yd, &pd);
        yd[b].eps = 0.0;
        c_y[b] = c;
        for a in 0..n {
            r_y[a * n + b] = r[a];
        }
    }
    let h = 1e-6 * tau.abs().max(1.0);
    let c_t =
        (sys.event_condition(i, tau + h, y, p) - sys.event_condition(i, tau - h, y, p)) / (2.0 * h);
    let rate: f64 = c_y.iter().zip(&g_before).map(|(c, g)| c * g).sum::<f64>() + c_t;
    // R_y g⁻ − g⁺: how the state after the event moves as the event moves.
    let drift: Vec<f64> = (0..n)
        .map(|a| (0..n).map(|b| r_y[a * n + b] * g_before[b]).sum::<f64>() - g_after[a])
        .collect();
    let old = s.to_vec();
    for (j, w) in wrt.iter().enumerate() {
        let (mut c_z, mut r_z) = (0.0, vec![0.0; n]);
        if let Wrt::Parameter(q) = *w {
            pd[q].eps = 1.0;
            (c_z, r_z) = seeded(&yd, &pd);
            pd[q].eps = 0.0;
        }
        let column = |b: usize| old[b * k + j];
        c_z += (0..n).map(|b| c_y[b] * column(b)).sum::<f64>();
        let dtau = -c_z / rate;
        for a in 0..n {
            let carried: f64 = (0..n).map(|b| r_y[a * n + b] * column(b)).sum();
            s[a * k + j] = carried + r_z[a] + drift[a] * dtau;
        }
    }
    y.copy_from_slice(&y_new);
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
