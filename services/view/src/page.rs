//! The web page: one self-contained HTML file (no script or style fetched from anywhere)
//! served over HTTP by `tiny_http`; the page itself speaks the Foxglove WebSocket protocol to
//! the view's server, like any other client. Read-only: it only subscribes.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU16, Ordering};
use std::thread::JoinHandle;

use tiny_http::{Header, Method, Response, Server};

/// The page, with `__HVS_WS_PORT__` where the WebSocket port goes.
pub const PAGE_HTML: &str = include_str!("page.html");

/// The channels the page subscribes to (its script lists them; a test keeps the two equal).
pub const PAGE_TOPICS: [&str; 8] = [
    crate::channels::LEFT_IMAGE,
    crate::channels::DISPARITY_IMAGE,
    crate::channels::FUSED_IMAGE,
    crate::channels::RANGES,
    crate::channels::DECISIONS,
    crate::channels::ACTUATOR,
    crate::channels::STAGES,
    crate::channels::LEGEND,
];

/// The page as served when the WebSocket server listens on `ws_port` (0: not listening).
pub fn page(ws_port: u16) -> String {
    PAGE_HTML.replace("__HVS_WS_PORT__", &ws_port.to_string())
}

/// The HTTP server could not start.
#[derive(Debug, thiserror::Error)]
#[error("cannot serve the web page on {addr}: {detail}")]
pub struct PageError {
    /// The address.
    pub addr: SocketAddr,
    /// The reason (tiny_http gives a boxed error).
    pub detail: String,
}

/// The running page server.
pub struct PageServer {
    server: Arc<Server>,
    addr: SocketAddr,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for PageServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PageServer")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
}

impl PageServer {
    /// Binds `addr` and serves the page from a thread; `ws_port` is read per request (the
    /// WebSocket server may come up later).
    pub fn start(addr: SocketAddr, ws_port: Arc<AtomicU16>) -> Result<Self, PageError> {
        let server = Server::http(addr).map_err(|e| PageError {
            addr,
            detail: e.to_string(),
        })?;
        let bound = server.server_addr().to_ip().unwrap_or(addr);
        let server = Arc::new(server);
        let s = Arc::clone(&server);
        let thread = std::thread::Builder::new()
            .name("view-http".into())
            .spawn(move || serve(&s, &ws_port))
            .map_err(|e| PageError {
                addr,
                detail: e.to_string(),
            })?;
        Ok(Self {
            server,
            addr: bound,
            thread: Some(thread),
        })
    }

    /// The bound address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Drop for PageServer {
    fn drop(&mut self) {
        self.server.unblock();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn header(name: &str, value: &str) -> Option<Header> {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).ok()
}

fn serve(server: &Server, ws_port: &AtomicU16) {
    for request in server.incoming_requests() {
        let path = request.url().split('?').next().unwrap_or("");
        let response = match (request.method(), path) {
            (Method::Get | Method::Head, "/" | "/index.html") => {
                let mut r = Response::from_string(page(ws_port.load(Ordering::Relaxed)));
                for h in [
                    header("Content-Type", "text/html; charset=utf-8"),
                    header("Cache-Control", "no-store"),
                ]
                .into_iter()
                .flatten()
                {
                    r.add_header(h);
                }
                r
            }
            (Method::Get | Method::Head, _) => {
                Response::from_string("not found: the page is at /\n").with_status_code(404)
            }
            _ => Response::from_string("read-only: GET / only\n").with_status_code(405),
        };
        if let Err(e) = request.respond(response) {
            tracing::debug!("web page client went away: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_is_self_contained_and_names_the_port() {
        let p = page(41234);
        assert!(p.contains("41234"));
        assert!(!p.contains("__HVS_WS_PORT__"));
        for remote in ["http://", "https://", "//cdn", "<link "] {
            assert!(!p.contains(remote), "the page fetches {remote}");
        }
        assert!(
            p.contains("foxglove.sdk.v1"),
            "speaks the Foxglove protocol"
        );
    }

    #[test]
    fn the_page_subscribes_to_page_topics() {
        let want = PAGE_HTML
            .split("const WANT = {")
            .nth(1)
            .and_then(|r| r.split("};").next())
            .unwrap_or("");
        let listed = want.matches("\": \"").count();
        assert_eq!(listed, PAGE_TOPICS.len(), "{want}");
        for t in PAGE_TOPICS {
            assert!(
                want.contains(&format!("\"{t}\"")),
                "{t} not in the page's list"
            );
        }
    }
}
