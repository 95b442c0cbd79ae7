//! One WebSocket connection to an openpi policy server, async: the stream to the checked address
//! (TLS for `wss://`), the `/healthz` probe, the handshake and the metadata the server sends
//! first, then one request and one reply per decision, each under its deadline, every failure
//! turned into a reason a participant can act on.
//!
//! We connect the TCP stream ourselves, to the address the endpoint check resolved, and run the
//! WebSocket handshake over it: a second DNS answer cannot redirect us (as for gRPC).

use std::sync::Arc;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_rustls::TlsConnector;
use tokio_rustls::rustls::pki_types::pem::PemObject;
use tokio_rustls::rustls::pki_types::{CertificateDer, ServerName};
use tokio_rustls::rustls::{ClientConfig, RootCertStore};
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};

use super::wire;
use crate::endpoint::Endpoint;
use crate::{Credentials, RemoteConfig, RemoteError};
use kitchen_r_episode::policy::PolicyError;

trait Io: AsyncRead + AsyncWrite + Send + Unpin {}
impl<T: AsyncRead + AsyncWrite + Send + Unpin> Io for T {}

/// Longest `/healthz` answer head read.
const HEALTH_HEAD: usize = 4096;
/// Characters of a text message (openpi's traceback) quoted in a reason: its last ones.
const QUOTED: usize = 200;

/// Where and how to connect; cheap to clone, kept to reconnect after a failed call.
#[derive(Clone)]
pub(crate) struct Target {
    pub(crate) endpoint: Endpoint,
    creds: Credentials,
    pub(crate) call_deadline: Duration,
    max_answer_bytes: usize,
    max_request_bytes: usize,
}

/// An open connection whose metadata has arrived.
pub(crate) struct WsConn {
    ws: WebSocketStream<Box<dyn Io>>,
    /// The keys of the metadata the server sent on connect.
    pub(crate) metadata: Vec<String>,
}

impl Target {
    pub(crate) fn new(endpoint: Endpoint, creds: &Credentials, cfg: &RemoteConfig) -> Target {
        Target {
            endpoint,
            creds: creds.clone(),
            call_deadline: cfg.call_deadline(),
            max_answer_bytes: cfg.max_answer_bytes,
            max_request_bytes: cfg.max_request_bytes,
        }
    }

    fn uri(&self) -> String {
        self.endpoint.uri.clone()
    }

    /// TCP to the checked address, then TLS for `wss://` (the public web roots, plus the
    /// participant's CA when given).
    async fn stream(&self) -> Result<Box<dyn Io>, String> {
        let tcp = TcpStream::connect(self.endpoint.addrs[0])
            .await
            .map_err(|e| format!("connect: {e}"))?;
        let _ = tcp.set_nodelay(true);
        if !self.endpoint.tls {
            return Ok(Box::new(tcp));
        }
        let mut roots = RootCertStore {
            roots: webpki_roots::TLS_SERVER_ROOTS.to_vec(),
        };
        if let Some(pem) = &self.creds.ca_pem {
            for c in CertificateDer::pem_slice_iter(pem) {
                let c = c.map_err(|e| format!("the CA certificate: {e}"))?;
                roots.add(c).map_err(|e| format!("the CA certificate: {e}"))?;
            }
        }
        let provider = Arc::new(tokio_rustls::rustls::crypto::ring::default_provider());
        let config = ClientConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .map_err(|e| format!("TLS: {e}"))?
            .with_root_certificates(roots)
            .with_no_client_auth();
        let name = ServerName::try_from(self.endpoint.host.clone()).map_err(|e| format!("TLS name: {e}"))?;
        let tls = TlsConnector::from(Arc::new(config))
            .connect(name, tcp)
            .await
            .map_err(|e| format!("TLS handshake: {e}"))?;
        Ok(Box::new(tls))
    }

