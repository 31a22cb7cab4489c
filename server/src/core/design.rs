//! What the server decides for each user at join, from the user's device and the surveyed reach of the
//! operational point it holds (`kinloop_linkage::algorithms::reach`): the mapping between device and VE (a position
//! scale and a force scale) and the graphics controller's gains K_g, B_g (paper section IV, Fig 3).
//!
//! **The mapping.** A device is small and weak beside most linkages (a Touch's workspace is 16 × 12 cm
//! and its continuous force 0.88 N; the crank-rocker's coupler sweeps 18 × 14 cm and weighs 13 N at the
//! hand). The position scale `c_p` (device metres per VE metre) fits the OP's reach into
//! [`WORKSPACE_FILL`] of the device's workspace along the axis that binds, so the hand moves through the
//! linkage's whole motion without reaching the device's walls. The force scale `c_f` (device newtons per VE
//! newton) maps the static load at the OP (gravity through the closed loops, 90th percentile over the
//! reach) to [`LOAD_FRACTION`] of the device's continuous force, and to at most [`PEAK_SHARE`] of its peak
//! force: the hand still feels the weight, with room to feel the inertia and the loops on top of it. The
//! second bound matters for a device whose one published force is both its peak and its continuous one (the
//! omega.3's 12 N): the continuous bound alone would leave it a third of the headroom above the load that
//! a device rated for half its peak continuously has, and the dynamic forces of a tour then sit at its
//! peak. A scene without gravity has no static load; then the
//! load that sets the scale is the force that moves the OP's lightest direction across its reach in a
//! second on a minimum-jerk path (peak acceleration `5.77 d / T²`, Flash & Hogan 1985). Angles map one to
//! one and torques by `c_f c_p`, so every axis scales power alike (`protocol::Mapping`).
//!
//! **The grasp.** On a device that renders torque the user holds the OP rigidly when the OP's lightest
//! rotational inertia, times the torque scale `c_f c_p`, is within what the device can be made to feel
//! (`renders_rotation`); otherwise as through a pin. Where a pin would lose most of the coupling's hold and
//! the device's torque can carry a rigid grasp, the force scale rises to hold the OP rigidly (`grasp`).
//!
//! **The coupling.** The graphics controller ties the VE's OP to the user's local model (eq 4 applies it
//! beside the force channel). It is a spring-damper on the OP's effective mass, and what makes it stable
//! or not is its natural frequency against the rates and delays of the loop it closes (VE → snapshot →
//! local model → uplink → VE), not its stiffness in N/m. So the gains are designed per group of axes from
//! the OP's lightest effective mass over the reach: translation `m = 1 / max λ(Λ⁻¹_vv)`, rotation
//! `I = 1 / max λ(Λ⁻¹_ωω)` (the blocks of eq 9's Λ⁻¹), `K = m ω_g²`, `B = 2 ζ m ω_g`, critically damped.
//! Since Λ⁻¹ is positive semi-definite, its largest eigenvalue is at most the sum of its blocks' largest,
//! so along every direction of the coupled OP (rotation and translation tied by the loops) the coupling's
//! frequency is at most `√2 ω_g`. The paper's gains
//! (K_g = 1000 N/m, 10⁴ N·m/rad) put the testbed's link 2 at 2.6 Hz in translation but, on OPs that turn
//! about a nearly fixed point, the angular 10⁴ N·m/rad made a loop with the local model that the VE could
//! not hold (README, Known limits of earlier versions): designed from the inertia, no OP gets a coupling
//! stiffer than its own mass can follow. On a linkage of one degree of freedom the damping is at least what
//! keeps the OP's modes along its path at [`PATH_DAMPING_RATIO`]: its heavier masses there, held by the
//! coupling's spring and the linkage's own forces at rest (`path_damping`).
//!
//! **The frequency and the round trip.** The coupling's loop has three delays: a VE step, a device period
//! (the uplinks that move its reference) and the user's network round trip `T` (the OP goes out in a
//! snapshot, the local model follows it, its pose comes back in an uplink). A critically damped PD on a mass
//! crosses over at `ω_c = √(2 + √5) ω_g ≈ 2.06 ω_g` with a phase margin of `atan(2 √(2 + √5)) ≈ 76°`, and a
//! delay `τ` takes `ω_c τ` of it. Each delay may last at most a [`RATE_MARGIN`]th of the coupling's period
//! (`ω_g τ ≤ 2π / 50`, 15° at the crossover): one delay at its bound leaves 61°, all three 32°. So
//! ```text
//! f_g = min(f_VE / 50, f_device / 50, max(COUPLING_HZ, 1 / (50 T)))
//! ```
//! [`COUPLING_HZ`] (8 Hz) is the floor, the default every delay gets: on a round trip of 2.5 ms or more the
//! phase rule alone would ask for less, and the loop is held by what the local model predicts over the delay
//! and by the passivity controller (`passivity`), not by the PD's phase margin. The coupling is stiffer only
//! where the delay itself leaves the PD well damped: `1 / (50 T)` below 2.5 ms, up to the rate margins' cap
//! (20 Hz at 1 kHz, reached at `T ≤ 1 ms`). `T` is the server's own measurement of the user's link when it
//! joins (the QUIC connection's round trip after the handshake; the virtual-time harness passes its emulated
//! link's): a client that understated its round trip would be given a coupling too stiff for the VE every
//! user shares. A join without a measured round trip gets the floor ([`CouplingFrequency::designed`]).
//! Mid-session the delay the VE measures can only soften the coupling ([`soften`]): its round-trip estimate
//! (`round_trip`, less the tick a client waits before it answers a snapshot) plus what a gap between uplinks (lost
//! ones) held the reference beyond a device period. When that exceeds what the frequency holds, the gains go
//! down to the rule's for the longer delay. Lowering `K` at a
//! stretch `e` removes `½ ΔK e²` from the spring and lowering `B` only dissipates less, so the change takes
//! energy out and puts none in. The gains never rise mid-session: a rise stores energy at the stretch that no
//! one put in (the passivity controller pays for its own rises of β from its account).

