//! The view's WebSocket under bad input, without a browser: malformed, oversized and senseless messages get
//! an error back and are counted, a flood of drags is cut to the rate, a page that keeps misbehaving and a
//! message beyond the transport's limit are closed, another site's origin is refused, and through all of it
//! the VE keeps ticking and its QUIC user keeps getting snapshots.

mod support;
mod view_support;

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use kinloop_linkage::model::builtin;
use kinloop_server::view::ViewConfig;
use kinloop_server::{Server, ServerConfig, ServerHandle};
use serde_json::{json, Value};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{connect_async, MaybeTlsStream, WebSocketStream};
use view_support::Pusher;

type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

fn start_server() -> ServerHandle {
    let scene = builtin::scene("paper-testbed").unwrap().unwrap();
    let mut config = ServerConfig::new(scene, "paper-testbed", loopback());
    config.realtime = false;
    config.view = Some(ViewConfig { grab_without_token: true, ..ViewConfig::new(loopback()) });
    Server::start(config).unwrap()
}

/// The next message that is not a frame (`None` when the socket closed).
async fn reply(socket: &mut Socket) -> Option<Value> {
    let until = Instant::now() + Duration::from_secs(5);
    while Instant::now() < until {
        match tokio::time::timeout(Duration::from_secs(5), socket.next()).await.ok()?? {
            Ok(Message::Text(t)) => {
                let v: Value = serde_json::from_str(&t).expect("the server sends JSON");
                if v["type"] != "frame" {
                    return Some(v);
                }
            }
            Ok(Message::Close(_)) | Err(_) => return None,
            Ok(_) => {}
        }
    }
    panic!("no reply within 5 s")
}

async fn admitted(server: &ServerHandle) -> Socket {
    let url = format!("ws://{}/ws", server.view_addr().unwrap());
    let (mut socket, _) = connect_async(url).await.expect("the socket opens");
    let hello = reply(&mut socket).await.unwrap();
    assert_eq!((hello["type"].as_str(), hello["auth"].as_str()), (Some("hello"), Some("none")), "{hello}");
    socket.send(Message::text(json!({"type": "auth"}).to_string())).await.unwrap();
    let welcome = reply(&mut socket).await.unwrap();
    assert_eq!(welcome["type"], "welcome", "{welcome}");
    assert_eq!(welcome["can_grab"], true, "--view-grab opens grabbing without tokens");
    socket
}

async fn expect_error(socket: &mut Socket, sent: Message, containing: &str) {
    socket.send(sent).await.unwrap();
    let r = reply(socket).await.expect("an answer, the socket still open");
    assert_eq!(r["type"], "error", "{r}");
    let message = r["message"].as_str().unwrap();
    assert!(message.contains(containing), "{message:?} should say {containing:?}");
}

