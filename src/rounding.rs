//! Numbers rounded for summaries, sentences and chart labels, shared by the charts and the experiments.

/// `x` rounded to `digits` significant digits.
pub fn significant(x: f64, digits: i32) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(digits - 1 - x.abs().log10().floor() as i32);
    (x * scale).round() / scale
}

/// A number for a sentence: whole numbers without decimals, others to 3 significant digits; "n/a" when
/// not finite.
pub fn num(x: f64) -> String {
    if !x.is_finite() {
        "n/a".into()
    } else if x == x.round() && x.abs() < 1e12 {
        format!("{x:.0}")
    } else {
        format!("{}", significant(x, 3))
    }
}

/// `x` rounded to `decimals` decimals (for summaries).
pub fn round(x: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (x * scale).round() / scale
}
