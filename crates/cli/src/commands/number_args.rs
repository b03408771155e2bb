//! Clap value parsers for numbers that must be finite and in range. NaN passes every `<` and
//! `>` check unnoticed (and then poisons the result), so the range is checked where the
//! argument is parsed, with a one-line error naming the value.

/// A finite number ≥ 0.
pub fn non_negative(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{s:?}: {e}"))?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{s}: expected a finite number ≥ 0"))
    }
}

/// [`non_negative`] as `f32`.
pub fn non_negative_f32(s: &str) -> std::result::Result<f32, String> {
    non_negative(s).and_then(|v| to_f32(s, v))
}

/// A finite number > 0.
pub fn positive(s: &str) -> std::result::Result<f64, String> {
    match non_negative(s)? {
        0.0 => Err(format!("{s}: expected a finite number > 0")),
        v => Ok(v),
    }
}

/// A fraction in (0, 1].
pub fn fraction(s: &str) -> std::result::Result<f64, String> {
    match positive(s)? {
        v if v <= 1.0 => Ok(v),
        _ => Err(format!("{s}: expected a fraction in (0, 1]")),
    }
}

/// [`positive`] as `f32`.
pub fn positive_f32(s: &str) -> std::result::Result<f32, String> {
    positive(s).and_then(|v| to_f32(s, v))
}

/// `v` as `f32`, which must still be finite (1e300 is an `f64` but not an `f32`).
fn to_f32(s: &str, v: f64) -> std::result::Result<f32, String> {
    let single = v as f32;
    if single.is_finite() {
        Ok(single)
    } else {
        Err(format!(
            "{s}: expected a number within single precision's range"
        ))
    }
}

/// A whole number in `lo..=hi` (clap's own ranged parsers cover `u64`/`i64` only).
pub fn count_in(s: &str, lo: usize, hi: usize) -> std::result::Result<usize, String> {
    match s.parse::<usize>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        _ => Err(format!("{s}: expected a whole number from {lo} to {hi}")),
    }
}

/// A whole number ≥ 1.
pub fn positive_count(s: &str) -> std::result::Result<usize, String> {
    match s.parse::<usize>() {
        Ok(v) if v >= 1 => Ok(v),
        _ => Err(format!("{s}: expected a whole number ≥ 1")),
    }
}

/// Two comma-separated numbers (their ranges are the caller's to check); `example` shows the
/// form in the error.
pub fn number_pair(s: &str, example: &str) -> std::result::Result<(f64, f64), String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected two numbers like {example}"))?;
    match v[..] {
        [a, b] => Ok((a, b)),
        _ => Err(format!("expected two numbers like {example}")),
    }
}