use kinloop_linkage::algorithms::reach::OpReach;
use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_protocol::codec::limits::{MAX_MAPPING_SCALE, MIN_MAPPING_SCALE};
use kinloop_protocol::codec::validate;
use kinloop_protocol::{CouplingGains, DeviceCaps, Mapping, MappingRequest};

mod grasp;
#[cfg(test)]
mod grasp_tests;
mod path_damping;
use grasp::{held_rigidly, lightest, renders_rotation, MASS_REDUCTION};
use path_damping::path_damping;
pub use path_damping::PATH_DAMPING_RATIO;

/// Fraction of the device's workspace the OP's reach spans along the binding axis.
pub const WORKSPACE_FILL: f64 = 0.8;
/// Fraction of the device's continuous force the static load at the OP maps to: a quarter to a half
/// leaves the hand room to push against the load in either direction.
pub const LOAD_FRACTION: f64 = 0.35;
/// Largest fraction of the device's peak force the static load at the OP maps to: about five and a half
/// times the load left up to the peak, as the simulated presets' continuous figures leave them (paper
/// device 5.7, Falcon 6.4, Touch 10.7: the bound is met by each, so it changes none of their mappings).
pub const PEAK_SHARE: f64 = 0.18;
/// Natural frequency of the graphics controller on the OP's lightest effective mass (Hz).
pub const COUPLING_HZ: f64 = 8.0;
/// Damping ratio of the graphics controller.
pub const COUPLING_DAMPING_RATIO: f64 = 1.0;
/// The coupling's frequency stays below the VE rate and the device rate divided by this.
pub const RATE_MARGIN: f64 = 50.0;
/// Time a minimum-jerk motion across the reach takes when no gravity sets the force scale (s).
const CROSSING_S: f64 = 1.0;
/// Reach extents below this fraction of the largest are not fitted (a slider moves on one axis only).
const DEGENERATE_EXTENT: f64 = 0.01;

/// Why a device or a mapping request cannot serve an OP (becomes a `RefusalReason::Device`).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// The device describes another number of axes than the scene's operational space has.
    #[error("device {device} describes {got} axes; this {kind} scene's operational space has {expected} ({axes})")]
    Axes {
        /// The device's name.
        device: String,
        /// Axes it described.
        got: usize,
        /// Axes the scene needs.
        expected: usize,
        /// `planar` or `spatial`.
        kind: &'static str,
        /// The scene's axis names.
        axes: &'static str,
    },
    /// A device whose numbers cannot describe a real device.
    #[error("device {device}: {what}")]
    Impossible {
        /// The device's name.
        device: String,
        /// What is wrong.
        what: String,
    },
    /// A scale the client asked for that would take the device past its limits.
    #[error("{what}")]
    Scale {
        /// What is wrong, with the largest scale allowed.
        what: String,
    },
    /// The refusal rule [`check_holdable`] states in advance: over most of its reach the OP's static load,
    /// mapped by the smallest force scale the wire carries, exceeds what the device holds continuously.
    #[error(
        "{PREDICTED_REFUSAL}: holding the OP still over most of its reach takes {needed_n:.2} N of device \
         {device} (static load {load:.4e} scene force units, force scale {force_scale:.4e}), beyond its \
         continuous {continuous_n} N; a lighter linkage, a weaker gravity or spring, an OP nearer the pivots or a \
         stronger device would change this"
    )]
    Unholdable {
        /// The device's name.
        device: String,
        /// The static load that sets the force scale (scene force units).
        load: f64,
        /// The force scale (device N per scene force unit).
        force_scale: f64,
        /// The device force it maps to.
        needed_n: f64,
        /// The device's continuous force.
        continuous_n: f64,
    },
    /// The other refusal [`check_holdable`] states: an OP that cannot move renders nothing.
    #[error("{PREDICTED_REFUSAL}: the OP cannot move (its linkage has no degree of freedom); an OP on a linkage that moves would change this")]
    Motionless,
}

/// The static load `device` holds at the OP of `reach` (scene force units): the share of the least wrench that
/// is force (`OpReach::static_force_n`) on a device that renders torque, and on one that renders none (its
/// angular axes only sensed: a Falcon, a Touch) the force that holds the linkage through a pin
/// (`OpReach::static_pin_force_n`), which carries the link's gravity torque through the lever.
pub fn static_load<S: Space>(reach: &OpReach<S>, device: &DeviceCaps) -> f64 {
    if device.max_torque_nm > 0.0 {
        reach.static_force_n
    } else {
        reach.static_pin_force_n
    }
}

/// The words every refusal of [`check_holdable`] begins with, so that a tally can tell a refusal predicted by
/// the stated rule from any other.
pub const PREDICTED_REFUSAL: &str = "refused by the load rule";

