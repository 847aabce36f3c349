//! Time series given by samples: input signals u(t) and measured records b(t).

use std::sync::atomic::{AtomicUsize, Ordering};

use serde::{Deserialize, Serialize};

use crate::error::SignalError;

/// Which one-sided limit to take at a time where a signal jumps.
///
/// The integrators stop on every declared discontinuity and evaluate each stage with the
/// limit from inside the step, so a piecewise-constant input is integrated exactly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The limit from the left, u(t⁻).
    Before,
    /// The limit from the right, u(t⁺) (the value a right-continuous signal has at t).
    After,
}

/// How a sampled signal is continued between its samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    /// Piecewise linear between samples (continuous; kinks at the samples).
    #[default]
    Linear,
    /// Piecewise constant: sample i holds on [t_i, t_{i+1}) (right-continuous; jumps at the
    /// samples where the value changes).
    Step,
}

/// A signal given by samples (t_i, v_i), strictly increasing t_i, held constant outside the
/// sampled range.
#[derive(Debug)]
pub struct Signal {
    times: Vec<f64>,
    values: Vec<f64>,
    interpolation: Interpolation,
    /// The interval of the last lookup: integrators ask for nearby times, so the next
    /// lookup usually needs no search.
    hint: AtomicUsize,
}

impl Clone for Signal {
    fn clone(&self) -> Self {
        Self {
            times: self.times.clone(),
            values: self.values.clone(),
            interpolation: self.interpolation,
            hint: AtomicUsize::new(self.hint.load(Ordering::Relaxed)),
        }
    }
}

impl PartialEq for Signal {
    fn eq(&self, other: &Self) -> bool {
        self.times == other.times
            && self.values == other.values
            && self.interpolation == other.interpolation
    }
}

impl Signal {
    /// A signal from its samples. Errors on mismatched lengths, no samples, non-finite numbers
    /// or times that do not strictly increase.
    pub fn new(
        times: Vec<f64>,
        values: Vec<f64>,
        interpolation: Interpolation,
    ) -> Result<Self, SignalError> {
        if times.len() != values.len() {
            return Err(SignalError::LengthMismatch { times: times.len(), values: values.len() });
        }
        if times.is_empty() {
            return Err(SignalError::Empty);
        }
        if let Some(index) = times.iter().chain(&values).position(|v| !v.is_finite()) {
            return Err(SignalError::NonFinite { index: index % times.len() });
        }
        if let Some(index) = times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(SignalError::NotIncreasing {
                index: index + 1,
                previous: times[index],
                time: times[index + 1],
            });
        }
        Ok(Self { times, values, interpolation, hint: AtomicUsize::new(0) })
    }

    /// A piecewise-constant signal that starts at `initial` and changes to `value` at `time`
    /// for each `(time, value)` in `changes`: the usual shape of a test input (step, doublet).
    pub fn steps(initial: f64, changes: &[(f64, f64)]) -> Result<Self, SignalError> {
        let mut times = Vec::with_capacity(changes.len() + 1);
        let mut values = Vec::with_capacity(changes.len() + 1);
        let first = changes.first().map_or(0.0, |c| c.0);
        times.push(first - 1.0);
        values.push(initial);
        for &(t, v) in changes {
            times.push(t);
            values.push(v);
        }
        Self::new(times, values, Interpolation::Step)
    }

    /// Sample times.
    pub fn times(&self) -> &[f64] {
        &self.times
    }
    /// Sample values.
    pub fn values(&self) -> &[f64] {
        &self.values
    }
    /// The interpolation between samples.
    pub fn interpolation(&self) -> Interpolation {
        self.interpolation
    }

    /// Index of the first sample after t (strictly after for the right limit, at or after
    /// for the left limit): where t lies among the samples.
    fn locate(&self, t: f64, side: Side) -> usize {
        let before = |ti: f64| match side {
            Side::After => ti <= t,
            Side::Before => ti < t,
        };
        let times = &self.times;
        let hint = self.hint.load(Ordering::Relaxed).min(times.len());
        // The hinted answer holds when the sample before it is before t and it is not.
        let fits =
            |i: usize| (i == 0 || before(times[i - 1])) && (i == times.len() || !before(times[i]));
        if fits(hint) {
            return hint;
        }
        if hint < times.len() && fits(hint + 1) {
            self.hint.store(hint + 1, Ordering::Relaxed);
            return hint + 1;
        }
        let i = times.partition_point(|&ti| before(ti));
        self.hint.store(i, Ordering::Relaxed);
        i
    }

    /// The value at t; at a jump of a step signal, the limit from `side`.
    pub fn value(&self, t: f64, side: Side) -> f64 {
        let n = self.times.len();
        let after = self.locate(t, side);
        if after == 0 {
            return self.values[0];
        }
        if after == n {
            return self.values[n - 1];
        }
        let i = after - 1;
        match self.interpolation {
            Interpolation::Step => self.values[i],
            Interpolation::Linear => {
                let (t0, t1) = (self.times[i], self.times[i + 1]);
                let w = (t - t0) / (t1 - t0);
                self.values[i] + w * (self.values[i + 1] - self.values[i])
            }
        }
    }

    /// Times where the signal jumps (step signals where the value changes; none for linear).
    pub fn jumps(&self) -> impl Iterator<Item = f64> + '_ {
        let step = self.interpolation == Interpolation::Step;
        self.times
            .windows(2)
            .zip(self.values.windows(2))
            .filter(move |(_, v)| step && v[1] - v[0] != 0.0)
            .map(|(t, _)| t[1])
    }
}

