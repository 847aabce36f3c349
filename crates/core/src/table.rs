//! A fit as people read it: the estimates with their uncertainty next to what was expected,
//! then how the run went and its history (what `sysid fit` prints; `{estimate}` prints the
//! same without expected values).

use std::fmt;

use crate::certificate::Bound;
use crate::estimate::Estimate;
use crate::format::significant;

/// What a fit is compared with: a published reference answer, or the truth the data were
/// made from.
#[derive(Clone, Debug, PartialEq)]
pub struct Expected {
    /// "reference" or "truth": the column's heading.
    pub label: &'static str,
    /// Expected values of unknowns, by name (some unknowns may have none).
    pub values: Vec<(String, f64)>,
    /// The expected cost ε and where it comes from.
    pub cost: Option<(f64, &'static str)>,
}

impl Expected {
    /// The expected value of the unknown `name`, if there is one.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.values.iter().find(|(n, _)| n == name).map(|p| p.1)
    }
}

impl Estimate {
    /// The readable report: estimates, standard errors and 95 % intervals (with a column of
    /// `expected` values where given), then the verdict, the termination, the iterations,
    /// the cost, the degrees of freedom, the work, and one row per iterate.
    pub fn table(&self, expected: Option<&Expected>) -> String {
        let mut out = String::new();
        // A column of expected values only where there are some.
        let column = |v: &str| expected.map_or(String::new(), |_| format!(" {v:>24}"));
        // The names' column as wide as the longest name (PEtab's run to 30 characters).
        let names = self.names.iter().chain(self.scales.iter().map(|s| &s.name));
        let w = crate::format::column_width(names.map(String::as_str), 10);
        out += &format!(
            "  {:<w$} {:>24} {:>14} {:>34}{}\n",
            "unknown",
            "estimate",
            "std. error",
            "95 % interval (Student's t)",
            column(expected.map_or("", |e| e.label))
        );
        for (i, name) in self.names.iter().enumerate() {
            let on_bound = self.certificate.active[i].is_some();
            let se = match &self.std_errors {
                _ if self.certificate.active[i] == Some(Bound::PriorLocation) => {
                    "at prior".to_string()
                }
                _ if self.certificate.active[i] == Some(Bound::SwitchOnSample) => {
                    "at sample".to_string()
                }
                _ if on_bound => "on bound".to_string(),
                Some(s) => significant(s[i], 5),
                None => "—".to_string(),
            };
            let interval = match &self.intervals {
                Some(list) if !on_bound => {
                    format!("[{}, {}]", significant(list[i][0], 6), significant(list[i][1], 6))
                }
                _ => "—".to_string(),
            };
            let value =
                expected.and_then(|e| e.value(name)).map_or(String::new(), |v| format!("{v}"));
            let bound = match self.certificate.active[i] {
                Some(Bound::Lower) => "   on its lower bound",
                Some(Bound::Upper) => "   on its upper bound",
                Some(Bound::PriorLocation) => "   at its Laplace prior's location",
                Some(Bound::SwitchOnSample) => "   its switch on a sample time",
                None => "",
            };
            out += &format!(
                "  {name:<w$} {:>24} {se:>14} {interval:>34}{}{bound}\n",
                significant(self.values[i], 10),
                column(&value)
            );
        }
        for scale in &self.scales {
            let se = scale.std_error.map_or("—".to_string(), |s| significant(s, 5));
            let interval = match (scale.interval, scale.bound) {
                (Some([a, b]), None) => format!("[{}, {}]", significant(a, 6), significant(b, 6)),
                _ => "—".to_string(),
            };
            let bound = match scale.bound {
                Some(Bound::Lower) => "   on its lower bound",
                Some(Bound::Upper) => "   on its upper bound",
                _ => "",
            };
            out += &format!(
                "  {:<w$} {:>24} {se:>14} {interval:>34}{}{bound}   (noise scale, closed form)\n",
                scale.name,
                significant(scale.value, 10),
                column(""),
            );
        }
        out += "\n";
        out += &format!("  converged    {}\n", self.verdict());
        out += &format!("  termination  {}\n", self.termination);
        if let Some(first) = &self.retry {
            out += &format!(
                "  retry        the first run from this start ended {} at objective {} after {} iterations, on flat ground; a second ran from the start with a first radius of one own scale, and the {} run is reported (the time and counts are both runs')\n",
                first.termination.code(),
                significant(first.objective, 10),
                first.iterations,
                if first.reported { "first" } else { "second" }
            );
        }
        if let Some(at) = self.failed_at() {
            out += &format!("  failed at    {at}\n");
        }
        if let Some(space) = &self.certificate.null_space {
            out += &format!(
                "  identifiability  the data cannot identify {} here (condition {:.1e}): the combination {} is not seen by the data\n",
                space.unknowns.join(", "),
                space.condition,
                space.combination()
            );
        }
        let reported = if self.best_iteration == self.iterations {
            String::new()
        } else {
            format!(" (the best, iterate {}, is reported)", self.best_iteration)
        };
        out += &format!("  iterations   {}{reported}\n", self.iterations);
        let reference = expected
            .and_then(|e| e.cost)
            .map_or(String::new(), |(cost, source)| format!("   (reference {cost}, {source})"));
        out += &format!("  cost ε       {}{reference}\n", significant(self.cost, 10));
        if let (true, Some(nll)) = (self.noise_model, self.nll) {
            let criteria = match (self.aic(), self.bic()) {
                (Some(a), Some(b)) => {
                    format!("; AIC {}, BIC {}", significant(a, 8), significant(b, 8))
                }
                _ => String::new(),
            };
            // The integration's share of the figure, where the certificate measured it.
            let error = match self.nll_error() {
                Some(e) if e.is_infinite() => {
                    " (its integration error unmeasured: its evaluation at a tenth of the tolerances fails)".to_string()
                }
                Some(e) if e > 0.0 => format!(" ± {e:.1e} (integration)"),
                _ => String::new(),
            };
            out += &format!(
                "  nll          {}{error} (negative log-likelihood{criteria})\n",
                significant(nll, 10)
            );
            // What the fit minimised, where priors pull the estimates from the data's optimum
            // (the JSON's `prior`: the table showed the NLL alone).
            if let Some(prior) = self.prior {
                out += &format!(
                    "  prior        {} (negative log-prior); objective {} (nll + prior, what the fit minimises)\n",
                    significant(prior, 10),
                    significant(nll + prior, 10)
                );
            }
        }
        if self.experiments.len() > 1 {
            for x in &self.experiments {
                let nll = x.nll.map_or("—".to_string(), |v| significant(v, 8));
                out +=
                    &format!("  experiment   {:<16} {:>5} values, nll {nll}\n", x.name, x.points);
            }
        }
        let dof = self.dof.map_or("—".to_string(), |d| d.to_string());
        out += &format!("  dof          {dof} (measured values − unknowns not held on a bound)\n");
        out += &format!(
            "  work         {} integrations, {} steps ({} rejected), {} right-hand-side evaluations, {:.3} ms\n\n",
            self.counts.integrations,
            self.counts.steps,
            self.counts.rejected_steps,
            self.counts.rhs_evaluations,
            self.elapsed.as_secs_f64() * 1e3
        );
        out + &self.history_table()
    }

