//! `kinloop devices [--check] [--json]`: what a user with hardware needs on day one. Which vendor library was
//! found (path, SDK version) or where kinloop looked and which variable to set; each device with its model and
//! published spec; a permission problem on the USB device node named (Linux). `--check` opens each device with
//! forces off, reads its position for one second at the haptic loop's rate on the loop's own clock, and prints
//! the workspace box seen and the rate reached. The library search, the spec table and the frames are
//! `kinloop_client::device::dhd`'s; this file only reports them.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Result};
use kinloop_client::device::dhd::library::{candidates, LIBRARY_VARIABLE, SDK_VARIABLE};
use kinloop_client::device::dhd::specs::ModelSpec;
use kinloop_client::device::dhd::{frames, DhdError, DhdLibrary, OpenedDhd};
use kinloop_client::driver::rt_loop::paced;

use super::devices_hd::{CHECK_DURATION, CHECK_RATE_HZ};
use serde_json::{json, Value};

/// Arguments of `kinloop devices`.
#[derive(clap::Args, Debug)]
pub struct DevicesArgs {
    /// Open each device with forces off, read its position for one second at 1 kHz, and print the workspace
    /// seen and the rate reached; for an OpenHaptics device, its servo thread's lateness beside kinloop's own
    /// loop's.
    #[arg(long)]
    pub check: bool,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// USB vendor IDs of the devices the DHD library drives: Force Dimension's, and FTDI's with the Falcon's
/// product ID (Novint used FTDI's chip).
const USB_IDS: [(&str, Option<&str>, &str); 2] =
    [("1451", None, "Force Dimension"), ("0403", Some("cb48"), "Novint Falcon")];

/// Surveys the DHD library and its devices and prints what it found; fails when no library or no device
/// could be used, so scripts can test the exit code.
pub fn run(args: &DevicesArgs) -> Result<()> {
    let hd = super::devices_hd::survey(args.check);
    let hd_usable = hd["usable"].as_bool() == Some(true);
    let library = match DhdLibrary::find() {
        Ok(library) => Arc::new(library),
        Err(e) => return not_usable(args, &e, hd),
    };
    let count = library.device_count();
    // Without dhdGetDeviceCount (older SDKs) the first device is tried.
    let indices = 0..count.map_or(1, |c| c.clamp(0, i32::from(u8::MAX)) as u8);
    let devices: Vec<Value> = indices.map(|index| survey(&library, index, args.check)).collect();
    let usable = devices.iter().any(|d| d["error"].is_null());
    let permission = (!usable).then(usb_permission_problem).flatten();
    let report = json!({
        "library": {
            "path": library.path().display().to_string(),
            "sdk_version": library.version().to_string(),
        },
        "device_count": count,
        "devices": devices,
        "permission_problem": permission,
        "hd": hd,
    });
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_text(&report);
        super::devices_hd::print_text(&report["hd"]);
    }
    if !usable && !hd_usable {
        bail!(
            "no usable DHD device through {}{}",
            library.path().display(),
            permission.map_or(String::new(), |p| format!(": {p}"))
        );
    }
    Ok(())
}

