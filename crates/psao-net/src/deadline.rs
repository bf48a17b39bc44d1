//! Deadlines on a server connection's byte stream, below every protocol (TLS, HTTP,
//! WebSocket, raw frames): a write that makes no progress for [`Deadlines::write_stall`]
//! fails, and so does a connection on which nothing moves in either direction for
//! [`Deadlines::idle`]. A peer that stops reading (a "slow reader") or goes silent therefore
//! gives its connection, and the connection permit it holds, back in bounded time.

use std::future::Future;
use std::io::{self, IoSlice};
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::{Instant, Sleep};

/// How long a connection may stall.
#[derive(Clone, Copy, Debug)]
pub struct Deadlines {
    /// Longest time a pending write (or flush) may make no progress: the peer's receive
    /// window stayed full.
    pub write_stall: Duration,
    /// Longest time without a byte read or written.
    pub idle: Duration,
}

/// What the server uses: a write stalled for 15 s means a peer that does not read (a live
/// client on a slow link still drains its window within seconds); 60 s without any traffic
/// outlasts a browser's keep-alive period (10 s) even in a background tab throttled to one
/// timer per second.
pub const SERVER_DEADLINES: Deadlines = Deadlines {
    write_stall: Duration::from_secs(15),
    idle: Duration::from_secs(60),
};

/// `inner` with [`Deadlines`] enforced; reads and writes (vectored ones included) are passed
/// through unchanged otherwise.
pub struct Deadlined<T> {
    inner: T,
    limits: Deadlines,
    /// Fires when the pending write has made no progress for `write_stall`.
    write_timer: Option<Pin<Box<Sleep>>>,
    /// Fires when nothing moved for `idle`; reset by every byte read or written.
    idle_timer: Pin<Box<Sleep>>,
}

impl<T> Deadlined<T> {
    /// Wraps `inner`; its idle clock starts now.
    pub fn new(inner: T, limits: Deadlines) -> Self {
        Self {
            inner,
            limits,
            write_timer: None,
            idle_timer: Box::pin(tokio::time::sleep(limits.idle)),
        }
    }

    fn progressed(&mut self) {
        let at = Instant::now() + self.limits.idle;
        self.idle_timer.as_mut().reset(at);
    }

    /// `Err(TimedOut)` once the idle deadline passed (registering the waker otherwise).
    fn check_idle(&mut self, cx: &mut Context<'_>) -> io::Result<()> {
        match self.idle_timer.as_mut().poll(cx) {
            Poll::Ready(()) => Err(timed_out(format!(
                "no traffic for {} s",
                self.limits.idle.as_secs()
            ))),
            Poll::Pending => Ok(()),
        }
    }

    /// Handles the outcome of a write-side poll: progress resets both clocks, a pending one
    /// arms the stall timer and fails once it fired.
    fn after_write<R>(
        &mut self,
        cx: &mut Context<'_>,
        polled: Poll<io::Result<R>>,
        progress: impl Fn(&R) -> bool,
    ) -> Poll<io::Result<R>> {
        match polled {
            Poll::Ready(Ok(r)) => {
                if progress(&r) {
                    self.write_timer = None;
                    self.progressed();
                }
                Poll::Ready(Ok(r))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => {
                let stall = self.limits.write_stall;
                let timer = self
                    .write_timer
                    .get_or_insert_with(|| Box::pin(tokio::time::sleep(stall)));
                if timer.as_mut().poll(cx).is_ready() {
                    return Poll::Ready(Err(timed_out(format!(
                        "the peer read nothing for {} s",
                        stall.as_secs()
                    ))));
                }
                if let Err(e) = self.check_idle(cx) {
                    return Poll::Ready(Err(e));
                }
                Poll::Pending
            }
        }
    }
}

fn timed_out(message: String) -> io::Error {
    io::Error::new(io::ErrorKind::TimedOut, message)
}

impl<T: AsyncRead + Unpin> AsyncRead for Deadlined<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.inner).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                if buf.filled().len() > before {
                    self.progressed();
                }
                Poll::Ready(Ok(()))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => match self.check_idle(cx) {
                Ok(()) => Poll::Pending,
                Err(e) => Poll::Ready(Err(e)),
            },
        }
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for Deadlined<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write(cx, buf);
        self.after_write(cx, polled, |&n| n > 0)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        self.after_write(cx, polled, |&n| n > 0)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let polled = Pin::new(&mut self.inner).poll_flush(cx);
        self.after_write(cx, polled, |_| true)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    const SHORT: Deadlines = Deadlines {
        write_stall: Duration::from_secs(2),
        idle: Duration::from_secs(5),
    };

    #[tokio::test(start_paused = true)]
    async fn a_write_the_peer_never_reads_fails_after_the_stall_deadline() {
        let (a, _b) = tokio::io::duplex(1024);
        let mut d = Deadlined::new(a, SHORT);
        let t0 = Instant::now();
        let err = d.write_all(&[7u8; 4096]).await.unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
        let waited = t0.elapsed();
        assert!(
            waited >= SHORT.write_stall && waited < SHORT.idle,
            "{waited:?}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_silent_connection_fails_after_the_idle_deadline() {
        let (a, _b) = tokio::io::duplex(1024);
        let mut d = Deadlined::new(a, SHORT);
        let t0 = Instant::now();
        let err = d.read(&mut [0u8; 16]).await.unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
        assert!(t0.elapsed() >= SHORT.idle);
    }

    #[tokio::test(start_paused = true)]
    async fn traffic_keeps_a_connection_alive_past_the_deadlines() {
        let (a, mut b) = tokio::io::duplex(64);
        let mut d = Deadlined::new(a, SHORT);
        let peer = tokio::spawn(async move {
            let mut got = Vec::new();
            let mut buf = [0u8; 8];
            // Reads slowly: 8 bytes a second, never stalling the writer for 2 s.
            while got.len() < 96 {
                tokio::time::sleep(Duration::from_secs(1)).await;
                let n = b.read(&mut buf).await.unwrap();
                got.extend_from_slice(&buf[..n]);
            }
            got
        });
        d.write_all(&[1u8; 96]).await.unwrap();
        assert_eq!(peer.await.unwrap(), vec![1u8; 96]);
    }
}
