//! Who may use a server: the access token (in a client's hello, or `Authorization: Bearer …`
//! on HTTP), and which web pages may talk to it. A browser sends `Origin` with every
//! WebSocket upgrade and cross-origin fetch; the server answers only pages from its own
//! origin, from loopback, or from origins the operator allowed (`--allow-origin`). The `Host`
//! of every HTTP request must be an IP address, `localhost`, or an allowed origin's host, so a
//! page on another domain that re-resolves its name to this server (DNS rebinding) is refused.

use std::net::IpAddr;

use hyper::header::{self, HeaderMap};

use crate::NetError;

/// The token and the allowed origins.
#[derive(Clone, Debug, Default)]
pub struct Access {
    token: Option<String>,
    /// Allowed origins besides the server's own and loopback, as `scheme://host[:port]`,
    /// lowercase.
    origins: Vec<String>,
}

impl Access {
    /// `token` (none: no token needed) and `allow_origins` (each `http://host[:port]` or
    /// `https://host[:port]`).
    pub fn new(token: Option<String>, allow_origins: &[String]) -> Result<Self, NetError> {
        if token.as_deref().is_some_and(str::is_empty) {
            return Err(NetError::Config("the access token is empty".into()));
        }
        let mut origins = Vec::new();
        for o in allow_origins {
            let lower = o.trim_end_matches('/').to_ascii_lowercase();
            match split_origin(&lower) {
                Some((_, authority)) if !authority.is_empty() => origins.push(lower),
                _ => {
                    return Err(NetError::Config(format!(
                        "--allow-origin {o:?}: expected http://HOST[:PORT] or https://HOST[:PORT]"
                    )))
                }
            }
        }
        Ok(Self { token, origins })
    }

    /// Whether a token is needed.
    pub fn needs_token(&self) -> bool {
        self.token.is_some()
    }

    /// Whether `given` is the token (always, when none is needed); compared in constant time.
    pub fn token_ok(&self, given: Option<&str>) -> bool {
        match &self.token {
            None => true,
            Some(expected) => constant_time_eq(given.unwrap_or("").as_bytes(), expected.as_bytes()),
        }
    }

    /// Whether an HTTP request carries the token (`Authorization: Bearer TOKEN`).
    pub fn request_authorized(&self, headers: &HeaderMap) -> bool {
        let bearer = headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "));
        self.token_ok(bearer)
    }

    /// Whether a request's `Host` header may be answered (absent: a non-browser client).
    pub fn host_allowed(&self, host: Option<&str>) -> bool {
        let Some(host) = host else {
            return true;
        };
        let name = host_name(host).to_ascii_lowercase();
        name.parse::<IpAddr>().is_ok()
            || is_localhost_name(&name)
            || self
                .origins
                .iter()
                .filter_map(|o| split_origin(o))
                .any(|(_, authority)| host_name(authority) == name)
    }

    /// Whether a page from `origin` may open a session or read a cross-origin answer, for a
    /// request whose `Host` is `host` (already checked by [`Access::host_allowed`]).
    pub fn origin_allowed(&self, origin: &str, host: Option<&str>) -> bool {
        let origin = origin.to_ascii_lowercase();
        let Some((_, authority)) = split_origin(&origin) else {
            return false; // "null" (sandboxed frames, file:// pages) and garbage
        };
        let name = host_name(authority);
        is_loopback(name)
            || host.is_some_and(|h| h.eq_ignore_ascii_case(authority))
            || self.origins.contains(&origin)
    }
}

/// `(scheme, authority)` of an `http(s)://authority` origin.
fn split_origin(origin: &str) -> Option<(&str, &str)> {
    let (scheme, authority) = origin.split_once("://")?;
    let valid = matches!(scheme, "http" | "https")
        && !authority.is_empty()
        && !authority.contains(['/', '?', '#', '@', ' ']);
    valid.then_some((scheme, authority))
}

/// The host of `host[:port]` (`[v6]:port` gives the address without brackets).
fn host_name(authority: &str) -> &str {
    if let Some(rest) = authority.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    match authority.rsplit_once(':') {
        Some((h, port)) if port.bytes().all(|b| b.is_ascii_digit()) => h,
        _ => authority,
    }
}

fn is_localhost_name(name: &str) -> bool {
    name == "localhost" || name.ends_with(".localhost")
}

fn is_loopback(name: &str) -> bool {
    is_localhost_name(name) || name.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn access(origins: &[&str]) -> Access {
        let o: Vec<String> = origins.iter().map(|s| s.to_string()).collect();
        Access::new(Some("sesame".into()), &o).unwrap()
    }

    #[test]
    fn tokens_compare_exactly() {
        let a = access(&[]);
        assert!(a.token_ok(Some("sesame")));
        assert!(!a.token_ok(Some("sesam")));
        assert!(!a.token_ok(None));
        assert!(Access::default().token_ok(None));
        let mut h = HeaderMap::new();
        assert!(!a.request_authorized(&h));
        h.insert(header::AUTHORIZATION, "Bearer sesame".parse().unwrap());
        assert!(a.request_authorized(&h));
        h.insert(header::AUTHORIZATION, "Basic sesame".parse().unwrap());
        assert!(!a.request_authorized(&h));
        assert!(Access::new(Some(String::new()), &[]).is_err());
    }

    #[test]
    fn hosts_must_be_addresses_localhost_or_allowed_names() {
        let a = access(&["https://psao.example.org"]);
        for ok in [
            "127.0.0.1:7878",
            "[::1]:7878",
            "192.0.2.7",
            "localhost:7878",
            "psao.example.org",
            "PSAO.example.org:443",
        ] {
            assert!(a.host_allowed(Some(ok)), "{ok}");
        }
        assert!(a.host_allowed(None));
        for bad in [
            "evil.example.com:7878",
            "rebind.attacker.net",
            "example.org",
        ] {
            assert!(!a.host_allowed(Some(bad)), "{bad}");
        }
    }

    #[test]
    fn origins_are_own_loopback_or_allowed() {
        let a = access(&["https://viewer.example.org"]);
        let host = Some("192.0.2.7:7878");
        assert!(a.origin_allowed("http://192.0.2.7:7878", host));
        assert!(a.origin_allowed("http://127.0.0.1:9999", host));
        assert!(a.origin_allowed("http://localhost:3000", host));
        assert!(a.origin_allowed("http://[::1]:8000", host));
        assert!(a.origin_allowed("https://viewer.example.org", host));
        assert!(!a.origin_allowed("https://viewer.example.org:8443", host));
        assert!(!a.origin_allowed("http://evil.example.com", host));
        assert!(!a.origin_allowed("http://192.0.2.8:7878", host));
        assert!(!a.origin_allowed("null", host));
        assert!(Access::new(None, &["ftp://x".into()]).is_err());
        assert!(Access::new(None, &["https://x/path".into()]).is_err());
    }
}
