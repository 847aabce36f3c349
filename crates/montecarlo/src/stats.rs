//! The statistics of a study, from its trial records alone: success rates with Wilson
//! intervals, bias, spread and RMSE of the successful estimates against the truth, the
//! Cramér–Rao bound and the efficiency it implies, coverage of the fits' own intervals, and
//! percentiles of iterations and time.

use serde::{Deserialize, Serialize};

use crate::trial::{REFERENCE, StudySpec, TrialRecord};
use sysid_core::format::shortest;

pub use sysid_core::confidence::Z95;

/// What a study established, written to `summary.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// The settings.
    pub spec: StudySpec,
    /// Names of the unknowns.
    pub unknowns: Vec<String>,
    /// Their true values.
    pub truth: Vec<f64>,
    /// Cramér–Rao standard deviations at the truth.
    pub crb_sd: Vec<f64>,
    /// Trials whose records are summarised.
    pub trials: usize,
    /// The reference fit from the truth, then each method in the study's order.
    pub methods: Vec<MethodSummary>,
}

/// One method over all trials.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MethodSummary {
    /// Method name (`reference` for the fit from the truth).
    pub method: String,
    /// Trials that count: those whose reference fit converged (all trials for the
    /// reference itself).
    pub trials: usize,
    /// Successful trials among them (converged, for the reference).
    pub successes: usize,
    /// successes / trials.
    pub success_rate: f64,
    /// Wilson 95 % interval of the success rate.
    pub success_interval: [f64; 2],
    /// How many trials ended how (`success`, `other_minimum`, `diverged`, ...), by outcome.
    pub outcomes: Vec<Count>,
    /// Accuracy per unknown over the successful trials.
    pub accuracy: Vec<Accuracy>,
    /// Updates of the unknowns over every counted trial, successful or not.
    pub iterations: Percentiles,
    /// Time per fit over every counted trial (ms; differs from run to run).
    pub time_ms: Percentiles,
}

/// A number of trials with one outcome.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Count {
    /// The outcome.
    pub outcome: String,
    /// How many.
    pub count: usize,
}

/// The successful estimates of one unknown against the truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// The unknown.
    pub name: String,
    /// Mean error (estimate − truth).
    pub bias: Option<f64>,
    /// Standard deviation of the estimates (n − 1 in the denominator).
    pub sd: Option<f64>,
    /// Root mean square error against the truth.
    pub rmse: Option<f64>,
    /// The Cramér–Rao standard deviation.
    pub crb_sd: f64,
    /// CRB variance / observed variance: 1 for an efficient estimator.
    pub efficiency: Option<f64>,
    /// Fraction of successful fits whose own 95 % interval (estimate ± t_{0.975, N−k}
    /// standard errors, Student's t) contains the truth.
    pub coverage: Option<f64>,
}

/// Median and 90th percentile (linear interpolation between order statistics).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// 50 %.
    pub median: Option<f64>,
    /// 90 %.
    pub p90: Option<f64>,
}

/// The Wilson score interval at 95 % for `successes` out of `n` ([0, 1] for n = 0).
pub fn wilson(successes: usize, n: usize) -> [f64; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    let n = n as f64;
    let p = successes as f64 / n;
    let z2 = Z95 * Z95;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = Z95 / (1.0 + z2 / n) * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    [(centre - half).max(0.0), (centre + half).min(1.0)]
}

/// The q-quantile (0 ≤ q ≤ 1) of `values`, interpolating linearly between order statistics.
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let at = q * (v.len() - 1) as f64;
    let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
    Some(v[lo] + (v[hi] - v[lo]) * (at - lo as f64))
}

fn percentiles(values: &[f64]) -> Percentiles {
    Percentiles { median: quantile(values, 0.5), p90: quantile(values, 0.9) }
}

