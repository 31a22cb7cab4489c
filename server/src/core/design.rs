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
//! **The hold.** The linear stiffness is at least what holds the OP's static load (as the device holds it,
//! [`static_load`]) within [`HOLD_STRETCH`] of its reach's extent, critically damped on the lightest mass at
//! that stiffness. The hand's force reaches the VE through the force channel; where it falls (a hand
//! turning back where a crank is wound against its load) the spring alone holds the linkage near the device,
//! and one designed on the lightest mass alone let a wound crank snap round, 3 cm of stretch under its load
//! against its 1.8 cm radius. This binds on heavy, wound linkages only, and puts their coupling above the
//! frequency the rule below gives: measured on generated linkages (docs/robustness.md), it leaves far fewer
//! sessions unstable, not more. A stiff hold under delay turns the passivity controller's PD off sooner; the
//! force channel's fade (`passivity`) is what then keeps a late push from running the VE off.
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

/// The coupling's spring holds the OP's static load within this fraction of its reach's extent: where the
/// hand's force in the VE falls (a hand turning back), the spring alone keeps a wound linkage near the
/// device.
pub const HOLD_STRETCH: f64 = 0.1;
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
    static_load_held::<S>(reach, device.max_torque_nm > 0.0)
}

/// [`static_load`] for a device that renders torque or not.
fn static_load_held<S: Space>(reach: &OpReach<S>, torque: bool) -> f64 {
    if torque {
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
    let extent = reach.largest_extent();
    let hold = if extent > 0.0 { static_load_held(reach, torque) / (HOLD_STRETCH * extent) } else { 0.0 };
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
        if a < lin && m > 0.0 {
            stiffness[a] = stiffness[a].max(hold);
        }
        let omega = if m > 0.0 { (stiffness[a] / m).sqrt() } else { omega };
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
mod tests;
