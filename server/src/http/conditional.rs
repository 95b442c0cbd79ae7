//! Conditional GET (RFC 9110 §13) for files the server serves with a validator (the episode
//! videos): whether a request's `If-None-Match` / `If-Modified-Since` lets the answer be an
//! empty 304 Not Modified.
//!
//! Rules, as §13.1 and §13.2.2 say for GET and HEAD:
//! - `If-None-Match` is a `*` or a comma-separated list of entity tags, compared *weakly*
//!   (`W/"x"` matches `"x"`): any match means 304; `*` matches whenever the file exists.
//!   A header we cannot read matches nothing (the full answer is always safe).
//! - `If-Modified-Since` is read only when there is no `If-None-Match`: 304 when the file was
//!   not modified after that date (at the one-second resolution of HTTP dates). An invalid
//!   date is ignored.
//! - Both are evaluated before `Range`: a 304 has no body, whatever range was asked.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use axum::http::{HeaderMap, header};

/// Whether the request's preconditions say the client's copy is current (answer 304).
/// `etag` is the file's entity tag as sent (`"…"`); `modified` its modification time.
pub(crate) fn not_modified(headers: &HeaderMap, etag: &str, modified: Option<SystemTime>) -> bool {
    let text = |name| {
        headers
            .get(name)
            .and_then(|v: &axum::http::HeaderValue| v.to_str().ok())
    };
    if headers.contains_key(header::IF_NONE_MATCH) {
        return text(header::IF_NONE_MATCH).is_some_and(|list| none_match_matches(list, etag));
    }
    match (text(header::IF_MODIFIED_SINCE), modified) {
        (Some(since), Some(modified)) => match httpdate::parse_http_date(since.trim()) {
            Ok(since) => whole_seconds(modified) <= since,
            Err(_) => false,
        },
        _ => false,
    }
}

/// The `Last-Modified` value of a file modified at `modified`.
pub(crate) fn last_modified(modified: SystemTime) -> String {
    httpdate::fmt_http_date(modified)
}

/// `modified` cut to whole seconds, as an HTTP date can say it.
fn whole_seconds(t: SystemTime) -> SystemTime {
    let secs = t.duration_since(UNIX_EPOCH).unwrap_or_default().as_secs();
    UNIX_EPOCH + Duration::from_secs(secs)
}

/// Whether an `If-None-Match` value matches `etag` by weak comparison.
fn none_match_matches(list: &str, etag: &str) -> bool {
    if list.trim() == "*" {
        return true;
    }
    let ours = opaque(etag);
    entity_tags(list).is_some_and(|tags| tags.iter().any(|t| Some(*t) == ours))
}

/// The opaque part of an entity tag (`"x"` or `W/"x"` → `x`), quotes required.
fn opaque(tag: &str) -> Option<&str> {
    let tag = tag.trim();
    let tag = tag.strip_prefix("W/").unwrap_or(tag);
    tag.strip_prefix('"')?.strip_suffix('"')
}

/// The opaque tags of a comma-separated list of entity tags; `None` when it is malformed. A
/// tag may itself contain commas (`etagc` allows them), so the list is scanned, not split.
fn entity_tags(list: &str) -> Option<Vec<&str>> {
    let mut tags = Vec::new();
    let mut rest = list;
    loop {
        rest = rest.trim_start_matches([' ', '\t', ',']);
        if rest.is_empty() {
            return Some(tags);
        }
        rest = rest.strip_prefix("W/").unwrap_or(rest);
        let body = rest.strip_prefix('"')?;
        let end = body.find('"')?;
        tags.push(&body[..end]);
        rest = &body[end + 1..];
        if !(rest.is_empty() || rest.starts_with([' ', '\t', ','])) {
            return None;
        }
    }
}

#[cfg(test)]
mod tests {
    use axum::http::HeaderValue;

    use super::*;

    const TAG: &str = "\"abc\"";

    fn headers(pairs: &[(header::HeaderName, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.append(k.clone(), HeaderValue::from_str(v).unwrap());
        }
        h
    }

    fn inm(v: &str) -> bool {
        not_modified(&headers(&[(header::IF_NONE_MATCH, v)]), TAG, None)
    }

    #[test]
    fn if_none_match_compares_weakly_reads_lists_and_star() {
        assert!(inm("\"abc\""));
        assert!(inm("W/\"abc\""), "weak comparison for GET");
        assert!(inm("\"x\", W/\"y\" ,\"abc\""));
        assert!(inm("\"a,b\", \"abc\""), "a comma inside a tag is part of it");
        assert!(inm("*"));
        assert!(!inm("\"abcd\""));
        assert!(!inm("abc"), "unquoted: malformed, matches nothing");
        assert!(!inm("\"x\" junk, \"abc\""), "malformed list");
        assert!(!inm(""));
        assert!(!not_modified(&HeaderMap::new(), TAG, None));
    }

    #[test]
    fn if_modified_since_counts_only_without_if_none_match() {
        let modified = UNIX_EPOCH + Duration::from_millis(1_700_000_000_400);
        let at = |secs: u64| httpdate::fmt_http_date(UNIX_EPOCH + Duration::from_secs(secs));
        let ims = |v: &str| not_modified(&headers(&[(header::IF_MODIFIED_SINCE, v)]), TAG, Some(modified));
        // The same second as the file (HTTP dates have no fractions): not modified since.
        assert!(ims(&at(1_700_000_000)));
        assert!(ims(&at(1_700_000_500)));
        assert!(!ims(&at(1_699_999_999)), "modified after that date");
        assert!(!ims("yesterday"), "an invalid date is ignored");
        assert_eq!(last_modified(modified), at(1_700_000_000));
        // If-None-Match decides alone when present, even when it does not match.
        let both = headers(&[
            (header::IF_NONE_MATCH, "\"other\""),
            (header::IF_MODIFIED_SINCE, at(1_700_000_500).as_str()),
        ]);
        assert!(!not_modified(&both, TAG, Some(modified)));
        // No modification time known: If-Modified-Since cannot be evaluated.
        let h = headers(&[(header::IF_MODIFIED_SINCE, at(1_700_000_500).as_str())]);
        assert!(!not_modified(&h, TAG, None));
    }
}
