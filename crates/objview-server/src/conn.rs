//! Connections of `objview serve`: the accept loop, per-connection time limits and the
//! connection cap (docs/server-api.md, "Connections").
//!
//! Every connection is served by hyper's HTTP/1.1 server (keep-alive) over a socket wrapper that
//! notes when bytes move, and watched by a timer in its own task:
//! - **idle**: no request being handled and no byte of a new one → closed `idle_timeout` after
//!   its last activity (a byte read or written, a response produced);
//! - **header**: the first byte of a request arrived but its head is not complete → closed
//!   `header_timeout` after that first byte (a slowly trickled head does not reset it);
//! - **body**: a handler reads the body within `body_timeout` or answers 408 and the
//!   connection closes (see [`crate::api`]);
//! - while a handler works (the engine) nothing is timed here: the episode's own limits apply.
//!
//! **Cap**: at most `max_connections` connections are open. A connection accepted beyond the cap
//! closes the open connection that is *evictable* (idle, half-sent head, or a body still
//! arriving) and has been quiet the longest; so a client that holds idle sockets up to the cap
//! cannot lock anyone out — the newest connection always gets in, and the one that waited the
//! longest without doing anything pays. Only when every open connection is inside a handler is
//! the new one refused: `503 overloaded` with `Connection: close`, written directly and closed
//! cleanly. When the process runs out of file descriptors anyway (accept fails with
//! EMFILE/ENFILE), the quietest evictable connection is closed as well, so that accepting goes on.
//!
//! Graceful shutdown: the listener stops, idle connections and half-sent requests (head or body)
//! are closed at once, requests the server is working on finish and get their answers.

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::Router;
use hyper_util::rt::TokioIo;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tower::ServiceExt;

use crate::error::ApiError;

/// Default of `--max-connections`.
pub const DEFAULT_MAX_CONNECTIONS: usize = 256;
/// Default of `--header-timeout` (seconds).
pub const DEFAULT_HEADER_TIMEOUT_S: f64 = 10.0;
/// Default of `--body-timeout` (seconds).
pub const DEFAULT_BODY_TIMEOUT_S: f64 = 30.0;
/// Default of `--idle-timeout` (seconds).
pub const DEFAULT_IDLE_TIMEOUT_S: f64 = 60.0;

/// File descriptors kept free for everything but client sockets (mesh and cache files, the
/// database, refusals) when the cap is lowered to fit the descriptor limit.
pub const DESCRIPTOR_RESERVE: u64 = 64;

/// At most this many 503 refusals are being written at a time; beyond that a refused socket is
/// closed at once.
const MAX_REFUSALS_IN_FLIGHT: usize = 16;

/// How long a refusal may take (write the 503, read what the client sent, close).
const REFUSAL_TIME: Duration = Duration::from_secs(2);

const NONE: u64 = u64::MAX;

/// How often a connection with a request in progress looks whether it became half-sent during a
/// shutdown.
const SHUTDOWN_RECHECK: Duration = Duration::from_millis(100);

/// The limits of [`serve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConnLimits {
    /// Open connections at most (≥ 1).
    pub max_connections: usize,
    /// From the first byte of a request to the end of its head.
    pub header_timeout: Duration,
    /// From the last activity of a connection without a request in progress to its close.
    pub idle_timeout: Duration,
}

/// One open connection's state, shared by its task, its socket wrapper, its requests and the
/// registry. Times are milliseconds since the registry's epoch.
#[derive(Debug)]
pub struct Conn {
    id: u64,
    epoch: Instant,
    last_activity: AtomicU64,
    /// First byte of a request head not yet dispatched ([`NONE`]: none).
    head_since: AtomicU64,
    /// Requests inside the router.
    handling: AtomicUsize,
    /// Of those, requests whose handler is waiting for the body.
    receiving_body: AtomicUsize,
    kill: tokio::sync::Notify,
}

impl Conn {
    fn new(id: u64, epoch: Instant) -> Conn {
        let c = Conn {
            id,
            epoch,
            last_activity: AtomicU64::new(0),
            head_since: AtomicU64::new(NONE),
            handling: AtomicUsize::new(0),
            receiving_body: AtomicUsize::new(0),
            kill: tokio::sync::Notify::new(),
        };
        c.touch();
        c
    }

