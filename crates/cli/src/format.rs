//! Number formatting for tables.

/// `digits` significant digits: ten are enough to compare estimates with published values
/// and short enough to read (JSON output keeps every digit).
pub fn significant(v: f64, digits: usize) -> String {
    let a = v.abs();
    if !v.is_finite() {
        return if v.is_nan() { "—".into() } else { format!("{v}") };
    }
    if a == 0.0 || (1e-3..1e7).contains(&a) {
        let before = a.log10().floor() as i64 + 1;
        let decimals = if a == 0.0 { digits - 1 } else { (digits as i64 - before).max(0) as usize };
        format!("{v:.decimals$}")
    } else {
        format!("{v:.*e}", digits - 1)
    }
}
