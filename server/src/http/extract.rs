//! axum's extractors with their rejections mapped to [`ServiceError`], so a bad path segment
//! (`/api/v1/scenes/%ff`), query string or body answers the documented JSON error with a
//! `code` and the request id instead of axum's plain-text default. Handlers use these and never
//! the raw `Path`, `Query` or `Bytes`.

use std::net::{IpAddr, SocketAddr};

use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use bytes::Bytes;
use serde::de::DeserializeOwned;

use crate::error::ServiceError;
use crate::service::AppState;

/// `axum::extract::Path`, refusing with 400 `bad_request` (e.g. a segment that is not UTF-8).
#[derive(Debug)]
pub(crate) struct PathArg<T>(pub T);

impl<T, S> FromRequestParts<S> for PathArg<T>
where
    T: DeserializeOwned + Send,
    S: Send + Sync,
{
    type Rejection = ServiceError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ServiceError> {
        match axum::extract::Path::<T>::from_request_parts(parts, state).await {
            Ok(axum::extract::Path(v)) => Ok(PathArg(v)),
            Err(e) => Err(ServiceError::BadRequest(format!(
                "bad URL path: {}",
                e.body_text()
            ))),
        }
    }
}

/// `axum::extract::Query`, refusing with 400 `bad_request`.
#[derive(Debug)]
pub(crate) struct QueryArgs<T>(pub T);

impl<T, S> FromRequestParts<S> for QueryArgs<T>
where
    T: DeserializeOwned,
    S: Send + Sync,
{
    type Rejection = ServiceError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ServiceError> {
        match axum::extract::Query::<T>::from_request_parts(parts, state).await {
            Ok(axum::extract::Query(v)) => Ok(QueryArgs(v)),
            Err(e) => Err(ServiceError::BadRequest(format!(
                "bad query string: {}",
                e.body_text()
            ))),
        }
    }
}

/// The whole body, at most `max_body_bytes` (the router's `DefaultBodyLimit`): past it, 413
/// `body_too_large` with the limit. For the small JSON bodies of organiser and registration
/// routes; plan files are streamed instead, so their refusal can name the line.
#[derive(Debug)]
pub(crate) struct BodyBytes(pub Bytes);

impl FromRequest<AppState> for BodyBytes {
    type Rejection = ServiceError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, ServiceError> {
        match Bytes::from_request(req, state).await {
            Ok(b) => Ok(BodyBytes(b)),
            Err(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => Err(ServiceError::BodyTooLarge {
                limit: state.config().max_body_bytes,
            }),
            Err(e) => Err(ServiceError::BadRequest(format!(
                "cannot read the body: {}",
                e.body_text()
            ))),
        }
    }
}

/// The client's address for the login throttle: see [`client_address`], from the TCP peer
/// and `[sessions] client_address_header` behind `trusted_proxy_hops` proxies. `None` when
/// unknown (a router driven without a socket, as unit tests do, or an entry that is no address).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ClientAddr(pub Option<IpAddr>);

impl FromRequestParts<AppState> for ClientAddr {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let cfg = &state.config().sessions;
        let peer = (parts.extensions.get::<axum::extract::ConnectInfo<SocketAddr>>()).map(|c| c.0.ip());
        if cfg.trusted_proxy_hops == 0 {
            return Ok(ClientAddr(client_address(peer, [], 0)));
        }
        let forwarded = parts.headers.get_all(cfg.client_address_header.as_str());
        let forwarded = forwarded.iter().map(|v| v.as_bytes());
        Ok(ClientAddr(client_address(
            peer,
            forwarded,
            cfg.trusted_proxy_hops,
        )))
    }
}

/// The address of the client behind `hops` trusted proxies, each of which appends the address
/// it received the request from to the `forwarded` header (`x-forwarded-for` style: the values
/// of every occurrence of the header, in order, each a comma-separated list).
///
/// Policy (docs/reference/pages.md, trusted proxies): the client is the rightmost address no
/// trusted proxy vouches for. The list is the header's entries followed by `peer`; `peer` is the
/// nearest proxy (hop 1) and each trusted proxy's entry is the address it received from, so the
/// client is the entry `hops` places left of `peer`. Entries further left were written by the
/// client or untrusted proxies and are never read, so forging them changes nothing. A list shorter than `hops + 1`
/// (fewer proxies than configured) gives its leftmost entry, the farthest hop known.
/// - `hops == 0`: `peer`; the header is not read at all.
/// - The chosen entry may be an IP address, optionally with a port (`1.2.3.4:5`, `[::1]:5`);
///   anything else (`unknown`, an obfuscated RFC 7239 name, garbage) is `None`, the one shared
///   bucket of unknown clients, never a bucket per distinct string.
/// - IPv4-mapped IPv6 addresses are their IPv4 address, so a dual-stack socket does not give one
///   client two buckets.
pub(crate) fn client_address<'a>(
    peer: Option<IpAddr>,
    forwarded: impl IntoIterator<Item = &'a [u8]>,
    hops: u8,
) -> Option<IpAddr> {
    if hops == 0 {
        return peer.map(|p| p.to_canonical());
    }
    let entries: Vec<&[u8]> = (forwarded.into_iter())
        .flat_map(|value| value.split(|b| *b == b','))
        .collect();
    // With `peer` appended at index `len`, the client is at `len - hops`.
    match entries.len().checked_sub(usize::from(hops)) {
        Some(i) => parse_entry(entries[i]),
        None => match entries.first() {
            Some(leftmost) => parse_entry(leftmost),
            None => peer.map(|p| p.to_canonical()),
        },
    }
}