/// The summary of `records` (any order; summed in trial order so that the result does not
/// depend on how the trials were scheduled).
pub fn summarise(
    spec: &StudySpec,
    unknowns: &[String],
    truth: &[f64],
    crb_sd: &[f64],
    records: &[TrialRecord],
) -> Summary {
    let mut sorted: Vec<&TrialRecord> = records.iter().collect();
    sorted.sort_by_key(|r| r.trial);
    let reference: std::collections::BTreeMap<usize, bool> =
        sorted.iter().filter(|r| r.method == REFERENCE).map(|r| (r.trial, r.converged)).collect();
    let names = std::iter::once(REFERENCE.to_string()).chain(spec.methods.iter().cloned());
    let methods = names
        .map(|method| {
            let rows: Vec<&TrialRecord> = sorted
                .iter()
                .copied()
                .filter(|r| r.method == method)
                .filter(|r| method == REFERENCE || reference.get(&r.trial) == Some(&true))
                .collect();
            summarise_method(&method, &rows, unknowns, truth, crb_sd)
        })
        .collect();
    Summary {
        spec: spec.clone(),
        unknowns: unknowns.to_vec(),
        truth: truth.to_vec(),
        crb_sd: crb_sd.to_vec(),
        trials: reference.len(),
        methods,
    }
}

fn summarise_method(
    method: &str,
    rows: &[&TrialRecord],
    unknowns: &[String],
    truth: &[f64],
    crb_sd: &[f64],
) -> MethodSummary {
    let good =
        |r: &TrialRecord| if method == REFERENCE { r.converged } else { r.success == Some(true) };
    let successful: Vec<&TrialRecord> = rows.iter().copied().filter(|r| good(r)).collect();
    let mut outcomes: Vec<Count> = Vec::new();
    for r in rows {
        match outcomes.iter_mut().find(|c| c.outcome == r.outcome) {
            Some(c) => c.count += 1,
            None => outcomes.push(Count { outcome: r.outcome.clone(), count: 1 }),
        }
    }
    outcomes.sort_by(|a, b| b.count.cmp(&a.count).then(a.outcome.cmp(&b.outcome)));
    let accuracy = unknowns
        .iter()
        .enumerate()
        .map(|(i, name)| accuracy(name, i, &successful, truth[i], crb_sd[i]))
        .collect();
    let iterations: Vec<f64> = rows.iter().map(|r| r.iterations as f64).collect();
    let times: Vec<f64> = rows.iter().map(|r| r.time_ms).collect();
    MethodSummary {
        method: method.to_string(),
        trials: rows.len(),
        successes: successful.len(),
        success_rate: if rows.is_empty() {
            0.0
        } else {
            successful.len() as f64 / rows.len() as f64
        },
        success_interval: wilson(successful.len(), rows.len()),
        outcomes,
        accuracy,
        iterations: percentiles(&iterations),
        time_ms: percentiles(&times),
    }
}

