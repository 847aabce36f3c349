//! Numbers for people: the one formatter of every table sysid prints (the command line's,
//! the studies' summaries, the report's), and the shortest exact form.
//! Also the comparison tables of `sysid compare` and the catalogue's expected values.

pub use crate::table::{Compared, Expected, compact, compact_header, comparison};

/// The width of a column that holds `names`: the longest's characters, at least `least`, at
/// most what Rust's formatting takes as a width (65 535; a longer name is printed whole, out of
/// line, where a wider width panicked).
pub fn column_width<'a>(names: impl IntoIterator<Item = &'a str>, least: usize) -> usize {
    let longest = names.into_iter().map(|n| n.chars().count()).max().unwrap_or(0);
    longest.max(least).min(u16::MAX as usize)
}

/// `v` in `digits` significant digits: fixed-point in [1e-3, 1e5), exponent form outside
/// (3.000e7 rather than 30000000), "—" for NaN. Tables print ten digits where estimates are
/// compared with published values and four where numbers are only read; JSON output keeps
/// every digit.
pub fn significant(v: f64, digits: usize) -> String {
    let digits = digits.max(1);
    if v.is_nan() {
        return "—".into();
    }
    if v.is_infinite() {
        return format!("{v}");
    }
    let a = v.abs();
    if a == 0.0 || (1e-3..1e5).contains(&a) {
        let before = if a == 0.0 { 1 } else { a.log10().floor() as i64 + 1 };
        let decimals = (digits as i64 - before).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.*e}", digits - 1)
    }
}

/// The shortest representation that reads back to the same f64, in exponent form outside
/// [1e-4, 1e9) (the integrators' messages write their times so).
pub use sysid_ode::shortest;

/// "k1 = 1e300, k2 = 0.5": the values `at` of the unknowns `names`, the ten farthest from 1
/// in magnitude when there are more (where a start that cannot be used usually goes wrong).
pub fn named_point(names: &[String], at: &[f64]) -> String {
    let mut order: Vec<usize> = (0..at.len()).collect();
    if at.len() > 10 {
        let far = |v: f64| v.abs().ln().abs();
        order.sort_by(|&a, &b| far(at[b]).total_cmp(&far(at[a])));
        order.truncate(10);
        order.sort_unstable();
    }
    let list: Vec<String> =
        order.iter().map(|&i| format!("{} = {}", names[i], shortest(at[i]))).collect();
    match at.len() > 10 {
        true => format!("{}, … ({} unknowns)", list.join(", "), at.len()),
        false => list.join(", "),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn significant_digits() {
        assert_eq!(significant(32.5, 10), "32.50000000");
        assert_eq!(significant(-0.25, 4), "-0.2500");
        assert_eq!(significant(0.0, 4), "0.000");
        assert_eq!(significant(3e7, 4), "3.000e7");
        assert_eq!(significant(56116.2, 4), "56116");
        assert_eq!(significant(1.2345e-5, 3), "1.23e-5");
        assert_eq!(significant(f64::NAN, 4), "—");
        assert_eq!(significant(f64::INFINITY, 4), "inf");
        assert_eq!(shortest(0.1 + 0.2), "0.30000000000000004");
        assert_eq!(shortest(2.5e-7), "2.5e-7");
    }
}
