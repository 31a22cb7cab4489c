//! The view in a real browser (headless Chromium through chromedriver): the live page draws the VE's
//! state as a QUIC client sees it in its snapshots, a mouse drag moves the linkage, a wrong token sees
//! nothing but a refusal, an observer watches, a recorded session replays at the slider's time, and the
//! panel shows the status bar's frame rate and its whole user table; a server of two rooms lists both and
//! shows each.
//! Screenshots go to `target/tmp/view/`.

mod support;
mod view_support;

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use fantoccini::actions::{InputSource, MouseActions, PointerAction, MOUSE_BUTTON_LEFT};
use fantoccini::Locator;
use kinloop_linkage::model::builtin;
use kinloop_server::view::replay::Replay;
use kinloop_server::view::{self, ViewConfig};
use kinloop_server::{Access, Server, ServerConfig, ServerHandle};
use view_support::{exclusive, num, Browser, Pusher};

const TOKENS: &str = "hands-token manipulator\nwatch-token observer\n";

/// Where the screenshots go.
fn output_dir() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("view")
}

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

fn start_server(record: Option<&Path>) -> ServerHandle {
    let scene = builtin::scene("paper-testbed").unwrap().unwrap();
    let mut config = ServerConfig::new(scene, "paper-testbed", loopback());
    config.access = Access::parse(TOKENS, "test tokens").unwrap();
    config.realtime = false;
    config.record = record.map(Path::to_path_buf);
    config.view = Some(ViewConfig::new(loopback()));
    Server::start(config).unwrap()
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn op(status: &serde_json::Value) -> [f64; 2] {
    let x = num(status, &["ops", "link2", "0"]).expect("link2 drawn");
    [x, num(status, &["ops", "link2", "1"]).expect("link2 drawn")]
}

async fn bounded<T>(test: impl std::future::Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(60), test).await.expect("the test took longer than 60 s")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_draws_the_ve_live_and_a_mouse_drag_moves_the_linkage() {
    let _one = exclusive().await;
    bounded(async {
        let server = start_server(None);
        let pusher = Pusher::start(&server, "hands-token", support::device(3)).await;
        let browser = Browser::start().await;
        let page = format!("http://{}/#token=hands-token", server.view_addr().unwrap());
        browser.client.goto(&page).await.unwrap();
        let first =
            browser.wait_for("ten frames", Duration::from_secs(15), |s| s["frames"].as_u64().unwrap_or(0) >= 10).await;
        assert_eq!(first["role"], "manipulator");
        assert_eq!(first["scene"], "paper-testbed");
        assert!(first["first_frame_ms"].as_f64().is_some(), "{first}");

        // The drawn OP is the VE's at the frame's step, as the QUIC client's snapshots report it.
        let mut drawn = Vec::new();
        for _ in 0..8 {
            tokio::time::sleep(Duration::from_millis(150)).await;
            let s = browser.status().await;
            let step = s["step"].as_u64().expect("a step");
            let (snapshot_step, ve) = pusher.op_at(step, 5).expect("a snapshot near the page's step");
            // A snapshot of the very step must agree to rounding; a neighbour's (its datagram was lost) within
            // the few steps of motion between them.
            let tolerance = if snapshot_step == step { 1e-9 } else { 1e-3 };
            let error = dist(op(&s), ve);
            assert!(error < tolerance, "step {step} (snapshot {snapshot_step}): page {:?}, VE {ve:?}", op(&s));
            drawn.push(op(&s));
        }
        let travelled = dist(drawn[0], drawn[drawn.len() - 1]);
        assert!(travelled > 1e-3, "the pushed linkage moved on the page: {travelled} m");
        let frames = browser.status().await["frames"].as_u64().unwrap();
        assert!(frames >= 20, "{frames} frames in about 1.5 s");
        browser.screenshot(&output_dir(), "live.png").await;

        // The pusher leaves; the page grabs link2 with the mouse and pulls it toward the middle of the canvas.
        pusher.leave().await;
        tokio::time::sleep(Duration::from_millis(400)).await;
        let before = browser.status().await;
        let (w, h) = (num(&before, &["size", "0"]).unwrap(), num(&before, &["size", "1"]).unwrap());
        let (px, py) =
            (num(&before, &["ops_px", "link2", "0"]).unwrap(), num(&before, &["ops_px", "link2", "1"]).unwrap());
        let (from_x, from_y) = (px - w / 2.0, py - h / 2.0);
        let towards = (-from_x, -from_y);
        let scale = 60.0 / towards.0.hypot(towards.1).max(1.0);
        let (to_x, to_y) = (from_x + towards.0 * scale, from_y + towards.1 * scale);
        let canvas = browser.client.find(Locator::Id("canvas")).await.unwrap();
        let mut mouse = MouseActions::new("mouse".into())
            .then(PointerAction::MoveToElement { element: canvas.clone(), duration: None, x: from_x, y: from_y })
            .then(PointerAction::Down { button: MOUSE_BUTTON_LEFT });
        for i in 1..=6 {
            let f = f64::from(i) / 6.0;
            mouse = mouse.then(PointerAction::MoveToElement {
                element: canvas.clone(),
                duration: Some(Duration::from_millis(60)),
                x: from_x + f * (to_x - from_x),
                y: from_y + f * (to_y - from_y),
            });
        }
        browser.client.perform_actions(mouse).await.unwrap();
        let grabbed =
            browser.wait_for("the grab admitted", Duration::from_secs(5), |s| s["grabbed"].as_u64().is_some()).await;
        let target = [num(&grabbed, &["target", "0"]).unwrap(), num(&grabbed, &["target", "1"]).unwrap()];
        tokio::time::sleep(Duration::from_millis(1500)).await;
        let held = browser.status().await;
        let users = held["users"].as_array().unwrap();
        assert!(users.iter().any(|u| u["browser"] == true && u["device"] == "mouse"), "the page is a user: {held}");
        let (start, now) = (op(&before), op(&held));
        assert!(dist(start, now) > 3e-3, "the drag moved link2: {start:?} -> {now:?} (target {target:?})");
        assert!(
            dist(now, target) < 0.5 * dist(start, target),
            "link2 went toward the drag target: {start:?} -> {now:?}, target {target:?}"
        );
        browser.screenshot(&output_dir(), "drag.png").await;
        browser.client.release_actions().await.unwrap();
        browser
            .wait_for("the grab released", Duration::from_secs(5), |s| {
                s["users"].as_array().is_some_and(|u| u.iter().all(|u| u["browser"] != true))
            })
            .await;
        let stats = server.stats().view.expect("view statistics");
        assert_eq!((stats.grabs, stats.grabs_refused, stats.unknown_ops), (1, 0, 0), "{stats:?}");
        assert!(stats.frames_sent >= frames, "{stats:?}");
        browser.close().await;
        server.shutdown().await.unwrap();
    })
    .await;
}

/// What the page shows of its panel: the frame rate in the panel and in the status bar, and whether every
/// cell of the user table lies within the panel (none cut off at its right edge, no sideways scrolling).
const PANEL_PROBE: &str = r#"
    const panel = document.getElementById("panel");
    const box = panel.getBoundingClientRect();
    const table = document.getElementById("users");
    const cells = [...table.querySelectorAll("tr > th, tr > td")].map((c) => c.getBoundingClientRect());
    const rate = document.getElementById("frame-rate");
    return {
        panel_rate: rate ? rate.textContent : null,
        status_fps: JSON.parse(document.getElementById("status").dataset.state).fps,
        rows: table.tBodies[0].rows.length,
        columns: table.tHead.rows[0].cells.length,
        panel: [box.left, box.right],
        cells: [Math.min(...cells.map((c) => c.left)), Math.max(...cells.map((c) => c.right))],
        panel_scroll: [panel.scrollWidth, panel.clientWidth],
        table_right: table.getBoundingClientRect().right,
    };
"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_panel_shows_the_status_bars_frame_rate_and_its_whole_user_table() {
    let _one = exclusive().await;
    bounded(async {
        let server = start_server(None);
        let pusher = Pusher::start(&server, "hands-token", support::device(3)).await;
        let browser = Browser::start().await;
        let page = format!("http://{}/#token=watch-token", server.view_addr().unwrap());
        browser.client.goto(&page).await.unwrap();
        browser.wait_for("ten frames", Duration::from_secs(15), |s| s["frames"].as_u64().unwrap_or(0) >= 10).await;
        // A wide window and one narrow enough that the stage and the panel compete for its width.
        for (width, height) in [(1280, 800), (640, 600)] {
            browser.client.set_window_size(width, height).await.unwrap();
            tokio::time::sleep(Duration::from_millis(1200)).await;
            let probe = browser.client.execute(PANEL_PROBE, vec![]).await.unwrap();
            let fps = probe["status_fps"].as_f64().unwrap_or_else(|| panic!("a rate in the status bar: {probe}"));
            // The view serves 60 frames/s; over loopback the page sees at least a few dozen.
            assert!(fps > 20.0, "{width} px: {probe}");
            assert_eq!(probe["panel_rate"], format!("{fps:.1}"), "{width} px: one rate on the page: {probe}");
            assert!(probe["rows"].as_u64() >= Some(1), "{width} px: the pusher in the table: {probe}");
            assert_eq!(probe["columns"], 7, "{probe}");
            let (left, right) = (num(&probe, &["panel", "0"]).unwrap(), num(&probe, &["panel", "1"]).unwrap());
            let (first, last) = (num(&probe, &["cells", "0"]).unwrap(), num(&probe, &["cells", "1"]).unwrap());
            assert!(first >= left && last <= right + 0.5, "{width} px: a cell outside the panel: {probe}");
            let (scroll, client) =
                (num(&probe, &["panel_scroll", "0"]).unwrap(), num(&probe, &["panel_scroll", "1"]).unwrap());
            assert!(scroll <= client, "{width} px: the panel scrolls sideways: {probe}");
            browser.screenshot(&output_dir(), &format!("panel-{width}.png")).await;
        }
        pusher.leave().await;
        browser.close().await;
        server.shutdown().await.unwrap();
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_token_sees_only_a_refusal_and_an_observer_only_watches() {
    let _one = exclusive().await;
    bounded(async {
        let server = start_server(None);
        let browser = Browser::start().await;
        let addr = server.view_addr().unwrap();
        browser.client.goto(&format!("http://{addr}/")).await.unwrap();
        let token = browser.client.wait().for_element(Locator::Id("token")).await.unwrap();
        token.send_keys("not-a-token").await.unwrap();
        browser.client.find(Locator::Css("#auth button")).await.unwrap().click().await.unwrap();
        let refused = browser.wait_for("the refusal", Duration::from_secs(5), |s| s["refused"].is_string()).await;
        assert!(refused["refused"].as_str().unwrap().contains("unknown token"), "{refused}");
        assert_eq!(refused["frames"], 0, "a refused page gets no frame");
        assert!(refused["scene"].is_null(), "nor the scene: {refused}");
        let shown = browser.client.find(Locator::Id("refused")).await.unwrap().text().await.unwrap();
        assert!(shown.starts_with("Refused:"), "{shown}");
        browser.screenshot(&output_dir(), "refused.png").await;

        browser.client.goto(&format!("http://{addr}/?again#token=watch-token")).await.unwrap();
        let watching = browser
            .wait_for("an observer's frames", Duration::from_secs(10), |s| s["frames"].as_u64().unwrap_or(0) >= 5)
            .await;
        assert_eq!((watching["role"].as_str(), watching["can_grab"].as_bool()), (Some("observer"), Some(false)));
        let stats = server.stats().view.unwrap();
        assert_eq!(stats.pages_refused, 1, "{stats:?}");
        browser.close().await;
        server.shutdown().await.unwrap();
    })
    .await;
}

/// The rows of a server recording, read straight from the CSV: time and the first user's OP position
/// (`None` in rows without users).
fn recorded_ops(csv: &str) -> Vec<(f64, Option<[f64; 2]>)> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let x = header.iter().position(|c| *c == "op_x").unwrap();
    lines
        .map(|line| {
            let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            (v[0], v.get(x).map(|_| [v[x], v[x + 1]]))
        })
        .collect()
}

/// The row shown at `t`: the last at or before it.
fn recorded_op_at(rows: &[(f64, Option<[f64; 2]>)], t: f64) -> Option<[f64; 2]> {
    rows.iter().take_while(|(at, _)| *at <= t).last().and_then(|(_, op)| *op)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recorded_session_replays_at_the_sliders_time() {
    let _one = exclusive().await;
    bounded(async {
        let dir = tempfile::tempdir().unwrap();
        let csv_path = dir.path().join("ve.csv");
        let server = start_server(Some(&csv_path));
        let pusher = Pusher::start(&server, "hands-token", support::device(3)).await;
        tokio::time::sleep(Duration::from_millis(1500)).await;
        pusher.leave().await;
        server.shutdown().await.unwrap();
        let csv = std::fs::read_to_string(&csv_path).unwrap();

        let scene = builtin::scene("paper-testbed").unwrap().unwrap();
        let replay = Replay::load(&csv_path, &scene, "paper-testbed").expect("the recording loads");
        let info = replay.info().clone();
        assert_eq!(info.source, "server");
        let handle = view::start_replay(&ViewConfig::new(loopback()), Access::open(), replay).unwrap();
        let browser = Browser::start().await;
        browser.client.goto(&format!("http://{}/", handle.local_addr())).await.unwrap();
        browser.wait_for("the first row", Duration::from_secs(10), |s| s["frames"].as_u64() >= Some(1)).await;

        // Click the slider in the middle of the time the pusher was in the VE: the page shows that row.
        let rows = recorded_ops(&csv);
        let with_user: Vec<f64> = rows.iter().filter(|(_, op)| op.is_some()).map(|(t, _)| *t).collect();
        let middle = 0.5 * (with_user[0] + with_user[with_user.len() - 1]);
        let fraction = (middle - info.t0) / (info.t1 - info.t0);
        let slider = browser.client.find(Locator::Id("slider")).await.unwrap();
        let (_, _, width, _) = slider.rectangle().await.unwrap();
        let click = MouseActions::new("mouse".into())
            .then(PointerAction::MoveToElement { element: slider, duration: None, x: (fraction - 0.5) * width, y: 0.0 })
            .then(PointerAction::Down { button: MOUSE_BUTTON_LEFT })
            .then(PointerAction::Up { button: MOUSE_BUTTON_LEFT });
        browser.client.perform_actions(click).await.unwrap();
        let shown = browser
            .wait_for("the row at the slider's time", Duration::from_secs(5), |s| {
                let (t, asked) = (s["t"].as_f64(), s["replay_t"].as_f64());
                matches!((t, asked), (Some(t), Some(a)) if (a - middle).abs() < 0.1 * (info.t1 - info.t0) && t <= a && a - t < 0.01)
            })
            .await;
        let asked = shown["replay_t"].as_f64().unwrap();
        let recorded = recorded_op_at(&rows, asked).expect("the pusher's row at the slider's time");
        let page_user = [num(&shown, &["users", "0", "pos", "0"]).unwrap(), num(&shown, &["users", "0", "pos", "1"]).unwrap()];
        assert!(dist(page_user, recorded) < 1e-9, "at {asked} s: page {page_user:?}, recording {recorded:?}");
        // The linkage is drawn from the recorded q: its OP is where the recorded coupling saw it, a step earlier.
        assert!(dist(op(&shown), recorded) < 1e-3, "at {asked} s: drawn {:?}, recorded {recorded:?}", op(&shown));
        browser.screenshot(&output_dir(), "replay.png").await;

        // Play runs the clock forward.
        browser.client.find(Locator::Id("play")).await.unwrap().click().await.unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
        let later = browser.status().await;
        assert!(later["replay_t"].as_f64().unwrap() > asked, "playing moves the time: {later}");
        browser.close().await;
        handle.shutdown().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_spatial_scene_is_drawn_in_perspective_and_the_camera_orbits() {
    let _one = exclusive().await;
    bounded(async {
        let scene = builtin::scene("spherical-four-bar").unwrap().unwrap();
        let mut config = ServerConfig::new(scene, "spherical-four-bar", loopback());
        config.realtime = false;
        config.view = Some(ViewConfig::new(loopback()));
        let server = Server::start(config).unwrap();
        let browser = Browser::start().await;
        browser.client.goto(&format!("http://{}/", server.view_addr().unwrap())).await.unwrap();
        let before = browser
            .wait_for("frames of the spatial scene", Duration::from_secs(10), |s| s["frames"].as_u64() >= Some(5))
            .await;
        assert_eq!((before["role"].as_str(), before["can_grab"].as_bool()), (Some("observer"), Some(false)));
        assert_eq!(before["ops"]["coupler"].as_array().map(Vec::len), Some(3), "a 3-D point: {before}");
        let (w, h) = (num(&before, &["size", "0"]).unwrap(), num(&before, &["size", "1"]).unwrap());
        let (px, py) =
            (num(&before, &["ops_px", "coupler", "0"]).unwrap(), num(&before, &["ops_px", "coupler", "1"]).unwrap());
        assert!((0.0..w).contains(&px) && (0.0..h).contains(&py), "the OP is on the canvas: {px}, {py} in {w}x{h}");

        // Dragging on empty canvas orbits the camera (the OP is far from the drag's start).
        let canvas = browser.client.find(Locator::Id("canvas")).await.unwrap();
        let (x0, y0) = (if px > w / 2.0 { -w / 3.0 } else { w / 3.0 }, h / 3.0);
        let orbit = MouseActions::new("mouse".into())
            .then(PointerAction::MoveToElement { element: canvas.clone(), duration: None, x: x0, y: y0 })
            .then(PointerAction::Down { button: MOUSE_BUTTON_LEFT })
            .then(PointerAction::MoveToElement {
                element: canvas,
                duration: Some(Duration::from_millis(200)),
                x: x0 + 120.0,
                y: y0 - 40.0,
            })
            .then(PointerAction::Up { button: MOUSE_BUTTON_LEFT });
        browser.client.perform_actions(orbit).await.unwrap();
        let after = browser.status().await;
        let (yaw0, yaw1) = (num(&before, &["camera", "0"]).unwrap(), num(&after, &["camera", "0"]).unwrap());
        assert!((yaw1 - (yaw0 - 1.2)).abs() < 1e-6, "120 px to the right turn the camera by 1.2 rad: {yaw0} -> {yaw1}");
        browser.screenshot(&output_dir(), "spatial.png").await;
        assert_eq!(server.stats().view.unwrap().grabs, 0);
        browser.close().await;
        server.shutdown().await.unwrap();
    })
    .await;
}

/// A server of two rooms serves both on one view address: the page lists the rooms its token may watch
/// (none for no token), and the second room's link opens its page, which draws that room's linkage live.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_two_room_server_lists_both_rooms_and_shows_the_second_rooms_frames() {
    use kinloop_server::driver::rooms::{RoomSpec, TestKnobs};
    let _one = exclusive().await;
    bounded(async {
        let room = |name: &str, scene: &str| RoomSpec {
            name: name.into(),
            scene: builtin::scene(scene).unwrap().unwrap(),
            scene_label: scene.into(),
            access: Access::parse(TOKENS, "test tokens").unwrap(),
            max_users: 4,
            record: None,
            knobs: TestKnobs::default(),
        };
        let scene = builtin::scene("paper-testbed").unwrap().unwrap();
        let mut config = ServerConfig::new(scene, "paper-testbed", loopback());
        config.realtime = false;
        config.rt_threads = 1;
        config.rooms = vec![room("bench-a", "paper-testbed"), room("bench-b", "fourbar-crank-rocker")];
        config.view = Some(ViewConfig::new(loopback()));
        let server = Server::start(config).unwrap();
        let addr = server.view_addr().unwrap();
        let browser = Browser::start().await;
        browser.client.goto(&format!("http://{addr}/#token=watch-token")).await.unwrap();
        let front = browser
            .wait_for("the room list", Duration::from_secs(10), |s| s["rooms"].as_array().map(Vec::len) == Some(2))
            .await;
        assert_eq!(front["rooms"], serde_json::json!(["bench-a", "bench-b"]));
        assert_eq!(front["scene"], "paper-testbed", "`/` shows the first room");

        browser.client.find(Locator::Css("#rooms a:nth-child(2)")).await.unwrap().click().await.unwrap();
        let second = browser
            .wait_for("the second room's frames", Duration::from_secs(10), |s| {
                s["room"] == "bench-b" && s["frames"].as_u64() >= Some(5)
            })
            .await;
        assert_eq!(second["scene"], "fourbar-crank-rocker");
        assert!(second["ops"]["coupler"].is_array() && second["ops"]["link2"].is_null(), "its linkage: {second}");
        let pages = |name: &str| {
            let report = server.room_stats().into_iter().find(|r| r.name == name).unwrap();
            report.stats.view.unwrap().pages_total
        };
        assert_eq!((pages("bench-a"), pages("bench-b")), (1, 1), "one page each");
        browser.screenshot(&output_dir(), "second-room.png").await;

        // A page without a token is told of no room that needs one.
        let listed = http_get(addr, "/rooms").await;
        assert!(listed.ends_with(r#"{"rooms":[]}"#), "{listed}");
        browser.close().await;
        server.shutdown_rooms().await.unwrap();
    })
    .await;
}

/// A plain HTTP/1.1 GET: the whole answer, headers and body.
async fn http_get(addr: SocketAddr, path: &str) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let request = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).await.unwrap();
    answer
}
