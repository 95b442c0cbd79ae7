//! Instants the server sends, parsed without a date library: its RFC 3339 timestamps
//! (`created_at`) and the HTTP `Date` header, as Unix milliseconds (for the ETA).

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

fn unix_ms(y: i64, mo: i64, d: i64, h: i64, mi: i64, sec: i64) -> i64 {
    ((days_from_civil(y, mo, d) * 24 + h) * 60 + mi) * 60_000 + sec * 1000
}

/// `2026-11-22T23:15:28.123Z` or `...+01:00` → Unix milliseconds.
pub(crate) fn parse_rfc3339_ms(t: &str) -> Option<i64> {
    let n = |a: usize, b: usize| t.get(a..b)?.parse::<i64>().ok();
    let base = unix_ms(n(0, 4)?, n(5, 7)?, n(8, 10)?, n(11, 13)?, n(14, 16)?, n(17, 19)?);
    let rest = t.get(19..)?;
    let (digits, zone) = match rest.strip_prefix('.') {
        Some(f) => f.split_at(f.find(|c: char| !c.is_ascii_digit()).unwrap_or(f.len())),
        None => ("", rest),
    };
    let frac_ms = format!("{digits:0<3}").get(..3)?.parse::<i64>().ok()?;
    let offset_min = match zone {
        "Z" | "z" => 0,
        z if z.len() == 6 => {
            let sign = if z.starts_with('-') { -1 } else { 1 };
            sign * (z.get(1..3)?.parse::<i64>().ok()? * 60 + z.get(4..6)?.parse::<i64>().ok()?)
        }
        _ => return None,
    };
    Some(base + frac_ms - offset_min * 60_000)
}

/// An HTTP `Date` (`Sun, 22 Nov 2026 23:15:28 GMT`) → Unix milliseconds.
pub(crate) fn parse_http_date_ms(t: &str) -> Option<i64> {
    let f: Vec<&str> = t.split_whitespace().collect();
    let [_, day, month, year, clock, "GMT"] = f.as_slice() else {
        return None;
    };
    const MONTHS: [&str; 12] = [
        "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
    ];
    let mo = MONTHS.iter().position(|m| m == month)? as i64 + 1;
    let hms: Vec<i64> = clock.split(':').map(|x| x.parse().ok()).collect::<Option<_>>()?;
    let [h, mi, sec] = hms.as_slice() else {
        return None;
    };
    Some(unix_ms(year.parse().ok()?, mo, day.parse().ok()?, *h, *mi, *sec))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_parse_to_the_same_instant() {
        let a = parse_rfc3339_ms("2026-11-22T23:15:28Z").unwrap();
        assert_eq!(parse_http_date_ms("Sun, 22 Nov 2026 23:15:28 GMT"), Some(a));
        assert_eq!(parse_rfc3339_ms("2026-11-22T23:15:28.25Z"), Some(a + 250));
        assert_eq!(parse_rfc3339_ms("2026-11-23T00:15:28+01:00"), Some(a));
        assert_eq!(parse_rfc3339_ms("1970-01-01T00:00:01Z"), Some(1000));
        assert_eq!(parse_rfc3339_ms("garbage"), None);
    }
}