/// The refusal rule, stated in advance (docs/robustness.md): a manipulator is refused at join when its OP
/// cannot move, or when the static load that sets the force scale (the 90th percentile over the OP's surveyed
/// reach of gravity, springs and actuators at rest, as the device holds it: [`static_load`]), times the force scale the
/// mapping chose, exceeds the device's continuous force. [`choose_mapping`] maps that load to
/// [`LOAD_FRACTION`] of the continuous force, so this holds only where the wire's range of scales
/// (`MIN_MAPPING_SCALE`) kept the scale from going low enough: over most of the reach the device could not
/// hold the linkage. The largest load is not the test: near a dead centre it tends to infinity on linkages
/// that render (a hand does not stay there). Everything compared is in device newtons, so the rule does not
/// depend on the scene's units. A user whose VE compensates gravity (`Mapping::gravity_compensation`) is not
/// held to the load part.
pub fn check_holdable<S: Space>(reach: &OpReach<S>, device: &DeviceCaps, mapping: &Mapping) -> Result<(), DesignError> {
    if reach.dof == 0 {
        return Err(DesignError::Motionless);
    }
    let load = static_load(reach, device);
    let needed_n = load * mapping.force_scale;
    // With gravity compensation the VE holds the static load, not the device.
    if !mapping.gravity_compensation && needed_n > device.continuous_force_n {
        return Err(DesignError::Unholdable {
            device: device.name.clone(),
            load,
            force_scale: mapping.force_scale,
            needed_n,
            continuous_n: device.continuous_force_n,
        });
    }
    Ok(())
}

/// The scene's axes, for messages.
fn axis_names<S: Space>() -> (&'static str, &'static str) {
    match S::DIM {
        3 => ("planar", "x, y, θ"),
        _ => ("spatial", "x, y, z, rx, ry, rz"),
    }
}

/// Checks that `device` describes a real device in the scene's operational space and that the scales
/// `request` asks for are usable: the wire's own checks first (a caller that joins without the wire gets
/// them too), then what only the scene can tell.
pub fn check_request<S: Space>(device: &DeviceCaps, request: &MappingRequest) -> Result<(), DesignError> {
    validate::mapping_request(request).map_err(|e| DesignError::Scale { what: e.to_string() })?;
    validate::device(device)
        .map_err(|e| DesignError::Impossible { device: device.name.clone(), what: e.to_string() })?;
    let (kind, axes) = axis_names::<S>();
    let lists = [device.workspace_min.len(), device.workspace_max.len(), device.damping.len(), device.mass.len()];
    if let Some(&got) = lists.iter().find(|&&len| len != S::DIM) {
        return Err(DesignError::Axes { device: device.name.clone(), got, expected: S::DIM, kind, axes });
    }
    let impossible = |what: String| DesignError::Impossible { device: device.name.clone(), what };
    let lin = <S::Point as VecOps>::LEN;
    for a in 0..lin {
        let extent = device.workspace_max[a] - device.workspace_min[a];
        if !is_positive(extent) {
            let axis = ["x", "y", "z"].get(a).copied().unwrap_or("?");
            return Err(impossible(format!("its workspace has no extent along {axis} ({extent} m)")));
        }
    }
    if !is_positive(device.max_force_n) {
        return Err(impossible(format!("a peak force of {} N renders nothing", device.max_force_n)));
    }
    if !is_positive(device.continuous_force_n) || device.continuous_force_n > device.max_force_n {
        return Err(impossible(format!(
            "continuous force {} N must be positive and at most the peak {} N",
            device.continuous_force_n, device.max_force_n
        )));
    }
    if !is_positive(device.max_stiffness_n_per_m) {
        return Err(impossible(format!("a stable stiffness of {} N/m renders nothing", device.max_stiffness_n_per_m)));
    }
    Ok(())
}

/// The mapping for `device` at the OP of `reach` (see the module documentation), with what the client
/// asked for taking precedence; a requested scale that would push the device past its peak force (static
/// load; only for a user who renders forces, a manipulator) or its reach past the workspace is refused with
/// the largest that would not.
pub fn choose_mapping<S: Space>(
    reach: &OpReach<S>,
    linkage: &[OpReach<S>],
    device: &DeviceCaps,
    request: &MappingRequest,
    renders_force: bool,
) -> Result<Mapping, DesignError> {
    let largest = reach.largest_extent();
    let fit = workspace_fit(reach, device);
    let position_scale = match request.position_scale {
        Some(asked) => {
            if fit.is_finite() && asked > fit {
                return Err(DesignError::Scale {
                    what: format!(
                        "position scale {asked} would take the OP's reach ({largest:.3} m) past device {}'s \
                         workspace; at most {fit:.3}",
                        device.name
                    ),
                });
            }
            asked
        }
        None => filling_scale(reach, device),
    };
    let loaded = load_scale(reach, device);
    let at_fill = torque_and_grasp(reach, device, position_scale, loaded);
    // The default reach is narrowed by the linkage's narrowing for this device (see `reach_narrowing`): the
    // same factor for every OP, so that users holding one linkage at different OPs keep the proportions of
    // their reaches, and none feels another's hand stiffened by a reach narrowed more than its own. The force
    // scale stays at most what it is at the fill: a narrower reach eases the static torque's bound, but
    // raising the forces with it would spend the headroom other users' pushes need.
    let position_scale = match (request.position_scale, request.force_scale) {
        (None, None) => {
            let own = reach_narrowing(reach, device);
            position_scale * linkage.iter().map(|r| reach_narrowing(r, device)).fold(own, f64::min)
        }
        _ => position_scale,
    };
    let mut force_scale = torque_and_grasp(reach, device, position_scale, loaded).min(at_fill);
    if let Some(asked) = request.force_scale {
        let load = static_load(reach, device);
        if renders_force && asked * load > device.max_force_n {
            // The load is positive here (a zero load fits any scale).
            let most = device.max_force_n / load;
            return Err(DesignError::Scale {
                what: format!(
                    "force scale {asked} would need {:.2} N of device {} to hold the OP's static load of {:.4e} \
                     scene force units (peak {} N); at most {most:.4e}",
                    asked * load,
                    device.name,
                    load,
                    device.max_force_n
                ),
            });
        }
        force_scale = asked;
    }
    // The wire's range for a mapping, which holds a scene written in any units of `limits::UNIT_RANGE`.
    let in_range = |scale: f64| scale.clamp(MIN_MAPPING_SCALE, MAX_MAPPING_SCALE);
    let (position_scale, force_scale) = (in_range(position_scale), in_range(force_scale));
    Ok(Mapping {
        position_scale,
        force_scale,
        gravity_compensation: request.gravity_compensation,
        rigid_grasp: renders_rotation(reach, device, force_scale * position_scale),
    })
}

