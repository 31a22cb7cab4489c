//! The controllers' gains for a session: chosen (designed, the paper's, or given), capped to what the
//! device renders stably, and converted to VE units through the mapping.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::Welcome;

use super::config::{ControllerGains, CoreConfig, GainChoice};
use super::design;
use super::{CoreError, Scales};

/// Gains after resolution and capping to the device: in VE units for the controllers, which compute on the
/// VE side of the mapping, and as the device feels them.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedGains<S: Space> {
    /// k_j (N/m, scaled coordinates), VE units.
    pub joint_stiffness: f64,
    /// b_j (N s/m), VE units.
    pub joint_damping: f64,
    /// K_pc, VE units.
    pub position_stiffness: S::OpVec,
    /// B_pc, VE units.
    pub position_damping: S::OpVec,
    /// The same gains as the device renders them (device units), after the caps.
    pub device: ControllerGains,
    /// Factor applied to every stiffness so that k_j + K_pc stays within the device's stable stiffness.
    pub stiffness_cap: f64,
    /// Factor applied to every damping likewise.
    pub damping_cap: f64,
}

/// Picks the gains (device units), caps them to what the device renders stably (`k_j + K_pc ≤
/// max_stiffness` and `b_j + B_pc ≤ max_damping` on the linear axes; angular gains scale by the same
/// factors) and converts them to VE units through the mapping.
pub(super) fn resolve_gains<S: Space>(
    config: &CoreConfig,
    welcome: &Welcome,
    scales: &Scales,
) -> Result<ResolvedGains<S>, CoreError> {
    let period_s = config.period.as_secs_f64();
    let chosen = match &config.gains {
        GainChoice::Designed => design::designed_gains::<S>(
            &config.device,
            &welcome.mapping,
            &welcome.coupling,
            welcome.scene.length_scale,
            period_s,
        ),
        GainChoice::Paper => ControllerGains::paper(config.device.linear_mass(), S::DIM),
        GainChoice::Custom(g) => g.clone(),
    };
    let scalar_ok = |x: f64| x.is_finite() && x >= 0.0;
    if !scalar_ok(chosen.joint_stiffness) || !scalar_ok(chosen.joint_damping) {
        return Err(CoreError::Gains(format!(
            "k_j = {} and b_j = {} must be finite and non-negative",
            chosen.joint_stiffness, chosen.joint_damping
        )));
    }
    let position_stiffness = per_axis::<S>("K_pc", &chosen.position_stiffness)?;
    let position_damping = per_axis::<S>("B_pc", &chosen.position_damping)?;
    let linear_max = |v: &S::OpVec| S::op_lin(v).as_slice().iter().fold(0.0f64, |a, b| a.max(*b));
    let cap = |total: f64, limit: f64| {
        if limit.is_finite() && limit > 0.0 && total > limit {
            limit / total
        } else {
            1.0
        }
    };
    let stiffness_cap = cap(chosen.joint_stiffness + linear_max(&position_stiffness), config.device.max_stiffness);
    let damping_cap = cap(chosen.joint_damping + linear_max(&position_damping), config.device.max_damping);
    let device = ControllerGains {
        joint_stiffness: chosen.joint_stiffness * stiffness_cap,
        joint_damping: chosen.joint_damping * damping_cap,
        position_stiffness: (position_stiffness * stiffness_cap).as_slice().to_vec(),
        position_damping: (position_damping * damping_cap).as_slice().to_vec(),
    };
    // k_j and b_j act along the constrained directions, linear first: they scale as a linear gain.
    let joint = scales.position / scales.force;
    Ok(ResolvedGains {
        joint_stiffness: device.joint_stiffness * joint,
        joint_damping: device.joint_damping * joint,
        position_stiffness: scales.gain_to_ve::<S>(&(position_stiffness * stiffness_cap)),
        position_damping: scales.gain_to_ve::<S>(&(position_damping * damping_cap)),
        device,
        stiffness_cap,
        damping_cap,
    })
}

/// A per-axis gain list as a vector: one finite, non-negative value per axis of the space.
fn per_axis<S: Space>(what: &str, values: &[f64]) -> Result<S::OpVec, CoreError> {
    if values.len() != S::DIM || values.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
        return Err(CoreError::Gains(format!("{what} needs {} finite non-negative values, got {values:?}", S::DIM)));
    }
    Ok(S::OpVec::from_slice(values))
}
