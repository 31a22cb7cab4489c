//! Reading the drivers' `--record` CSV files back into the harness's samples, so the demo's charts are drawn
//! by the same code as the `paper` experiment's (`experiments::paper`).
//!
//! - the client's file (`kinloop_client::driver::record`): one row per haptic tick, time since its loop
//!   started, the device and local-model poses, each controller's wrench, the count its controllers used;
//! - the server's file (`kinloop_server::driver` record): one row per VE step, VE time, q, q̇, λ, the closure
//!   error, then per user `user_id`, OP pose, applied wrench, constraint count.
//!
//! The two clocks start at different instants; [`merge`] maps a client's time onto the VE's with the
//! offset the demo measured between the two starts, and fills each client sample's VE operational point and
//! VE constraint count from the VE row of that instant.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use kinloop_client::axes::{pose_names, wrench_names};
use kinloop_linkage::math::space::SceneKind;

use kinloop_harness::{ClientSample, VeSample};

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordReadError {
    /// The file could not be read.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file has no header line.
    #[error("{file}: empty (no header line)")]
    Empty {
        /// The file.
        file: PathBuf,
    },
    /// A column the reader needs is not in the header.
    #[error("{file}: no column {column:?} in the header")]
    MissingColumn {
        /// The file.
        file: PathBuf,
        /// The column.
        column: String,
    },
    /// A row that does not parse.
    #[error("{file}:{line}: {what}")]
    BadRow {
        /// The file.
        file: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
}

/// A CSV file's header, for finding columns by name.
struct Header {
    file: PathBuf,
    columns: HashMap<String, usize>,
}

impl Header {
    fn index(&self, column: &str) -> Result<usize, RecordReadError> {
        self.columns
            .get(column)
            .copied()
            .ok_or_else(|| RecordReadError::MissingColumn { file: self.file.clone(), column: column.to_owned() })
    }

    /// The indices of `prefix_name` for each name.
    fn group(&self, prefix: &str, names: &[&str]) -> Result<Vec<usize>, RecordReadError> {
        names.iter().map(|n| self.index(&format!("{prefix}_{n}"))).collect()
    }
}

/// A data row: its 1-based line number and its numbers.
type Row = (usize, Vec<f64>);

/// The file's header and its data rows as numbers (empty fields read as NaN), with their line numbers.
fn read_csv(file: &Path) -> Result<(Header, Vec<Row>), RecordReadError> {
    let text = std::fs::read_to_string(file).map_err(|source| RecordReadError::Io { file: file.to_owned(), source })?;
    let mut lines = text.lines().enumerate();
    let (_, head) = lines.next().ok_or_else(|| RecordReadError::Empty { file: file.to_owned() })?;
    let columns = head.split(',').enumerate().map(|(i, c)| (c.trim().to_owned(), i)).collect();
    let header = Header { file: file.to_owned(), columns };
    let mut rows = Vec::new();
    for (i, line) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let values = line
            .split(',')
            .map(|f| match f.trim() {
                "" => Ok(f64::NAN),
                t => t.parse::<f64>().map_err(|_| format!("{t:?} is not a number")),
            })
            .collect::<Result<Vec<f64>, String>>()
            .map_err(|what| RecordReadError::BadRow { file: file.to_owned(), line: i + 1, what })?;
        rows.push((i + 1, values));
    }
    Ok((header, rows))
}

fn bad_row(file: &Path, line: usize, what: impl Into<String>) -> RecordReadError {
    RecordReadError::BadRow { file: file.to_owned(), line, what: what.into() }
}

/// Reads a client's recording (one row per tick). The VE's OP and count are left empty; see [`merge`].
pub fn read_client(file: &Path, kind: SceneKind) -> Result<Vec<ClientSample>, RecordReadError> {
    let (header, rows) = read_csv(file)?;
    let position = &pose_names(kind)[..kind.point_dim()];
    let wrench = wrench_names(kind);
    let time = header.index("time_s")?;
    let device = header.group("device", position)?;
    let model = header.group("model", position)?;
    let [hand, pc, jc, imp, cmd] = ["hand", "pc", "jc", "imp", "cmd"].map(|p| header.group(p, wrench));
    let (hand, pc, jc, imp, cmd) = (hand?, pc?, jc?, imp?, cmd?);
    let (count, age, gain) =
        (header.index("constraint_count")?, header.index("snapshot_age_s")?, header.index("gain")?);
    let width = header.columns.len();
    rows.into_iter()
        .map(|(line, row)| {
            if row.len() != width {
                return Err(bad_row(file, line, format!("{} fields, the header has {width}", row.len())));
            }
            let pick = |columns: &[usize]| columns.iter().map(|&c| row[c]).collect::<Vec<f64>>();
            let count = row[count];
            if !(count >= 0.0 && count.fract() == 0.0 && count <= 6.0) {
                return Err(bad_row(file, line, format!("constraint count {count} is not a count")));
            }
            Ok(ClientSample {
                t: row[time],
                device: pick(&device),
                device_twist: Vec::new(),
                model: pick(&model),
                model_twist: Vec::new(),
                ve_op: None,
                ve_heard_s: None,
                joint_constraint: pick(&jc),
                position_channel: pick(&pc),
                impedance: pick(&imp),
                command: pick(&cmd),
                hand: pick(&hand),
                constraint_count: count as usize,
                snapshot_count: 0,
                snapshot_age: Some(row[age]).filter(|a| a.is_finite()),
                gain: row[gain],
                // Not recorded by the driver; nothing the charts read.
                clamp_scale: f64::NAN,
            })
        })
        .collect()
}

