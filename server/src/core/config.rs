//! What a [`VeCore`](super::VeCore) is told at construction: rates, integration, coupling gains, fades,
//! guards. Every field has the paper's value or a documented default.

use std::time::Duration;

use kinloop_linkage::{algorithms::integrator::Integrator, math::space::Space, math::space::VecOps};

/// Gains along the operational axes: the same value on every linear axis and on every angular axis, or one
/// value per axis (`k` of them, linear axes first).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum AxisGains {
    /// `linear` on x, y (, z) and `angular` on θ (or on ωx, ωy, ωz).
    Uniform {
        /// Gain on each linear axis (N/m or N·s/m).
        linear: f64,
        /// Gain on each angular axis (N·m/rad or N·m·s/rad).
        angular: f64,
    },
    /// One gain per operational axis, linear first.
    PerAxis(Vec<f64>),
}

impl AxisGains {
    /// The gains as an operational vector of space `S`.
    pub fn resolve<S: Space>(&self, what: &'static str) -> Result<S::OpVec, VeConfigError> {
        let lin = <S::Point as VecOps>::LEN;
        let mut out = S::OpVec::zero();
        match self {
            AxisGains::Uniform { linear, angular } => {
                for axis in 0..S::DIM {
                    out[axis] = if axis < lin { *linear } else { *angular };
                }
            }
            AxisGains::PerAxis(values) => {
                if values.len() != S::DIM {
                    return Err(VeConfigError::GainLength { what, got: values.len(), expected: S::DIM });
                }
                out.as_mut_slice().copy_from_slice(values);
            }
        }
        if let Some(&value) = out.as_slice().iter().find(|g| !(g.is_finite() && **g >= 0.0)) {
            return Err(VeConfigError::Gain { what, value });
        }
        Ok(out)
    }
}

/// Sanity limits on what a client may report (see `guards`). Stated in SI at the user's device; the VE holds
/// each user to them in the scene's units, through the user's mapping (`device_side`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GuardLimits {
    /// Largest distance between a client's local-model OP and the VE's OP (device m): farther is a broken
    /// client.
    pub max_model_offset_m: f64,
    /// Largest linear speed of a local-model OP (device m/s).
    pub max_model_speed_m_per_s: f64,
    /// Largest angular speed of a local-model OP (rad/s).
    pub max_model_angular_speed_rad_per_s: f64,
    /// Hand force limit when the device announced none (device N).
    pub default_max_force_n: f64,
    /// Hand torque limit when the device announced none (device N·m).
    pub default_max_torque_nm: f64,
    /// Slack over the device's announced peak force and torque before a hand wrench is clipped (fraction).
    pub device_cap_slack: f64,
    /// A hand wrench beyond the device's peak (with slack) times this is absurd and the uplink rejected;
    /// below that it is clipped to the peak (≥ 1).
    pub absurd_wrench_factor: f64,
    /// A burst of rejected uplinks ends after this long without a rejection (one log line per burst).
    pub rejection_burst_quiet: Duration,
}

impl Default for GuardLimits {
    fn default() -> Self {
        GuardLimits {
            max_model_offset_m: 1.0,
            max_model_speed_m_per_s: 20.0,
            max_model_angular_speed_rad_per_s: 200.0,
            default_max_force_n: 100.0,
            default_max_torque_nm: 10.0,
            device_cap_slack: 0.05,
            absurd_wrench_factor: 10.0,
            rejection_burst_quiet: Duration::from_secs(1),
        }
    }
}

