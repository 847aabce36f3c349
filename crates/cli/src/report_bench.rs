//! The benchmark section of the report, from criterion's saved results
//! (`target/criterion/<group>/<id>/new/estimates.json`, written by `cargo bench`): the fit
//! times per system and method, and the exponents of the scaling benchmark.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Criterion's directory: `$CARGO_TARGET_DIR/criterion`, else `target/criterion`.
fn criterion_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(|| PathBuf::from("target"), PathBuf::from)
        .join("criterion")
}

/// Median times (ns) of every benchmark of `group`, by id (`a/b/c`), sorted by id.
fn medians(group: &str) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    collect(&criterion_dir().join(group), "", &mut out);
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

fn collect(dir: &Path, id: &str, out: &mut Vec<(String, f64)>) {
    let estimates = dir.join("new").join("estimates.json");
    if let Ok(text) = std::fs::read_to_string(&estimates)
        && let Ok(v) = serde_json::from_str::<serde_json::Value>(&text)
        && let Some(ns) = v["median"]["point_estimate"].as_f64()
    {
        // Criterion writes `/` inside a benchmark name as `_`.
        out.push((id.replace('_', "/"), ns));
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.path().is_dir() && name != "report" {
            let id = if id.is_empty() { name } else { format!("{id}/{name}") };
            collect(&entry.path(), &id, out);
        }
    }
}

/// Least-squares slope of log(time) against log(size): the exponent p of time ∝ size^p.
pub fn exponent(points: &[(f64, f64)]) -> Option<f64> {
    if points.len() < 2 {
        return None;
    }
    let n = points.len() as f64;
    let (xs, ys): (Vec<f64>, Vec<f64>) = points.iter().map(|&(x, y)| (x.ln(), y.ln())).unzip();
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

fn time(ns: f64) -> String {
    if ns >= 1e9 {
        format!("{:.2} s", ns / 1e9)
    } else if ns >= 1e6 {
        format!("{:.2} ms", ns / 1e6)
    } else {
        format!("{:.1} µs", ns / 1e3)
    }
}

/// The "Benchmarks" section of the report.
pub fn section() -> String {
    let mut md = String::from("\n## Benchmarks\n\n");
    let fits = medians("fit");
    let scaling = medians("scaling");
    let ode = medians("ode");
    if fits.is_empty() && scaling.is_empty() && ode.is_empty() {
        md += "No criterion results were found in `target/criterion`: run `cargo bench -p sysid` \
               and regenerate the report to fill this section.\n";
        return md;
    }
    md += "Medians of criterion's samples on this machine (`cargo bench -p sysid`; the report \
           reads them from `target/criterion`).\n";
    if !fits.is_empty() {
        md += "\n**Time to fit from the default start** (`--bench methods`):\n\n| system / method | median |\n|---|---|\n";
        for (id, ns) in &fits {
            let _ = writeln!(md, "| {id} | {} |", time(*ns));
        }
    }
    if !ode.is_empty() {
        md += "\n**Integration** (`--bench ode`):\n\n| system / what | median |\n|---|---|\n";
        for (id, ns) in &ode {
            let _ = writeln!(md, "| {id} | {} |", time(*ns));
        }
    }
    if !scaling.is_empty() {
        md += "\n**Scaling of one Goodman iteration** (`--bench scaling`, Lorenz-96; one \
               iteration = one integration of the states and their sensitivities with the sums \
               ε, U, A, then the Newton step):\n\n| dimension | sizes | medians | exponent p (time ∝ size^p) |\n|---|---|---|---|\n";
        let mut exponents = Vec::new();
        for dim in ["n", "k", "m"] {
            let mut points: Vec<(f64, f64)> = scaling
                .iter()
                .filter_map(|(id, ns)| {
                    let (d, size) = id.split_once('/')?;
                    (d == dim).then_some((size.parse::<f64>().ok()?, *ns))
                })
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            if points.is_empty() {
                continue;
            }
            let p = exponent(&points);
            let sizes: Vec<String> = points.iter().map(|p| format!("{}", p.0)).collect();
            let times: Vec<String> = points.iter().map(|p| time(p.1)).collect();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} |",
                match dim {
                    "n" => "states n",
                    "k" => "unknowns k",
                    _ => "measurements M",
                },
                sizes.join(", "),
                times.join(", "),
                p.map_or("—".into(), |p| format!("{p:.2}"))
            );
            if let Some(p) = p {
                exponents.push((dim, p));
            }
        }
        let of = |d: &str| exponents.iter().find(|e| e.0 == d).map(|e| e.1);
        if let (Some(pn), Some(pk), Some(pm)) = (of("n"), of("k"), of("m"))
            && (0.7..1.3).contains(&pn)
            && (0.7..1.3).contains(&pk)
            && pm < 0.5
        {
            let _ = writeln!(
                md,
                "\nThe time of an iteration grows about in proportion to n and to k \
                     (p = {pn:.2}, {pk:.2}) and hardly with M (p = {pm:.2}): the integration \
                     of the n × k sensitivity equations dominates, one dual-number evaluation \
                     of the right-hand side per stage. The sums over the data (M k²) and the \
                     k × k solve stay small at these sizes, and the step count is set by the \
                     dynamics, not by the number of measurement times (the dense output \
                     interpolates between steps)."
            );
        }
        if let Some((dim, p)) = exponents.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
            let _ = writeln!(
                md,
                "\nThe steepest growth is in {} (p = {p:.2}).",
                match *dim {
                    "n" => "the number of states",
                    "k" => "the number of unknowns",
                    _ => "the number of measurements",
                }
            );
        }
    }
    md
}

#[cfg(test)]
mod tests {
    #[test]
    fn exponent_of_a_power_law() {
        let points: Vec<(f64, f64)> = [4.0, 16.0, 64.0].iter().map(|&n| (n, 3.0 * n * n)).collect();
        let p = super::exponent(&points).unwrap();
        assert!((p - 2.0).abs() < 1e-12, "{p}");
        assert!(super::exponent(&points[..1]).is_none());
    }
}
