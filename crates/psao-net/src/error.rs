//! The typed error of the networking crate.

use psao_client::ClientError;
use psao_delta::DeltaError;
use psao_raster::PoseError;
use psao_scene::AnimationError;
use psao_server::ServerError;
use psao_wire::{ErrorCode, WireError};

/// Why serving, viewing or the in-process pipeline failed.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// An operating-system I/O operation failed; `what` names it.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Bytes from the peer were not a valid frame or message.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// The WebSocket layer failed (handshake or connection).
    #[error("WebSocket: {0}")]
    WebSocket(#[from] Box<tokio_tungstenite::tungstenite::Error>),
    /// A codec could not be made, or an update did not decode; `what` says whose.
    #[error("{what}: {source}")]
    Codec {
        /// Whose codec (e.g. "cannot decode the server's update").
        what: &'static str,
        /// The codec's error.
        #[source]
        source: DeltaError,
    },
    /// A decoded update could not be applied to the client's state.
    #[error("cannot apply the server's update: {0}")]
    Apply(#[from] ClientError),
    /// The server could not start or step.
    #[error(transparent)]
    Server(#[from] ServerError),
    /// The scene's animation cannot be played.
    #[error("the scene's animation cannot be played: {0}")]
    Animation(#[from] AnimationError),
    /// The posed scene cannot be rasterized.
    #[error("cannot rasterize the posed scene: {0}")]
    Raster(#[from] PoseError),
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
    /// A served relighting model cannot relight the scene's character.
    #[error("relit character {character}: {source}")]
    Relight {
        /// The character's index among the scene's skinned characters.
        character: u32,
        /// Why.
        #[source]
        source: psao_prt::PrtError,
    },
    /// The server sent an error message (refusing the session or ending it).
    #[error("the server refused the session ({code:?}): {message}")]
    Refused {
        /// The server's error code.
        code: ErrorCode,
        /// The server's message.
        message: String,
    },
    /// The peer broke the protocol (unexpected message, text frame, missing hello, …).
    #[error("{0}")]
    Protocol(String),
    /// No connection could be (re)established in time.
    #[error("no connection for {seconds:.0} s: {last}")]
    Unreachable {
        /// Seconds waited.
        seconds: f64,
        /// The last connection failure.
        last: String,
    },
    /// The NATS server could not be reached or refused a request (scale-out roles).
    #[error("NATS: {0}")]
    Nats(String),
    /// TLS could not be set up (certificate, key) or its handshake failed.
    #[error("TLS: {0}")]
    Tls(String),
    /// The caller's frame sink failed (e.g. writing images).
    #[error(transparent)]
    Sink(Box<dyn std::error::Error + Send + Sync>),
}

impl NetError {
    /// An I/O error while doing `what`.
    pub fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> NetError {
        let what = what.into();
        move |source| NetError::Io { what, source }
    }

    /// A codec error while doing `what`.
    pub fn codec(what: &'static str) -> impl FnOnce(DeltaError) -> NetError {
        move |source| NetError::Codec { what, source }
    }
}

impl From<tokio_tungstenite::tungstenite::Error> for NetError {
    fn from(e: tokio_tungstenite::tungstenite::Error) -> Self {
        NetError::WebSocket(Box::new(e))
    }
}