/// Configuration of a [`VeCore`](super::VeCore).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VeConfig {
    /// Rate of the VE loop (Hz); each tick is one integrator step of `1 / ve_rate_hz`.
    pub ve_rate_hz: f64,
    /// Rate at which every user's snapshot is built (Hz), at most `ve_rate_hz`.
    pub snapshot_rate_hz: f64,
    /// Integration scheme.
    pub integrator: Integrator,
    /// Project q and q̇ onto the closure manifold after each step.
    pub projection: bool,
    /// Treat the graphics-controller PD linearly implicitly (semi-implicit Euler only): stable for any gains.
    /// Off reproduces the explicit coupling of the stability experiment.
    pub implicit_coupling: bool,
    /// Graphics-controller stiffness K_g per operational axis for every user (paper: 1000 N/m, 1000 N/m,
    /// 10000 N·m/rad); `None` designs each user's from its OP's inertia (`design`).
    pub coupling_stiffness: Option<AxisGains>,
    /// Graphics-controller damping B_g per operational axis for every user (paper: 100 N·s/m, 100 N·s/m,
    /// 10000 N·m·s/rad); `None` designs each user's.
    pub coupling_damping: Option<AxisGains>,
    /// Penalty contact stiffness (N/m); `None` takes the scene's (paper: 15,000 N/m).
    pub contact_stiffness: Option<f64>,
    /// Penalty contact damping (N·s/m); `None` takes the scene's (paper: 300 N·s/m).
    pub contact_damping: Option<f64>,
    /// Contacts closer than this gap, in the scene's length scales (`Model::length_scale`), are sent to
    /// clients as local-model contact terms.
    pub contact_margin: f64,
    /// Time-domain passivity observer/controller on every coupling (see `passivity`). On by default: without
    /// delay it leaves the tracking as it is, and it bounds what a delayed coupling can give the VE; the paper's
    /// VE ([`VeConfig::paper`]) has none.
    pub passivity: bool,
    /// With `passivity`: the per-axis controller instead of the port's (each OP axis on its own account, the
    /// axis left free rather than braked when scaled; see `passivity`). Off by default: under delay it
    /// cuts axes that merely pass energy on; it is the one that steadies the paper's stiff angular gains on a
    /// turning link, where the port controller does not.
    pub passivity_per_axis: bool,
    /// Play each user's uplinks out at the stream's steady delay (a jitter buffer, see `playout`) instead of
    /// following the newest on arrival. On by default: network jitter reaches the VE as a shaking
    /// reference otherwise. Its hold lengthens the loop through which users on one OP push each other, so
    /// `sharing` weights that loop by the round trip including the hold.
    pub jitter_buffer: bool,
    /// The round trip (s) up to which a user's local model takes the other users' hands whole from its
    /// snapshot's b̂ (one other user; N − 1 others share it); longer round trips take proportionally less (see
    /// `sharing`). Infinite takes them whole at any delay, as the paper's b̂ does, which is unstable with
    /// several users under delay.
    pub exchange_delay_s: f64,
    /// Longest lead of a coupling's target over its newest uplink (s; see `Coupling::steer_lead`): the VE aims
    /// each graphics controller at where the local model was predicted to be the network's one-way delay after
    /// the uplink left, up to this and no further than the heard motion supports
    /// (`coupling_lead_guess_miss_m`), and only while that delay is within `coupling_lead_delays_s`. 0
    /// follows what it has heard (the paper's VE, [`VeConfig::paper`]); the default is
    /// [`DEFAULT_COUPLING_LEAD_MAX_S`].
    pub coupling_lead_max_s: f64,
    /// The one-way delays (s, from and until, inclusive; until may be infinite) over which the VE leads: a
    /// user whose link is faster or slower is followed as heard. The default is
    /// [`DEFAULT_COUPLING_LEAD_DELAYS_S`].
    pub coupling_lead_delays_s: [f64; 2],
    /// How far a lead's guess may miss the hand at its worst (m at the user's device, ≥ 0; see
    /// `Coupling::trusted_lead_s`): the lead is cut so that the heard twist's recent rates of change, held over
    /// the lead, put no more energy into the coupling's spring K_g than its linear part holds stretched this far
    /// at the device (in the scene's units through the user's mapping and coupling, `device_side`): without
    /// the bound, pokes and releases under delay make energy. A larger bound leads further (the OP nearer the
    /// device) and lets the felt impedance stray further from the linkage's.
    pub coupling_lead_guess_miss_m: f64,
    /// Energy a coupling may generate (beyond what it absorbed and its client put in) before the passivity
    /// controller has scaled its PD to zero (J at the user's device, ≥ 0, held in the scene's units through the
    /// user's mapping, `device_side`; zero scales it to zero at once; see `passivity`).
    pub passivity_allowance_j: f64,
    /// Duration of a coupling's fade in or out (raised cosine).
    pub fade_time: Duration,
    /// A manipulator whose uplinks stop this long fades out until they resume.
    pub silent_timeout: Duration,
    /// Most users at once (leaving users still fading out do not count).
    pub max_users: usize,
    /// Limits on what clients may report.
    pub guards: GuardLimits,
    /// Most overdue ticks one `handle_timeout` runs; beyond that the VE skips ahead (and counts it) instead
    /// of running a burst that would make it later still.
    pub max_catch_up_ticks: u32,
    /// Seed of the session ids handed out in welcomes.
    pub session_seed: u64,
    /// Hold the linkage at rest while no manipulator's coupling holds it (the VE does not step, its
    /// velocity is zero). A linkage left to itself falls and swings for as long as the server runs, and the
    /// first user to join then has to catch a moving linkage through the network's delay, which can go
    /// unstable where the same join at rest renders well. Off (`kinloop-server --free-run`) the linkage moves on its own.
    pub rest_unheld: bool,
    /// The step's own energy account (`kinloop_linkage::algorithms::energy_guard`): what semi-implicit Euler
    /// makes in a fast swing is taken back out of the kinetic energy, at the end of the step that made it. On by
    /// default: a linkage falling through a dead centre under a user's hand otherwise swings up on the step's
    /// error. The paper's VE has none.
    pub energy_guard: bool,
}

