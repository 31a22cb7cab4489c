//! What a [`HapticCore`](super::HapticCore) is told at construction: the device it drives, the controller
//! choices and gains, the safety envelope and the uplink policy. Plain data, `Clone`, no IO.

use std::time::Duration;

use crate::device::DeviceSpec;

/// The free directions' pull toward the VE takes at least this many round trips as its time constant.
///
/// Along the free directions the VE follows the model, a one-way delay late, so what that pull corrects comes
/// back a round trip `T` later. A correction `ẋ = −x(t − T) / τ` is stable only for `T < π τ / 2`; compared
/// with the VE's state predicted to now (not with the model's own state that the VE answered) the pull is
/// far from that bound, and `τ ≥ 2 T` keeps the margin the bound asks for anyway (crossover at `1/τ` with at
/// most `T/τ` = 0.5 rad of delay phase). Slower only means the model and the VE part for longer before they
/// meet again (`latency` experiment).
pub const FREE_BLEND_PER_ROUND_TRIP: f64 = 2.0;

/// How the joint-constraint controller renders the constrained directions (paper section VI).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ConstraintMode {
    /// First manipulation (Fig 6): a spring-damper `k_j, b_j` along the constrained directions.
    #[default]
    Stiffness,
    /// Second manipulation (Fig 7): zero the device's acceleration along the constrained directions by
    /// cancelling the hand wrench there. Needs the hand wrench (sensor, or the observer's estimate).
    Impedance,
}

impl ConstraintMode {
    /// Parses `stiffness` or `impedance`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "stiffness" => Some(ConstraintMode::Stiffness),
            "impedance" => Some(ConstraintMode::Impedance),
            _ => None,
        }
    }
}

/// Which local model runs at the haptic rate (paper eq 11/13).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelForm {
    /// The reduced operational-space form `ẍ = Λ̂⁻¹ F + b̂`: its cost does not grow with the linkage.
    #[default]
    Op,
    /// The paper's configuration-space form (eq 11): needs the snapshot's `config` terms; falls back to the
    /// reduced form for snapshots without them.
    Config,
}

impl ModelForm {
    /// Parses `op` or `config`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "op" => Some(ModelForm::Op),
            "config" => Some(ModelForm::Config),
            _ => None,
        }
    }
}

/// Controller gains in device units, what the hand feels (the paper's testbed values in
/// [`ControllerGains::paper`]; the core converts them through the session's mapping).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ControllerGains {
    /// Joint-constraint stiffness `k_j` along constrained directions, in scaled coordinates (N/m).
    pub joint_stiffness: f64,
    /// Joint-constraint damping `b_j` (N s/m).
    pub joint_damping: f64,
    /// Position-channel stiffness `K_pc` per operational axis (N/m, N m/rad).
    pub position_stiffness: Vec<f64>,
    /// Position-channel damping `B_pc` per operational axis (N s/m, N m s/rad).
    pub position_damping: Vec<f64>,
}

/// The paper's joint-constraint stiffness per kilogram of device mass (section VI), N/m/kg.
pub const PAPER_JOINT_STIFFNESS_PER_KG: f64 = 200.0;
/// The paper's joint-constraint damping per kilogram of device mass, N s/m/kg.
pub const PAPER_JOINT_DAMPING_PER_KG: f64 = 50.0;

impl ControllerGains {
    /// The paper's gains for a device of `device_mass_kg` on its linear axes: `k_j = 200 N/m/kg`,
    /// `b_j = 50 N s/m/kg`, `K_pc = (100 N/m, 100 N/m, 0.5 N m/rad)`, `B_pc = (70, 70, 0.375)`; spatial
    /// scenes repeat the linear and angular values on each axis.
    pub fn paper(device_mass_kg: f64, op_dim: usize) -> Self {
        let linear = if op_dim == 6 { 3 } else { 2 };
        let per_axis = |lin: f64, ang: f64| (0..op_dim).map(|i| if i < linear { lin } else { ang }).collect();
        ControllerGains {
            joint_stiffness: PAPER_JOINT_STIFFNESS_PER_KG * device_mass_kg,
            joint_damping: PAPER_JOINT_DAMPING_PER_KG * device_mass_kg,
            position_stiffness: per_axis(100.0, 0.5),
            position_damping: per_axis(70.0, 0.375),
        }
    }
}