    fn now_ms(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    fn touch(&self) {
        self.last_activity.store(self.now_ms(), Ordering::SeqCst);
    }

    fn on_read(&self) {
        self.touch();
        if self.handling.load(Ordering::SeqCst) == 0 {
            let _ = self.head_since.compare_exchange(NONE, self.now_ms(), Ordering::SeqCst, Ordering::SeqCst);
        }
    }

    /// Whether closing it would lose no work of the server: no request inside the router, or
    /// one still waiting for its body.
    fn evictable(&self) -> bool {
        self.handling.load(Ordering::SeqCst) == 0 || self.receiving_body.load(Ordering::SeqCst) > 0
    }

    /// Whether a request is half-sent: its head, or the body its handler waits for.
    fn half_sent(&self) -> bool {
        self.head_since.load(Ordering::SeqCst) != NONE || self.receiving_body.load(Ordering::SeqCst) > 0
    }

    /// When (ms) the connection is closed if nothing happens before; `None` while a request is
    /// handled.
    fn deadline(&self, limits: &ConnLimits) -> Option<u64> {
        if self.handling.load(Ordering::SeqCst) > 0 {
            return None;
        }
        let ms = |d: Duration| d.as_millis() as u64;
        let head = self.head_since.load(Ordering::SeqCst);
        Some(if head != NONE {
            head.saturating_add(ms(limits.header_timeout))
        } else {
            self.last_activity.load(Ordering::SeqCst).saturating_add(ms(limits.idle_timeout))
        })
    }
}

/// Marks a request as inside the router until dropped.
struct Handling(Arc<Conn>);

impl Handling {
    fn enter(conn: Arc<Conn>) -> Handling {
        conn.handling.fetch_add(1, Ordering::SeqCst);
        conn.head_since.store(NONE, Ordering::SeqCst);
        conn.touch();
        Handling(conn)
    }
}

impl Drop for Handling {
    fn drop(&mut self) {
        self.0.handling.fetch_sub(1, Ordering::SeqCst);
        self.0.touch();
    }
}

/// The connection of a request (a request extension): a handler reading the body says so with
/// [`ConnHandle::receiving_body`].
#[derive(Debug, Clone)]
pub struct ConnHandle(Arc<Conn>);

impl ConnHandle {
    /// Marks the connection as waiting for a body (evictable) until the guard is dropped.
    pub fn receiving_body(&self) -> ReceivingBody {
        self.0.receiving_body.fetch_add(1, Ordering::SeqCst);
        ReceivingBody(self.0.clone())
    }
}

/// See [`ConnHandle::receiving_body`].
#[derive(Debug)]
pub struct ReceivingBody(Arc<Conn>);

impl Drop for ReceivingBody {
    fn drop(&mut self) {
        self.0.receiving_body.fetch_sub(1, Ordering::SeqCst);
        self.0.touch();
    }
}

/// The open connections.
#[derive(Debug)]
pub struct Registry {
    epoch: Instant,
    next_id: AtomicU64,
    conns: Mutex<HashMap<u64, Arc<Conn>>>,
    evicted: AtomicU64,
    refused: AtomicU64,
}

impl Default for Registry {
    fn default() -> Self {
        Registry {
            epoch: Instant::now(),
            next_id: AtomicU64::new(0),
            conns: Mutex::default(),
            evicted: AtomicU64::new(0),
            refused: AtomicU64::new(0),
        }
    }
}

/// What [`Registry::admit`] decided.
#[derive(Debug)]
enum Admission {
    /// Open it (after closing the connection that made room, if any).
    Admit(Arc<Conn>),
    /// Every open connection is busy: refuse it.
    Refuse,
}

impl Registry {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u64, Arc<Conn>>> {
        self.conns.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Open connections now.
    pub fn open(&self) -> usize {
        self.lock().len()
    }

    /// Connections admitted so far (a client that keeps its connection alive adds one for all
    /// its requests).
    pub fn admitted(&self) -> u64 {
        self.next_id.load(Ordering::SeqCst)
    }

