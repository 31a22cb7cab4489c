//! The OpenHaptics part of `kinloop devices`: whether `libHD` was found (where kinloop looked and which
//! variable to set when not), and the device `hdInitDevice` opens by default, described by the figures it
//! reports (`hdGetDoublev`) and its calibration state, with force output never enabled. With `--check`, the
//! vendor's servo thread calls a reading callback for a second (`driver::device_clock::check`), and
//! kinloop's own loop then runs empty for as long on the same machine (`driver::rt_loop::timer_floor`): the
//! two loops' lateness side by side. The search, the calls and the units are `kinloop_client::device::hd`'s;
//! this file only reports them.

use std::time::Duration;

use kinloop_client::device::hd::library::{candidates, LIBRARY_VARIABLE, SDK_VARIABLE};
use kinloop_client::device::hd::{HdLibrary, OpenedHd};
use kinloop_client::device::HdRequest;
use kinloop_client::driver::device_clock;
use kinloop_client::driver::rt_loop::timer_floor;
use serde_json::{json, Value};

/// The haptic loop's rate, at which `--check` reads both kinds of device (Hz).
pub(super) const CHECK_RATE_HZ: f64 = 1000.0;
/// How long `--check` reads.
pub(super) const CHECK_DURATION: Duration = Duration::from_secs(1);

/// The HD library and its default device as JSON (`"usable"`: a device was described); with `check`, the
/// two loops' lateness (see the module documentation).
pub fn survey(check: bool) -> Value {
    let library = match HdLibrary::find() {
        Ok(library) => library,
        Err(e) => {
            let looked: Vec<String> = candidates().iter().map(|p| p.display().to_string()).collect();
            return json!({
                "library": Value::Null, "usable": false, "error": e.to_string(), "looked": looked,
                "variables": [LIBRARY_VARIABLE, SDK_VARIABLE],
            });
        }
    };
    let path = library.path().display().to_string();
    let request = HdRequest { name: None, fallback: None, calibrate: false };
    match OpenedHd::describe(library, &request) {
        Ok((opened, calibrated)) => {
            let s = opened.spec();
            let workspace_mm = [0, 1, 2].map(|i| 1e3 * (s.workspace_max[i] - s.workspace_min[i]));
            let device = json!({
                "name": opened.name(),
                "model": s.model,
                "workspace_mm": workspace_mm,
                "peak_force_n": s.max_force_n,
                "continuous_force_n": s.continuous_force_n,
                "stiffness_n_per_m": s.max_stiffness,
                "damping_n_s_per_m": s.max_damping,
                "calibrated": calibrated,
            });
            let check = check.then(|| loops_lateness(&opened));
            // Dropping `opened` disables the device (force output was never enabled).
            json!({ "library": path, "usable": true, "error": Value::Null, "device": device, "check": check })
        }
        Err(e) => json!({ "library": path, "usable": false, "error": e.to_string() }),
    }
}

/// The servo thread's lateness reading `opened` for [`CHECK_DURATION`], then kinloop's own loop's, empty, for
/// as long (SCHED_FIFO when granted, as a session's).
fn loops_lateness(opened: &OpenedHd) -> Value {
    let servo = device_clock::check(opened, CHECK_RATE_HZ, CHECK_DURATION);
    let (own, fifo) = timer_floor(CHECK_RATE_HZ, CHECK_DURATION, true);
    json!({
        "servo": {
            "reads": servo.reads, "failed_reads": servo.failed_reads, "ticks": servo.lateness.ticks,
            "lateness_us_p50": servo.lateness.p50_us, "lateness_us_p99": servo.lateness.p99_us,
            "lateness_us_max": servo.lateness.max_us,
        },
        "kinloop_loop": {
            "ticks": own.ticks, "realtime_priority": fifo, "lateness_us_p50": own.p50_us,
            "lateness_us_p99": own.p99_us, "lateness_us_max": own.max_us,
        },
    })
}

/// The survey as text.
pub fn print_text(hd: &Value) {
    let Some(path) = hd["library"].as_str() else {
        println!("HD library (OpenHaptics): not found: {}", hd["error"].as_str().unwrap_or("?"));
        return;
    };
    println!("HD library (OpenHaptics): {path}");
    let d = &hd["device"];
    if d.is_null() {
        println!("  default device: cannot be used: {}", hd["error"].as_str().unwrap_or("?"));
        return;
    }
    let ws: Vec<String> = d["workspace_mm"].as_array().into_iter().flatten().map(|v| format!("{v:.1}")).collect();
    println!(
        "  default device {:?}: {}, workspace {} mm (right x up x towards you), peak force {} N, continuous {} N, \
         stiffness {} N/m, damping {} N s/m{}",
        d["name"].as_str().unwrap_or("?"),
        d["model"].as_str().unwrap_or("?"),
        ws.join(" x "),
        d["peak_force_n"],
        d["continuous_force_n"],
        d["stiffness_n_per_m"],
        d["damping_n_s_per_m"],
        match d["calibrated"].as_bool() {
            Some(false) => "; NEEDS calibrating: put the stylus in its inkwell, or pass --hd-calibrate to the client",
            _ => "",
        }
    );
    let c = &hd["check"];
    if !c.is_null() {
        let (servo, own) = (&c["servo"], &c["kinloop_loop"]);
        let us = |v: &Value| v.as_f64().map_or_else(|| "?".into(), |x| format!("{x:.0}"));
        println!(
            "    check (forces off, 1 s each): the servo thread's callbacks {} reads, {} failed, lateness p99 {} µs, \
             max {} µs; kinloop's own loop (empty{}) lateness p99 {} µs, max {} µs",
            servo["reads"],
            servo["failed_reads"],
            us(&servo["lateness_us_p99"]),
            us(&servo["lateness_us_max"]),
            if own["realtime_priority"].as_bool() == Some(true) { ", SCHED_FIFO" } else { ", normal priority" },
            us(&own["lateness_us_p99"]),
            us(&own["lateness_us_max"]),
        );
    }
}