/// Where the controller gains come from.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum GainChoice {
    /// Designed from the device and the operational point the `Welcome` describes (`design`).
    #[default]
    Designed,
    /// The paper's values scaled by this device's linear mass ([`ControllerGains::paper`]).
    Paper,
    /// Exactly these.
    Custom(ControllerGains),
}

/// How constrained directions are weighted from the snapshot's relative singular values `r_i = σ_i / σ_1`.
///
/// The weight is 1 at or below `full_below`, 0 at or above `none_above`, and a smoothstep in between, so a
/// direction that drifts across the server's 0.02 threshold (the testbed does, ≈1 s into the paper's
/// manipulation) fades in and out instead of switching the joint-constraint force on and off. The reported
/// count uses hysteresis: a direction counts once `r_i ≤ count_enter` and stops counting at `r_i ≥ count_exit`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConstraintWeighting {
    /// Full weight at or below this relative singular value.
    pub full_below: f64,
    /// Zero weight at or above this relative singular value.
    pub none_above: f64,
    /// A direction starts counting at or below this relative singular value (the server's threshold).
    pub count_enter: f64,
    /// A counted direction stops counting at or above this relative singular value.
    pub count_exit: f64,
}

impl Default for ConstraintWeighting {
    fn default() -> Self {
        ConstraintWeighting { full_below: 0.02, none_above: 0.04, count_enter: 0.02, count_exit: 0.03 }
    }
}

/// A snapshot is stale once older than this many times the longest recent gap between snapshots, when that is
/// longer than `SafetyConfig::max_snapshot_age` (`HapticCore::stale_after`): the next gap of a link may be
/// somewhat longer than the longest seen so far.
pub const STALE_GAP_MARGIN: f64 = 1.5;

/// However long a link's gaps have been, a snapshot this old is stale (`HapticCore::stale_after`): the force
/// fades within half a second of the last news from the VE.
pub const LONGEST_STALE_AGE: Duration = Duration::from_millis(500);

/// The safety envelope (see [`super::safety`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SafetyConfig {
    /// Time to ramp the force in at start and after every resume.
    pub ramp_in: Duration,
    /// A snapshot older than this is stale: the force fades out (on a link whose snapshots come with longer
    /// gaps, a margin over the longest of them, `HapticCore::stale_after`).
    pub max_snapshot_age: Duration,
    /// Time to fade the force to zero once the snapshot is stale (smooth: a smoothstep of a linear ramp).
    pub fade_out: Duration,
    /// Snapshot Λ̂⁻¹ entries beyond this magnitude (1/kg) are refused as corrupt.
    pub max_inverse_inertia: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        SafetyConfig {
            ramp_in: Duration::from_millis(200),
            max_snapshot_age: Duration::from_millis(100),
            fade_out: Duration::from_millis(50),
            max_inverse_inertia: 1e6,
        }
    }
}

/// Perceptual deadband on the uplink (IEEE 1918.1.1 style, Weber's law): an uplink leaves only when the
/// wrench changed by more than `weber_fraction` of its last sent value (plus a floor), when the model pose
/// moved by more than `pose_threshold` (scaled metres: `(Δp, L Δθ)`), when the status flags changed, or when
/// `max_interval` passed since the last one.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UplinkDeadband {
    /// Relative change of the wrench that is perceptible (Weber fraction), e.g. 0.1.
    pub weber_fraction: f64,
    /// Smallest wrench change sent, device N (scaled: torques divided by L), so a near-zero wrench does not
    /// chatter.
    pub wrench_floor_n: f64,
    /// Smallest model pose change sent, device m (scaled).
    pub pose_threshold_m: f64,
    /// Longest gap between uplinks.
    pub max_interval: Duration,
}

