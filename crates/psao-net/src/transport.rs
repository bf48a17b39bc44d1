//! Frame transports: raw frames back to back on a byte stream ("tcp") and WebSocket (one
//! binary message per frame), behind one reader and one writer type. A server tells a raw
//! connection from HTTP by its first bytes (an HTTP method, or anything else, which the
//! frame reader then judges); WebSockets arrive as HTTP upgrades at `/ws` (see
//! [`crate::http`]).

use std::path::Path;
use std::time::Duration;

use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use psao_wire::{decode_frame, decode_payload, FrameHeader, Message, WireError, HEADER_LEN};
use tokio::io::{AsyncReadExt, AsyncWriteExt, ReadHalf, WriteHalf};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::protocol::{Role, WebSocketConfig};
use tokio_tungstenite::tungstenite::Message as WsMessage;
use tokio_tungstenite::WebSocketStream;

use crate::io::{BoxIo, Prefixed};
use crate::NetError;

type Ws = WebSocketStream<BoxIo>;

/// First bytes of the HTTP requests the server answers (anything else is read as frames).
const HTTP_METHODS: [&[u8; 4]; 7] = [
    b"GET ", b"HEAD", b"POST", b"PUT ", b"DELE", b"OPTI", b"PATC",
];

/// Why reading a frame failed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The bytes were not a valid frame or message.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// The connection failed (or closed in the middle of a frame).
    #[error("connection: {0}")]
    Io(String),
}

/// Receives frames.
pub enum FrameReader {
    /// Raw frames: header, then payload.
    Tcp(ReadHalf<BoxIo>),
    /// WebSocket: one binary message per frame.
    Ws(SplitStream<Ws>),
}

/// Sends frames.
pub enum FrameWriter {
    /// Raw frames.
    Tcp(WriteHalf<BoxIo>),
    /// WebSocket.
    Ws(SplitSink<Ws, WsMessage>),
}

fn ws_config(limit: u32) -> WebSocketConfig {
    let max = limit as usize + HEADER_LEN;
    WebSocketConfig::default()
        .max_message_size(Some(max))
        .max_frame_size(Some(max))
}

fn split_raw(io: BoxIo) -> (FrameReader, FrameWriter) {
    let (r, w) = tokio::io::split(io);
    (FrameReader::Tcp(r), FrameWriter::Tcp(w))
}

fn split_ws(ws: Ws) -> (FrameReader, FrameWriter) {
    let (w, r) = ws.split();
    (FrameReader::Ws(r), FrameWriter::Ws(w))
}

/// What a new server-side connection turned out to be.
pub enum Accepted {
    /// Raw frames.
    Frames(FrameReader, FrameWriter),
    /// An HTTP request (maybe a WebSocket upgrade): the stream, first bytes put back.
    Http(BoxIo),
}

/// Server side: read the first bytes (within `timeout`) and tell raw frames from HTTP.
pub async fn accept(mut io: BoxIo, timeout: Duration) -> Result<Accepted, NetError> {
    let mut first = [0u8; 4];
    let mut got = 0;
    tokio::time::timeout(timeout, async {
        while got < first.len() {
            match io.read(&mut first[got..]).await? {
                0 => break,
                n => got += n,
            }
        }
        Ok::<_, std::io::Error>(())
    })
    .await
    .map_err(|_| NetError::Protocol("no data from the peer in time".into()))?
    .map_err(NetError::io("reading the first bytes"))?;
    if got < first.len() {
        return Err(NetError::Protocol(
            "the peer closed before sending anything".into(),
        ));
    }
    let io: BoxIo = Box::new(Prefixed::new(first.to_vec(), io));
    if HTTP_METHODS.contains(&&first) {
        Ok(Accepted::Http(io))
    } else {
        let (r, w) = split_raw(io);
        Ok(Accepted::Frames(r, w))
    }
}

/// Server side of a WebSocket whose HTTP upgrade is done; `limit` bounds incoming frames.
pub async fn websocket_server(io: BoxIo, limit: u32) -> (FrameReader, FrameWriter) {
    let ws = WebSocketStream::from_raw_socket(io, Role::Server, Some(ws_config(limit))).await;
    split_ws(ws)
}