impl VeConfig {
    /// The paper's VE: 1 kHz, semi-implicit Euler with projection and implicit coupling, the paper's
    /// K_g = (1000, 1000, 10000), B_g = (100, 100, 10000) for every user, the scene's contacts. The default
    /// ([`VeConfig::default`]) is the same VE with each user's gains designed from its OP's inertia.
    pub fn paper() -> Self {
        VeConfig {
            ve_rate_hz: 1000.0,
            snapshot_rate_hz: 1000.0,
            integrator: Integrator::SemiImplicitEuler,
            projection: true,
            implicit_coupling: true,
            coupling_stiffness: Some(AxisGains::Uniform { linear: 1000.0, angular: 10_000.0 }),
            coupling_damping: Some(AxisGains::Uniform { linear: 100.0, angular: 10_000.0 }),
            contact_stiffness: None,
            contact_damping: None,
            // 5 mm on the slider-crank (L = 28.7 mm), the scene whose wall this margin was first chosen on.
            contact_margin: 0.175,
            passivity: false,
            passivity_per_axis: false,
            jitter_buffer: true,
            exchange_delay_s: super::sharing::EXCHANGE_DELAY_S,
            // About what the graphics controller's linear spring (1000 N/m) holds at 2 mm, the device-OP
            // distance stiffness rendering keeps (Fig 6b).
            passivity_allowance_j: 2.0e-3,
            coupling_lead_max_s: 0.0,
            coupling_lead_delays_s: DEFAULT_COUPLING_LEAD_DELAYS_S,
            // A millimetre at the handle, the order of the device-OP distance stiffness rendering keeps.
            coupling_lead_guess_miss_m: 1.0e-3,
            fade_time: Duration::from_millis(200),
            silent_timeout: Duration::from_millis(250),
            max_users: 16,
            guards: GuardLimits::default(),
            max_catch_up_ticks: 10,
            session_seed: 0x006b_696e_6c6f_6f70,
            rest_unheld: true,
            energy_guard: false,
        }
    }