/// Named input signals u(t) of a system, in the order of its signature's inputs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Inputs {
    signals: Vec<Signal>,
    jumps: Vec<f64>,
}

impl Inputs {
    /// Input signals in signature order.
    pub fn new(signals: Vec<Signal>) -> Self {
        let mut jumps: Vec<f64> = signals.iter().flat_map(Signal::jumps).collect();
        jumps.sort_by(f64::total_cmp);
        jumps.dedup();
        Self { signals, jumps }
    }

    /// Number of signals.
    pub fn len(&self) -> usize {
        self.signals.len()
    }
    /// Whether there are no signals.
    pub fn is_empty(&self) -> bool {
        self.signals.is_empty()
    }
    /// The signals.
    pub fn signals(&self) -> &[Signal] {
        &self.signals
    }

    /// Writes u(t) (the limit from `side` at a jump) into `u`.
    pub fn eval(&self, t: f64, side: Side, u: &mut [f64]) {
        for (ui, s) in u.iter_mut().zip(&self.signals) {
            *ui = s.value(t, side);
        }
    }

    /// All jump times, ascending and without repeats: the discontinuities to declare.
    pub fn jumps(&self) -> &[f64] {
        &self.jumps
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_close_abs;

    #[test]
    fn linear_interpolates_and_holds_outside() {
        let s =
            Signal::new(vec![0.0, 1.0, 3.0], vec![0.0, 2.0, 0.0], Interpolation::Linear).unwrap();
        assert_close_abs(s.value(-1.0, Side::After), 0.0, 0.0);
        assert_close_abs(s.value(0.5, Side::After), 1.0, 0.0);
        assert_close_abs(s.value(2.0, Side::Before), 1.0, 0.0);
        assert_close_abs(s.value(1.0, Side::Before), 2.0, 0.0);
        assert_close_abs(s.value(1.0, Side::After), 2.0, 0.0);
        assert_close_abs(s.value(9.0, Side::After), 0.0, 0.0);
        assert_eq!(s.jumps().count(), 0);
    }

    #[test]
    fn step_takes_one_sided_limits_at_jumps() {
        let s = Signal::steps(0.0, &[(1.0, 0.05), (2.0, -0.05), (3.0, 0.0)]).unwrap();
        assert_close_abs(s.value(1.0, Side::Before), 0.0, 0.0);
        assert_close_abs(s.value(1.0, Side::After), 0.05, 0.0);
        assert_close_abs(s.value(1.5, Side::Before), 0.05, 0.0);
        assert_close_abs(s.value(2.0, Side::Before), 0.05, 0.0);
        assert_close_abs(s.value(2.0, Side::After), -0.05, 0.0);
        assert_close_abs(s.value(3.5, Side::After), 0.0, 0.0);
        assert_eq!(s.jumps().collect::<Vec<_>>(), vec![1.0, 2.0, 3.0]);
    }

    proptest::proptest! {
        /// Lookups in any order agree with a fresh signal (no hint) for both sides.
        #[test]
        fn hinted_lookups_match_fresh_ones(
            queries in proptest::collection::vec(-1.0..6.0f64, 1..60),
            step in proptest::bool::ANY,
        ) {
            let interpolation = if step { Interpolation::Step } else { Interpolation::Linear };
            let times = vec![0.0, 0.5, 1.0, 2.0, 2.5, 4.0, 5.0];
            let values = vec![1.0, -1.0, 3.0, 0.5, 0.5, 2.0, -2.0];
            let used = Signal::new(times.clone(), values.clone(), interpolation).unwrap();
            // Exact sample times too, where the two sides differ.
            for q in queries.iter().copied().chain(times.iter().copied()) {
                for side in [Side::Before, Side::After] {
                    let fresh = Signal::new(times.clone(), values.clone(), interpolation).unwrap();
                    proptest::prop_assert_eq!(used.value(q, side).to_bits(), fresh.value(q, side).to_bits());
                }
            }
        }
    }

    #[test]
    fn rejects_bad_samples() {
        let bad = |t: Vec<f64>, v: Vec<f64>| Signal::new(t, v, Interpolation::Linear).unwrap_err();
        assert_eq!(bad(vec![0.0], vec![]), SignalError::LengthMismatch { times: 1, values: 0 });
        assert_eq!(bad(vec![], vec![]), SignalError::Empty);
        assert_eq!(bad(vec![0.0, 1.0], vec![1.0, f64::NAN]), SignalError::NonFinite { index: 1 });
        assert_eq!(
            bad(vec![0.0, 1.0, 1.0], vec![0.0; 3]),
            SignalError::NotIncreasing { index: 2, previous: 1.0, time: 1.0 }
        );
    }
}
