//! HTTP on the serve port, through hyper: `/` the browser viewer (embedded in the binary),
//! `/viewer.js` its script, `/psao.wasm` its decoder (crates/psao-wasm), `/scene.glb` the
//! served scene as binary glTF, `/characters/N.prt` the relighting model of skinned character
//! N (404 when there is none), `/characters/index.json` how many there are and their SH
//! lighting, `/health` a JSON status, and the WebSocket upgrade at `/ws`,
//! after which the connection speaks frames. Only GET and HEAD are answered (405 otherwise);
//! unknown paths get 404, a `/ws` request that is no valid upgrade 400; request heads are
//! limited in size and time.
//!
//! With a token ([`Access`]), `/scene.glb` and `/characters/…` need
//! `Authorization: Bearer TOKEN` (401 without) and `/health` tells only that the server is
//! up; `/`, `/viewer.js` and `/psao.wasm` are the viewer program itself (the same bytes in
//! every psao build, no scene data) and answer anyone, so that a page opened with `#token=…`
//! can start. Every request's `Host` and every upgrade's `Origin` must be allowed (403
//! otherwise); `/health` is readable cross-origin by allowed origins only (a viewer loaded
//! from another edge of a session asks it).

use std::convert::Infallible;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bytes::Bytes;
use http_body_util::Full;
use hyper::body::Incoming;
use hyper::header::{self, HeaderValue};
use hyper::server::conn::http1;
use hyper::service::service_fn;
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};
use psao_wire::{MAX_CLIENT_FRAME, PROTOCOL_VERSION};
use tokio_tungstenite::tungstenite::handshake::derive_accept_key;

use crate::access::Access;
use crate::admission::Permit;
use crate::characters::ServedCharacters;
use crate::io::BoxIo;
use crate::transport::{websocket_server, FrameReader, FrameWriter};

/// The viewer page (built from `web/` by esbuild; see web/README.md).
const INDEX_HTML: &str = include_str!("../../../web/dist/index.html");
/// The viewer's script bundle.
const VIEWER_JS: &str = include_str!("../../../web/dist/viewer.js");
/// The viewer's decoder (crates/psao-wasm, built by web/build-wasm.sh).
const VIEWER_WASM: &[u8] = include_bytes!("../../../web/dist/psao.wasm");
/// Largest request head (request line + headers) read, bytes (hyper's minimum is 8 KiB).
const MAX_REQUEST_HEAD: usize = 16 << 10;
/// Time a connection has to send a complete request head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// Live numbers `/health` reports, updated by the simulation.
#[derive(Debug, Default)]
pub struct Health {
    /// Clients in session.
    pub clients: AtomicUsize,
    /// Server frames stepped.
    pub server_frame: AtomicU64,
    /// Scale-out edges: the frame whose record batches are overdue, which partitions', since
    /// when (`scale::edge::Stall`); `None` when nothing is.
    pub stalled: std::sync::Mutex<Option<serde_json::Value>>,
}

/// Receives the frame transport of each WebSocket that completed its upgrade, with the
/// connection's permit (held until the session ends).
pub type WebSocketHandler = dyn Fn(FrameReader, FrameWriter, Permit) + Send + Sync;

/// What the HTTP side serves.
pub struct HttpContext {
    /// `/scene.glb`.
    pub scene_glb: Bytes,
    /// `/characters/N.prt`: the relit characters' models.
    pub characters: Arc<ServedCharacters>,
    /// The scene's name, for `/health`.
    pub scene_name: String,
    /// `/health`'s live numbers.
    pub health: Arc<Health>,
    /// The token and the allowed origins.
    pub access: Arc<Access>,
    /// Takes over upgraded `/ws` connections.
    pub on_websocket: Box<WebSocketHandler>,
}

/// Answers HTTP requests on `io` until the peer closes, the head timeout passes or a
/// WebSocket upgrade takes the connection over (`permit` then passes to its session).
pub async fn serve_http(
    io: BoxIo,
    ctx: Arc<HttpContext>,
    permit: Permit,
) -> Result<(), hyper::Error> {
    let service = service_fn(move |req| {
        let (ctx, permit) = (ctx.clone(), permit.clone());
        async move { Ok::<_, Infallible>(route(req, &ctx, permit)) }
    });
    let mut builder = http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(HEAD_TIMEOUT)
        .max_buf_size(MAX_REQUEST_HEAD);
    builder
        .serve_connection(TokioIo::new(io), service)
        .with_upgrades()
        .await
}