    /// VE period.
    pub fn ve_period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.ve_rate_hz)
    }

    /// Snapshot period.
    pub fn snapshot_period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.snapshot_rate_hz)
    }

    /// Checks the numbers; called by [`VeCore::new`](super::VeCore::new).
    pub fn validate(&self) -> Result<(), VeConfigError> {
        let rate_ok = |r: f64| r.is_finite() && (1.0..=100_000.0).contains(&r);
        if !rate_ok(self.ve_rate_hz) {
            return Err(VeConfigError::Rate { what: "ve_rate_hz", value: self.ve_rate_hz });
        }
        if !rate_ok(self.snapshot_rate_hz) || self.snapshot_rate_hz > self.ve_rate_hz {
            return Err(VeConfigError::Rate { what: "snapshot_rate_hz", value: self.snapshot_rate_hz });
        }
        let non_negative = [
            ("contact_margin", self.contact_margin),
            ("passivity_allowance_j", self.passivity_allowance_j),
            ("coupling_lead_max_s", self.coupling_lead_max_s),
            ("coupling_lead_guess_miss_m", self.coupling_lead_guess_miss_m),
            ("contact_stiffness", self.contact_stiffness.unwrap_or(0.0)),
            ("contact_damping", self.contact_damping.unwrap_or(0.0)),
            ("guards.max_model_offset_m", self.guards.max_model_offset_m),
            ("guards.max_model_speed_m_per_s", self.guards.max_model_speed_m_per_s),
            ("guards.max_model_angular_speed_rad_per_s", self.guards.max_model_angular_speed_rad_per_s),
            ("guards.default_max_force_n", self.guards.default_max_force_n),
            ("guards.default_max_torque_nm", self.guards.default_max_torque_nm),
            ("guards.device_cap_slack", self.guards.device_cap_slack),
        ];
        if let Some((what, value)) = non_negative.into_iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            return Err(VeConfigError::Negative { what, value });
        }
        if !(self.guards.absurd_wrench_factor.is_finite() && self.guards.absurd_wrench_factor >= 1.0) {
            return Err(VeConfigError::Negative {
                what: "guards.absurd_wrench_factor (at least 1)",
                value: self.guards.absurd_wrench_factor,
            });
        }
        if self.exchange_delay_s.is_nan() || self.exchange_delay_s <= 0.0 {
            return Err(VeConfigError::Negative { what: "exchange_delay_s (positive)", value: self.exchange_delay_s });
        }
        let [from, until] = self.coupling_lead_delays_s;
        if !(from.is_finite() && from >= 0.0) {
            return Err(VeConfigError::Negative { what: "coupling_lead_delays_s[0] (from, finite)", value: from });
        }
        if until.is_nan() || until < from {
            return Err(VeConfigError::Negative {
                what: "coupling_lead_delays_s[1] (until, at least from)",
                value: until,
            });
        }
        if self.fade_time.is_zero() {
            return Err(VeConfigError::Negative { what: "fade_time", value: 0.0 });
        }
        if self.max_users == 0 || self.max_users > kinloop_protocol::codec::limits::MAX_LIST_ENTRIES {
            return Err(VeConfigError::MaxUsers { value: self.max_users });
        }
        Ok(())
    }
}

/// The default longest lead (s; [`VeConfig::coupling_lead_max_s`]), over the one-way delays of
/// [`DEFAULT_COUPLING_LEAD_DELAYS_S`]: led by up to 100 ms the VE's OP stays nearer the device under delay
/// without making any session of the latency sweep unstable (docs/benchmarks.md has the figures).
pub const DEFAULT_COUPLING_LEAD_MAX_S: f64 = 0.1;

/// The one-way delays (s) over which the VE leads by default ([`VeConfig::coupling_lead_delays_s`]): from
/// 75 ms on. Below that the VE that follows is already near the device, and the lead's guesses, small as the
/// gain is, can tip a session over the energy criterion. There is no upper edge: the client's local model
/// follows its path, so a lead at long delays makes no session of the latency grid unstable and still brings
/// the OP nearer the device.
pub const DEFAULT_COUPLING_LEAD_DELAYS_S: [f64; 2] = [0.075, f64::INFINITY];

impl Default for VeConfig {
    /// The paper's VE with each user's graphics-controller gains designed from its device and its OP, the
    /// passivity controller on, and each target led by up to [`DEFAULT_COUPLING_LEAD_MAX_S`] (none).
    fn default() -> Self {
        VeConfig {
            coupling_stiffness: None,
            coupling_damping: None,
            passivity: true,
            coupling_lead_max_s: DEFAULT_COUPLING_LEAD_MAX_S,
            energy_guard: true,
            ..VeConfig::paper()
        }
    }
}

