//! Browser sessions of the HTML pages, shared by the organiser console (`/admin`) and the
//! participant pages (`/team`, `/submissions/{id}`): session cookies, CSRF tokens and the
//! headers every page is sent with.
//!
//! Policy:
//! - A session cookie holds a session id (`crate::service::sessions`: random, stored hashed
//!   server-side, never a credential), `HttpOnly` (no script reads it),
//!   `SameSite=Strict` (no other site's page or link sends it), `Path=/`, and `Secure` when the
//!   request came over https (as a reverse proxy says in `X-Forwarded-Proto` or `Forwarded`;
//!   a spoofed header only makes the spoofer's own browser drop the cookie on http).
//! - Every form carries a CSRF field checked on POST (SameSite alone is not relied on): the
//!   browser holds a random nonce in the `kitchen_r_csrf` cookie (same attributes, no expiry)
//!   and the field is a keyed hash of that nonce and the session cookie the form was rendered
//!   under. Another site can neither read the nonce nor compute the field; a field leaked from
//!   one session is worthless in another. The key is random per server process, so a form
//!   rendered before a restart is refused with "reload the page". A request a browser marks
//!   `Sec-Fetch-Site: cross-site` is refused outright.
//! - Pages are `Cache-Control: no-store` with a Content-Security-Policy that allows no script
//!   at all, images and media (the episode videos) from the server itself only, and cannot be
//!   framed: one rule for every HTML answer, in the stack ([`super::stack::PAGE_HEADERS`]).

use std::sync::OnceLock;

use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};

/// The CSRF nonce cookie.
pub(super) const CSRF_COOKIE: &str = "kitchen_r_csrf";
/// What a refused form says.
pub(super) const CSRF_REFUSED: &str =
    "This form expired or was sent from another site: reload the page and send it again.";
/// The form field holding the CSRF token.
pub(super) const CSRF_FIELD: &str = "csrf";

/// The value of cookie `name`, if the request has it.
pub(super) fn cookie<'a>(headers: &'a HeaderMap, name: &str) -> Option<&'a str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|kv| kv.trim().strip_prefix(name)?.strip_prefix('='))
        .find(|v| !v.is_empty())
}

/// The session id a session cookie holds, if any.
pub(super) fn session_id<'a>(headers: &'a HeaderMap, name: &str) -> Option<&'a str> {
    cookie(headers, name)
}

/// Whether the request reached us over https (directly or through a proxy that says so).
pub(super) fn https(headers: &HeaderMap) -> bool {
    let value = |h: &str| {
        headers
            .get(h)
            .and_then(|v| v.to_str().ok())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default()
    };
    value("x-forwarded-proto").split(',').next().map(str::trim) == Some("https")
        || value("forwarded").contains("proto=https")
}

/// A `Set-Cookie` value with the attributes of [the policy](self); `max_age` `None` is a
/// browser-session cookie, `Some(0)` deletes it.
pub(super) fn set_cookie(name: &str, value: &str, max_age: Option<u32>, secure: bool) -> HeaderValue {
    let mut c = format!("{name}={value}; Path=/; HttpOnly; SameSite=Strict");
    if let Some(s) = max_age {
        c.push_str(&format!("; Max-Age={s}"));
    }
    if secure {
        c.push_str("; Secure");
    }
    // Names are constants and values hex: always a valid header.
    HeaderValue::from_str(&c).unwrap_or_else(|_| HeaderValue::from_static("invalid=; Max-Age=0"))
}

/// The session cookie for session id `id` (hex, so always a valid cookie value).
pub(super) fn session_cookie(name: &str, id: &str, max_age: u32, secure: bool) -> HeaderValue {
    set_cookie(name, id, Some(max_age), secure)
}

fn key() -> &'static [u8; 32] {
    static KEY: OnceLock<[u8; 32]> = OnceLock::new();
    KEY.get_or_init(rand::random)
}

/// The CSRF token of a form rendered for a browser holding `nonce` under `session` (the raw
/// session cookie value, empty when there is none).
fn token(nonce: &str, session: &str) -> String {
    let mut h = Sha256::new();
    h.update(key());
    h.update(nonce.as_bytes());
    h.update([0]);
    h.update(session.as_bytes());
    hex::encode(&h.finalize()[..16])
}

/// What a page needs to render forms: the hidden field, and the nonce cookie to set when the
/// browser had none.
#[derive(Debug, Clone)]
pub(super) struct Csrf {
    pub field: String,
    pub set_cookie: Option<HeaderValue>,
}

/// The CSRF field for forms on a page answering `headers`, bound to session cookie `session`.
pub(super) fn csrf(headers: &HeaderMap, session: &str) -> Csrf {
    let raw_session = cookie(headers, session).unwrap_or("");
    let (nonce, set) = match cookie(headers, CSRF_COOKIE) {
        Some(n) => (n.to_string(), None),
        None => {
            let n = hex::encode(rand::random::<[u8; 16]>());
            let c = set_cookie(CSRF_COOKIE, &n, None, https(headers));
            (n, Some(c))
        }
    };
    let field = format!(
        "<input type=hidden name={CSRF_FIELD} value=\"{}\">",
        token(&nonce, raw_session)
    );
    Csrf {
        field,
        set_cookie: set,
    }
}