/// One entry of a forwarded-for list: an IP address, with or without a port.
fn parse_entry(entry: &[u8]) -> Option<IpAddr> {
    let entry = std::str::from_utf8(entry).ok()?.trim();
    let ip = (entry.parse::<IpAddr>().ok())
        .or_else(|| entry.parse::<SocketAddr>().ok().map(|s| s.ip()))
        .or_else(|| entry.strip_prefix('[')?.strip_suffix(']')?.parse().ok())?;
    Some(ip.to_canonical())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(s: &str) -> Option<IpAddr> {
        Some(s.parse().unwrap())
    }

    /// The client behind `hops` proxies, the peer being 10.0.0.1.
    fn client(headers: &[&str], hops: u8) -> Option<IpAddr> {
        client_address(ip("10.0.0.1"), headers.iter().map(|h| h.as_bytes()), hops)
    }

    #[test]
    fn no_trusted_proxy_means_the_peer_whatever_the_header_says() {
        assert_eq!(client(&["192.0.2.4"], 0), ip("10.0.0.1"));
        assert_eq!(client(&[], 0), ip("10.0.0.1"));
        assert_eq!(client_address(None, [b"192.0.2.4".as_slice()], 0), None);
        assert_eq!(client_address(ip("::ffff:10.0.0.9"), [], 0), ip("10.0.0.9"));
    }

    #[test]
    fn the_client_is_the_rightmost_address_no_trusted_proxy_vouches_for() {
        assert_eq!(client(&["a, b, 192.0.2.3"], 1), ip("192.0.2.3"));
        assert_eq!(client(&["a, 192.0.2.2, 192.0.2.3"], 2), ip("192.0.2.2"));
        assert_eq!(client(&["192.0.2.1, b, c"], 3), ip("192.0.2.1"));
        // Every occurrence of the header counts, in order.
        assert_eq!(client(&["a, 192.0.2.2", "192.0.2.3"], 1), ip("192.0.2.3"));
        assert_eq!(client(&["a, 192.0.2.2", "192.0.2.3"], 2), ip("192.0.2.2"));
        assert_eq!(client(&[" 2001:db8::1 "], 1), ip("2001:db8::1"));
    }

    #[test]
    fn a_list_shorter_than_the_hops_gives_its_leftmost_entry() {
        // No header: the peer itself (the request reached the server without the proxies).
        assert_eq!(client(&[], 1), ip("10.0.0.1"));
        assert_eq!(client(&[], 2), ip("10.0.0.1"));
        assert_eq!(client(&["192.0.2.5"], 2), ip("192.0.2.5"));
        assert_eq!(client(&["192.0.2.5, 192.0.2.6"], 5), ip("192.0.2.5"));
        assert_eq!(client_address(None, [], 1), None);
    }

    #[test]
    fn entries_with_ports_are_addresses_and_garbage_is_the_unknown_client() {
        assert_eq!(client(&["a, 192.0.2.3:4711"], 1), ip("192.0.2.3"));
        assert_eq!(client(&["[2001:db8::2]:443"], 1), ip("2001:db8::2"));
        assert_eq!(client(&["[2001:db8::3]"], 1), ip("2001:db8::3"));
        assert_eq!(client(&["::ffff:192.0.2.4"], 1), ip("192.0.2.4"));
        // Whatever the garbage, it is one key (None), never a fresh bucket per string.
        for garbage in ["unknown", "", "_hidden", "1.2.3", "192.0.2.3 x", "é"] {
            assert_eq!(client(&[garbage], 1), None, "{garbage:?}");
            assert_eq!(client(&["192.0.2.9", garbage], 1), None, "{garbage:?}");
        }
        assert_eq!(client_address(ip("10.0.0.1"), [b"\xff\xfe".as_slice()], 1), None);
        // Garbage left of the client's entry is never read.
        assert_eq!(client(&["\u{1}, unknown, 192.0.2.3"], 1), ip("192.0.2.3"));
    }

    #[test]
    fn whatever_a_client_writes_behind_one_proxy_its_entry_is_the_proxys() {
        // The client's own header, which the proxy appends the client's address (192.0.2.8) to.
        for forged in [
            "",
            "1.2.3.4, ",
            "1.2.3.4, 5.6.7.8, ",
            "unknown, 9.9.9.9,",
            "garbage, ",
        ] {
            let sent = format!("{forged}192.0.2.8");
            assert_eq!(client(&[&sent], 1), ip("192.0.2.8"), "{forged:?}");
        }
    }
}