    /// `GET /healthz`: the status code, or why nothing usable answered.
    pub(crate) async fn health(&self) -> Result<u16, String> {
        let deadline = self.call_deadline;
        let probe = async {
            let mut s = self.stream().await?;
            let host = self.endpoint.uri.split_once("://").map_or("", |(_, h)| h);
            let req = format!("GET /healthz HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n");
            s.write_all(req.as_bytes())
                .await
                .map_err(|e| format!("sending GET /healthz: {e}"))?;
            let mut head = Vec::with_capacity(256);
            let mut buf = [0u8; 512];
            while !head.windows(2).any(|w| w == b"\r\n") && head.len() < HEALTH_HEAD {
                let n = s
                    .read(&mut buf)
                    .await
                    .map_err(|e| format!("reading /healthz: {e}"))?;
                if n == 0 {
                    break;
                }
                head.extend_from_slice(&buf[..n]);
            }
            let line = String::from_utf8_lossy(&head);
            let status = line.lines().next().unwrap_or("");
            match status.split_whitespace().collect::<Vec<_>>().as_slice() {
                [http, code, ..] if http.starts_with("HTTP/1.") => code
                    .parse()
                    .map_err(|_| format!("GET /healthz answered {status:?}, not an HTTP status")),
                _ if head.is_empty() => Err("GET /healthz: the connection closed without an answer".into()),
                _ => Err(format!("GET /healthz answered {status:?}, not HTTP")),
            }
        };
        tokio::time::timeout(deadline, probe).await.unwrap_or_else(|_| {
            Err(format!(
                "GET /healthz: no answer within {:.1} s",
                deadline.as_secs_f64()
            ))
        })
    }