/// Reads the server's recording (one row per VE step): time, q, closure error and every user's OP position,
/// wrench and constraint count.
pub fn read_ve(file: &Path, kind: SceneKind) -> Result<Vec<VeSample>, RecordReadError> {
    let (header, rows) = read_csv(file)?;
    let n = header.columns.keys().filter(|c| c.starts_with("q_")).count();
    let m = header.columns.keys().filter(|c| c.starts_with("lambda_")).count();
    let (time, q0, closure, users) =
        (header.index("t_s")?, header.index("q_0")?, header.index("closure_error_m")?, header.index("users")?);
    let (pose_len, k) = (pose_names(kind).len(), kind.op_dim());
    // Per user: id, pose, wrench, count (server/src/driver/record.rs).
    let group = 1 + pose_len + k + 1;
    let first_group = users + 1;
    if first_group != 2 + 2 * n + m + 2 {
        return Err(bad_row(file, 1, "the header does not have the VE record's layout (t, step, q, q̇, λ, ...)"));
    }
    rows.into_iter()
        .map(|(line, row)| {
            let present = row.get(users).copied().unwrap_or(f64::NAN);
            if !(present >= 0.0 && present.fract() == 0.0) {
                return Err(bad_row(file, line, format!("user count {present} is not a count")));
            }
            let expected = first_group + present as usize * group;
            if row.len() != expected {
                return Err(bad_row(file, line, format!("{} fields, {present} users need {expected}", row.len())));
            }
            let users = row[first_group..]
                .chunks_exact(group)
                .map(|g| {
                    let position = g[1..1 + kind.point_dim()].to_vec();
                    let wrench = g[1 + pose_len..1 + pose_len + k].to_vec();
                    (g[0] as u32, position, wrench, g[group - 1] as u8)
                })
                .collect();
            Ok(VeSample {
                t: row[time],
                q: row[q0..q0 + n].to_vec(),
                closure_error: row[closure],
                users,
                kinetic_energy: f64::NAN,
                potential_energy: f64::NAN,
            })
        })
        .collect()
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

    #[test]
    fn broken_client_files_name_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let short = write(dir.path(), "short.csv", &format!("{CLIENT_HEADER}\n0.1,2\n"));
        let e = read_client(&short, SceneKind::Planar).unwrap_err().to_string();
        assert!(e.contains("short.csv:2") && e.contains("2 fields"), "{e}");
        let text = write(dir.path(), "text.csv", &format!("{CLIENT_HEADER}\n0.1,x\n"));
        let e = read_client(&text, SceneKind::Planar).unwrap_err().to_string();
        assert!(e.contains("text.csv:2") && e.contains("\"x\""), "{e}");
        let e = read_client(&write(dir.path(), "h.csv", "time_s,gain\n"), SceneKind::Planar).unwrap_err();
        assert!(matches!(e, RecordReadError::MissingColumn { .. }), "{e}");
        let e = read_client(&write(dir.path(), "e.csv", ""), SceneKind::Planar).unwrap_err();
        assert!(matches!(e, RecordReadError::Empty { .. }), "{e}");
        let e = read_client(&dir.path().join("absent.csv"), SceneKind::Planar).unwrap_err();
        assert!(matches!(e, RecordReadError::Io { .. }), "{e}");
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

    #[test]
    fn a_ve_row_with_the_wrong_width_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let good = std::fs::read_to_string(ve_file(dir.path())).unwrap();
        let bad = write(dir.path(), "bad.csv", &format!("{good}0.003,3,0.6,0,0,0,2,7,0.4\n"));
        let e = read_ve(&bad, SceneKind::Planar).unwrap_err().to_string();
        assert!(e.contains("bad.csv:4") && e.contains("2 users need 23"), "{e}");
    }
}
