//! Time series recorded by the harness, for charts, CSV files and the experiments' checks.

use std::time::Duration;

use kinloop_client::core::TickReport;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_server::core::VeState;

/// One client tick, in plain numbers (operational vectors flattened, linear part first).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ClientSample {
    /// Time, s.
    pub t: f64,
    /// Device handle position, mapped into the VE's frame by the client's indexing.
    pub device: Vec<f64>,
    /// Device twist (linear first) as the core measured it, VE units.
    pub device_twist: Vec<f64>,
    /// Local-model OP position.
    pub model: Vec<f64>,
    /// Local-model OP twist.
    pub model_twist: Vec<f64>,
    /// The VE's OP position (as the VE last computed it), if joined.
    pub ve_op: Option<Vec<f64>>,
    /// Client time up to which the VE has heard of this client (its newest uplink used), if joined and heard.
    pub ve_heard_s: Option<f64>,
    /// Joint-constraint controller wrench.
    pub joint_constraint: Vec<f64>,
    /// Position-channel wrench.
    pub position_channel: Vec<f64>,
    /// Impedance-controller wrench.
    pub impedance: Vec<f64>,
    /// The wrench sent to the device (after safety).
    pub command: Vec<f64>,
    /// The hand's wrench on the handle, VE units (the harness knows the simulated hand's true wrench).
    pub hand: Vec<f64>,
    /// Constraint count the controllers used (with hysteresis).
    pub constraint_count: usize,
    /// Constraint count in the newest snapshot.
    pub snapshot_count: u8,
    /// Age of the newest snapshot, s.
    pub snapshot_age: Option<f64>,
    /// Output gate (ramp / staleness fade), 0..1.
    pub gain: f64,
    /// Clamp scale applied for the device limits (1 = not clamped).
    pub clamp_scale: f64,
}

fn v<V: VecOps>(x: &V) -> Vec<f64> {
    x.as_slice().to_vec()
}

impl ClientSample {
    /// From a tick report, the device's true pose and the VE's OP.
    pub fn from_report<S: Space>(
        r: &TickReport<S>,
        device: OpPose<S>,
        ve_op: Option<OpPose<S>>,
        command: &S::OpVec,
    ) -> Self {
        ClientSample {
            t: r.time.as_secs_f64(),
            device: v(&device.position),
            device_twist: v(&r.device_twist),
            model: v(&r.model_pose.position),
            model_twist: v(&r.model_twist),
            ve_op: ve_op.map(|p| v(&p.position)),
            ve_heard_s: None,
            joint_constraint: v(&r.wrenches.joint_constraint),
            position_channel: v(&r.wrenches.position_channel),
            impedance: v(&r.wrenches.impedance),
            command: v(command),
            hand: v(&r.hand_wrench),
            constraint_count: r.constraint_count,
            snapshot_count: r.snapshot_constraint_count,
            snapshot_age: r.snapshot_age.map(|a| a.as_secs_f64()),
            gain: r.gain,
            clamp_scale: r.clamp_scale,
        }
    }
}

/// One VE tick.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct VeSample {
    /// Time, s.
    pub t: f64,
    /// Joint positions.
    pub q: Vec<f64>,
    /// Closure error at the start of the step, m.
    pub closure_error: f64,
    /// Per user: OP position, applied wrench, constraint count.
    pub users: Vec<(u32, Vec<f64>, Vec<f64>, u8)>,
    /// Kinetic energy of the linkage after the tick, J.
    pub kinetic_energy: f64,
    /// Potential energy (gravity, springs) of the linkage after the tick, J.
    pub potential_energy: f64,
}

impl VeSample {
    /// From the VE's state after a tick.
    pub fn from_state<S: Space>(now: Duration, s: &VeState<'_, S>) -> Self {
        VeSample {
            t: now.as_secs_f64(),
            q: s.q.as_slice().to_vec(),
            closure_error: s.closure_error,
            users: s.users().map(|u| (u.user_id, v(&u.op_pose.position), v(&u.wrench), u.constraint_count)).collect(),
            kinetic_energy: 0.0,
            potential_energy: 0.0,
        }
    }
}

/// Everything recorded in a session.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Recording {
    /// Client names, in plan order.
    pub names: Vec<String>,
    /// Per client, its samples.
    pub clients: Vec<Vec<ClientSample>>,
    /// VE samples.
    pub ve: Vec<VeSample>,
}

impl Recording {
    /// An empty recording for these clients.
    pub fn new(names: Vec<String>) -> Self {
        let n = names.len();
        Recording { names, clients: vec![Vec::new(); n], ve: Vec::new() }
    }

    /// Adds a client sample.
    pub fn push_client(&mut self, i: usize, s: ClientSample) {
        self.clients[i].push(s);
    }

    /// Adds a VE sample.
    pub fn push_ve(&mut self, s: VeSample) {
        self.ve.push(s);
    }

    /// Client `i`'s samples as CSV (one row per sample).
    pub fn client_csv(&self, i: usize) -> String {
        let mut out = String::from(
            "t,device_x,device_y,model_x,model_y,ve_op_x,ve_op_y,jc_fx,jc_fy,jc_tz,cmd_fx,cmd_fy,cmd_tz,count,snapshot_count,snapshot_age,gain,clamp\n",
        );
        for s in &self.clients[i] {
            let g = |v: &[f64], k: usize| v.get(k).copied().unwrap_or(f64::NAN);
            let ve = s.ve_op.clone().unwrap_or_default();
            out.push_str(&format!(
                "{:.6},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{},{:.4},{:.4}\n",
                s.t,
                g(&s.device, 0),
                g(&s.device, 1),
                g(&s.model, 0),
                g(&s.model, 1),
                g(&ve, 0),
                g(&ve, 1),
                g(&s.joint_constraint, 0),
                g(&s.joint_constraint, 1),
                g(&s.joint_constraint, 2),
                g(&s.command, 0),
                g(&s.command, 1),
                g(&s.command, 2),
                s.constraint_count,
                s.snapshot_count,
                s.snapshot_age.map_or(String::new(), |a| format!("{a:.6}")),
                s.gain,
                s.clamp_scale
            ));
        }
        out
    }
}