/// The DHD library could not be used: where kinloop looked and what to set, as JSON or text, and a failure
/// unless an OpenHaptics device was found (`hd`, the HD survey).
fn not_usable(args: &DevicesArgs, error: &DhdError, hd: Value) -> Result<()> {
    let hd_usable = hd["usable"].as_bool() == Some(true);
    if !args.json {
        super::devices_hd::print_text(&hd);
    }
    if args.json {
        let looked: Vec<String> = candidates().iter().map(|p| p.display().to_string()).collect();
        let report = json!({
            "library": Value::Null,
            "error": error.to_string(),
            "looked": looked,
            "variables": [LIBRARY_VARIABLE, SDK_VARIABLE],
            "hd": hd,
        });
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    if hd_usable {
        if !args.json {
            println!("DHD library: not found: {error}");
        }
        return Ok(());
    }
    bail!("{error}")
}

/// Device `index`: its model and spec, and with `check` the positions it reads; or why it cannot be opened.
fn survey(library: &Arc<DhdLibrary>, index: u8, check: bool) -> Value {
    let opened = match OpenedDhd::open(library.clone(), index) {
        Ok(opened) => opened,
        Err(e) => return json!({ "index": index, "error": e.to_string() }),
    };
    let mut device = json!({
        "index": index,
        "error": Value::Null,
        "calibrated": opened.calibrated(),
        "model": spec_json(opened.model()),
    });
    if check {
        device["check"] = read_positions(&opened);
    }
    // Dropping `opened` zeroes the force, keeps forces disabled and closes the device (its lease).
    device
}

fn spec_json(model: &ModelSpec) -> Value {
    json!({
        "name": model.name,
        "system_type": model.system,
        "workspace_mm": model.half_extent.map(|h| 2e3 * h),
        "peak_force_n": model.max_force_n,
        "continuous_force_n": model.continuous_force_n,
        "stiffness_n_per_m": model.max_stiffness,
        "dof": model.dof,
        "gripper": model.gripper,
        "source": model.source,
    })
}

/// Reads `opened`'s position (forces off) every tick for [`CHECK_DURATION`]: the box the handle swept in
/// kinloop's frame (mm), the rate of good reads reached, and the failed reads.
fn read_positions(opened: &OpenedDhd) -> Value {
    let mut low = [f64::INFINITY; 3];
    let mut high = [f64::NEG_INFINITY; 3];
    let (mut reads, mut failures) = (0u64, 0u64);
    let mut first_failure = None;
    let started = Instant::now();
    let lateness = paced(CHECK_RATE_HZ, CHECK_DURATION, |_| match opened.position() {
        Ok(p) if p.iter().all(|x| x.is_finite()) => {
            let p = frames::to_kinloop(p);
            for ((lo, hi), x) in low.iter_mut().zip(high.iter_mut()).zip(p) {
                *lo = lo.min(x);
                *hi = hi.max(x);
            }
            reads += 1;
        }
        Ok(p) => {
            failures += 1;
            first_failure.get_or_insert_with(|| format!("non-finite position {p:?}"));
        }
        Err(e) => {
            failures += 1;
            first_failure.get_or_insert(e);
        }
    });
    let elapsed = started.elapsed().as_secs_f64();
    let seen = reads > 0;
    json!({
        "reads": reads,
        "failed_reads": failures,
        "first_failure": first_failure,
        "rate_hz": if elapsed > 0.0 { reads as f64 / elapsed } else { 0.0 },
        "lateness_us_p99": lateness.p99_us,
        "workspace_seen_mm": seen.then(|| json!({
            "min": low.map(|x| 1e3 * x),
            "max": high.map(|x| 1e3 * x),
        })),
    })
}

fn print_text(report: &Value) {
    let library = &report["library"];
    println!("DHD library: {} (SDK {})", str_of(&library["path"]), str_of(&library["sdk_version"]));
    match report["device_count"].as_i64() {
        Some(n) => println!("devices: {n} (dhdGetDeviceCount)"),
        None => println!("devices: this SDK has no dhdGetDeviceCount; trying device 0"),
    }
    for device in report["devices"].as_array().into_iter().flatten() {
        let index = &device["index"];
        if let Some(error) = device["error"].as_str() {
            println!("  device {index}: cannot be used: {error}");
            continue;
        }
        let m = &device["model"];
        let ws = m["workspace_mm"].as_array().map(|w| mm_triple(w)).unwrap_or_default();
        println!(
            "  device {index}: {} (system type {}), {} DOF{}, workspace {ws} mm (right x up x towards you), \
             peak force {} N, continuous {} N, stiffness {} N/m{}",
            str_of(&m["name"]),
            m["system_type"],
            m["dof"],
            if m["gripper"].as_bool() == Some(true) { " + gripper" } else { "" },
            m["peak_force_n"],
            m["continuous_force_n"],
            m["stiffness_n_per_m"],
            match device["calibrated"].as_bool() {
                Some(false) => "; NOT calibrated: calibrate it with the SDK's tools (drdAutoInit)",
                _ => "",
            }
        );
        println!("    source: {}", str_of(&m["source"]));
        let check = &device["check"];
        if check.is_null() {
            continue;
        }
        let seen = &check["workspace_seen_mm"];
        let range = match (seen["min"].as_array(), seen["max"].as_array()) {
            (Some(lo), Some(hi)) => format!("from {} to {} mm", mm_triple(lo), mm_triple(hi)),
            _ => "nothing (no good read)".into(),
        };
        println!(
            "    check (forces off, 1 s): {} reads at {:.1} Hz, {} failed{}; workspace seen {range}",
            check["reads"],
            check["rate_hz"].as_f64().unwrap_or(0.0),
            check["failed_reads"],
            check["first_failure"].as_str().map_or(String::new(), |f| format!(" (first: {f})")),
        );
    }
    if report["devices"].as_array().is_some_and(Vec::is_empty) {
        println!("  no device found");
    }
    if let Some(problem) = report["permission_problem"].as_str() {
        println!("permission: {problem}");
    }
}

fn str_of(v: &Value) -> &str {
    v.as_str().unwrap_or("?")
}

fn mm_triple(values: &[Value]) -> String {
    values.iter().map(|v| format!("{:.1}", v.as_f64().unwrap_or(f64::NAN))).collect::<Vec<_>>().join(" x ")
}

/// On Linux: a USB device of a DHD vendor whose node (`/dev/bus/usb/BUS/DEV`) this user cannot open for
/// writing, named with what to do; otherwise what to check. None elsewhere.
fn usb_permission_problem() -> Option<String> {
    if !cfg!(target_os = "linux") {
        return None;
    }
    let read =
        |dir: &std::path::Path, name: &str| std::fs::read_to_string(dir.join(name)).ok().map(|s| s.trim().to_owned());
    // Without sysfs (a container) no node can be named; the advice below still holds.
    let entries = std::fs::read_dir("/sys/bus/usb/devices").into_iter().flatten();
    for entry in entries.flatten() {
        let dir = entry.path();
        let (Some(vendor), Some(product)) = (read(&dir, "idVendor"), read(&dir, "idProduct")) else { continue };
        let Some((_, _, maker)) = USB_IDS.iter().find(|(v, p, _)| *v == vendor && p.is_none_or(|p| p == product))
        else {
            continue;
        };
        let (Some(bus), Some(dev)) = (read(&dir, "busnum"), read(&dir, "devnum")) else { continue };
        let node = format!("/dev/bus/usb/{:0>3}/{:0>3}", bus, dev);
        if let Err(e) = std::fs::OpenOptions::new().read(true).write(true).open(&node) {
            if e.kind() == std::io::ErrorKind::PermissionDenied {
                return Some(format!(
                    "the {maker} USB device {vendor}:{product} at {node} cannot be opened by this user (EACCES); add \
                     a udev rule, e.g. SUBSYSTEM==\"usb\", ATTR{{idVendor}}==\"{vendor}\", MODE=\"0666\" in \
                     /etc/udev/rules.d/, then replug it"
                ));
            }
        }
    }
    Some(
        "no DHD device could be opened; check that it is plugged in and powered, that `lsusb` lists it, and that \
         this user may open its node under /dev/bus/usb (a udev rule)"
            .into(),
    )
}
