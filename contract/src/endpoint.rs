//! Which policy endpoints a worker may call. Endpoints are untrusted input typed by
//! participants: without this check a registered `http://10.0.0.5:80` or `http://169.254.169.254`
//! would make the evaluation platform probe its own private network (SSRF).
//!
//! An endpoint is `http://HOST:PORT` or `https://HOST:PORT` (gRPC), or `ws://HOST:PORT` or
//! `wss://HOST:PORT` (openpi WebSocket), nothing more (no path, no user info). Every address the host resolves to must be allowed; the worker then connects to the
//! checked address itself, so a second DNS answer cannot swap in a refused one.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, ToSocketAddrs};

use serde::{Deserialize, Serialize};

/// Config section `[policy.allowed_networks]`: address ranges a policy endpoint may resolve to
/// besides public unicast addresses. The embedded default allows loopback only, so local
/// evaluation and tests work while a server reached over the Internet refuses its own LAN.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AllowedNetworks {
    /// `127.0.0.0/8`, `::1` and the unspecified addresses `0.0.0.0`, `::`.
    pub loopback: bool,
    /// RFC 1918 (`10/8`, `172.16/12`, `192.168/16`), CGNAT (`100.64/10`) and IPv6 ULA (`fc00::/7`).
    pub private: bool,
    /// `169.254/16` (cloud metadata lives here) and `fe80::/10`.
    pub link_local: bool,
}

impl Default for AllowedNetworks {
    fn default() -> Self {
        AllowedNetworks {
            loopback: true,
            private: false,
            link_local: false,
        }
    }
}

impl AllowedNetworks {
    /// Everything, for tools run by the participant on their own machine (`check-policy`).
    pub const ALL: AllowedNetworks = AllowedNetworks {
        loopback: true,
        private: true,
        link_local: true,
    };
}

/// Address classes with a config switch; anything else is public unicast or never allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum NetworkKind {
    Loopback,
    Private,
    LinkLocal,
    /// Multicast, broadcast and reserved ranges (`0/8`, `240/4`): never a policy server.
    NotUnicast,
}

impl NetworkKind {
    fn describe(self) -> &'static str {
        match self {
            NetworkKind::Loopback => "loopback",
            NetworkKind::Private => "private (RFC 1918, CGNAT or ULA)",
            NetworkKind::LinkLocal => "link-local",
            NetworkKind::NotUnicast => "multicast, broadcast or reserved",
        }
    }

    /// The config key that allows this class, if any.
    fn config_key(self) -> Option<&'static str> {
        match self {
            NetworkKind::Loopback => Some("policy.allowed_networks.loopback"),
            NetworkKind::Private => Some("policy.allowed_networks.private"),
            NetworkKind::LinkLocal => Some("policy.allowed_networks.link_local"),
            NetworkKind::NotUnicast => None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EndpointError {
    #[error(
        "policy endpoint {endpoint:?} must look like http://HOST:PORT or https://HOST:PORT (gRPC), \
         or ws://HOST:PORT or wss://HOST:PORT (openpi WebSocket): {reason}"
    )]
    Malformed { endpoint: String, reason: String },
    #[error("policy endpoint host {host:?} does not resolve: {reason}")]
    Resolve { host: String, reason: String },
    #[error(
        "policy endpoint {endpoint} resolves to {addr}, a {kind} address, which this server refuses{hint}"
    )]
    Refused {
        endpoint: String,
        addr: IpAddr,
        kind: &'static str,
        hint: String,
    },
}

/// The wire a policy endpoint speaks, told by its URL's scheme.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// `http://`, `https://`: `kitchen_r.policy.v1.Policy` over gRPC.
    Grpc,
    /// `ws://`, `wss://`: openpi's WebSocket + msgpack-numpy protocol.
    Openpi,
}

impl Transport {
    /// The transport of `endpoint` by its scheme; `None` for any other scheme.
    pub fn of(endpoint: &str) -> Option<Transport> {
        parse_scheme(endpoint.trim()).map(|(t, _, _)| t)
    }
}

/// `(transport, tls, rest)` of `endpoint`.
fn parse_scheme(endpoint: &str) -> Option<(Transport, bool, &str)> {
    [
        ("http://", Transport::Grpc, false),
        ("https://", Transport::Grpc, true),
        ("ws://", Transport::Openpi, false),
        ("wss://", Transport::Openpi, true),
    ]
    .into_iter()
    .find_map(|(p, t, tls)| endpoint.strip_prefix(p).map(|rest| (t, tls, rest)))
}