/// The position scale at which the OP's reach fills [`WORKSPACE_FILL`] of the device's workspace on the
/// binding axis (one for a reach without extent): the default reach before `reach_narrowing`.
pub fn filling_scale<S: Space>(reach: &OpReach<S>, device: &DeviceCaps) -> f64 {
    let fit = workspace_fit(reach, device);
    if fit.is_finite() {
        WORKSPACE_FILL * fit
    } else {
        1.0
    }
}

/// The binding axis's ratio of device workspace to the OP's reach (infinite for a reach without extent).
fn workspace_fit<S: Space>(reach: &OpReach<S>, device: &DeviceCaps) -> f64 {
    let (extent, largest) = (reach.extent(), reach.largest_extent());
    (0..<S::Point as VecOps>::LEN)
        .filter(|&a| extent.as_slice()[a] > DEGENERATE_EXTENT * largest)
        .map(|a| (device.workspace_max[a] - device.workspace_min[a]) / extent.as_slice()[a])
        .fold(f64::INFINITY, f64::min)
}

/// The force scale that maps the OP's load (static, or carrying its lightest mass across the reach in
/// CROSSING_S without gravity) to the device's [`load_target`]; the static load as the device holds it
/// ([`static_load`]).
fn load_scale<S: Space>(reach: &OpReach<S>, device: &DeviceCaps) -> f64 {
    let (mass, _) = lightest(reach);
    let largest = reach.largest_extent();
    let dynamic = if mass.is_finite() { mass * 5.77 * largest / (CROSSING_S * CROSSING_S) } else { 0.0 };
    let load = static_load(reach, device).max(dynamic);
    if load > 0.0 {
        load_target(device) / load
    } else {
        1.0
    }
}

/// The factor in `[MIN_REACH_SHARE, 1]` by which the OP's default reach is narrowed on `device`. The device
/// renders the OP's lightest mass as `m c_f / c_p`, and no controller makes its handle feel more than
/// MASS_REDUCTION times lighter than itself: a reach mapped so wide that the linkage would feel lighter than
/// that by more than REDUCTION_MARGIN is narrowed until it does not (the hand then moves the device less for
/// the same motion of the linkage, rather than push a handle the controllers cannot make light). Only on a
/// device with a force sensor, whose handle the impedance controller makes lighter: without one there is no
/// reduction for the bound to leave a margin to, and narrowed so, seed 17's crank on a Falcon at 300 ms
/// gained energy.
pub fn reach_narrowing<S: Space>(reach: &OpReach<S>, device: &DeviceCaps) -> f64 {
    let (mass, _) = lightest(reach);
    let (handle, fit) = (handle_mass::<S>(device), workspace_fit(reach, device));
    if !(device.has_force_sensor && mass.is_finite() && mass > 0.0 && handle > 0.0 && fit.is_finite()) {
        return 1.0;
    }
    let fill = filling_scale(reach, device);
    let at_fill = torque_and_grasp(reach, device, fill, load_scale(reach, device));
    let narrowed = mass * at_fill * MASS_REDUCTION * REDUCTION_MARGIN / handle;
    (narrowed / fill).clamp(MIN_REACH_SHARE, 1.0)
}

/// The force scale once the static torque fits at `position_scale` (devices that render torque: torques scale
/// by `c_f c_p`) and the grasp rule has had its say, from the load's `force_scale`.
fn torque_and_grasp<S: Space>(reach: &OpReach<S>, device: &DeviceCaps, position_scale: f64, force_scale: f64) -> f64 {
    let mut force_scale = force_scale;
    let torque_load = reach.static_torque_nm * position_scale;
    if device.max_torque_nm > 0.0 && torque_load > 0.0 {
        force_scale = force_scale.min(LOAD_FRACTION * 0.5 * device.max_torque_nm / torque_load);
    }
    held_rigidly(reach, device, position_scale, force_scale)
}

/// The factor by which the narrowed reach leaves the linkage feeling lighter than the controllers can make the
/// handle (see `choose_mapping`).
pub const REDUCTION_MARGIN: f64 = 2.0;

/// The narrowest share of the workspace the OP's reach is narrowed to for the linkage to feel no lighter than
/// the handle can be made (see `choose_mapping`).
pub const MIN_REACH_SHARE: f64 = 0.1;

/// The handle's mass (kg): the largest of the device's linear axes', zero if it has none.
fn handle_mass<S: Space>(device: &DeviceCaps) -> f64 {
    device.mass.iter().take(<S::Point as VecOps>::LEN).fold(0.0, |a: f64, &m| a.max(m))
}

/// The force (device N) the static load at the OP maps to: [`LOAD_FRACTION`] of the continuous force, at
/// most [`PEAK_SHARE`] of the peak.
pub fn load_target(device: &DeviceCaps) -> f64 {
    (LOAD_FRACTION * device.continuous_force_n).min(PEAK_SHARE * device.max_force_n)
}

/// The graphics controller's natural frequency for one user, and what it was chosen from (see the module
/// documentation, "The frequency and the round trip").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CouplingFrequency {
    /// The natural frequency in use (rad/s).
    pub omega: f64,
    /// The VE's rate (Hz).
    pub ve_rate_hz: f64,
    /// The rate at which the user's device moves the coupling's reference (Hz).
    pub device_rate_hz: f64,
}

