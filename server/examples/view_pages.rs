//! Opens N pages of a running view and reports what they saw, to measure the view's frame rate and first
//! frame, and what many pages cost the VE:
//!
//! ```text
//! cargo run --release -p kinloop-server --example view_pages -- http://127.0.0.1:8080/ PAGES SECONDS [raw]
//! ```
//! Pages are tabs of one headless Chromium (through chromedriver, as the tests drive it); with `raw` they are
//! plain WebSocket clients that read every frame (the server's own cost, without a browser on the same
//! cores). Prints one JSON object: per page frames/s over the run, first-frame times (ms after navigation).

#[path = "../tests/view_support/mod.rs"]
mod view_support;

use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: view_pages URL PAGES SECONDS [raw]";
    let url = args.get(1).expect(usage).clone();
    let pages: usize = args.get(2).and_then(|a| a.parse().ok()).expect(usage);
    let seconds: f64 = args.get(3).and_then(|a| a.parse().ok()).expect(usage);
    let raw = args.get(4).is_some_and(|a| a == "raw");
    let report = if raw { raw_pages(&url, pages, seconds).await } else { browser_pages(&url, pages, seconds).await };
    println!("{}", serde_json::to_string_pretty(&report).unwrap());
}

async fn browser_pages(url: &str, pages: usize, seconds: f64) -> serde_json::Value {
    let browser = view_support::Browser::start().await;
    let c = &browser.client;
    let mut handles = Vec::new();
    for i in 0..pages {
        if i > 0 {
            let window = c.new_window(true).await.unwrap();
            c.switch_to_window(window.handle).await.unwrap();
        }
        c.goto(url).await.unwrap();
        handles.push(c.window().await.unwrap());
    }
    let mut first = Vec::new();
    let mut start = Vec::new();
    for h in &handles {
        c.switch_to_window(h.clone()).await.unwrap();
        let s = browser.wait_for("a frame", Duration::from_secs(20), |s| s["frames"].as_u64() >= Some(1)).await;
        first.push(s["first_frame_ms"].as_f64().unwrap_or(f64::NAN));
        start.push((Instant::now(), s["frames"].as_u64().unwrap_or(0)));
    }
    tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
    let mut rates = Vec::new();
    for (h, (at, frames)) in handles.iter().zip(start) {
        c.switch_to_window(h.clone()).await.unwrap();
        let s = browser.status().await;
        let now = s["frames"].as_u64().unwrap_or(0);
        rates.push((now - frames) as f64 / at.elapsed().as_secs_f64());
    }
    browser.close().await;
    json!({ "pages": pages, "kind": "headless chromium tabs", "frames_per_s": rates, "first_frame_ms": first })
}

async fn raw_pages(url: &str, pages: usize, seconds: f64) -> serde_json::Value {
    let ws = url.replace("http://", "ws://").trim_end_matches('/').to_string() + "/ws";
    let mut tasks = Vec::new();
    for _ in 0..pages {
        let ws = ws.clone();
        tasks.push(tokio::spawn(async move {
            let (mut socket, _) = tokio_tungstenite::connect_async(ws).await.expect("the view's socket");
            socket.send(Message::text(r#"{"type":"auth"}"#)).await.unwrap();
            let until = Instant::now() + Duration::from_secs_f64(seconds);
            let mut frames = 0u64;
            while let Ok(Some(Ok(m))) = tokio::time::timeout_at(until.into(), socket.next()).await {
                if let Message::Text(t) = m {
                    frames += u64::from(t.starts_with(r#"{"type":"frame""#));
                }
            }
            frames as f64 / seconds
        }));
    }
    let mut rates = Vec::new();
    for t in tasks {
        rates.push(t.await.unwrap());
    }
    json!({ "pages": pages, "kind": "raw websocket clients", "frames_per_s": rates })
}