/// A parsed, resolved and checked endpoint.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Endpoint {
    /// As the participant wrote it, normalised to `scheme://host:port`.
    pub(crate) uri: String,
    pub(crate) transport: Transport,
    pub(crate) tls: bool,
    /// Host name or address without brackets; the TLS server name and `:authority`.
    pub(crate) host: String,
    pub(crate) port: u16,
    /// The checked addresses, in resolver order; the worker connects to the first.
    pub(crate) addrs: Vec<SocketAddr>,
}

/// `scheme://host:port` split into (transport, tls, host, port), with no network access.
pub(crate) fn parse(endpoint: &str) -> Result<(Transport, bool, String, u16), EndpointError> {
    let bad = |reason: &str| EndpointError::Malformed {
        endpoint: endpoint.to_string(),
        reason: reason.to_string(),
    };
    let Some((transport, tls, rest)) = parse_scheme(endpoint) else {
        return Err(bad("the scheme must be http, https, ws or wss"));
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.contains(['/', '?', '#', '@']) {
        return Err(bad("no path, query or user info is allowed"));
    }
    let (host, port) = if let Some(r) = rest.strip_prefix('[') {
        let (h, p) = r
            .split_once("]:")
            .ok_or_else(|| bad("an IPv6 host needs [ADDR]:PORT"))?;
        h.parse::<Ipv6Addr>().map_err(|_| bad("bad IPv6 address"))?;
        (h, p)
    } else {
        rest.rsplit_once(':').ok_or_else(|| bad("the port is missing"))?
    };
    if host.is_empty() {
        return Err(bad("the host is missing"));
    }
    let port: u16 = port
        .parse()
        .map_err(|_| bad("the port must be a number in 1..=65535"))?;
    if port == 0 {
        return Err(bad("the port must be a number in 1..=65535"));
    }
    Ok((transport, tls, host.to_string(), port))
}

/// The configurable class of `ip`, or `None` for a public unicast address. An IPv6 address
/// that carries an IPv4 address (mapped, compatible, SIIT, NAT64, 6to4, Teredo) is classified
/// by the IPv4 address inside it: a translator or relay delivers it there.
pub(crate) fn classify(ip: IpAddr) -> Option<NetworkKind> {
    match ip {
        IpAddr::V4(v4) => classify_v4(v4),
        IpAddr::V6(v6) => match embedded_v4(v6) {
            Some(v4) => classify_v4(v4),
            None => classify_v6(v6),
        },
    }
}

/// The IPv4 address an IPv6 address reaches, for every standard embedding.
fn embedded_v4(ip: Ipv6Addr) -> Option<Ipv4Addr> {
    let s = ip.segments();
    let low = Ipv4Addr::from(((u32::from(s[6])) << 16) | u32::from(s[7]));
    let is_zero = |range: &[u16]| range.iter().all(|&x| x == 0);
    if let Some(v4) = ip.to_ipv4_mapped() {
        // ::ffff:a.b.c.d
        Some(v4)
    } else if is_zero(&s[..6]) && !ip.is_loopback() && !ip.is_unspecified() {
        // ::a.b.c.d, IPv4-compatible (deprecated, still routed by some stacks)
        Some(low)
    } else if is_zero(&s[..4]) && s[4] == 0xffff && s[5] == 0 {
        // ::ffff:0:a.b.c.d, SIIT (RFC 6145)
        Some(low)
    } else if s[0] == 0x64 && s[1] == 0xff9b && (is_zero(&s[2..6]) || s[2] == 1) {
        // 64:ff9b::/96 well-known NAT64 prefix and 64:ff9b:1::/48 local-use (RFC 6052, 8215)
        Some(low)
    } else if s[0] == 0x2002 {
        // 2002:AABB:CCDD::/48, 6to4 (RFC 3056)
        Some(Ipv4Addr::from(((u32::from(s[1])) << 16) | u32::from(s[2])))
    } else if s[0] == 0x2001 && s[1] == 0 {
        // 2001::/32 Teredo: the client's address is the last 32 bits, inverted (RFC 4380)
        Some(Ipv4Addr::from(!u32::from(low)))
    } else {
        None
    }
}

fn classify_v4(ip: Ipv4Addr) -> Option<NetworkKind> {
    let [a, b, ..] = ip.octets();
    if ip.is_loopback() || ip.is_unspecified() {
        Some(NetworkKind::Loopback)
    } else if a == 0 || a >= 240 {
        // 0.0.0.0/8 "this network" (Linux connects 0.x to the local host) and 240/4 reserved.
        Some(NetworkKind::NotUnicast)
    } else if ip.is_private() || (a == 100 && (64..128).contains(&b)) {
        Some(NetworkKind::Private)
    } else if ip.is_link_local() {
        Some(NetworkKind::LinkLocal)
    } else if ip.is_multicast() || ip.is_broadcast() {
        Some(NetworkKind::NotUnicast)
    } else {
        None
    }
}

fn classify_v6(ip: Ipv6Addr) -> Option<NetworkKind> {
    let first = ip.segments()[0];
    if ip.is_loopback() || ip.is_unspecified() {
        Some(NetworkKind::Loopback)
    } else if first & 0xfe00 == 0xfc00 || first & 0xffc0 == 0xfec0 {
        // ULA, and the deprecated site-local fec0::/10 some stacks still route inside a site.
        Some(NetworkKind::Private)
    } else if first & 0xffc0 == 0xfe80 {
        Some(NetworkKind::LinkLocal)
    } else if ip.is_multicast() {
        Some(NetworkKind::NotUnicast)
    } else {
        None
    }
}

impl AllowedNetworks {
    fn allows(&self, kind: NetworkKind) -> bool {
        match kind {
            NetworkKind::Loopback => self.loopback,
            NetworkKind::Private => self.private,
            NetworkKind::LinkLocal => self.link_local,
            NetworkKind::NotUnicast => false,
        }
    }

    /// `Ok` when `ip` may be called.
    pub(crate) fn check(&self, endpoint: &str, ip: IpAddr) -> Result<(), EndpointError> {
        match classify(ip) {
            Some(kind) if !self.allows(kind) => Err(EndpointError::Refused {
                endpoint: endpoint.to_string(),
                addr: ip,
                kind: kind.describe(),
                hint: kind.config_key().map_or_else(String::new, |k| {
                    format!(" (an organiser allows it with `{k} = true` in the server config)")
                }),
            }),
            _ => Ok(()),
        }
    }
}

/// The well-known ranges of each switchable class, as CIDR text: the server's and the worker's
/// `allow_networks` list names them.
pub(crate) const CLASS_RANGES: [(&str, NetworkKind); 9] = [
    ("127.0.0.0/8", NetworkKind::Loopback),
    ("::1/128", NetworkKind::Loopback),
    ("10.0.0.0/8", NetworkKind::Private),
    ("172.16.0.0/12", NetworkKind::Private),
    ("192.168.0.0/16", NetworkKind::Private),
    ("100.64.0.0/10", NetworkKind::Private),
    ("fc00::/7", NetworkKind::Private),
    ("169.254.0.0/16", NetworkKind::LinkLocal),
    ("fe80::/10", NetworkKind::LinkLocal),
];

impl AllowedNetworks {
    /// An `allow_networks` list of CIDR ranges as address classes. Only the ranges of
    /// `CLASS_RANGES` are accepted, and one of them allows its whole class (the check is by
    /// class), so a list never suggests a finer filter than the one applied.
    pub fn from_cidrs<S: AsRef<str>>(list: &[S]) -> Result<AllowedNetworks, String> {
        let mut a = AllowedNetworks {
            loopback: false,
            private: false,
            link_local: false,
        };
        for item in list {
            let item = item.as_ref().trim();
            let kind = CLASS_RANGES
                .iter()
                .find(|(r, _)| r.eq_ignore_ascii_case(item))
                .map(|(_, k)| *k)
                .ok_or_else(|| {
                    let known: Vec<&str> = CLASS_RANGES.iter().map(|(r, _)| *r).collect();
                    format!(
                        "allow_networks: {item:?} is not one of the ranges that can be allowed ({}); \
                         public addresses are always allowed",
                        known.join(", ")
                    )
                })?;
            match kind {
                NetworkKind::Loopback => a.loopback = true,
                NetworkKind::Private => a.private = true,
                NetworkKind::LinkLocal => a.link_local = true,
                NetworkKind::NotUnicast => {}
            }
        }
        Ok(a)
    }
}

/// The [`CLASS_RANGES`] entry `ip` falls in, to name in a refusal.
pub(crate) fn class_range(ip: IpAddr) -> Option<&'static str> {
    let ip = match ip {
        IpAddr::V6(v6) => embedded_v4(v6).map_or(ip, IpAddr::V4),
        v4 => v4,
    };
    let inside = |net: &str| -> bool {
        let Some((base, bits)) = net.split_once('/') else {
            return false;
        };
        let (Ok(base), Ok(bits)) = (base.parse::<IpAddr>(), bits.parse::<u32>()) else {
            return false;
        };
        match (base, ip) {
            (IpAddr::V4(b), IpAddr::V4(a)) => {
                let mask = u32::MAX.checked_shl(32 - bits).unwrap_or(0);
                u32::from(b) & mask == u32::from(a) & mask
            }
            (IpAddr::V6(b), IpAddr::V6(a)) => {
                let mask = u128::MAX.checked_shl(128 - bits).unwrap_or(0);
                u128::from(b) & mask == u128::from(a) & mask
            }
            _ => false,
        }
    };
    CLASS_RANGES.iter().map(|(r, _)| *r).find(|r| inside(r))
}