impl UplinkDeadband {
    /// The deadband with its floors, stated at the device, in the VE's units through the mapping's scales (a
    /// device newton is `1 / c_f` VE force units, a device metre `1 / c_p` VE length units), so that it
    /// passes the same uplinks whatever units the scene is written in.
    pub fn in_ve_units(&self, scales: &super::scales::Scales) -> Self {
        UplinkDeadband {
            wrench_floor_n: self.wrench_floor_n / scales.force,
            pose_threshold_m: self.pose_threshold_m / scales.position,
            ..*self
        }
    }
}

impl Default for UplinkDeadband {
    fn default() -> Self {
        UplinkDeadband {
            weber_fraction: 0.1,
            wrench_floor_n: 0.02,
            pose_threshold_m: 2e-4,
            max_interval: Duration::from_millis(20),
        }
    }
}

/// Default [`CoreConfig::linearization_reach`], in length scales: a fraction of the linkage's size, chosen by
/// the `latency` experiment (docs/benchmarks.md) between walls that stay stiff too far from where they were
/// linearized (the device saturates under long delays) and walls so soft the OP parts from the device. On a
/// linkage of one degree of freedom the frame is carried along the OP's path to the model (`follow_path`),
/// so the distance this softens by stays near zero there and the reach matters on linkages of more degrees
/// of freedom. The price is softer walls far from the linearization point.
pub const LINEARIZATION_REACH: f64 = 0.25;

/// Everything a [`HapticCore`](super::HapticCore) needs besides the `Welcome`.
#[derive(Clone, Debug, PartialEq)]
pub struct CoreConfig {
    /// The device the core drives (limits, masses).
    pub device: DeviceSpec,
    /// Stiffness or acceleration-zeroing rendering of the constrained directions.
    pub constraint_mode: ConstraintMode,
    /// Which local model.
    pub form: ModelForm,
    /// Gains.
    pub gains: GainChoice,
    /// Constrained-direction weighting and count hysteresis.
    pub weighting: ConstraintWeighting,
    /// Nominal tick period (used for the first tick and to bound a late tick's step).
    pub period: Duration,
    /// Time constant with which the local model is pulled toward the VE's (predicted) operational point
    /// along the constrained directions, where the frozen local model drifts off the linkage's motion (it
    /// moves on straight lines while the OP moves on curves). The paper resets the local model at each
    /// update; a first-order pull with a short time constant keeps it as close while never stepping the force.
    pub blend_time_constant: Duration,
    /// Time constant of the same pull in the free directions. There the VE follows the local model (the
    /// graphics controller couples it to the uplink's model pose) and lags it by the uplink path, so a fast
    /// pull would drag the model back onto a VE that is only following it, and slow both; a slow pull only
    /// keeps them from parting for good. The core never pulls faster than
    /// `free_blend_round_trips` round trips.
    pub free_blend_time_constant: Duration,
    /// The free directions' pull takes at least this many round trips as its time constant
    /// ([`FREE_BLEND_PER_ROUND_TRIP`](FREE_BLEND_PER_ROUND_TRIP) by default, see there); 0 leaves
    /// `free_blend_time_constant` as it is at every delay.
    pub free_blend_round_trips: f64,
    /// Pay the pull toward the VE from an energy tank that only the coupling's dampers fill, so the model's
    /// updates never put into the device-model coupling more energy than it dissipated (`passive_update`).
    pub passive_update: bool,
    /// Check the two-port as a whole from the client's end (`port_passivity`): while the VE's coupling has given
    /// the linkage more than the hand put into the client's end, net (beyond
    /// [`PORT_ALLOWANCE_J`](super::port_passivity::PORT_ALLOWANCE_J)), the local model gives up its kinetic
    /// energy rather than give it to the hand. Only while the user holds the linkage alone.
    pub port_passivity: bool,
    /// Check the two-port at the device's own port (`device_port`): while the motors have given the device more
    /// than the hand put in there and the linkage gave the VE's coupling, net (beyond
    /// [`DEVICE_PORT_ALLOWANCE_J`](super::device_port::DEVICE_PORT_ALLOWANCE_J)), the device is damped. Only
    /// while the user holds the linkage alone.
    pub device_port_passivity: bool,
    /// On a device without a force sensor, render the load b̂ carries in the free directions as a feedforward
    /// pair (`HapticCore::controllers`): the device is commanded `Λ̂ b̂` and the local model held up by as
    /// much, so the position channels carry no static load and the model stays on the device. Only while the
    /// user holds the linkage alone; weighted and paid for as the impedance controller's b̂ is (`bias_trust`).
    pub load_feedforward: bool,
    /// How far, in length scales `L` (scaled distance `|(Δp, L Δθ)|`), the local model may move from the pose
    /// its snapshot terms were computed at before the constrained directions are rendered softer (see
    /// `controllers::linearization_trust`). Under delay the model runs ahead of the VE by a round trip of
    /// motion, on a tangent plane taken where the VE was; `f64::INFINITY` never softens.
    pub linearization_reach: f64,
    /// On a linkage of one degree of freedom whose welcome carries the OP's path (`OpSummary::path`), carry
    /// the snapshot's frame along the path to where the local model is, and hold the model to the path
    /// rather than to the tangent line at the snapshot's pose: the walls stay where the joints put them however
    /// far the model runs ahead of the VE (a round trip of motion under delay), and the frame's distance from
    /// its linearization point, which `linearization_reach` softens by, stays near zero.
    pub follow_path: bool,
    /// Time constant of the first-order filter on the snapshot terms the controllers use (Λ̂⁻¹ and the
    /// constrained-direction projector), so a new snapshot never steps the force; zero takes them as they come.
    pub terms_time_constant: Duration,
    /// Bandwidth (rad/s) of the momentum observer that estimates the hand wrench on devices without a
    /// force sensor (used only by the impedance-mode joint-constraint controller); 0 disables it.
    pub hand_observer_bandwidth: f64,
    /// Map the device's current pose onto the operational point at the first snapshot (position offset
    /// plus a handle-frame orientation offset), as a user grasping the handle where the linkage is.
    pub index_at_first_snapshot: bool,
    /// The safety envelope.
    pub safety: SafetyConfig,
    /// Uplink deadband; `None` sends an uplink every tick.
    pub deadband: Option<UplinkDeadband>,
}

