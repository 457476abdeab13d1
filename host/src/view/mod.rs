//! The live view: a web page that shows the puppet while it performs
//! (`marionette view`, and `--view` on `demo`, `emulate`, `stream` and
//! `live`).
//!
//! # Design
//!
//! - **Server.** [`View::start`] binds the address (localhost unless told
//!   otherwise with `--listen`), then serves from its own thread on a
//!   single-threaded tokio runtime with axum. Two routes, both `GET`:
//!   `/`, the page (one HTML file with its script inline, built into the
//!   binary: nothing is fetched from anywhere else), and `/events`, a
//!   server-sent-events stream of [`scene::Snapshot`]s as JSON. Every other
//!   path is 404 and every other method 405.
//! - **Read-only.** Nothing the page or anyone else sends reaches the
//!   board: the server has no route that takes data, and the session's
//!   loop only *offers* snapshots to it.
//! - **Rate.** The session offers a snapshot for every frame it sees;
//!   [`View::offer`] builds one only when [`FRAME_INTERVAL`] has passed
//!   since the last (60 a second at most), so the view costs the loop
//!   nothing in between. A client always gets the newest snapshot first,
//!   then each new one; a slow client skips snapshots rather than queueing
//!   them.
//! - **Disconnects.** When the session ends, [`View::end`] publishes a
//!   last snapshot marked disconnected; if the server goes away, the page
//!   keeps the last figure, greys it and says it lost the board.

pub mod scene;
pub mod watch;

use axum::Router;
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use scene::Snapshot;
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tokio::sync::{oneshot, watch as latest};

/// The shortest time between two snapshots.
pub const FRAME_INTERVAL: Duration = Duration::from_millis(16);

/// The default address: this machine only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8765";

/// The page, with its script and style inline.
const PAGE: &str = include_str!("page.html");

/// The page may load nothing from anywhere: its own script and style
/// (inline), and its event stream.
const POLICY: &str = "default-src 'none'; script-src 'unsafe-inline'; \
                      style-src 'unsafe-inline'; connect-src 'self'";

/// Why the view could not start.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The address could not be bound.
    #[error("the view's address {addr}: {source}")]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The server's runtime could not start.
    #[error("the view's server: {0}")]
    Runtime(std::io::Error),
}

/// A running view server.
pub struct View {
    addr: SocketAddr,
    feed: latest::Sender<Arc<str>>,
    last: Mutex<Option<Instant>>,
    shown: Mutex<Option<Snapshot>>,
    stop: Option<oneshot::Sender<()>>,
}

impl View {
    /// Binds `listen` and starts serving.
    pub fn start(listen: SocketAddr) -> Result<View, ViewError> {
        let bind = |source| ViewError::Bind {
            addr: listen,
            source,
        };
        let listener = std::net::TcpListener::bind(listen).map_err(bind)?;
        listener.set_nonblocking(true).map_err(bind)?;
        let addr = listener.local_addr().map_err(bind)?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .map_err(ViewError::Runtime)?;
        let (feed, rx) = latest::channel(Arc::<str>::from("{}"));
        let (stop, stopped) = oneshot::channel::<()>();
        std::thread::spawn(move || {
            runtime.block_on(async move {
                let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                    return;
                };
                let app = Router::new()
                    .route("/", get(page))
                    .route("/events", get(move || events(rx.clone())));
                tokio::select! {
                    _ = axum::serve(listener, app) => {}
                    _ = stopped => {}
                }
            });
        });
        Ok(View {
            addr,
            feed,
            last: Mutex::new(None),
            shown: Mutex::new(None),
            stop: Some(stop),
        })
    }

    /// Where the page is.
    #[must_use]
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Publishes the snapshot `make` builds, if [`FRAME_INTERVAL`] has
    /// passed since the last one (otherwise `make` is not called).
    pub fn offer(&self, make: impl FnOnce() -> Snapshot) {
        let now = Instant::now();
        let Ok(mut last) = self.last.lock() else {
            return;
        };
        if last.is_some_and(|t| now.duration_since(t) < FRAME_INTERVAL) {
            return;
        }
        *last = Some(now);
        drop(last);
        self.publish(&make());
    }

    /// Publishes a snapshot now.
    pub fn publish(&self, snapshot: &Snapshot) {
        if let Ok(json) = serde_json::to_string(snapshot) {
            self.feed.send_replace(Arc::from(json));
        }
        if let Ok(mut shown) = self.shown.lock() {
            *shown = Some(snapshot.clone());
        }
    }

    /// The session has ended: the last snapshot again, marked
    /// disconnected, served for `linger` more.
    pub fn end(&self, linger: Duration) {
        let last = self.shown.lock().ok().and_then(|s| s.clone());
        if let Some(mut last) = last {
            last.link.connected = false;
            self.publish(&last);
        }
        std::thread::sleep(linger);
    }
}

