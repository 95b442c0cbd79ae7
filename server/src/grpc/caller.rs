//! The gRPC side of caller resolution: a tower layer around the tonic server that reads each
//! call's `authorization` metadata once, resolves it with [`AppState::caller`] and puts the
//! [`Caller`] in the call's extensions, where a method takes it with [`caller`]. The HTTP side
//! is the `Caller` extractor in `crate::http`; both read the header with one function.

use std::task::{Context, Poll};

use axum::http::{self, header};
use tonic::{Request, Status};

use crate::probe::BoxFuture;
use crate::service::auth::bearer_token;
use crate::service::{AppState, Caller};

#[derive(Debug, Clone)]
pub(crate) struct CallerLayer {
    state: AppState,
}

impl CallerLayer {
    pub(crate) fn new(state: AppState) -> Self {
        CallerLayer { state }
    }
}

impl<S> tower::Layer<S> for CallerLayer {
    type Service = CallerService<S>;

    fn layer(&self, inner: S) -> CallerService<S> {
        CallerService {
            state: self.state.clone(),
            inner,
        }
    }
}

#[derive(Debug, Clone)]
pub(crate) struct CallerService<S> {
    state: AppState,
    inner: S,
}

impl<S, ReqBody, ResBody> tower::Service<http::Request<ReqBody>> for CallerService<S>
where
    S: tower::Service<http::Request<ReqBody>, Response = http::Response<ResBody>> + Clone + Send + 'static,
    S::Future: Send,
    ReqBody: Send + 'static,
    ResBody: Default,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = BoxFuture<'static, Result<Self::Response, Self::Error>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, mut req: http::Request<ReqBody>) -> Self::Future {
        // Call the instance `poll_ready` readied; leave a fresh clone for the next call.
        let fresh = self.inner.clone();
        let mut inner = std::mem::replace(&mut self.inner, fresh);
        let state = self.state.clone();
        Box::pin(async move {
            let header = req.headers().get(header::AUTHORIZATION);
            let token = header.and_then(|v| v.to_str().ok()).and_then(bearer_token);
            match state.caller(token).await {
                Ok(caller) => {
                    req.extensions_mut().insert(caller);
                    inner.call(req).await
                }
                Err(e) => Ok(Status::from(e).into_http()),
            }
        })
    }
}

/// The caller [`CallerLayer`] resolved for this call.
pub(crate) fn caller<T>(req: &Request<T>) -> Result<Caller, Status> {
    req.extensions()
        .get::<Caller>()
        .cloned()
        .ok_or_else(|| Status::internal("the server was built without its caller layer"))
}