fn accuracy(name: &str, i: usize, rows: &[&TrialRecord], truth: f64, crb_sd: f64) -> Accuracy {
    let n = rows.len();
    let errors: Vec<f64> = rows.iter().map(|r| r.values[i] - truth).collect();
    let mean = (n > 0).then(|| errors.iter().sum::<f64>() / n as f64);
    let sd = (n > 1).then(|| {
        let m = mean.unwrap_or(0.0);
        (errors.iter().map(|e| (e - m) * (e - m)).sum::<f64>() / (n - 1) as f64).sqrt()
    });
    let rmse = (n > 0).then(|| (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt());
    // Fits that hold the unknown on a bound have no interval for it.
    let intervals: Vec<[f64; 2]> =
        rows.iter().filter_map(|r| r.intervals.as_ref().and_then(|list| list[i])).collect();
    let coverage = (!intervals.is_empty()).then(|| {
        let inside = intervals.iter().filter(|[lo, hi]| (*lo..=*hi).contains(&truth)).count();
        inside as f64 / intervals.len() as f64
    });
    Accuracy {
        name: name.to_string(),
        bias: mean,
        sd,
        rmse,
        crb_sd,
        efficiency: sd.filter(|s| *s > 0.0).map(|s| (crb_sd * crb_sd) / (s * s)),
        coverage,
    }
}

impl Summary {
    /// The statistics as Markdown tables: success and cost per method, then accuracy per
    /// unknown.
    pub fn markdown(&self) -> String {
        let s = &self.spec;
        let mut out = format!(
            "# Study: {}\n\n{} trials, noise {}·σ, starts perturbed by ρ = {}, seed {}; reference: \
             {} from the truth. A method succeeds on a trial when it converges to the reference \
             fit's cost (within 1e-6 relative).\n\n",
            s.system,
            self.trials,
            shortest(s.noise),
            shortest(s.perturb),
            s.seed,
            s.reference
        );
        out += "| method | success | 95 % interval | outcomes | iterations (median / 90 %) | time ms (median / 90 %) |\n";
        out += "|---|---|---|---|---|---|\n";
        for m in &self.methods {
            let outcomes: Vec<String> =
                m.outcomes.iter().map(|c| format!("{} {}", c.outcome, c.count)).collect();
            // No trial judged: no rate (the JSON's 0 is a placeholder, json.md).
            let (rate, interval) = match m.trials {
                0 => ("—".to_string(), "—".to_string()),
                _ => (
                    format!("{:.1} %", 100.0 * m.success_rate),
                    format!(
                        "{:.1}–{:.1} %",
                        100.0 * m.success_interval[0],
                        100.0 * m.success_interval[1]
                    ),
                ),
            };
            out += &format!(
                "| {} | {}/{} ({rate}) | {interval} | {} | {} / {} | {} / {} |\n",
                m.method,
                m.successes,
                m.trials,
                outcomes.join(", "),
                number(m.iterations.median, 1),
                number(m.iterations.p90, 1),
                number(m.time_ms.median, 3),
                number(m.time_ms.p90, 3),
            );
        }
        // A method is judged only on the trials whose reference fit converged.
        let judged = self.methods.iter().find(|m| m.method == REFERENCE).map(|r| r.successes);
        if let Some(judged) = judged.filter(|&j| j < self.trials) {
            out += &format!(
                "\nThe other methods are judged on the {judged} of {} trials whose reference fit \
                 converged{}.\n",
                self.trials,
                match judged {
                    0 =>
                        ": none, so nothing is measured (a larger --max-iterations lets the \
                          reference fit converge)",
                    _ => "",
                }
            );
        }
        for (i, name) in self.unknowns.iter().enumerate() {
            out += &format!(
                "\n## {name}: truth {}, Cramér–Rao σ {}\n\n",
                significant(self.truth[i]),
                significant(self.crb_sd[i])
            );
            out += "| method | bias | sd | RMSE | efficiency (CRB var / var) | coverage of the 95 % t interval |\n";
            out += "|---|---|---|---|---|---|\n";
            for m in &self.methods {
                let a = &m.accuracy[i];
                out += &format!(
                    "| {} | {} | {} | {} | {} | {} |\n",
                    m.method,
                    a.bias.map_or("—".into(), significant),
                    a.sd.map_or("—".into(), significant),
                    a.rmse.map_or("—".into(), significant),
                    number(a.efficiency, 3),
                    a.coverage.map_or("—".into(), |c| format!("{:.1} %", 100.0 * c)),
                );
            }
        }
        out
    }
}

fn number(v: Option<f64>, decimals: usize) -> String {
    v.map_or("—".into(), |v| format!("{v:.decimals$}"))
}

/// Four significant digits, as the summaries' tables give them.
pub(crate) fn significant(v: f64) -> String {
    sysid_core::format::significant(v, 4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_matches_the_closed_form() {
        // 8 of 10: centre (0.8 + 1.92/10) / 1.384, half-width 1.96/1.384 · √(0.016 + 0.0096).
        let [lo, hi] = wilson(8, 10);
        assert!((lo - 0.490_162).abs() < 1e-6, "{lo}");
        assert!((hi - 0.943_317).abs() < 1e-6, "{hi}");
        let [lo, hi] = wilson(0, 0);
        assert!(lo.abs() < 1e-300 && (hi - 1.0).abs() < 1e-300, "{lo} {hi}");
        let [lo, hi] = wilson(5, 5);
        assert!(lo > 0.5 && (hi - 1.0).abs() < 1e-15, "{lo} {hi}");
    }

    #[test]
    fn quantiles_interpolate() {
        let v = [4.0, 1.0, 3.0, 2.0, 5.0];
        assert!((quantile(&v, 0.5).unwrap() - 3.0).abs() < 1e-15);
        assert!((quantile(&v, 0.9).unwrap() - 4.6).abs() < 1e-15);
        assert!(quantile(&[], 0.5).is_none());
    }
}