async fn snapshots_keep_coming(pusher: &Pusher) {
    let count = || pusher.ops_by_step.lock().unwrap().len();
    let before = count();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(count() > before + 50, "the QUIC user still gets snapshots: {before} -> {}", count());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_messages_get_errors_floods_are_cut_and_the_ve_carries_on() {
    tokio::time::timeout(Duration::from_secs(60), async {
        let server = start_server();
        let pusher = Pusher::start(&server, "any", support::device(3)).await;
        let mut page = admitted(&server).await;

        expect_error(&mut page, Message::text("not json"), "malformed message").await;
        expect_error(&mut page, Message::text(r#"{"type":"jump"}"#), "malformed message").await;
        expect_error(
            &mut page,
            Message::text(r#"{"type":"grab","op":"link9"}"#),
            "unknown operational point \"link9\"",
        )
        .await;
        expect_error(&mut page, Message::text("x".repeat(8 * 1024)), "bytes not read").await;
        expect_error(&mut page, Message::binary(vec![1u8, 2, 3]), "binary").await;
        expect_error(&mut page, Message::text(r#"{"type":"drag","target":[0.0,0.0]}"#), "without a grab").await;
        expect_error(&mut page, Message::text(r#"{"type":"seek","t":1.0}"#), "recordings").await;

        page.send(Message::text(r#"{"type":"grab","op":"link2"}"#)).await.unwrap();
        let grabbed = reply(&mut page).await.unwrap();
        assert_eq!(grabbed["type"], "grabbed", "{grabbed}");
        expect_error(&mut page, Message::text(r#"{"type":"drag","target":[1e9,0.0]}"#), "finite").await;
        expect_error(&mut page, Message::text(r#"{"type":"drag","target":[0.0,0.0,0.0]}"#), "2 numbers").await;

        // A flood: 2,000 drags as fast as the socket takes them. At most the burst and 100/s pass.
        let started = Instant::now();
        let before = server.stats().view.unwrap();
        for i in 0..2000 {
            let x = 0.03 + 1e-6 * f64::from(i);
            page.send(Message::text(json!({"type": "drag", "target": [x, 0.02]}).to_string())).await.unwrap();
        }
        let notice = reply(&mut page).await.unwrap();
        assert!(notice["message"].as_str().unwrap().contains("dropped"), "{notice}");
        tokio::time::sleep(Duration::from_millis(200)).await;
        let after = server.stats().view.unwrap();
        let used = after.events_used - before.events_used;
        let allowed = 10.0 + 100.0 * started.elapsed().as_secs_f64() + 1.0;
        assert!((used as f64) <= allowed, "{used} drags used in {:?}", started.elapsed());
        assert_eq!(used + after.events_dropped - before.events_dropped, 2000, "every drag used or counted: {after:?}");
        snapshots_keep_coming(&pusher).await;

        // Past the transport's limit the socket closes; the grab it held leaves the VE.
        page.send(Message::text("y".repeat(200 * 1024))).await.unwrap();
        // Notices of the flood (one a second) may still be on their way, and the grab's release comes last.
        while let Some(r) = reply(&mut page).await {
            let flood = r["message"].as_str().is_some_and(|m| m.contains("dropped"));
            assert!(flood || r["type"] == "released", "closed after 200 KB, not {r}");
        }
        let until = Instant::now() + Duration::from_secs(5);
        while server.stats().users != 1 {
            assert!(Instant::now() < until, "the page's grab left the VE: {} users", server.stats().users);
            tokio::time::sleep(Duration::from_millis(50)).await;
        }

        // A page that keeps sending nonsense is closed after 100 bad messages.
        let mut noisy = admitted(&server).await;
        for _ in 0..=100 {
            noisy.send(Message::text("{")).await.unwrap();
        }
        let mut closed = false;
        for _ in 0..=102 {
            if reply(&mut noisy).await.is_none() {
                closed = true;
                break;
            }
        }
        assert!(closed, "closed after more than 100 bad messages");

        // The first message must be auth; another site's page is refused before any message.
        let url = format!("ws://{}/ws", server.view_addr().unwrap());
        let (mut early, _) = connect_async(url.clone()).await.unwrap();
        let _hello = reply(&mut early).await.unwrap();
        early.send(Message::text(r#"{"type":"grab","op":"link2"}"#)).await.unwrap();
        let refused = reply(&mut early).await.unwrap();
        assert_eq!(refused["type"], "refused", "{refused}");
        let mut request = url.into_client_request().unwrap();
        request.headers_mut().insert("origin", HeaderValue::from_static("http://evil.example"));
        assert!(connect_async(request).await.is_err(), "a foreign origin gets no socket");

        snapshots_keep_coming(&pusher).await;
        let stats = server.shutdown().await.unwrap();
        let view = stats.view.expect("view statistics in the server's");
        assert_eq!(view.unknown_ops, 1, "{view:?}");
        assert!(view.messages_malformed >= 100 + 7, "{view:?}");
        assert!(view.messages_oversize >= 1, "{view:?}");
        assert_eq!((view.grabs, view.pages_refused), (1, 2), "{view:?}");
        assert_eq!(stats.ve.core.state_restores, 0, "{:?}", stats.ve.core);
        pusher.leave().await;
    })
    .await
    .expect("the test took longer than 60 s");
}