    /// Connections closed so far to make room for a new one.
    pub fn evicted(&self) -> u64 {
        self.evicted.load(Ordering::SeqCst)
    }

    /// Connections refused so far (503) because every open one was busy.
    pub fn refused(&self) -> u64 {
        self.refused.load(Ordering::SeqCst)
    }

    /// Closes the evictable connection that has been quiet the longest; whether there was one.
    fn evict_one(&self, conns: &mut HashMap<u64, Arc<Conn>>) -> bool {
        let victim = conns
            .values()
            .filter(|c| c.evictable())
            .min_by_key(|c| (c.last_activity.load(Ordering::SeqCst), c.id))
            .map(|c| c.id);
        match victim.and_then(|id| conns.remove(&id)) {
            Some(c) => {
                c.kill.notify_one();
                self.evicted.fetch_add(1, Ordering::SeqCst);
                true
            }
            None => false,
        }
    }

    fn admit(&self, max: usize) -> Admission {
        let mut conns = self.lock();
        while conns.len() >= max.max(1) {
            if !self.evict_one(&mut conns) {
                self.refused.fetch_add(1, Ordering::SeqCst);
                return Admission::Refuse;
            }
        }
        let id = self.next_id.fetch_add(1, Ordering::SeqCst);
        let c = Arc::new(Conn::new(id, self.epoch));
        conns.insert(id, c.clone());
        Admission::Admit(c)
    }

    fn remove(&self, id: u64) {
        self.lock().remove(&id);
    }
}

/// A socket that tells its [`Conn`] when bytes move.
struct Watched {
    io: TcpStream,
    conn: Arc<Conn>,
}

impl AsyncRead for Watched {
    fn poll_read(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        let r = Pin::new(&mut this.io).poll_read(cx, buf);
        if matches!(r, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            this.conn.on_read();
        }
        r
    }
}

impl AsyncWrite for Watched {
    fn poll_write(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_write(cx, buf);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            this.conn.touch();
        }
        r
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.io).poll_write_vectored(cx, bufs);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            this.conn.touch();
        }
        r
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().io).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().io).poll_shutdown(cx)
    }
}

/// The soft limit on open file descriptors of this process, where the system says (Linux).
pub fn descriptor_limit() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = text.lines().find(|l| l.starts_with("Max open files"))?;
    line.split_whitespace().nth(3)?.parse().ok()
}

/// `requested` lowered so that the connections fit in `limit` descriptors with
/// [`DESCRIPTOR_RESERVE`] to spare (at least 1).
pub fn fit_descriptor_limit(requested: usize, limit: Option<u64>) -> usize {
    match limit {
        Some(l) => requested.min(l.saturating_sub(DESCRIPTOR_RESERVE).max(1) as usize),
        None => requested,
    }
}

/// Whether an accept error means the process or system has no descriptor left.
fn out_of_descriptors(e: &io::Error) -> bool {
    // EMFILE and ENFILE (the same numbers on Linux and the BSDs).
    matches!(e.raw_os_error(), Some(23 | 24))
}

fn connection_error(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::ConnectionAborted | io::ErrorKind::ConnectionReset | io::ErrorKind::ConnectionRefused
    )
}

/// Writes the 503 of a refused connection, reads what the client sent (so that closing does not
/// reset the connection under the answer) and closes it, within [`REFUSAL_TIME`].
async fn refuse(mut stream: TcpStream) {
    let body = ApiError::Overloaded(
        "every connection of the server is busy with a request; try again in a moment".into(),
    )
    .body()
    .to_string();
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\n\
         connection: close\r\nretry-after: 1\r\n\r\n{body}",
        body.len()
    );
    let _ = tokio::time::timeout(REFUSAL_TIME, async {
        let mut rest = answer.as_bytes();
        while !rest.is_empty() {
            stream.writable().await?;
            match stream.try_write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) => return Err(e),
            }
        }
        std::future::poll_fn(|cx| Pin::new(&mut stream).poll_shutdown(cx)).await?;
        let mut buf = [0u8; 4096];
        let mut read = 0usize;
        while read < 1 << 16 {
            stream.readable().await?;
            match stream.try_read(&mut buf) {
                Ok(0) => break,
                Ok(n) => read += n,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) => return Err(e),
            }
        }
        Ok::<(), io::Error>(())
    })
    .await;
}

