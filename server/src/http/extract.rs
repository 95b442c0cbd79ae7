//! axum's extractors with their rejections mapped to [`ServiceError`], so a bad path segment
//! (`/api/v1/scenes/%ff`), query string or body answers the documented JSON error with a
//! `code` and the request id instead of axum's plain-text default. Handlers use these and never
//! the raw `Path`, `Query` or `Bytes`.

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

/// The client's address for the login throttle: the `[sessions] client_address_header`'s first
/// address when configured (behind a reverse proxy), else the TCP peer's; `None` when neither
/// is known (a router driven without a socket, as unit tests do).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ClientAddr(pub Option<std::net::IpAddr>);

impl FromRequestParts<AppState> for ClientAddr {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let header = &state.config().sessions.client_address_header;
        if !header.is_empty() {
            let forwarded = (parts.headers.get(header.as_str()))
                .and_then(|v| v.to_str().ok())
                .and_then(|v| v.split(',').next())
                .and_then(|a| a.trim().parse().ok());
            if forwarded.is_some() {
                return Ok(ClientAddr(forwarded));
            }
        }
        let peer = parts
            .extensions
            .get::<axum::extract::ConnectInfo<std::net::SocketAddr>>()
            .map(|c| c.0.ip());
        Ok(ClientAddr(peer))
    }
}