/// A [`VeConfig`] that cannot run.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VeConfigError {
    /// A rate outside 1 Hz..100 kHz, or a snapshot rate above the VE rate.
    #[error("{what} = {value} Hz must be between 1 and 100000 Hz (snapshots no faster than the VE)")]
    Rate {
        /// Which rate.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// A gain vector of the wrong length.
    #[error("{what} has {got} gains; this scene's operational space has {expected} axes")]
    GainLength {
        /// Which gains.
        what: &'static str,
        /// Given.
        got: usize,
        /// Needed.
        expected: usize,
    },
    /// A negative or non-finite gain.
    #[error("{what} gain {value} must be finite and ≥ 0")]
    Gain {
        /// Which gains.
        what: &'static str,
        /// The value.
        value: f64,
    },
    /// A negative or non-finite setting (or a zero duration that must be positive).
    #[error("{what} = {value} must be finite and positive or zero as documented")]
    Negative {
        /// Which setting.
        what: &'static str,
        /// The value.
        value: f64,
    },
    /// An operational point's reach could not be surveyed.
    #[error("surveying the operational points: {0}")]
    Survey(String),
    /// `max_users` of 0 or more than a snapshot can list.
    #[error("max_users = {value} must be between 1 and {}", kinloop_protocol::codec::limits::MAX_LIST_ENTRIES)]
    MaxUsers {
        /// The value.
        value: usize,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exchange_delay_must_be_positive_and_may_be_infinite() {
        assert_eq!(VeConfig::default().validate(), Ok(()));
        let with = |exchange_delay_s| VeConfig { exchange_delay_s, ..VeConfig::default() }.validate();
        assert_eq!(with(f64::INFINITY), Ok(()));
        for bad in [0.0, -0.01, f64::NAN] {
            match with(bad) {
                Err(VeConfigError::Negative { what, .. }) => assert!(what.starts_with("exchange_delay_s"), "{what}"),
                other => panic!("{bad}: {other:?}"),
            }
        }
    }

    /// The lead's cap and guess energy are refused by name when negative or not finite; zero is allowed
    /// (no lead).
    #[test]
    fn the_lead_numbers_must_be_finite_and_not_negative() {
        type WithValue = fn(f64) -> VeConfig;
        let set: [(&str, WithValue); 2] = [
            ("coupling_lead_max_s", |v| VeConfig { coupling_lead_max_s: v, ..VeConfig::default() }),
            ("coupling_lead_guess_miss_m", |v| VeConfig { coupling_lead_guess_miss_m: v, ..VeConfig::default() }),
        ];
        for (name, with) in set {
            assert_eq!(with(0.0).validate(), Ok(()), "{name}");
            for bad in [-1e-3, f64::NAN, f64::INFINITY] {
                match with(bad).validate() {
                    Err(VeConfigError::Negative { what, .. }) => assert_eq!(what, name),
                    other => panic!("{name} = {bad}: {other:?}"),
                }
            }
        }
        // The delays a lead acts over: from finite and not negative, until at least from (infinite allowed),
        // each refused by its own name with its own value.
        let delays = |d: [f64; 2]| VeConfig { coupling_lead_delays_s: d, ..VeConfig::default() }.validate();
        assert_eq!(delays([0.0, f64::INFINITY]), Ok(()));
        assert_eq!(delays([0.1, 0.1]), Ok(()));
        for (bad, field, value) in [
            ([-0.1, 0.4], "coupling_lead_delays_s[0]", -0.1),
            ([f64::INFINITY, f64::INFINITY], "coupling_lead_delays_s[0]", f64::INFINITY),
            ([0.3, 0.1], "coupling_lead_delays_s[1]", 0.1),
            ([0.1, f64::NAN], "coupling_lead_delays_s[1]", f64::NAN),
        ] {
            match delays(bad) {
                Err(VeConfigError::Negative { what, value: got }) => {
                    assert!(what.starts_with(field), "{bad:?}: {what}");
                    assert!(got == value || (got.is_nan() && value.is_nan()), "{bad:?}: {got}");
                }
                other => panic!("{bad:?}: {other:?}"),
            }
        }
    }
}