/// Parse, resolve and check `endpoint`: every resolved address must be allowed.
pub(crate) fn resolve(endpoint: &str, allowed: &AllowedNetworks) -> Result<Endpoint, EndpointError> {
    let (transport, tls, host, port) = parse(endpoint)?;
    let addrs: Vec<SocketAddr> = match host.parse::<IpAddr>() {
        Ok(ip) => vec![SocketAddr::new(ip, port)],
        Err(_) => (host.as_str(), port)
            .to_socket_addrs()
            .map_err(|e| EndpointError::Resolve {
                host: host.clone(),
                reason: e.to_string(),
            })?
            .collect(),
    };
    if addrs.is_empty() {
        return Err(EndpointError::Resolve {
            host,
            reason: "no addresses".into(),
        });
    }
    let scheme = match (transport, tls) {
        (Transport::Grpc, false) => "http",
        (Transport::Grpc, true) => "https",
        (Transport::Openpi, false) => "ws",
        (Transport::Openpi, true) => "wss",
    };
    let shown = if host.contains(':') {
        format!("{scheme}://[{host}]:{port}")
    } else {
        format!("{scheme}://{host}:{port}")
    };
    for a in &addrs {
        allowed.check(&shown, a.ip())?;
    }
    Ok(Endpoint {
        uri: shown,
        transport,
        tls,
        host,
        port,
        addrs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    #[test]
    fn parses_the_accepted_forms_only() {
        let g = Transport::Grpc;
        assert_eq!(
            parse("http://example.org:50051").unwrap(),
            (g, false, "example.org".into(), 50051)
        );
        assert_eq!(
            parse("https://1.2.3.4:443/").unwrap(),
            (g, true, "1.2.3.4".into(), 443)
        );
        assert_eq!(parse("http://[::1]:7").unwrap(), (g, false, "::1".into(), 7));
        let o = Transport::Openpi;
        assert_eq!(parse("ws://h:8000").unwrap(), (o, false, "h".into(), 8000));
        assert_eq!(parse("wss://[::1]:443/").unwrap(), (o, true, "::1".into(), 443));
        assert_eq!(Transport::of(" wss://h:1"), Some(o));
        assert_eq!(Transport::of("grpc://h:1"), None);
        for bad in [
            "grpc://h:1",
            "http://h",
            "http://h:0",
            "http://h:99999",
            "http://h:1/path",
            "http://u@h:1",
            "http://:1",
            "ws://h:1/path",
            "ws://h",
            "h:1",
        ] {
            assert!(
                matches!(parse(bad), Err(EndpointError::Malformed { .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn classifies_every_special_range() {
        let cases = [
            ("127.0.0.1", Some(NetworkKind::Loopback)),
            ("0.0.0.0", Some(NetworkKind::Loopback)),
            ("::1", Some(NetworkKind::Loopback)),
            ("::ffff:127.0.0.1", Some(NetworkKind::Loopback)),
            ("10.1.2.3", Some(NetworkKind::Private)),
            ("172.31.0.1", Some(NetworkKind::Private)),
            ("192.168.1.1", Some(NetworkKind::Private)),
            ("100.64.0.1", Some(NetworkKind::Private)),
            ("100.127.255.255", Some(NetworkKind::Private)),
            ("fd00::1", Some(NetworkKind::Private)),
            ("::ffff:10.0.0.1", Some(NetworkKind::Private)),
            ("169.254.169.254", Some(NetworkKind::LinkLocal)),
            ("fe80::1", Some(NetworkKind::LinkLocal)),
            ("224.0.0.1", Some(NetworkKind::NotUnicast)),
            ("255.255.255.255", Some(NetworkKind::NotUnicast)),
            ("0.1.2.3", Some(NetworkKind::NotUnicast)),
            ("240.0.0.1", Some(NetworkKind::NotUnicast)),
            // IPv6 carrying an IPv4 address is classified by it (an SSRF gap otherwise).
            ("::10.0.0.1", Some(NetworkKind::Private)),
            ("::127.0.0.1", Some(NetworkKind::Loopback)),
            ("::ffff:0:a00:1", Some(NetworkKind::Private)),
            ("64:ff9b::a00:1", Some(NetworkKind::Private)),
            ("64:ff9b::a9fe:a9fe", Some(NetworkKind::LinkLocal)),
            ("64:ff9b:1::7f00:1", Some(NetworkKind::Loopback)),
            ("2002:a00:1::1", Some(NetworkKind::Private)),
            ("2002:a9fe:a9fe::1", Some(NetworkKind::LinkLocal)),
            ("2001:0:4136:e378:8000:63bf:f5ff:fffe", Some(NetworkKind::Private)),
            ("fec0::1", Some(NetworkKind::Private)),
            ("64:ff9b::808:808", None),
            ("2002:808:808::1", None),
            ("8.8.8.8", None),
            ("100.128.0.1", None),
            ("172.32.0.1", None),
            ("2001:db8::1", None),
        ];
        for (s, want) in cases {
            assert_eq!(classify(ip(s)), want, "{s}");
        }
    }

    #[test]
    fn the_default_allows_loopback_only_and_names_the_key() {
        let d = AllowedNetworks::default();
        assert!(resolve("http://127.0.0.1:5000", &d).is_ok());
        assert!(resolve("http://93.184.216.34:443", &d).is_ok());
        let err = resolve("http://192.168.0.10:5000", &d).unwrap_err().to_string();
        assert!(err.contains("192.168.0.10") && err.contains("private"), "{err}");
        assert!(err.contains("policy.allowed_networks.private = true"), "{err}");
        let err = resolve("http://169.254.169.254:80", &d).unwrap_err().to_string();
        assert!(
            err.contains("link-local") && err.contains("policy.allowed_networks.link_local"),
            "{err}"
        );
        let none = AllowedNetworks { loopback: false, ..d };
        let err = resolve("http://[::1]:5000", &none).unwrap_err().to_string();
        assert!(
            err.contains("loopback") && err.contains("http://[::1]:5000"),
            "{err}"
        );
        let err = resolve("http://224.0.0.1:5000", &AllowedNetworks::ALL)
            .unwrap_err()
            .to_string();
        assert!(err.contains("multicast") && !err.contains("allows it"), "{err}");
    }

    #[test]
    fn cidr_lists_map_to_classes() {
        let a = AllowedNetworks::from_cidrs(&["127.0.0.0/8", "::1/128"]).unwrap();
        assert_eq!(a, AllowedNetworks::default());
        let a = AllowedNetworks::from_cidrs(&["10.0.0.0/8", "FE80::/10"]).unwrap();
        assert!(!a.loopback && a.private && a.link_local);
        let err = AllowedNetworks::from_cidrs(&["10.1.0.0/16"]).unwrap_err();
        assert!(err.contains("10.1.0.0/16") && err.contains("10.0.0.0/8"), "{err}");
        assert_eq!(class_range(ip("10.2.3.4")), Some("10.0.0.0/8"));
        assert_eq!(class_range(ip("172.20.0.1")), Some("172.16.0.0/12"));
        assert_eq!(class_range(ip("::ffff:192.168.1.1")), Some("192.168.0.0/16"));
        assert_eq!(class_range(ip("fd12::1")), Some("fc00::/7"));
        assert_eq!(class_range(ip("8.8.8.8")), None);
    }

    #[test]
    fn a_configured_range_is_allowed() {
        let all = AllowedNetworks::ALL;
        assert!(resolve("http://10.0.0.1:1", &all).is_ok());
        assert!(resolve("https://[fe80::1]:1", &all).is_ok());
        let e = resolve("https://localhost:443", &AllowedNetworks::default()).unwrap();
        assert!(e.tls && e.host == "localhost" && e.addrs.iter().all(|a| a.ip().is_loopback()));
        // A WebSocket endpoint is checked by the same rules.
        let err = resolve("ws://10.0.0.1:8000", &AllowedNetworks::default()).unwrap_err();
        assert!(err.to_string().contains("ws://10.0.0.1:8000"), "{err}");
        let e = resolve("wss://127.0.0.1:8000", &AllowedNetworks::default()).unwrap();
        assert!(e.tls && e.transport == Transport::Openpi && e.uri == "wss://127.0.0.1:8000");
    }
}
