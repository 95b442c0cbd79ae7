//! Login throttling that cannot be turned against users (docs/reference/pages.md): failed logins
//! are limited per client address only, and the client address is the rightmost one no trusted
//! proxy vouches for. Through the router, then through the real server (`Server::run`) on
//! 127.0.0.1:0.

use std::net::{IpAddr, SocketAddr};

use axum::body::Body;
use axum::http::{Request, header};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::tests::{Answer, call, get, pair};
use super::*;
use crate::http::{admin, router};
use crate::testutil::{ADMIN, FakeProbe, Fixture, WORKER, fixture};

/// Behind one proxy that appends to `x-forwarded-for`, with `per_address` failures a minute.
async fn behind_one_proxy(per_address: u32) -> Fixture {
    fixture(FakeProbe::ok(2), |c| {
        c.sessions.failures_per_minute_per_address = per_address;
        c.sessions.trusted_proxy_hops = 1;
        c.sessions.client_address_header = "x-forwarded-for".into();
    })
    .await
}

/// A login form's POST as the proxy passes it on: `forwarded` is its `x-forwarded-for`, the
/// client's own value (if any) with the client's address appended.
fn post_login(path: &str, form: &Answer, forwarded: &str, token: &str) -> Request<Body> {
    let nonce = pair(&form.cookie(crate::http::session::CSRF_COOKIE).unwrap());
    Request::post(path)
        .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded")
        .header(header::COOKIE, nonce)
        .header("x-forwarded-for", forwarded)
        .body(Body::from(format!("token={token}&csrf={}", form.csrf())))
        .unwrap()
}

#[tokio::test]
async fn a_flood_of_failed_logins_from_many_addresses_locks_out_no_one_else() {
    let f = behind_one_proxy(10).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let form = call(&app, get("/team/login", "")).await;
    // 200 addresses fail in well under a minute (the overall cap this replaced was 120), each
    // behind a forged first entry the proxy appended to.
    for i in 0..200u32 {
        let from = format!("198.51.100.7, 10.0.{}.{}", i / 256, i % 256);
        let a = call(&app, post_login("/team/login", &form, &from, "kr_guess")).await;
        assert_eq!(a.status, StatusCode::UNAUTHORIZED, "{from}: {}", a.body);
    }
    // Each address is still limited: nine more failures spend the first one's ten.
    for n in 0..10 {
        let a = call(&app, post_login("/team/login", &form, "10.0.0.0", "kr_guess")).await;
        let want = [StatusCode::UNAUTHORIZED, StatusCode::TOO_MANY_REQUESTS][usize::from(n == 9)];
        assert_eq!(a.status, want, "{n}");
    }
    // Any other address logs in, team and organiser alike.
    let a = call(&app, post_login("/team/login", &form, "203.0.113.9", &token)).await;
    assert_eq!(a.status, StatusCode::SEE_OTHER, "{}", a.body);
    assert!(a.cookie(TEAM_COOKIE).is_some());
    let console = call(&app, get("/admin", "")).await;
    let a = call(&app, post_login("/admin/login", &console, "203.0.113.10", ADMIN)).await;
    assert_eq!(a.status, StatusCode::SEE_OTHER, "{}", a.body);
    assert!(a.cookie(admin::COOKIE).is_some());
}

#[tokio::test]
async fn behind_one_trusted_proxy_a_forged_forwarded_entry_does_not_escape_the_limit() {
    let f = behind_one_proxy(3).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let form = call(&app, get("/team/login", "")).await;
    // The client writes a new first entry each time; the proxy appends its real address.
    for i in 0..3 {
        let from = format!("1.2.3.{i}, 192.0.2.50");
        let a = call(&app, post_login("/team/login", &form, &from, "kr_guess")).await;
        assert_eq!(a.status, StatusCode::UNAUTHORIZED);
    }
    for (from, t) in [
        ("1.2.3.99, 192.0.2.50", "kr_guess"),
        ("192.0.2.50", token.as_str()),
    ] {
        let a = call(&app, post_login("/team/login", &form, from, t)).await;
        assert_eq!(a.status, StatusCode::TOO_MANY_REQUESTS, "{from}: {}", a.body);
        let wait: u64 = a.headers[header::RETRY_AFTER].to_str().unwrap().parse().unwrap();
        assert!((1..=20).contains(&wait), "{wait}");
    }
    // Garbage where the proxy's entry should be is one shared unknown client, not a new one
    // per string: it is throttled like an address.
    for i in 0..3 {
        let from = format!("192.0.2.51, garbage-{i}");
        let a = call(&app, post_login("/team/login", &form, &from, "kr_guess")).await;
        assert_eq!(a.status, StatusCode::UNAUTHORIZED);
    }
    let a = call(
        &app,
        post_login("/team/login", &form, "192.0.2.51, other", "kr_guess"),
    )
    .await;
    assert_eq!(a.status, StatusCode::TOO_MANY_REQUESTS);
}

/// An HTTP/1.1 answer read off a socket.
struct Reply {
    status: u16,
    head: String,
    body: String,
}

impl Reply {
    fn header(&self, name: &str) -> Option<&str> {
        (self.head.lines()).find_map(|l| {
            let (n, v) = l.split_once(':')?;
            n.eq_ignore_ascii_case(name).then(|| v.trim())
        })
    }

    /// The `name=value` of the cookie `name` it sets.
    fn cookie(&self, name: &str) -> Option<&str> {
        (self.head.lines()).find_map(|l| {
            let (n, v) = l.split_once(':')?;
            let pair = v.trim().split(';').next()?;
            (n.eq_ignore_ascii_case("set-cookie") && pair.starts_with(&format!("{name}="))).then_some(pair)
        })
    }
}

