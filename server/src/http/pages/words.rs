//! How the HTML pages put numbers in words, once: the participant pages and the organiser's
//! console ([`crate::http::admin`]) both read durations so.

/// A number of seconds as `1h 02m`, `3m 05s` or `42s`.
pub(in crate::http) fn duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    match s {
        0..60 => format!("{s}s"),
        60..3600 => format!("{}m {:02}s", s / 60, s % 60),
        _ => format!("{}h {:02}m", s / 3600, (s % 3600) / 60),
    }
}
