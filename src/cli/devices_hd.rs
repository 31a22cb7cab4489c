//! The OpenHaptics part of `kinloop devices`: whether `libHD` was found (where kinloop looked and which
//! variable to set when not), and the device `hdInitDevice` opens by default, described by the figures it
//! reports (`hdGetDoublev`) and its calibration state, with force output never enabled. The search, the
//! calls and the units are `kinloop_client::device::hd`'s; this file only reports them.

use kinloop_client::device::hd::library::{candidates, LIBRARY_VARIABLE, SDK_VARIABLE};
use kinloop_client::device::hd::{HdLibrary, OpenedHd};
use kinloop_client::device::HdRequest;
use serde_json::{json, Value};

/// The HD library and its default device as JSON (`"usable"`: a device was described).
pub fn survey() -> Value {
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
            // Dropping `opened` disables the device (force output was never enabled).
            json!({ "library": path, "usable": true, "error": Value::Null, "device": device })
        }
        Err(e) => json!({ "library": path, "usable": false, "error": e.to_string() }),
    }
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
}
