//! Reading the drivers' `--record` CSV files back into the harness's samples, so the demo's charts are drawn
//! by the same code as the `paper` experiment's (`experiments::paper`). The files are read by the record
//! crate ([`kinloop_record::read`]):
//!
//! - the client's file: one row per haptic tick, time since its loop started, the device and local-model
//!   poses, each controller's wrench, the count its controllers used;
//! - the server's file: one row per VE step, VE time, q, q̇, λ, the closure error, then per user `user_id`,
//!   OP pose, applied wrench, constraint count.
//!
//! The two clocks start at different instants; [`merge`] maps a client's time onto the VE's with the
//! offset the demo measured between the two starts, and fills each client sample's VE operational point and
//! VE constraint count from the VE row of that instant.

use std::path::Path;

use kinloop_linkage::math::space::SceneKind;
use kinloop_record::{read, ReadError, TickRecord, VeRow};

use kinloop_harness::{ClientSample, VeSample};

/// A client's tick as the harness's sample. The VE's OP and count are left empty; see [`merge`].
fn client_sample(r: &TickRecord, kind: SceneKind) -> ClientSample {
    let (point, k) = (kind.point_dim(), kind.op_dim());
    ClientSample {
        t: r.time_s,
        device: r.device_pose[..point].to_vec(),
        device_twist: Vec::new(),
        model: r.model_pose[..point].to_vec(),
        model_twist: Vec::new(),
        ve_op: None,
        ve_heard_s: None,
        joint_constraint: r.joint_constraint[..k].to_vec(),
        position_channel: r.position_channel[..k].to_vec(),
        impedance: r.impedance[..k].to_vec(),
        command: r.command[..k].to_vec(),
        hand: r.hand[..k].to_vec(),
        constraint_count: usize::from(r.constraint_count),
        snapshot_count: 0,
        snapshot_age: Some(r.snapshot_age_s).filter(|a| a.is_finite()),
        gain: r.gain,
        // Not recorded by the driver; nothing the charts read.
        clamp_scale: f64::NAN,
    }
}

/// A VE step as the harness's sample: time, q, closure error and every user's OP position, wrench and
/// constraint count.
fn ve_sample(r: &VeRow, kind: SceneKind) -> VeSample {
    let (point, k) = (kind.point_dim(), kind.op_dim());
    VeSample {
        t: r.t_s,
        q: r.q.clone(),
        closure_error: r.closure_error,
        users: r
            .users
            .iter()
            .map(|u| (u.user_id, u.op_pose[..point].to_vec(), u.wrench[..k].to_vec(), u.constraint_count))
            .collect(),
        kinetic_energy: f64::NAN,
        potential_energy: f64::NAN,
    }
}

/// Reads a client's recording (one row per tick). The VE's OP and count are left empty; see [`merge`].
pub fn read_client(file: &Path, kind: SceneKind) -> Result<Vec<ClientSample>, ReadError> {
    Ok(read::read_client(file, kind)?.iter().map(|r| client_sample(r, kind)).collect())
}

/// Reads the server's recording (one row per VE step).
pub fn read_ve(file: &Path, kind: SceneKind) -> Result<Vec<VeSample>, ReadError> {
    Ok(read::read_ve(file, kind)?.1.iter().map(|r| ve_sample(r, kind)).collect())
}

/// Fills each client sample's VE operational point and VE constraint count for `user_id` from the VE row
/// at the same instant: the client's `t + offset_s` on the VE's clock (the VE row is the latest one at or
/// before that time). Samples before the user appears in the VE keep `ve_op = None`.
pub fn merge(samples: &mut [ClientSample], ve: &[VeSample], user_id: u32, offset_s: f64) {
    for s in samples {
        let at = ve.partition_point(|v| v.t <= s.t + offset_s);
        let found = at.checked_sub(1).and_then(|i| ve[i].users.iter().find(|u| u.0 == user_id));
        if let Some((_, position, _, count)) = found {
            s.ve_op = Some(position.clone());
            s.snapshot_count = *count;
        }
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    const CLIENT_HEADER: &str = "time_s,device_x,device_y,device_theta,model_x,model_y,model_theta,hand_fx,hand_fy,\
hand_tz,pc_fx,pc_fy,pc_tz,jc_fx,jc_fy,jc_tz,imp_fx,imp_fy,imp_tz,contact_fx,contact_fy,contact_tz,cmd_fx,cmd_fy,\
cmd_tz,constraint_count,snapshot_age_s,gain";

    #[test]
    fn a_client_row_lands_in_the_named_fields() {
        let dir = tempfile::tempdir().unwrap();
        let row = "0.5,1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,2,NaN,0.75";
        let file = write(dir.path(), "c.csv", &format!("{CLIENT_HEADER}\n{row}\n"));
        let s = &read_client(&file, SceneKind::Planar).unwrap()[0];
        assert_eq!((s.t, s.device.clone(), s.model.clone()), (0.5, vec![1.0, 2.0], vec![4.0, 5.0]));
        assert_eq!((s.hand.clone(), s.joint_constraint.clone()), (vec![7.0, 8.0, 9.0], vec![13.0, 14.0, 15.0]));
        assert_eq!((s.command.clone(), s.constraint_count, s.gain), (vec![22.0, 23.0, 24.0], 2, 0.75));
        assert_eq!(s.snapshot_age, None, "NaN age: no snapshot yet");
    }

    /// A VE file with n = 1, m = 1: two rows, the second with two users.
    fn ve_file(dir: &Path) -> PathBuf {
        let header = "t_s,step,q_0,qd_0,lambda_0,closure_error_m,users,user_id,op_x,op_y,op_theta,wrench_fx,\
wrench_fy,wrench_tz,constraint_count,...(user group repeated per user)";
        let rows = [
            "0.001,1,0.5,0,0,1e-12,1,7,0.1,0.2,0.3,1,2,3,1",
            "0.002,2,0.6,0,0,2e-12,2,7,0.4,0.5,0.6,1,2,3,2,9,1,1,1,4,5,6,1",
        ];
        write(dir, "ve.csv", &format!("{header}\n{}\n{}\n", rows[0], rows[1]))
    }

    #[test]
    fn ve_rows_carry_every_user_and_merge_by_time() {
        let dir = tempfile::tempdir().unwrap();
        let ve = read_ve(&ve_file(dir.path()), SceneKind::Planar).unwrap();
        assert_eq!(ve.len(), 2);
        assert_eq!((ve[0].q.clone(), ve[1].closure_error), (vec![0.5], 2e-12));
        assert_eq!(ve[1].users[1], (9, vec![1.0, 1.0], vec![4.0, 5.0, 6.0], 1));
        let sample = |t| ClientSample { t, ..Default::default() };
        let mut samples = vec![sample(-0.0005), sample(0.0), sample(0.0012)];
        // The client started 1 ms after the VE.
        merge(&mut samples, &ve, 7, 0.001);
        assert_eq!(samples[0].ve_op, None, "before the first VE row");
        assert_eq!((samples[1].ve_op.clone(), samples[1].snapshot_count), (Some(vec![0.1, 0.2]), 1));
        assert_eq!((samples[2].ve_op.clone(), samples[2].snapshot_count), (Some(vec![0.4, 0.5]), 2));
    }
}