impl Drop for View {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}

/// `GET /`: the page.
async fn page() -> impl IntoResponse {
    (
        [
            (header::CONTENT_SECURITY_POLICY, POLICY),
            (header::CACHE_CONTROL, "no-store"),
        ],
        Html(PAGE),
    )
}

/// `GET /events`: the newest snapshot, then each new one.
async fn events(
    rx: latest::Receiver<Arc<str>>,
) -> Sse<impl futures_util::Stream<Item = Result<Event, Infallible>>> {
    let stream = futures_util::stream::unfold((rx, true), |(mut rx, first)| async move {
        if !first && rx.changed().await.is_err() {
            return None;
        }
        let data = rx.borrow_and_update().clone();
        Some((Ok(Event::default().data(&*data)), (rx, false)))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};

    fn get(addr: SocketAddr, request: &str, wanted: usize) -> String {
        let mut s = std::net::TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        s.write_all(request.as_bytes()).unwrap();
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        while got.len() < wanted {
            match s.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => got.extend_from_slice(&buf[..n]),
            }
        }
        String::from_utf8_lossy(&got).into_owned()
    }

    fn snapshot(t: f64) -> Snapshot {
        Snapshot {
            title: "t".into(),
            t_s: t,
            bones: vec![[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]],
            sides: vec![0],
            goals: Vec::new(),
            servos: Vec::new(),
            link: scene::LinkView::default(),
        }
    }

    #[test]
    fn serves_the_page_and_the_newest_snapshot_and_takes_nothing() {
        let view = View::start("127.0.0.1:0".parse().unwrap()).unwrap();
        let addr = view.addr;
        let page = get(
            addr,
            "GET / HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
            1 << 20,
        );
        assert!(page.starts_with("HTTP/1.1 200"), "{page}");
        assert!(page.contains("content-security-policy: default-src 'none'"));
        // Nothing outside the page itself: no http(s) URL in it.
        assert!(!PAGE.contains("http://") && !PAGE.contains("https://"));
        view.publish(&snapshot(1.5));
        let ev = get(addr, "GET /events HTTP/1.1\r\nHost: x\r\n\r\n", 300);
        assert!(ev.contains("text/event-stream"), "{ev}");
        assert!(ev.contains("\"t_s\":1.5"), "{ev}");
        // Read-only: no route takes data.
        let post = get(
            addr,
            "POST /events HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\nConnection: close\r\n\r\n{}",
            12,
        );
        assert!(post.starts_with("HTTP/1.1 405"), "{post}");
        let other = get(
            addr,
            "GET /arm HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
            12,
        );
        assert!(other.starts_with("HTTP/1.1 404"), "{other}");
    }

    #[test]
    fn offers_closer_than_the_interval_are_not_built() {
        let view = View::start("127.0.0.1:0".parse().unwrap()).unwrap();
        let built = std::cell::Cell::new(0);
        for _ in 0..100 {
            view.offer(|| {
                built.set(built.get() + 1);
                snapshot(0.0)
            });
        }
        // 100 offers in far less than 100 intervals.
        assert!(built.get() >= 1 && built.get() < 50, "{}", built.get());
    }
}