/// One request on a fresh connection to `server` from `local` (a loopback address).
async fn send(server: SocketAddr, local: IpAddr, request: String) -> Reply {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::new(local, 0)).unwrap();
    let mut stream = socket.connect(server).await.unwrap();
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut raw = String::new();
    stream.read_to_string(&mut raw).await.unwrap();
    let (head, body) = raw.split_once("\r\n\r\n").unwrap();
    let status = head.split(' ').nth(1).unwrap().parse().unwrap();
    Reply {
        status,
        head: head.to_string(),
        body: body.to_string(),
    }
}

/// The browser's login: the form's CSRF cookie and field, then the POST with `token`.
struct Browser {
    server: SocketAddr,
    local: IpAddr,
    nonce: String,
    csrf: String,
}

impl Browser {
    async fn open(server: SocketAddr, local: IpAddr) -> Browser {
        let form = send(server, local, format!("GET /team/login {HTTP}\r\n\r\n")).await;
        let nonce = form.cookie(crate::http::session::CSRF_COOKIE).unwrap();
        let csrf = form.body.split("name=csrf value=\"").nth(1).unwrap();
        Browser {
            server,
            local,
            nonce: nonce.to_string(),
            csrf: csrf.split('"').next().unwrap().to_string(),
        }
    }

    /// `POST /team/login` with `token`, sending `x-forwarded-for: forwarded` unless empty.
    async fn log_in(&self, token: &str, forwarded: &str) -> Reply {
        let body = format!("token={token}&csrf={}", self.csrf);
        let xff = match forwarded {
            "" => String::new(),
            f => format!("x-forwarded-for: {f}\r\n"),
        };
        let request = format!(
            "POST /team/login {HTTP}\r\ncookie: {}\r\n{xff}content-type: \
             application/x-www-form-urlencoded\r\ncontent-length: {}\r\n\r\n{body}",
            self.nonce,
            body.len()
        );
        send(self.server, self.local, request).await
    }
}

const HTTP: &str = "HTTP/1.1\r\nhost: kitchen-r.test\r\nconnection: close";
const LOOPBACK: IpAddr = IpAddr::V4(std::net::Ipv4Addr::LOCALHOST);

/// The real server over `f`'s state on 127.0.0.1:0, as the binary runs it, until the returned
/// sender is dropped; its HTTP address.
async fn serve(f: &Fixture) -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    let server = crate::Server {
        state: f.state.clone(),
        generated_admin_token: None,
        generated_worker_token: None,
        worker_token: WORKER.into(),
    };
    let http = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let grpc = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = http.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(server.run(http, grpc, async move {
        let _ = stopped.await;
    }));
    (addr, stop)
}

#[tokio::test]
async fn over_a_socket_behind_one_proxy_a_flood_locks_out_no_one_and_forgers_are_throttled() {
    let f = behind_one_proxy(10).await;
    let token = f.team("alpha").await;
    let (addr, _stop) = serve(&f).await;
    // This test's client is the proxy (127.0.0.1, the trusted hop) and writes what it appends.
    let proxy = Browser::open(addr, LOOPBACK).await;
    for i in 0..200u32 {
        let r = proxy
            .log_in("kr_guess", &format!("10.1.{}.{}", i / 256, i % 256))
            .await;
        assert_eq!(r.status, 401, "{i}: {}", r.head);
    }
    let r = proxy.log_in(&token, "203.0.113.9").await;
    assert_eq!(r.status, 303, "{}\n{}", r.head, r.body);
    assert!(r.cookie(TEAM_COOKIE).is_some(), "{}", r.head);
    // One client forging a new first entry each time is still one client.
    for i in 0..10 {
        let r = proxy.log_in("kr_guess", &format!("1.2.3.{i}, 192.0.2.50")).await;
        assert_eq!(r.status, 401, "{i}");
    }
    let r = proxy.log_in(&token, "1.2.3.200, 192.0.2.50").await;
    assert_eq!(r.status, 429, "{}", r.head);
    let wait: u64 = r.header("retry-after").unwrap().parse().unwrap();
    assert!((1..=6).contains(&wait), "{wait}");
    // The proxy's own requests (no header: it is the client) are another address.
    assert_eq!(proxy.log_in(&token, "").await.status, 303);
}

#[tokio::test]
async fn over_a_socket_no_header_is_trusted_by_default_and_peers_are_throttled_apart() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    assert_eq!(f.state.config().sessions.trusted_proxy_hops, 0);
    let token = f.team("alpha").await;
    let (addr, _stop) = serve(&f).await;
    let client = Browser::open(addr, LOOPBACK).await;
    // A forged header per try changes nothing: the peer is the client.
    for i in 0..10 {
        let r = client.log_in("kr_guess", &format!("10.2.0.{i}")).await;
        assert_eq!(r.status, 401, "{i}");
    }
    let r = client.log_in(&token, "10.2.0.99").await;
    assert_eq!(r.status, 429);
    assert!(r.header("retry-after").is_some());
    // Linux answers on all of 127/8: flood from 200 other peers, then log in from another one.
    if cfg!(target_os = "linux") {
        for i in 2..202u8 {
            let peer = IpAddr::from([127, 0, 1, i]);
            let r = Browser::open(addr, peer).await.log_in("kr_guess", "").await;
            assert_eq!(r.status, 401, "{peer}");
        }
        let other = Browser::open(addr, IpAddr::from([127, 0, 2, 1])).await;
        assert_eq!(other.log_in(&token, "").await.status, 303);
        assert_eq!(client.log_in(&token, "").await.status, 429);
    }
}