    /// Probe `/healthz` until it answers 200 or `deadline` passes: a server still starting is
    /// given time; one that answers another status until the end is refused with it.
    pub(crate) async fn wait_healthy(&self, deadline: Duration) -> Result<(), RemoteError> {
        let started = Instant::now();
        loop {
            let (answered, reason) = match self.health().await {
                Ok(200) => return Ok(()),
                Ok(code) => (
                    true,
                    format!(
                        "GET /healthz answered {code}, not 200 (openpi's WebsocketPolicyServer answers 200 OK)"
                    ),
                ),
                Err(e) => (false, e),
            };
            if started.elapsed() >= deadline {
                let endpoint = self.uri();
                return Err(if answered {
                    RemoteError::Health { endpoint, reason }
                } else {
                    RemoteError::Unreachable {
                        endpoint,
                        waited_s: started.elapsed().as_secs_f64(),
                        reason,
                    }
                });
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// Connect, shake hands and read the metadata, all within `deadline`.
    pub(crate) async fn open(&self, deadline: Duration) -> Result<WsConn, String> {
        tokio::time::timeout(deadline, self.open_now())
            .await
            .unwrap_or_else(|_| {
                Err(format!(
                    "the server sent no metadata within {:.1} s of the connection (an openpi \
                     server sends its metadata as soon as a client connects)",
                    deadline.as_secs_f64()
                ))
            })
    }

    /// [`Target::open`] without its deadline (the caller sets one).
    pub(crate) async fn open_now(&self) -> Result<WsConn, String> {
        let stream = self.stream().await?;
        let mut req = format!("{}/", self.uri())
            .into_client_request()
            .map_err(|e| format!("the WebSocket request: {e}"))?;
        if let Some(t) = &self.creds.token {
            // What openpi_client.WebsocketClientPolicy sends for its api_key.
            let v = format!("Api-Key {t}")
                .parse()
                .map_err(|_| "the token must be printable ASCII".to_string())?;
            req.headers_mut().insert("authorization", v);
        }
        let config = WebSocketConfig::default()
            .max_message_size(Some(self.max_answer_bytes))
            .max_frame_size(Some(self.max_answer_bytes));
        let (mut ws, _) = tokio_tungstenite::client_async_with_config(req, stream, Some(config))
            .await
            .map_err(|e| format!("WebSocket handshake: {}", self.describe(&e)))?;
        let first = next_binary(&mut ws, self.max_answer_bytes)
            .await
            .map_err(|e| format!("before its metadata: {e}"))?;
        let metadata = wire::metadata_keys(&first).map_err(|e| format!("the metadata: {e}"))?;
        Ok(WsConn { ws, metadata })
    }

    fn describe(&self, e: &WsError) -> String {
        describe(e, self.max_answer_bytes)
    }
}

impl WsConn {
    /// Send one packed observation and wait for the reply under the call deadline.
    pub(crate) async fn act(&mut self, t: &Target, request: Vec<u8>) -> Result<Vec<u8>, PolicyError> {
        if request.len() > t.max_request_bytes {
            return Err(PolicyError::Call(format!(
                "the observation is {} bytes, over the request size cap (policy.max_request_bytes \
                 = {}): ask for smaller images in the key map",
                request.len(),
                t.max_request_bytes
            )));
        }
        let exchange = async {
            self.ws
                .send(Message::Binary(request.into()))
                .await
                .map_err(|e| format!("sending the observation: {}", describe(&e, t.max_answer_bytes)))?;
            next_binary(&mut self.ws, t.max_answer_bytes).await
        };
        match tokio::time::timeout(t.call_deadline, exchange).await {
            Err(_) => Err(PolicyError::Timeout(t.call_deadline.as_secs_f64())),
            Ok(Err(e)) => Err(PolicyError::Call(format!(
                "openpi endpoint {}: {e}",
                t.endpoint.uri
            ))),
            Ok(Ok(b)) => Ok(b),
        }
    }

    /// Close politely; errors do not matter any more.
    pub(crate) async fn close(mut self) {
        let _ = tokio::time::timeout(Duration::from_millis(200), self.ws.close(None)).await;
    }
}

/// The next binary message; a text message, a close or an error is the reason it is not.
async fn next_binary(ws: &mut WebSocketStream<Box<dyn Io>>, cap: usize) -> Result<Vec<u8>, String> {
    loop {
        match ws.next().await {
            Some(Ok(Message::Binary(b))) => return Ok(b.to_vec()),
            Some(Ok(Message::Text(t))) => {
                // A traceback ends with the exception: quote the end, which a stored reason
                // (cut at 512 characters) keeps.
                let t = t.as_str().trim();
                let n = t.chars().count();
                let quoted: String = t.chars().skip(n.saturating_sub(QUOTED)).collect();
                let cut = if n > QUOTED { "…" } else { "" };
                return Err(format!(
                    "the server sent a text message instead of msgpack (openpi servers send a \
                     Python traceback this way when the policy raised): {cut}{quoted}"
                ));
            }
            Some(Ok(Message::Close(f))) => {
                return Err(match f {
                    Some(f) => format!(
                        "the server closed the connection (code {}{})",
                        u16::from(f.code),
                        if f.reason.is_empty() {
                            String::new()
                        } else {
                            format!(": {}", f.reason)
                        }
                    ),
                    None => "the server closed the connection".into(),
                });
            }
            Some(Ok(_)) => continue,
            Some(Err(e)) => return Err(describe(&e, cap)),
            None => return Err("the connection closed".into()),
        }
    }
}

/// A WebSocket error as a reason.
fn describe(e: &WsError, cap: usize) -> String {
    match e {
        WsError::Capacity(_) => format!("the answer exceeds the {cap}-byte size cap"),
        WsError::ConnectionClosed | WsError::AlreadyClosed => "the connection closed".into(),
        WsError::Protocol(p) => format!("the connection dropped or broke the WebSocket protocol ({p})"),
        WsError::Io(io) => format!("the connection dropped or could not be made ({io})"),
        WsError::Http(r) => format!(
            "the server answered HTTP {} instead of switching to WebSocket",
            r.status()
        ),
        other => other.to_string(),
    }
}