impl CouplingFrequency {
    /// The frequency for a VE at `ve_rate_hz`, a device at `device_rate_hz` and the user's network round trip
    /// as the server measured it (`None`: not measured, which gets [`COUPLING_HZ`]): the rule of the module
    /// documentation, `min(rates / RATE_MARGIN, max(COUPLING_HZ, 1 / (RATE_MARGIN T)))`.
    pub fn designed(ve_rate_hz: f64, device_rate_hz: f64, round_trip_s: Option<f64>) -> Self {
        let rates_hz = ve_rate_hz.min(device_rate_hz) / RATE_MARGIN;
        // A round trip of zero allows any frequency the rates do; an unknown or impossible one, none above
        // the default.
        let trip_hz = match round_trip_s {
            Some(trip) if trip >= 0.0 => 1.0 / (RATE_MARGIN * trip),
            _ => COUPLING_HZ,
        };
        let hz = COUPLING_HZ.max(trip_hz).min(rates_hz);
        CouplingFrequency { omega: std::f64::consts::TAU * hz, ve_rate_hz, device_rate_hz }
    }

    /// The longest round trip (s) this frequency was designed for: a coupling above [`COUPLING_HZ`] holds a
    /// round trip of at most a [`RATE_MARGIN`]th of its period; one at or below it, any.
    pub fn holds_round_trip_s(&self) -> f64 {
        if self.omega > std::f64::consts::TAU * COUPLING_HZ {
            std::f64::consts::TAU / (RATE_MARGIN * self.omega)
        } else {
            f64::INFINITY
        }
    }

    /// The frequency for a round trip measured mid-session, when it is longer than this one holds: never
    /// stiffer than this one (a rise stores energy at the spring's stretch that no one put in; lowering the
    /// gains removes `½ ΔK e²`, which only takes energy out). `None` while the round trip is held.
    pub fn softened(&self, round_trip_s: f64) -> Option<Self> {
        // NaN is no measurement.
        if round_trip_s.is_nan() || round_trip_s <= self.holds_round_trip_s() {
            return None;
        }
        let designed = CouplingFrequency::designed(self.ve_rate_hz, self.device_rate_hz, Some(round_trip_s));
        (designed.omega < self.omega).then_some(designed)
    }
}

/// Softens a coupling designed at `frequency` when the delay the VE measures mid-session is longer than it
/// holds: the gains keep the OP's mass and damping ratio and take the new frequency, `K ← K (ω'/ω)²`,
/// `B ← B ω'/ω`. The delay is the round trip (`estimate_s`, `round_trip::RoundTrip::estimate_s`, dated at the
/// uplink's arrival) less one period: the client answers a snapshot at its next tick, a wait the rate margins
/// budget already, so a perfect link measures up to one period (taken at the VE's rate, the device's at the
/// default rates), plus what the gap since the user's previous uplink (`gap_s`) held the
/// coupling's reference beyond a device period (lost uplinks: a delay no round trip shows). Returns whether
/// the gains changed.
pub fn soften<S: Space>(
    frequency: &mut CouplingFrequency,
    estimate_s: Option<f64>,
    gap_s: f64,
    stiffness: &mut S::OpVec,
    damping: &mut S::OpVec,
) -> bool {
    let trip = estimate_s.map_or(0.0, |trip| (trip - 1.0 / frequency.ve_rate_hz).max(0.0));
    let held = (gap_s - 1.0 / frequency.device_rate_hz).max(0.0);
    let Some(softer) = frequency.softened(trip + held) else {
        return false;
    };
    let ratio = softer.omega / frequency.omega;
    for a in 0..S::DIM {
        stiffness[a] *= ratio * ratio;
        damping[a] *= ratio;
    }
    *frequency = softer;
    true
}

/// K_g and B_g per operational axis for the OP of `reach` (see the module documentation). `torque`: the
/// user's device renders torque; without it the user holds the OP as through a pin, and the coupling
/// leaves the OP's orientation to the linkage (no angular gains).
pub fn coupling_gains<S: Space>(reach: &OpReach<S>, omega: f64, torque: bool) -> (S::OpVec, S::OpVec) {
    let (mass, inertia) = lightest(reach);
    let lin = <S::Point as VecOps>::LEN;
    let mut stiffness = S::OpVec::zero();
    let mut damping = S::OpVec::zero();
    for a in 0..S::DIM {
        let m = if a < lin {
            mass
        } else if torque {
            inertia
        } else {
            0.0
        };
        // An OP that does not move in a group needs no coupling there: the joints hold it.
        let m = if m.is_finite() { m } else { 0.0 };
        stiffness[a] = m * omega * omega;
        damping[a] = 2.0 * COUPLING_DAMPING_RATIO * m * omega;
        // Only where the OP translates at all: a path turning about a fixed point is the angular axes'.
        if a < lin && m > 0.0 {
            damping[a] = damping[a].max(path_damping(reach, stiffness[a]));
        }
    }
    (stiffness, damping)
}

/// The gains as the welcome carries them.
pub fn coupling_message<S: Space>(stiffness: &S::OpVec, damping: &S::OpVec) -> CouplingGains {
    CouplingGains { stiffness: stiffness.as_slice().to_vec(), damping: damping.as_slice().to_vec() }
}