/// Serves one connection until it ends, times out, is evicted or the server shuts down.
async fn connection(
    stream: TcpStream,
    conn: Arc<Conn>,
    router: Router,
    limits: ConnLimits,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
) {
    let _ = stream.set_nodelay(true);
    let io = TokioIo::new(Watched { io: stream, conn: conn.clone() });
    let for_requests = conn.clone();
    let service = hyper::service::service_fn(move |mut req: hyper::Request<hyper::body::Incoming>| {
        let handling = Handling::enter(for_requests.clone());
        req.extensions_mut().insert(ConnHandle(for_requests.clone()));
        let answer = router.clone().oneshot(req.map(axum::body::Body::new));
        async move {
            let r = answer.await;
            drop(handling);
            r
        }
    });
    let mut builder = hyper::server::conn::http1::Builder::new();
    // The head's time limit is ours (it starts at the first byte of a request, so that idle
    // keep-alive connections get the idle limit instead).
    builder.header_read_timeout(None::<Duration>).keep_alive(true);
    let served = builder.serve_connection(io, service);
    tokio::pin!(served);
    let mut shutting_down = *shutdown.borrow();
    if shutting_down {
        served.as_mut().graceful_shutdown();
    }
    let recheck = limits.header_timeout.min(limits.idle_timeout).max(Duration::from_millis(10));
    loop {
        if shutting_down && conn.half_sent() {
            break;
        }
        let now = conn.now_ms();
        let wake = match conn.deadline(&limits) {
            Some(d) if d <= now => break,
            // A head that starts while the connection is idle brings the deadline forward, to
            // its first byte + the header limit at the earliest: looking again a header limit
            // from now is in time for it.
            Some(d) => {
                conn.epoch + Duration::from_millis(d.min(now + limits.header_timeout.as_millis() as u64))
            }
            // A request is being handled: look again later.
            None => Instant::now() + if shutting_down { SHUTDOWN_RECHECK } else { recheck },
        };
        tokio::select! {
            _ = served.as_mut() => break,
            _ = conn.kill.notified() => break,
            _ = shutdown.changed(), if !shutting_down => {
                shutting_down = true;
                served.as_mut().graceful_shutdown();
            }
            _ = tokio::time::sleep_until(wake.into()) => {}
        }
    }
}

