//! The controllers' gains for a session: chosen (designed, the paper's, or given), capped to what the
//! device renders stably, and converted to VE units through the mapping.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::{OpSummary, Welcome};

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
    /// What the local model takes of K_pc along the constrained directions (`walls_of`), VE units.
    pub wall_stiffness: S::OpVec,
    /// The same of B_pc.
    pub wall_damping: S::OpVec,
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
    let (position_stiffness, position_damping) = (
        scales.gain_to_ve::<S>(&(position_stiffness * stiffness_cap)),
        scales.gain_to_ve::<S>(&(position_damping * damping_cap)),
    );
    let (wall_stiffness, wall_damping) = walls_of::<S>(&welcome.op, &position_stiffness, &position_damping, period_s);
    Ok(ResolvedGains {
        joint_stiffness: device.joint_stiffness * joint,
        joint_damping: device.joint_damping * joint,
        position_stiffness,
        position_damping,
        wall_stiffness,
        wall_damping,
        device,
        stiffness_cap,
        damping_cap,
    })
}

/// What the local model takes of the channels' stiffness and damping (VE units) along the constrained
/// directions: at most what a step at its start would hold on the OP's lightest mass and inertia over the
/// reach (`m_op`, `I_op` of `op`), `K T² / m ≤ 1/4` and `B T / m ≤ 1/4`. There the model's Λ̂⁻¹ is small but
/// not zero (filtered, and linearized at the snapshot's pose): the channels' whole stiffness would drag it
/// through the walls after a hand pushing into them, and the VE after it, where without any reaction there
/// the device's spring to a wall the model does not feel makes energy at a singular pose
/// (`channel_reaction`).
fn walls_of<S: Space>(op: &OpSummary, stiffness: &S::OpVec, damping: &S::OpVec, period_s: f64) -> (S::OpVec, S::OpVec) {
    let lightest = |inverse: f64| if inverse > 0.0 { 1.0 / inverse } else { f64::INFINITY };
    let (mass, inertia) = (lightest(op.inverse_mass_max), lightest(op.inverse_rotational_inertia_max));
    let lin = <S::Point as VecOps>::LEN;
    let (mut k, mut b) = (*stiffness, *damping);
    for a in 0..S::DIM {
        let m = if a < lin { mass } else { inertia };
        k[a] = k[a].min(WALL_STEP_MARGIN * m / (period_s * period_s));
        b[a] = b[a].min(WALL_STEP_MARGIN * m / period_s);
    }
    (k, b)
}

/// Fraction of an explicit step's stability bounds (`K T² / m < 4`, `B T / m < 2`, taken as one) the walls'
/// reaction keeps (`walls_of`).
const WALL_STEP_MARGIN: f64 = 0.25;

/// A per-axis gain list as a vector: one finite, non-negative value per axis of the space.
fn per_axis<S: Space>(what: &str, values: &[f64]) -> Result<S::OpVec, CoreError> {
    if values.len() != S::DIM || values.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
        return Err(CoreError::Gains(format!("{what} needs {} finite non-negative values, got {values:?}", S::DIM)));
    }
    Ok(S::OpVec::from_slice(values))
}