    /// One row per iterate: cost, |U|, step, condition, optimality, and a column for each
    /// diagnostic the method attached (multiple shooting's defect, ...).
    fn history_table(&self) -> String {
        let mut diagnostics: Vec<&str> = Vec::new();
        for (name, _) in self.history.iter().flat_map(|h| h.diagnostics.iter()) {
            if !diagnostics.contains(&name) {
                diagnostics.push(name);
            }
        }
        let mut out = format!(
            "  {:>9} {:>24} {:>12} {:>12} {:>12} {:>12}",
            "iteration", "cost ε", "|U|", "step", "condition", "optimality"
        );
        for name in &diagnostics {
            out += &format!(" {name:>12}");
        }
        out += "\n";
        let dash = |v: Option<f64>| {
            v.filter(|v| v.is_finite()).map_or("—".to_string(), |v| format!("{v:.3e}"))
        };
        for h in &self.history {
            out += &format!(
                "  {:>9} {:>24} {:>12} {:>12} {:>12} {:>12}",
                h.iteration,
                significant(h.cost, 10),
                dash(Some(h.gradient_norm)),
                dash(h.step_norm),
                dash(h.condition),
                dash(h.optimality),
            );
            for name in &diagnostics {
                out += &format!(" {:>12}", dash(h.diagnostic(name)));
            }
            out += "\n";
        }
        out
    }
}