fn route(req: Request<Incoming>, ctx: &Arc<HttpContext>, permit: Permit) -> Response<Full<Bytes>> {
    let host = req
        .headers()
        .get(header::HOST)
        .map(|h| h.to_str().unwrap_or("\u{fffd}"));
    if !ctx.access.host_allowed(host) {
        return text(
            StatusCode::FORBIDDEN,
            "this Host is not served (a name must be allowed with --allow-origin)\n",
        );
    }
    if req.method() != Method::GET && req.method() != Method::HEAD {
        let mut r = text(StatusCode::METHOD_NOT_ALLOWED, "only GET and HEAD\n");
        r.headers_mut()
            .insert(header::ALLOW, HeaderValue::from_static("GET, HEAD"));
        return r;
    }
    match req.uri().path() {
        "/" | "/index.html" => body(
            "text/html; charset=utf-8",
            Bytes::from_static(INDEX_HTML.as_bytes()),
        ),
        "/viewer.js" => body(
            "text/javascript; charset=utf-8",
            Bytes::from_static(VIEWER_JS.as_bytes()),
        ),
        "/psao.wasm" => body("application/wasm", Bytes::from_static(VIEWER_WASM)),
        "/scene.glb" if !ctx.access.request_authorized(req.headers()) => {
            let mut r = text(
                StatusCode::UNAUTHORIZED,
                "/scene.glb needs the token (Authorization: Bearer TOKEN)\n",
            );
            r.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            r
        }
        "/scene.glb" => body("model/gltf-binary", ctx.scene_glb.clone()),
        p if p.starts_with("/characters/") && !ctx.access.request_authorized(req.headers()) => {
            let mut r = text(
                StatusCode::UNAUTHORIZED,
                "/characters/ needs the token (Authorization: Bearer TOKEN)\n",
            );
            r.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            r
        }
        "/characters/index.json" => body("application/json", ctx.characters.index_json()),
        p if p.starts_with("/characters/") => match ctx.characters.model_at(p) {
            Some(model) => body("application/octet-stream", model),
            None => text(StatusCode::NOT_FOUND, "no such character\n"),
        },
        "/health" => health(&req, ctx, host),
        "/ws" => match req.headers().get(header::ORIGIN) {
            Some(o) if !ctx.access.origin_allowed(o.to_str().unwrap_or(""), host) => text(
                StatusCode::FORBIDDEN,
                "WebSocket from a page of another origin (allow it with --allow-origin)\n",
            ),
            _ => upgrade(req, ctx, permit),
        },
        _ => text(StatusCode::NOT_FOUND, "not found\n"),
    }
}

/// `/health`: the full status with the token (or when none is needed), else only that the
/// server is up; readable cross-origin by allowed origins.
fn health(req: &Request<Incoming>, ctx: &HttpContext, host: Option<&str>) -> Response<Full<Bytes>> {
    let status = if ctx.access.request_authorized(req.headers()) {
        serde_json::json!({
            "status": "ok",
            "protocol": PROTOCOL_VERSION,
            "scene": ctx.scene_name,
            "clients": ctx.health.clients.load(Ordering::Relaxed),
            "server_frame": ctx.health.server_frame.load(Ordering::Relaxed),
            "stalled": ctx.health.stalled.lock().ok().and_then(|s| s.clone()),
        })
    } else {
        serde_json::json!({ "status": "ok" })
    };
    let mut r = body("application/json", Bytes::from(status.to_string()));
    let h = r.headers_mut();
    h.insert(header::VARY, HeaderValue::from_static("Origin"));
    if let Some(origin) = req.headers().get(header::ORIGIN) {
        if ctx
            .access
            .origin_allowed(origin.to_str().unwrap_or(""), host)
        {
            h.insert(header::ACCESS_CONTROL_ALLOW_ORIGIN, origin.clone());
        }
    }
    r
}

/// Accepts a WebSocket upgrade (RFC 6455 §4.2) and hands the upgraded connection over.
fn upgrade(
    mut req: Request<Incoming>,
    ctx: &Arc<HttpContext>,
    permit: Permit,
) -> Response<Full<Bytes>> {
    let has = |name: header::HeaderName, token: &str| {
        req.headers().get_all(name).iter().any(|v| {
            v.to_str()
                .is_ok_and(|s| s.split(',').any(|t| t.trim().eq_ignore_ascii_case(token)))
        })
    };
    let valid = has(header::UPGRADE, "websocket")
        && has(header::CONNECTION, "upgrade")
        && req
            .headers()
            .get(header::SEC_WEBSOCKET_VERSION)
            .is_some_and(|v| v == "13");
    let key = req.headers().get(header::SEC_WEBSOCKET_KEY).cloned();
    let (true, Some(key)) = (valid, key) else {
        return text(
            StatusCode::BAD_REQUEST,
            "/ws expects a WebSocket upgrade (version 13)\n",
        );
    };
    let accept = derive_accept_key(key.as_bytes());
    let on_upgrade = hyper::upgrade::on(&mut req);
    let ctx = ctx.clone();
    tokio::spawn(async move {
        match on_upgrade.await {
            Ok(upgraded) => {
                let io: BoxIo = Box::new(TokioIo::new(upgraded));
                let (reader, writer) = websocket_server(io, MAX_CLIENT_FRAME).await;
                (ctx.on_websocket)(reader, writer, permit);
            }
            Err(e) => tracing::debug!("WebSocket upgrade failed: {e}"),
        }
    });
    let mut r = Response::new(Full::new(Bytes::new()));
    *r.status_mut() = StatusCode::SWITCHING_PROTOCOLS;
    let h = r.headers_mut();
    h.insert(header::UPGRADE, HeaderValue::from_static("websocket"));
    h.insert(header::CONNECTION, HeaderValue::from_static("Upgrade"));
    if let Ok(v) = HeaderValue::from_str(&accept) {
        h.insert(header::SEC_WEBSOCKET_ACCEPT, v);
    }
    r
}

fn body(content_type: &'static str, bytes: Bytes) -> Response<Full<Bytes>> {
    let mut r = Response::new(Full::new(bytes));
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

fn text(status: StatusCode, message: &'static str) -> Response<Full<Bytes>> {
    let mut r = body(
        "text/plain; charset=utf-8",
        Bytes::from_static(message.as_bytes()),
    );
    *r.status_mut() = status;
    r
}
