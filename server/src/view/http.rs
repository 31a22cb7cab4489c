//! HTTP: the page and its two assets (embedded in the binary: the view works offline), the room list and
//! the WebSocket upgrade of each room (see [`super::site`] for the paths), with axum on the caller's tokio
//! runtime.

use std::net::SocketAddr;
use std::sync::Arc;

use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use tokio::task::JoinHandle;

use super::site::Site;
use super::{socket, ViewError, TRANSPORT_MAX_BYTES};

const INDEX_HTML: &str = include_str!("../../assets/view/index.html");
const VIEW_JS: &str = include_str!("../../assets/view/view.js");
const VIEW_CSS: &str = include_str!("../../assets/view/view.css");

/// Binds `listen` and serves the site's rooms until shutdown; returns the bound address.
pub(crate) fn serve(listen: SocketAddr, site: Arc<Site>) -> Result<(SocketAddr, JoinHandle<()>), ViewError> {
    let bind = |source| ViewError::Bind { addr: listen, source };
    let listener = std::net::TcpListener::bind(listen).map_err(bind)?;
    listener.set_nonblocking(true).map_err(bind)?;
    let listener = tokio::net::TcpListener::from_std(listener).map_err(bind)?;
    let addr = listener.local_addr().map_err(bind)?;
    let mut shutdown = site.shutdown.subscribe();
    let app = Router::new()
        .route("/", get(|| async { asset("text/html; charset=utf-8", INDEX_HTML) }))
        .route("/room/{name}", get(room_page))
        .route("/view.js", get(|| async { asset("text/javascript; charset=utf-8", VIEW_JS) }))
        .route("/view.css", get(|| async { asset("text/css; charset=utf-8", VIEW_CSS) }))
        .route("/rooms", get(room_list))
        .route("/ws", get(|ws, headers, State(site)| upgrade(ws, headers, site, None)))
        .route(
            "/room/{name}/ws",
            get(|ws, headers, State(site), Path(name): Path<String>| upgrade(ws, headers, site, Some(name))),
        )
        .with_state(site);
    let task = tokio::spawn(async move {
        let stop = async move {
            let _ = shutdown.wait_for(|stop| *stop).await;
        };
        if let Err(error) = axum::serve(listener, app).with_graceful_shutdown(stop).await {
            tracing::error!(%error, "view: the HTTP server stopped");
        }
    });
    Ok((addr, task))
}

fn asset(content_type: &'static str, body: &'static str) -> Response {
    ([(header::CONTENT_TYPE, content_type), (header::CACHE_CONTROL, "no-cache")], body).into_response()
}

/// A browser sends the page's origin with the upgrade; one that is not this server's is another site
/// trying to use the visitor's browser (and, without tokens, its access), and is refused.
fn same_origin(headers: &HeaderMap) -> bool {
    let Some(origin) = headers.get(header::ORIGIN) else { return true };
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok()).unwrap_or("");
    let origin = origin.to_str().unwrap_or("");
    let origin_host = origin.strip_prefix("http://").or_else(|| origin.strip_prefix("https://")).unwrap_or("");
    !host.is_empty() && origin_host == host
}

fn no_room(name: &str) -> Response {
    (StatusCode::NOT_FOUND, format!("no room {name:?} on this server")).into_response()
}

/// A room's page (the same page as `/`; it opens its room's socket).
async fn room_page(State(site): State<Arc<Site>>, Path(name): Path<String>) -> Response {
    match site.room(Some(&name)) {
        Some(_) => asset("text/html; charset=utf-8", INDEX_HTML),
        None => no_room(&name),
    }
}

/// The rooms the page's token (`Authorization: Bearer TOKEN`; none: no token) may watch, as JSON.
async fn room_list(headers: HeaderMap, State(site): State<Arc<Site>>) -> Response {
    let auth = headers.get(header::AUTHORIZATION).and_then(|h| h.to_str().ok()).unwrap_or("");
    let token = auth.strip_prefix("Bearer ").unwrap_or("");
    let body = serde_json::json!({ "rooms": site.links(token) }).to_string();
    ([(header::CONTENT_TYPE, "application/json"), (header::CACHE_CONTROL, "no-cache")], body).into_response()
}

/// A page's socket to room `name` (none: the front room).
async fn upgrade(ws: WebSocketUpgrade, headers: HeaderMap, site: Arc<Site>, name: Option<String>) -> Response {
    let Some(view) = site.room(name.as_deref()) else {
        return no_room(name.as_deref().unwrap_or(""));
    };
    if !same_origin(&headers) {
        view.counters.bump(super::Counter::PagesRefused);
        return (StatusCode::FORBIDDEN, "the view only talks to its own page").into_response();
    }
    ws.max_message_size(TRANSPORT_MAX_BYTES)
        .max_frame_size(TRANSPORT_MAX_BYTES)
        .on_upgrade(move |socket| socket::serve(socket, view))
}

#[cfg(test)]
mod tests {
    use axum::http::HeaderValue;

    use super::*;

    #[test]
    fn only_the_pages_own_origin_may_open_a_socket() {
        let mut h = HeaderMap::new();
        assert!(same_origin(&h), "no Origin: not a browser on another site");
        h.insert(header::HOST, HeaderValue::from_static("127.0.0.1:8080"));
        h.insert(header::ORIGIN, HeaderValue::from_static("http://127.0.0.1:8080"));
        assert!(same_origin(&h));
        h.insert(header::ORIGIN, HeaderValue::from_static("http://evil.example"));
        assert!(!same_origin(&h));
        h.insert(header::ORIGIN, HeaderValue::from_static("null"));
        assert!(!same_origin(&h));
    }
}