/// One method's line in a comparison of methods on one problem.
pub struct Compared<'a> {
    /// The method as asked for.
    pub method: &'a str,
    /// Its fit, or why there is none.
    pub fit: Result<&'a Estimate, &'a str>,
    /// A line about how the fit was found (a multistart's outcome), if any.
    pub note: Option<String>,
}

/// The header of [`compact`]'s lines for the problem called `system`.
pub fn compact_header(system: &str) -> String {
    let w = system_width(system);
    format!(
        "{:<w$} {:<24} {:>4} {:>5} {:>18} {:>10}  {}\n",
        "system", "method", "conv", "iter", "cost ε", "time ms", "termination"
    )
}

/// The width of [`compact`]'s first column: the problem's name (a PEtab problem's is its YAML
/// file's path), at least 24.
fn system_width(system: &str) -> usize {
    crate::format::column_width([system], 24)
}

/// A comparison in one line per method: system, method, converged, iterations, cost, time,
/// the termination code and the note.
pub fn compact(system: &str, rows: &[Compared<'_>]) -> String {
    let w = system_width(system);
    let mut out = String::new();
    for row in rows {
        out += &match &row.fit {
            Ok(e) => format!(
                "{system:<w$} {:<24} {:>4} {:>5} {:>18} {:>10.3}  {}{}\n",
                row.method,
                if e.converged() { "yes" } else { "no" },
                e.iterations,
                significant(e.cost, 10),
                e.elapsed.as_secs_f64() * 1e3,
                e.termination.code(),
                match (e.noise_model, e.nll) {
                    (true, Some(nll)) => format!(", nll {}", significant(nll, 10)),
                    _ => String::new(),
                } + &row.note.as_ref().map_or(String::new(), |n| format!(", {n}")),
            ),
            Err(message) => format!("{system:<w$} {:<24} error: {message}\n", row.method),
        };
    }
    out
}

/// A comparison as a table: a row per method with its estimates under the `unknowns`, the
/// expected values under the header where known, and below a row why it did not converge
/// and its note.
pub fn comparison(
    unknowns: &[String],
    expected: Option<&Expected>,
    rows: &[Compared<'_>],
) -> String {
    let lead = |a: &str, b: &str, c: &str, d: &str, e: &str| {
        format!("  {a:<24} {b:>5} {c:>5} {d:>18} {e:>10}")
    };
    // The noise scales set in closed form are estimated with the rest: columns after the
    // unknowns (they were left out, though `fit` and the JSON list them).
    let scales: Vec<&str> = rows
        .iter()
        .find_map(|r| r.fit.ok().filter(|e| !e.scales.is_empty()))
        .map(|e| e.scales.iter().map(|s| s.name.as_str()).collect())
        .unwrap_or_default();
    let mut out = lead("method", "conv", "iter", "cost ε", "time ms");
    for name in unknowns.iter().map(String::as_str).chain(scales.iter().copied()) {
        out += &format!(" {name:>16}");
    }
    out += "\n";
    if let Some(expected) = expected {
        out += &lead(expected.label, "", "", "", "");
        for name in unknowns.iter().map(String::as_str).chain(scales.iter().copied()) {
            let v = expected.value(name).map_or(String::new(), |v| significant(v, 8));
            out += &format!(" {v:>16}");
        }
        out += "\n";
    }
    for row in rows {
        match &row.fit {
            Ok(e) => {
                out += &format!(
                    "  {:<24} {:>5} {:>5} {:>18} {:>10.3}",
                    row.method,
                    if e.converged() { "yes" } else { "no" },
                    e.iterations,
                    significant(e.cost, 10),
                    e.elapsed.as_secs_f64() * 1e3
                );
                for v in &e.values {
                    out += &format!(" {:>16}", significant(*v, 8));
                }
                for name in &scales {
                    let v = e.scales.iter().find(|s| s.name == *name);
                    let v = v.map_or(String::new(), |s| significant(s.value, 8));
                    out += &format!(" {v:>16}");
                }
                out += "\n";
                if !e.converged() {
                    out += &format!("  {:<24} └ {}\n", "", e.termination);
                }
            }
            Err(message) => out += &format!("  {:<24} error: {message}\n", row.method),
        }
        if let Some(note) = &row.note {
            out += &format!("  {:<24} └ {note}\n", "");
        }
    }
    out
}

impl fmt::Display for Estimate {
    /// [`table`](Estimate::table) without expected values.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.table(None))
    }
}