/// Client side: connect to `addr`: `HOST:PORT` (raw frames over TCP), `ws://HOST:PORT[/PATH]`
/// (WebSocket; the path defaults to `/ws`) or `wss://…` (WebSocket over TLS, trusting the
/// PEM certificates in `tls_ca`, else the Mozilla roots).
pub async fn connect(
    addr: &str,
    limit: u32,
    tls_ca: Option<&Path>,
) -> Result<(FrameReader, FrameWriter), NetError> {
    let (secure, rest) = match (addr.strip_prefix("ws://"), addr.strip_prefix("wss://")) {
        (Some(rest), _) => (false, Some(rest)),
        (_, Some(rest)) => (true, Some(rest)),
        _ => (false, None),
    };
    if let Some(rest) = rest {
        let (host, path) = match rest.find('/') {
            Some(i) => (&rest[..i], &rest[i..]),
            None => (rest, "/ws"),
        };
        let tcp = TcpStream::connect(host)
            .await
            .map_err(NetError::io(format!("cannot connect to {host}")))?;
        let _ = tcp.set_nodelay(true);
        let (io, url): (BoxIo, String) = if secure {
            let connector = crate::tls::connector(tls_ca)?;
            let name = host_name(host);
            let io = crate::tls::connect(&connector, name, tcp).await?;
            (io, format!("wss://{host}{path}"))
        } else {
            (Box::new(tcp), format!("ws://{host}{path}"))
        };
        let (ws, _) =
            tokio_tungstenite::client_async_with_config(url, io, Some(ws_config(limit))).await?;
        Ok(split_ws(ws))
    } else {
        let tcp = TcpStream::connect(addr)
            .await
            .map_err(NetError::io(format!("cannot connect to {addr}")))?;
        let _ = tcp.set_nodelay(true);
        Ok(split_raw(Box::new(tcp)))
    }
}

/// The host part of `HOST:PORT` (brackets of an IPv6 address removed).
fn host_name(host_port: &str) -> &str {
    let host = match host_port.rfind(':') {
        Some(i) if !host_port[i..].contains(']') => &host_port[..i],
        _ => host_port,
    };
    host.trim_start_matches('[').trim_end_matches(']')
}

impl FrameReader {
    /// The next message and its size on the wire (header included); `Ok(None)` when the
    /// peer closed cleanly between frames. Payloads above `limit` are refused before any
    /// allocation.
    pub async fn next(&mut self, limit: u32) -> Result<Option<(Message, usize)>, ReadError> {
        match self {
            FrameReader::Tcp(r) => {
                let mut header = [0u8; HEADER_LEN];
                match r.read_exact(&mut header[..1]).await {
                    Ok(_) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(None),
                    Err(e) => return Err(ReadError::Io(e.to_string())),
                }
                read_part(r, &mut header[1..], 1, HEADER_LEN).await?;
                let h = FrameHeader::parse(&header, limit)?;
                let mut payload = vec![0u8; h.len as usize];
                read_part(r, &mut payload, HEADER_LEN, HEADER_LEN + h.len as usize).await?;
                let message = decode_payload(&h, &payload)?;
                Ok(Some((message, HEADER_LEN + payload.len())))
            }
            FrameReader::Ws(r) => loop {
                let Some(msg) = r.next().await else {
                    return Ok(None);
                };
                match msg.map_err(|e| ReadError::Io(e.to_string()))? {
                    WsMessage::Binary(data) => {
                        let message = decode_frame(&data, limit)?;
                        return Ok(Some((message, data.len())));
                    }
                    WsMessage::Close(_) => return Ok(None),
                    WsMessage::Ping(_) | WsMessage::Pong(_) => continue,
                    WsMessage::Text(_) | WsMessage::Frame(_) => {
                        return Err(ReadError::Io(
                            "text WebSocket message (frames are binary)".into(),
                        ))
                    }
                }
            },
        }
    }
}

impl FrameReader {
    /// Read and discard what the peer still sends (at most 1 MiB, for at most `timeout`), so
    /// that closing afterwards does not reset the connection before the peer has read our
    /// last frame.
    pub async fn drain(&mut self, timeout: Duration) {
        let FrameReader::Tcp(r) = self else {
            return;
        };
        let mut buf = [0u8; 4096];
        let mut left = 1usize << 20;
        let _ = tokio::time::timeout(timeout, async {
            while left > 0 {
                match r.read(&mut buf).await {
                    Ok(0) | Err(_) => break,
                    Ok(n) => left = left.saturating_sub(n),
                }
            }
        })
        .await;
    }
}

/// Fill `buf` with the next bytes of a frame of `needed` bytes of which `before` have
/// arrived; the stream ending first is a truncated frame (counting what did arrive).
async fn read_part(
    r: &mut ReadHalf<BoxIo>,
    buf: &mut [u8],
    before: usize,
    needed: usize,
) -> Result<(), ReadError> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]).await {
            Ok(0) => {
                return Err(ReadError::Wire(WireError::Truncated {
                    needed: needed as u64,
                    available: (before + got) as u64,
                }))
            }
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(ReadError::Io(e.to_string())),
        }
    }
    Ok(())
}

impl FrameWriter {
    /// Send one encoded frame.
    pub async fn send(&mut self, frame: Vec<u8>) -> Result<(), NetError> {
        match self {
            FrameWriter::Tcp(w) => w
                .write_all(&frame)
                .await
                .map_err(NetError::io("sending a frame"))?,
            FrameWriter::Ws(w) => w.send(WsMessage::binary(frame)).await?,
        }
        Ok(())
    }

    /// Flush and close the sending side.
    pub async fn close(&mut self) {
        match self {
            FrameWriter::Tcp(w) => {
                let _ = w.shutdown().await;
            }
            FrameWriter::Ws(w) => {
                let _ = w.close().await;
            }
        }
    }
}
