//! Frame transports: raw TCP (frames back to back) and WebSocket (one binary message per
//! frame), behind one reader and one writer type. A server tells them apart by the first
//! bytes of a connection (`GET ` starts a WebSocket handshake, `PSW1` a TCP frame).

use std::time::Duration;

use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use psao_wire::{decode_frame, decode_payload, FrameHeader, Message, WireError, HEADER_LEN};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::Message as WsMessage;
use tokio_tungstenite::WebSocketStream;

use crate::NetError;

type Ws = WebSocketStream<TcpStream>;

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
    /// TCP: header, then payload.
    Tcp(OwnedReadHalf),
    /// WebSocket: one binary message per frame.
    Ws(SplitStream<Ws>),
}

/// Sends frames.
pub enum FrameWriter {
    /// TCP.
    Tcp(OwnedWriteHalf),
    /// WebSocket.
    Ws(SplitSink<Ws, WsMessage>),
}

fn ws_config(limit: u32) -> WebSocketConfig {
    let max = limit as usize + HEADER_LEN;
    WebSocketConfig::default()
        .max_message_size(Some(max))
        .max_frame_size(Some(max))
}

fn split_tcp(stream: TcpStream) -> (FrameReader, FrameWriter) {
    let _ = stream.set_nodelay(true);
    let (r, w) = stream.into_split();
    (FrameReader::Tcp(r), FrameWriter::Tcp(w))
}

fn split_ws(ws: Ws) -> (FrameReader, FrameWriter) {
    let (w, r) = ws.split();
    (FrameReader::Ws(r), FrameWriter::Ws(w))
}

/// Server side: detect the transport from the first bytes (within `timeout`) and complete a
/// WebSocket handshake when needed. `limit` bounds incoming frames.
pub async fn accept(
    stream: TcpStream,
    limit: u32,
    timeout: Duration,
) -> Result<(FrameReader, FrameWriter, &'static str), NetError> {
    let mut first = [0u8; 4];
    let peeked = tokio::time::timeout(timeout, async {
        loop {
            let n = stream.peek(&mut first).await?;
            if n == 0 || n == first.len() {
                return Ok::<_, std::io::Error>(n);
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    })
    .await
    .map_err(|_| NetError::Protocol("no data from the peer in time".into()))?
    .map_err(NetError::io("reading the first bytes"))?;
    if peeked < first.len() {
        return Err(NetError::Protocol(
            "the peer closed before sending anything".into(),
        ));
    }
    if &first == b"GET " {
        let ws =
            tokio_tungstenite::accept_async_with_config(stream, Some(ws_config(limit))).await?;
        let (r, w) = split_ws(ws);
        Ok((r, w, "websocket"))
    } else {
        let (r, w) = split_tcp(stream);
        Ok((r, w, "tcp"))
    }
}

/// Client side: connect to `addr`, either `HOST:PORT` (TCP) or `ws://HOST:PORT[/…]`.
pub async fn connect(addr: &str, limit: u32) -> Result<(FrameReader, FrameWriter), NetError> {
    if let Some(rest) = addr.strip_prefix("ws://") {
        let host = rest.split('/').next().unwrap_or(rest);
        let tcp = TcpStream::connect(host)
            .await
            .map_err(NetError::io(format!("cannot connect to {host}")))?;
        let _ = tcp.set_nodelay(true);
        let (ws, _) =
            tokio_tungstenite::client_async_with_config(addr, tcp, Some(ws_config(limit))).await?;
        Ok(split_ws(ws))
    } else {
        let tcp = TcpStream::connect(addr)
            .await
            .map_err(NetError::io(format!("cannot connect to {addr}")))?;
        Ok(split_tcp(tcp))
    }
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
                r.read_exact(&mut header[1..])
                    .await
                    .map_err(|e| truncated(e, 1))?;
                let h = FrameHeader::parse(&header, limit)?;
                let mut payload = vec![0u8; h.len as usize];
                r.read_exact(&mut payload)
                    .await
                    .map_err(|e| truncated(e, HEADER_LEN + h.len as usize))?;
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

fn truncated(e: std::io::Error, needed: usize) -> ReadError {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        ReadError::Wire(WireError::Truncated {
            needed: needed as u64,
            available: 0,
        })
    } else {
        ReadError::Io(e.to_string())
    }
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
