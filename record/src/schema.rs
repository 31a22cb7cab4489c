//! The columns of each record and how each column's numbers are printed. A client's record has fixed columns
//! for its scene's kind; a server's has fixed columns for the scene's coordinates and closure rows, then one
//! group of columns per user present (the header names the group once).

use kinloop_linkage::math::space::SceneKind;

use crate::axes::{pose_names, wrench_names};

/// How a column's numbers are printed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// A fixed number of decimals.
    Fixed(usize),
    /// Whole numbers without a fraction, others in the shortest form that reads back exactly.
    Shortest,
}

/// The client's per-tick columns' prefixes for its six wrenches, in file order.
pub const CLIENT_WRENCHES: [&str; 6] = ["hand", "pc", "jc", "imp", "contact", "cmd"];

/// The client's record (`kinloop-client --record`): one row per haptic tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClientSchema {
    /// The scene's kind: the pose and wrench columns.
    pub kind: SceneKind,
}

impl ClientSchema {
    /// Loop time: microseconds.
    pub const TIME: Format = Format::Fixed(6);
    /// Poses: nanometres, so that a replay draws the recorded point.
    pub const POSE: Format = Format::Fixed(9);
    /// Wrenches: micronewtons.
    pub const WRENCH: Format = Format::Fixed(6);
    /// The constraint count.
    pub const COUNT: Format = Format::Shortest;
    /// Snapshot age: microseconds.
    pub const AGE: Format = Format::Fixed(6);
    /// Output gain.
    pub const GAIN: Format = Format::Fixed(4);
    /// The server session (0 between servers).
    pub const SESSION: Format = Format::Shortest;
    /// The last column, which records written before it was added lack (read as session 1).
    pub const SESSION_COLUMN: &'static str = "session";

    /// Every column's name, in file order.
    pub fn columns(&self) -> Vec<String> {
        let mut columns = vec!["time_s".to_owned()];
        for prefix in ["device", "model"] {
            columns.extend(pose_names(self.kind).iter().map(|n| format!("{prefix}_{n}")));
        }
        for prefix in CLIENT_WRENCHES {
            columns.extend(wrench_names(self.kind).iter().map(|n| format!("{prefix}_{n}")));
        }
        columns.extend(["constraint_count", "snapshot_age_s", "gain", Self::SESSION_COLUMN].map(String::from));
        columns
    }

    /// The header line (without its newline).
    pub fn header(&self) -> String {
        self.columns().join(",")
    }
}

/// The last header column of a server's record: the user group's columns repeat once per user.
pub const USER_GROUP_REPEATS: &str = "...(user group repeated per user)";

/// The server's record (`kinloop-server --record`): one row per VE step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VeSchema {
    /// The scene's kind: the user group's pose and wrench columns.
    pub kind: SceneKind,
    /// Configuration coordinates (the `q_*` columns): `n`, or more with ball joints (a unit quaternion's four
    /// per three rates).
    pub nq: usize,
    /// Velocity coordinates (the `qd_*` columns).
    pub n: usize,
    /// Closure rows.
    pub m: usize,
}

impl VeSchema {
    /// Every number: whole numbers (step, user ids, counts) without a fraction.
    pub const NUMBER: Format = Format::Shortest;

    /// The columns before the user groups: `t_s, step, q_*, qd_*, lambda_*, closure_error_m, users`.
    pub fn fixed_columns(&self) -> Vec<String> {
        let mut columns = vec!["t_s".to_string(), "step".into()];
        columns.extend((0..self.nq).map(|i| format!("q_{i}")));
        columns.extend((0..self.n).map(|i| format!("qd_{i}")));
        columns.extend((0..self.m).map(|i| format!("lambda_{i}")));
        columns.extend(["closure_error_m".to_string(), "users".into()]);
        columns
    }

    /// One user group's columns: `user_id, op_<pose>, wrench_<axes>, constraint_count`.
    pub fn group_columns(&self) -> Vec<String> {
        let mut columns = vec!["user_id".to_string()];
        columns.extend(pose_names(self.kind).iter().map(|p| format!("op_{p}")));
        columns.extend(wrench_names(self.kind).iter().map(|a| format!("wrench_{a}")));
        columns.push("constraint_count".into());
        columns
    }

    /// Numbers before the user groups.
    pub fn fixed_len(&self) -> usize {
        2 + self.nq + self.n + self.m + 2
    }

    /// Numbers in one user group.
    pub fn group_len(&self) -> usize {
        1 + pose_names(self.kind).len() + wrench_names(self.kind).len() + 1
    }

    /// The header line (without its newline): the fixed columns, one user group, [`USER_GROUP_REPEATS`].
    pub fn header(&self) -> String {
        let mut columns = self.fixed_columns();
        columns.extend(self.group_columns());
        columns.push(USER_GROUP_REPEATS.into());
        columns.join(",")
    }

    /// The name of the number at `index` in a row, the user's place counted from 1 (`user 2 op_x`).
    pub fn column_name(&self, index: usize) -> String {
        match index.checked_sub(self.fixed_len()) {
            None => self.fixed_columns().swap_remove(index),
            Some(at) => {
                let (user, within) = (at / self.group_len(), at % self.group_len());
                format!("user {} {}", user + 1, self.group_columns().swap_remove(within))
            }
        }
    }
}

/// The kind of scene a header was written for: planar records name a `theta` column.
pub fn kind_of(columns: &[&str]) -> SceneKind {
    if columns.iter().any(|c| c.ends_with("_theta")) {
        SceneKind::Planar
    } else {
        SceneKind::Spatial
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_client_header_names_every_planar_column_once() {
        let header = ClientSchema { kind: SceneKind::Planar }.header();
        assert_eq!(
            header,
            "time_s,device_x,device_y,device_theta,model_x,model_y,model_theta,hand_fx,hand_fy,hand_tz,pc_fx,\
             pc_fy,pc_tz,jc_fx,jc_fy,jc_tz,imp_fx,imp_fy,imp_tz,contact_fx,contact_fy,contact_tz,cmd_fx,cmd_fy,\
             cmd_tz,constraint_count,snapshot_age_s,gain,session"
        );
        assert_eq!(ClientSchema { kind: SceneKind::Spatial }.columns().len(), 1 + 2 * 7 + 6 * 6 + 4);
    }

    #[test]
    fn the_ve_header_names_one_user_group_and_says_it_repeats() {
        let schema = VeSchema { kind: SceneKind::Planar, nq: 2, n: 2, m: 1 };
        assert_eq!(
            schema.header(),
            "t_s,step,q_0,q_1,qd_0,qd_1,lambda_0,closure_error_m,users,user_id,op_x,op_y,op_theta,wrench_fx,\
             wrench_fy,wrench_tz,constraint_count,...(user group repeated per user)"
        );
        assert_eq!((schema.fixed_len(), schema.group_len()), (9, 8));
        assert_eq!(schema.column_name(2), "q_0");
        assert_eq!(schema.column_name(9 + 8 + 1), "user 2 op_x");
    }
}