/// `x > 0`, false for NaN: a limit that is not a positive number renders nothing.
fn is_positive(x: f64) -> bool {
    x > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// The frequency (Hz) the rule gives at 1 kHz rates for a round trip `trip` (s).
    fn hz(trip: Option<f64>) -> f64 {
        CouplingFrequency::designed(1000.0, 1000.0, trip).omega / TAU
    }

    /// The phase margin (rad) of a critically damped PD on a unit mass at `omega` behind a loop delay of
    /// `delay_s`, computed numerically: the open loop `(B s + K) e^{-s τ} / s²` crosses |L| = 1 where a
    /// bisection finds it, and the margin is `π + arg L` there.
    fn delayed_phase_margin(omega: f64, delay_s: f64) -> f64 {
        let (k, b) = (omega * omega, 2.0 * COUPLING_DAMPING_RATIO * omega);
        let gain = |w: f64| (b * b * w * w + k * k).sqrt() / (w * w);
        let (mut lo, mut hi) = (1e-3 * omega, 1e3 * omega);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if gain(mid) > 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let crossover = 0.5 * (lo + hi);
        (b * crossover / k).atan() - crossover * delay_s
    }

    /// The rule of the module documentation at 1 kHz: a round trip of a millisecond or less gets the rate
    /// margins' 20 Hz, 1.25 ms 16 Hz, 2.5 ms and beyond (a 100 ms link) the default 8 Hz, as does a join
    /// whose round trip was not measured or is not a duration.
    #[test]
    fn a_fast_link_gets_a_stiffer_coupling_and_a_slow_one_the_default() {
        let close = |got: f64, want: f64| (got - want).abs() < 1e-9 * want;
        for (trip, want) in [(Some(0.0), 20.0), (Some(1e-3), 20.0), (Some(1.25e-3), 16.0), (Some(2.5e-3), 8.0)] {
            assert!(close(hz(trip), want), "{trip:?}: {} Hz", hz(trip));
        }
        for trip in [Some(0.1), Some(1.0), None, Some(f64::NAN), Some(-1e-3), Some(f64::INFINITY)] {
            assert_eq!(hz(trip), COUPLING_HZ, "{trip:?}");
        }
    }

    /// Over round trips from 0 to 0.2 s and rates from 100 Hz to 10 kHz: the frequency never rises with the
    /// round trip, never exceeds a fiftieth of either rate, is never below the default unless a rate demands
    /// it, and above the default the PD behind the round trip keeps more than 60° of phase margin (computed
    /// numerically, not from the rule's constants).
    #[test]
    fn the_frequency_falls_with_the_round_trip_within_the_rate_margins() {
        for (ve, device) in [(1000.0, 1000.0), (1000.0, 4000.0), (10000.0, 1000.0), (100.0, 1000.0), (4000.0, 4000.0)] {
            let mut last = f64::INFINITY;
            for i in 0..=2000 {
                let trip = i as f64 * 1e-4;
                let omega = CouplingFrequency::designed(ve, device, Some(trip)).omega;
                assert!(omega <= last, "{ve}/{device} Hz: rises at {trip} s");
                last = omega;
                let rates = TAU * f64::min(ve, device) / RATE_MARGIN;
                assert!(omega <= rates * (1.0 + 1e-12), "{ve}/{device} Hz at {trip} s: {omega} rad/s");
                assert!(omega >= (TAU * COUPLING_HZ).min(rates) * (1.0 - 1e-12));
                if omega > TAU * COUPLING_HZ * (1.0 + 1e-12) {
                    let margin = delayed_phase_margin(omega, trip).to_degrees();
                    assert!(margin > 60.0, "{ve}/{device} Hz at {trip} s: {margin}°");
                }
            }
        }
    }

    /// Mid-session the frequency only goes down: a round trip within what it holds changes nothing, a longer
    /// one lowers K by (ω'/ω)² and B by ω'/ω (the damping ratio kept), a shorter one afterwards does not
    /// raise them again, and gains designed at the default are never softened.
    #[test]
    fn a_longer_round_trip_only_softens_the_coupling() {
        use kinloop_linkage::math::space::Planar;
        use nalgebra::Vector3;
        let mass = Vector3::new(2.0, 2.0, 0.01);
        let mut frequency = CouplingFrequency::designed(1000.0, 1000.0, Some(0.0));
        let omega0 = frequency.omega;
        assert_eq!(omega0, TAU * 20.0);
        let (mut k, mut b) = (mass * omega0 * omega0, mass * 2.0 * omega0);
        let mut stiffest = k;
        // Estimates as the VE measures them, a tick (1 ms) above the network's round trip.
        for trip in [1e-3, 1.5e-3, 2e-3, 2.1e-3, 1.5e-3, 0.0, 3e-3, 2e-3, 0.1, 0.0, 3.0] {
            let before = k;
            let changed = soften::<Planar>(&mut frequency, Some(trip), 1e-3, &mut k, &mut b);
            assert_eq!(changed, k != before, "{trip}");
            assert!(trip > 2e-3 || !changed, "a round trip within a millisecond changed the gains");
            assert!(k.iter().zip(stiffest.iter()).all(|(now, most)| now <= most), "K rose at {trip} s");
            stiffest = k;
            let omega = frequency.omega;
            for a in 0..3 {
                assert!((k[a] - mass[a] * omega * omega).abs() <= 1e-12 * k[a]);
                assert!((b[a] - 2.0 * mass[a] * omega).abs() <= 1e-12 * b[a]);
            }
        }
        assert_eq!(frequency.omega, TAU * COUPLING_HZ);
        let mut default = CouplingFrequency::designed(1000.0, 1000.0, None);
        assert!(!soften::<Planar>(&mut default, Some(10.0), 1.0, &mut k, &mut b));
        assert!(!soften::<Planar>(&mut frequency, None, 1.0, &mut k, &mut b));
        assert!(!soften::<Planar>(&mut frequency, Some(f64::NAN), 1e-3, &mut k, &mut b));
        // Lost uplinks: on a perfect round trip, a gap of 3 ms holds the reference 2 ms beyond a device
        // period, which 20 Hz does not hold and 10 Hz does.
        let mut fast = CouplingFrequency::designed(1000.0, 1000.0, Some(0.0));
        assert!(!soften::<Planar>(&mut fast, Some(1e-3), 1e-3, &mut k, &mut b));
        assert!(soften::<Planar>(&mut fast, Some(1e-3), 3e-3, &mut k, &mut b));
        assert!((fast.omega - TAU * 10.0).abs() < 1e-9);
    }

    #[test]
    fn the_load_maps_below_both_the_continuous_and_the_peak_bound() {
        let device = |peak: f64, continuous: f64| DeviceCaps {
            max_force_n: peak,
            continuous_force_n: continuous,
            ..DeviceCaps::generous("d", 3)
        };
        // The simulated presets' figures (paper device 10/5 N, Falcon 8.9/4 N, Touch 3.3/0.88 N): the
        // continuous bound binds, so their mappings are what they were before the peak bound.
        for (peak, continuous) in [(10.0, 5.0), (8.9, 4.0), (3.3, 0.88)] {
            assert_eq!(load_target(&device(peak, continuous)), LOAD_FRACTION * continuous);
        }
        // One figure for both (the omega.3's 12 N): the peak bound binds, leaving 1/PEAK_SHARE of headroom.
        let omega = load_target(&device(12.0, 12.0));
        assert!((omega - PEAK_SHARE * 12.0).abs() < 1e-12 && 12.0 / omega > 5.5, "{omega}");
    }

    /// The stated load rule: the mapping the server chooses passes it (the load maps to `LOAD_FRACTION` of the
    /// continuous force); the same load with the force scale held at the wire's smallest, far above what the
    /// device holds, is refused with a message naming the rule and what would change it.
    #[test]
    fn the_load_rule_refuses_only_a_load_the_scale_could_not_bring_down() {
        use kinloop_linkage::algorithms::reach::{survey_op, SurveyConfig};
        use kinloop_linkage::math::space::Planar;
        use kinloop_linkage::model::{builtin, Model};
        let scene = builtin::scene("paper-testbed").expect("built in").expect("parses");
        let model = Model::<Planar>::compile(&scene, "paper-testbed").expect("compiles");
        let mut reach = survey_op(&model, 0, &SurveyConfig::default()).expect("surveys");
        reach.static_force_n = reach.static_force_n.max(1.0);
        let device = DeviceCaps { continuous_force_n: 5.0, max_force_n: 10.0, ..DeviceCaps::generous("d", 3) };
        let mapping = choose_mapping(&reach, &[], &device, &MappingRequest::default(), true).expect("a mapping");
        assert_eq!(check_holdable(&reach, &device, &mapping), Ok(()));
        let heavy = Mapping { force_scale: 10.0 * device.continuous_force_n / reach.static_force_n, ..mapping };
        let refused = check_holdable(&reach, &device, &heavy).expect_err("refused");
        let text = refused.to_string();
        assert!(text.starts_with(PREDICTED_REFUSAL) && text.contains("would change this"), "{text}");
        let compensated = Mapping { gravity_compensation: true, ..heavy };
        assert_eq!(check_holdable(&reach, &device, &compensated), Ok(()));
    }

    /// The reach is narrowed exactly where the linkage would feel lighter than the handle can be made, with
    /// the margin: a light load keeps the workspace's fill; a heavier one (a smaller force scale) narrows it
    /// until the OP's lightest mass feels `handle / (MASS_REDUCTION REDUCTION_MARGIN)`; a far heavier one stops
    /// at `MIN_REACH_SHARE` of the fill; a scale the client asks for is kept. (The testbed's static torque is
    /// far within the generous device's peak, so the force scale is the load's.)
    #[test]
    fn the_reach_narrows_until_the_linkage_feels_no_lighter_than_the_handle_can_be_made() {
        use kinloop_linkage::math::space::Planar;
        let mut reach = surveyed("paper-testbed").swap_remove(0);
        let (mass, _) = lightest(&reach);
        let handle = 0.5;
        let device = DeviceCaps { mass: vec![handle, handle, 0.0], ..DeviceCaps::generous("d", 3) };
        let massless = DeviceCaps { mass: vec![0.0; 3], ..device.clone() };
        let mapped = |reach: &OpReach<Planar>, device: &DeviceCaps, request: &MappingRequest| {
            choose_mapping(reach, &[], device, request, true).expect("a mapping")
        };
        let felt = |m: &Mapping| mass * m.force_scale / m.position_scale;
        let bound = MASS_REDUCTION * REDUCTION_MARGIN;
        let mut seen = [false; 3];
        for load in (-6..=12).map(|k| 10f64.powf(k as f64 / 2.0)) {
            reach.static_force_n = load;
            let fill = mapped(&reach, &massless, &MappingRequest::default()).position_scale;
            let m = mapped(&reach, &device, &MappingRequest::default());
            assert_eq!(m.force_scale, mapped(&reach, &massless, &MappingRequest::default()).force_scale);
            if fill * handle <= mass * m.force_scale * bound {
                seen[0] = true;
                assert_eq!(m.position_scale, fill, "load {load}: not narrowed");
                assert!(felt(&m) * bound >= handle * (1.0 - 1e-12));
            } else if m.position_scale > MIN_REACH_SHARE * fill {
                seen[1] = true;
                assert!(m.position_scale < fill);
                assert!((felt(&m) * bound / handle - 1.0).abs() < 1e-12, "load {load}: {}", felt(&m));
            } else {
                seen[2] = true;
                assert!((m.position_scale / fill - MIN_REACH_SHARE).abs() < 1e-12, "load {load}");
            }
            assert!((m.position_scale / fill - reach_narrowing(&reach, &device)).abs() < 1e-12);
            let asked = MappingRequest { position_scale: Some(0.9 * fill), ..MappingRequest::default() };
            assert_eq!(mapped(&reach, &device, &asked).position_scale, 0.9 * fill);
        }
        assert_eq!(seen, [true; 3], "the loads cover the three cases");
    }

    /// Every OP of one linkage is narrowed on a device by the same factor, the least of its OPs' own, so that
    /// users at different OPs keep their reaches' proportions; and the force scale never rises above the
    /// fill's, though a narrower reach eases the static torque's bound. The crank-rocker on the paper's device
    /// (1 kg handle, 0.2 N m): the crank tip needs more narrowing than the coupler, and at the fill its force
    /// scale is held down by its static torque.
    #[test]
    fn one_linkage_is_narrowed_by_one_factor_and_no_force_scale_rises() {
        let reaches = surveyed("fourbar-crank-rocker");
        let paper = DeviceCaps {
            max_force_n: 10.0,
            continuous_force_n: 5.0,
            max_torque_nm: 0.2,
            mass: vec![1.0, 1.0, 0.005],
            workspace_min: vec![-0.15, -0.15, -TAU],
            workspace_max: vec![0.15, 0.15, TAU],
            ..DeviceCaps::generous("paper", 3)
        };
        let own: Vec<f64> = reaches.iter().map(|r| reach_narrowing(r, &paper)).collect();
        let least = own.iter().copied().fold(1.0, f64::min);
        assert!(own.iter().any(|&f| f > least * 1.5), "the OPs differ: {own:?}");
        assert!((MIN_REACH_SHARE..1.0).contains(&least), "{least}");
        let default = MappingRequest::default();
        for reach in &reaches {
            let alone = choose_mapping(reach, &[], &paper, &default, true).expect("a mapping");
            let shared = choose_mapping(reach, &reaches, &paper, &default, true).expect("a mapping");
            let fill = filling_scale(reach, &paper);
            assert!(
                (shared.position_scale / fill - least).abs() < 1e-12,
                "{} vs {least}",
                shared.position_scale / fill
            );
            assert!(shared.position_scale <= alone.position_scale);
            let at_fill = torque_and_grasp(reach, &paper, fill, load_scale(reach, &paper));
            assert!(shared.force_scale <= at_fill && alone.force_scale <= at_fill);
        }
        let tip = &reaches[1];
        let (fill, load) = (filling_scale(tip, &paper), load_scale(tip, &paper));
        let (eased, at_fill) =
            (torque_and_grasp(tip, &paper, least * fill, load), torque_and_grasp(tip, &paper, fill, load));
        assert!(eased > at_fill, "the narrower reach eases the crank tip's torque bound: {eased} vs {at_fill}");
    }

    /// On a path the linear damping is the larger of the PD's critical damping on the lightest mass and, at
    /// the 90th percentile of the path's poses, `2 ζ_p √(m (K + K_rest))` (a hill counting as no stiffness);
    /// the stiffness and the angular gains do not change, and a pose next to a dead point (an inertia of
    /// 10⁹ kg) does not set it. Without path modes the gains are the PD's alone. Closed forms on the crank-
    /// rocker's coupler with its surveyed lightest mass and modes put in by hand.
    #[test]
    fn the_damping_holds_the_heavier_modes_along_the_path_and_nothing_else_changes() {
        use kinloop_linkage::algorithms::reach::PathMode;
        let coupler = surveyed("fourbar-crank-rocker").remove(0);
        let omega = TAU * COUPLING_HZ;
        let none = OpReach { path_modes: Vec::new(), ..coupler.clone() };
        let (k0, b0) = coupling_gains(&none, omega, true);
        let (mass, inertia) = grasp::lightest(&none);
        assert!(
            (k0[0] - mass * omega * omega).abs() < 1e-9 * k0[0] && (b0[0] - 2.0 * mass * omega).abs() < 1e-9 * b0[0]
        );
        // Nine poses of 2 kg held at 500 N/m, one at 3 kg on a hill, one next to a dead point.
        let mut modes = vec![PathMode { mass: 2.0, rest_stiffness: 500.0 }; 9];
        modes.push(PathMode { mass: 3.0, rest_stiffness: -1e6 });
        modes.push(PathMode { mass: 1e9, rest_stiffness: 500.0 });
        let with = OpReach { path_modes: modes, ..coupler.clone() };
        let (k, b) = coupling_gains(&with, omega, true);
        assert_eq!(k, k0, "the stiffness is the lightest mass's");
        let held = 2.0 * PATH_DAMPING_RATIO * (2.0 * (k0[0] + 500.0)).sqrt();
        let hill = 2.0 * PATH_DAMPING_RATIO * (3.0 * k0[0]).sqrt();
        let want = held.max(hill).max(b0[0]);
        assert!(want > 2.0 * b0[0], "the modes ask for more than the PD's own: {want} vs {}", b0[0]);
        for a in 0..2 {
            assert!((b[a] - want).abs() < 1e-9 * want, "axis {a}: {} vs {want}", b[a]);
        }
        assert_eq!(b[2], b0[2], "the angular damping is the lightest inertia's ({inertia} kg m²)");
        // Modes lighter and looser than the PD's design leave it as it was.
        let light = OpReach { path_modes: vec![PathMode { mass: 1e-6, rest_stiffness: 0.0 }; 5], ..coupler };
        assert_eq!(coupling_gains(&light, omega, true), (k0, b0));
    }

    /// Every OP of built-in planar scene `name`, surveyed.
    fn surveyed(name: &str) -> Vec<OpReach<kinloop_linkage::math::space::Planar>> {
        use kinloop_linkage::algorithms::reach::{survey_op, SurveyConfig};
        use kinloop_linkage::math::space::Planar;
        use kinloop_linkage::model::{builtin, Model};
        let scene = builtin::scene(name).expect("built in").expect("parses");
        let model = Model::<Planar>::compile(&scene, name).expect("compiles");
        (0..model.ops.len()).map(|op| survey_op(&model, op, &SurveyConfig::default()).expect("surveys")).collect()
    }
}