/// The most of the device's force (and torque) limit the load feedforward of a device without a sensor may
/// ask for (`CoreConfig::load_feedforward`); the position channels carry the rest of the load. `Λ̂ b̂` grows
/// without bound as the linkage nears a configuration where its OP cannot move (holding a load there takes a
/// mechanical advantage the linkage no longer has), and b̂'s velocity terms with it: rendered whole, such a
/// feedforward drove the device into its limits and the hand's swings into energy growth, where through the
/// position channels alone the model gives way.
pub const LOAD_FEEDFORWARD_SHARE: f64 = 0.1;

/// Least time (s) over which the load feedforward may rise from nothing to its largest
/// ([`LOAD_FEEDFORWARD_SHARE`] of the device's limit), or fall back: it comes in with the load it renders,
/// not as a step when the model restarts on a VE (a new snapshot, a server that takes over), and a load
/// that swings at a dead centre reaches the device only as fast as the channels would carry it.
pub const LOAD_FEEDFORWARD_RISE_S: f64 = 0.5;

impl CoreConfig {
    /// Defaults for `device`: stiffness mode, reduced form, designed gains, 1 kHz.
    pub fn new(device: DeviceSpec) -> Self {
        CoreConfig {
            device,
            constraint_mode: ConstraintMode::Stiffness,
            form: ModelForm::Op,
            gains: GainChoice::Designed,
            weighting: ConstraintWeighting::default(),
            period: Duration::from_millis(1),
            blend_time_constant: Duration::from_millis(20),
            free_blend_time_constant: Duration::from_millis(200),
            free_blend_round_trips: FREE_BLEND_PER_ROUND_TRIP,
            passive_update: true,
            port_passivity: true,
            device_port_passivity: true,
            load_feedforward: true,
            terms_time_constant: Duration::from_millis(5),
            linearization_reach: LINEARIZATION_REACH,
            follow_path: true,
            hand_observer_bandwidth: 50.0,
            index_at_first_snapshot: true,
            safety: SafetyConfig::default(),
            deadband: None,
        }
    }
}