/// Whether a POST with CSRF field `sent` is from a form this server rendered for this browser
/// under the same session cookie `session`.
pub(super) fn csrf_ok(headers: &HeaderMap, session: &str, sent: Option<&str>) -> bool {
    let cross_site = headers
        .get("sec-fetch-site")
        .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"cross-site"));
    let (Some(nonce), Some(sent)) = (cookie(headers, CSRF_COOKIE), sent) else {
        return false;
    };
    let want = token(nonce, cookie(headers, session).unwrap_or(""));
    // Constant time: the comparison does not say how much of the token was right.
    let same = want.len() == sent.len()
        && want
            .bytes()
            .zip(sent.bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0;
    !cross_site && same
}

/// What a login form says while failed logins are throttled.
pub(super) fn throttled_message(retry_after_s: u64) -> String {
    format!("Too many failed logins from your address: try again in {retry_after_s} s.")
}

/// `r` with `Retry-After: retry_after_s`.
pub(super) fn with_retry_after(mut r: Response, retry_after_s: u64) -> Response {
    r.headers_mut()
        .insert(header::RETRY_AFTER, HeaderValue::from(retry_after_s));
    r
}

/// An HTML answer; the pages' security headers are added by the stack
/// ([`super::stack::PAGE_HEADERS`]) to every HTML answer.
pub(super) fn html(status: StatusCode, body: String) -> Response {
    let mut r = (status, body).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/html; charset=utf-8"),
    );
    r
}

/// `html` with the CSRF nonce cookie set when the page made one.
pub(super) fn html_with(status: StatusCode, body: String, csrf: &Csrf) -> Response {
    let mut r = html(status, body);
    if let Some(c) = &csrf.set_cookie {
        r.headers_mut().append(header::SET_COOKIE, c.clone());
    }
    r
}

/// 303 to `location` (a path of ours), setting `cookies`.
pub(super) fn see_other(location: &str, cookies: &[HeaderValue]) -> Response {
    let mut r = StatusCode::SEE_OTHER.into_response();
    let h = r.headers_mut();
    if let Ok(v) = HeaderValue::from_str(location) {
        h.insert(header::LOCATION, v);
    }
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    for c in cookies {
        h.append(header::SET_COOKIE, c.clone());
    }
    r
}

/// A local path to return to after a login: only `/…` paths of this site. Not `//host` nor
/// `/\host`, and no space or control character (browsers drop tabs and newlines from URLs,
/// which would turn `/<TAB>/host` into `//host`).
pub(super) fn local_path(next: Option<&str>) -> Option<&str> {
    next.filter(|n| {
        n.starts_with('/')
            && !n.starts_with("//")
            && n.len() < 200
            && n.chars().all(|c| c.is_ascii_graphic() && c != '\\')
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(cookies: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(header::COOKIE, HeaderValue::from_str(cookies).unwrap());
        h
    }

    #[test]
    fn csrf_tokens_bind_the_nonce_and_the_session() {
        let fresh = csrf(&HeaderMap::new(), "s");
        let set = fresh.set_cookie.unwrap();
        let set = set.to_str().unwrap();
        for attr in ["HttpOnly", "SameSite=Strict", "Path=/"] {
            assert!(set.contains(attr), "{set}");
        }
        let nonce = set.split(';').next().unwrap().to_string();
        let field = |h: &HeaderMap| {
            let c = csrf(h, "s");
            assert!(c.set_cookie.is_none());
            c.field.split('"').nth(1).unwrap().to_string()
        };
        let h = headers(&format!("{nonce}; s=aa"));
        let t = field(&h);
        assert!(csrf_ok(&h, "s", Some(&t)));
        assert!(!csrf_ok(&h, "s", None));
        assert!(!csrf_ok(&h, "s", Some("0000")));
        // Another session or another browser's nonce: refused.
        assert!(!csrf_ok(&headers(&format!("{nonce}; s=bb")), "s", Some(&t)));
        assert!(!csrf_ok(&headers("kitchen_r_csrf=ff; s=aa"), "s", Some(&t)));
        let mut cross = h.clone();
        cross.insert("sec-fetch-site", HeaderValue::from_static("cross-site"));
        assert!(!csrf_ok(&cross, "s", Some(&t)));
    }

    #[test]
    fn https_is_read_from_proxy_headers_and_only_local_paths_are_followed() {
        let mut h = HeaderMap::new();
        assert!(!https(&h));
        h.insert("x-forwarded-proto", HeaderValue::from_static("https"));
        assert!(https(&h));
        assert!(
            set_cookie("a", "b", Some(1), true)
                .to_str()
                .unwrap()
                .ends_with("; Secure")
        );
        assert_eq!(local_path(Some("/submissions/3")), Some("/submissions/3"));
        for bad in [
            "//evil.example",
            "https://evil.example",
            "/\\evil",
            "/\t/evil.example",
            "/\n/x",
            "",
        ] {
            assert_eq!(local_path(Some(bad)), None, "{bad}");
        }
    }
}