/// Accepts connections on `listener` and serves `router` on each under `limits` until
/// `shutdown` resolves; then lets the open connections finish (see the module docs).
pub async fn serve(
    listener: tokio::net::TcpListener,
    router: Router,
    registry: Arc<Registry>,
    limits: ConnLimits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) {
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    // Every connection task holds a sender; when all are gone, the receiver ends.
    let (done_tx, mut done_rx) = tokio::sync::mpsc::channel::<()>(1);
    let refusals = Arc::new(tokio::sync::Semaphore::new(MAX_REFUSALS_IN_FLIGHT));
    tokio::pin!(shutdown);
    loop {
        let accepted = tokio::select! {
            _ = &mut shutdown => break,
            r = listener.accept() => r,
        };
        let stream = match accepted {
            Ok((s, _)) => s,
            Err(e) if out_of_descriptors(&e) => {
                // Make room, then give the closed connection's task a moment to let go of its
                // descriptor.
                registry.evict_one(&mut registry.lock());
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
            Err(e) if connection_error(&e) => continue,
            Err(e) => {
                eprintln!("objview serve: accepting a connection: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        match registry.admit(limits.max_connections) {
            Admission::Admit(conn) => {
                let (router, stop_rx, done, registry) =
                    (router.clone(), stop_rx.clone(), done_tx.clone(), registry.clone());
                tokio::spawn(async move {
                    let id = conn.id;
                    connection(stream, conn, router, limits, stop_rx).await;
                    registry.remove(id);
                    drop(done);
                });
            }
            Admission::Refuse => match refusals.clone().try_acquire_owned() {
                Ok(permit) => {
                    tokio::spawn(async move {
                        refuse(stream).await;
                        drop(permit);
                    });
                }
                Err(_) => drop(stream),
            },
        }
    }
    drop(listener);
    let _ = stop_tx.send(true);
    drop(done_tx);
    let _ = done_rx.recv().await;
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: ConnLimits = ConnLimits {
        max_connections: 2,
        header_timeout: Duration::from_millis(100),
        idle_timeout: Duration::from_millis(300),
    };

    #[test]
    fn an_idle_connection_closes_its_idle_timeout_after_its_last_activity() {
        let c = Conn::new(0, Instant::now());
        let t = c.last_activity.load(Ordering::SeqCst);
        assert_eq!(c.deadline(&LIMITS), Some(t + 300));
    }

    #[test]
    fn a_started_head_gets_the_header_timeout_from_its_first_byte() {
        let c = Arc::new(Conn::new(0, Instant::now()));
        c.on_read();
        let first = c.head_since.load(Ordering::SeqCst);
        assert_ne!(first, NONE);
        std::thread::sleep(Duration::from_millis(5));
        c.on_read(); // more bytes of the same head: the deadline stays
        assert_eq!(c.deadline(&LIMITS), Some(first + 100));
        // Dispatched: no deadline while it is handled, the idle one after.
        let h = Handling::enter(c.clone());
        assert_eq!(c.deadline(&LIMITS), None);
        c.on_read(); // body bytes are not a new head
        drop(h);
        assert_eq!(c.head_since.load(Ordering::SeqCst), NONE);
        assert_eq!(c.deadline(&LIMITS), Some(c.last_activity.load(Ordering::SeqCst) + 300));
    }

    #[test]
    fn a_handler_waiting_for_its_body_is_evictable() {
        let c = Arc::new(Conn::new(0, Instant::now()));
        let h = Handling::enter(c.clone());
        assert!(!c.evictable());
        let body = ConnHandle(c.clone()).receiving_body();
        assert!(c.evictable());
        drop(body);
        assert!(!c.evictable());
        drop(h);
        assert!(c.evictable());
    }

    #[test]
    fn at_the_cap_the_quietest_evictable_connection_makes_room() {
        let r = Registry::default();
        let Admission::Admit(a) = r.admit(2) else { panic!("refused under the cap") };
        let Admission::Admit(b) = r.admit(2) else { panic!("refused under the cap") };
        std::thread::sleep(Duration::from_millis(5));
        a.touch(); // a is now the more recent (though older): b is the quietest
        let Admission::Admit(_c) = r.admit(2) else { panic!("refused with idle connections") };
        assert_eq!((r.open(), r.evicted()), (2, 1));
        assert!(r.lock().contains_key(&a.id) && !r.lock().contains_key(&b.id));
    }

    #[test]
    fn at_the_cap_with_every_connection_busy_a_new_one_is_refused() {
        let r = Registry::default();
        let Admission::Admit(a) = r.admit(1) else { panic!("refused under the cap") };
        let busy = Handling::enter(a.clone());
        assert!(matches!(r.admit(1), Admission::Refuse));
        assert_eq!((r.open(), r.refused(), r.evicted()), (1, 1, 0));
        drop(busy);
        assert!(matches!(r.admit(1), Admission::Admit(_)));
        assert_eq!((r.open(), r.evicted()), (1, 1));
    }

    #[test]
    fn the_cap_is_lowered_to_fit_the_descriptor_limit() {
        assert_eq!(fit_descriptor_limit(256, Some(128)), 64);
        assert_eq!(fit_descriptor_limit(256, Some(1024)), 256);
        assert_eq!(fit_descriptor_limit(256, Some(10)), 1);
        assert_eq!(fit_descriptor_limit(256, None), 256);
    }

    #[test]
    fn the_descriptor_limit_is_read_where_the_system_says() {
        if cfg!(target_os = "linux") {
            assert!(descriptor_limit().is_some_and(|n| n > 0));
        }
    }
}
