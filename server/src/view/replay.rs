//! Recordings in the page (`kinloop view FILE.csv`): a server's `--record` CSV (one row per VE step: q and
//! every user's OP, wrench and constraint count) or a client's (one row per haptic tick: device and
//! local-model poses, hand wrench, constraint count). The page's timeline slider asks for a time
//! (`seek`); the row at or before it is drawn like a live frame.
//!
//! A client's recording holds the OP but not q: the linkage is drawn at the coordinates that close the
//! loops and put the scene's first OP on the recorded local-model OP (see [`Geometry::solve_for_op`]).

use std::path::Path;

use kinloop_linkage::{math::space::SceneKind, model::scene::Scene};

use super::compose::{compose, UserInfo};
use super::draw::{geometry, Geometry, SceneInfo};
use super::messages::{ReplayInfo, ToPage};
use super::sample::{pose_len, Sample, SampleUser};

/// Rows kept at most (an hour of a 1 kHz VE is 3.6 M rows; a page needs far fewer): longer recordings
/// keep every k-th row.
pub const MAX_ROWS: usize = 200_000;

/// A recording that cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file could not be read.
    #[error("cannot read {file}: {source}")]
    Read {
        /// The file.
        file: String,
        /// Why.
        source: std::io::Error,
    },
    /// Neither a server's nor a client's recording.
    #[error("{file}: not a kinloop recording (the header starts with neither t_s,step nor time_s,device_)")]
    UnknownFormat {
        /// The file.
        file: String,
    },
    /// A recording made on another scene.
    #[error("{file}: {what}; the scene {scene} does not match (pass the recording's scene with --scene)")]
    SceneMismatch {
        /// The file.
        file: String,
        /// What does not match.
        what: String,
        /// The scene given.
        scene: String,
    },
    /// A row that does not parse.
    #[error("{file}:{line}: {what}")]
    BadRow {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// No rows.
    #[error("{file}: no rows")]
    Empty {
        /// The file.
        file: String,
    },
    /// The scene does not compile.
    #[error(transparent)]
    Scene(#[from] kinloop_linkage::error::SceneError),
}

/// A loaded recording and the scene to draw it in.
pub struct Replay {
    samples: Vec<Sample>,
    geometry: Box<dyn Geometry>,
    info: ReplayInfo,
    users: Vec<UserInfo>,
}

impl std::fmt::Debug for Replay {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Replay").field("info", &self.info).finish_non_exhaustive()
    }
}

impl Replay {
    /// Reads `path` and checks it against `scene`.
    pub fn load(path: &Path, scene: &Scene, scene_label: &str) -> Result<Replay, ReplayError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ReplayError::Read { file: file.clone(), source })?;
        let name = path.file_name().map_or(file.clone(), |n| n.to_string_lossy().into_owned());
        Replay::parse(&text, &name, scene, scene_label)
    }

    /// Parses a recording's text; `file` names it in errors.
    pub fn parse(text: &str, file: &str, scene: &Scene, scene_label: &str) -> Result<Replay, ReplayError> {
        let mut geometry = geometry(scene, scene_label)?;
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let Some((_, header)) = lines.next() else { return Err(ReplayError::Empty { file: file.into() }) };
        let columns: Vec<&str> = header.split(',').map(str::trim).collect();
        let mismatch = |what: String| ReplayError::SceneMismatch { file: file.into(), what, scene: scene_label.into() };
        let server = columns.starts_with(&["t_s", "step"]);
        let client = columns.first() == Some(&"time_s") && columns.get(1).is_some_and(|c| c.starts_with("device_"));
        if !server && !client {
            return Err(ReplayError::UnknownFormat { file: file.into() });
        }
        let recorded_kind =
            if columns.iter().any(|c| c.ends_with("_theta")) { SceneKind::Planar } else { SceneKind::Spatial };
        if recorded_kind != scene.kind {
            return Err(mismatch(format!("it was recorded on a {recorded_kind:?} scene")));
        }
        let (source, rows) = if server {
            let n = columns.iter().filter(|c| c.starts_with("q_")).count();
            let m = columns.iter().filter(|c| c.starts_with("lambda_")).count();
            if n != geometry.info().n {
                return Err(mismatch(format!("it has {n} coordinates, the scene {}", geometry.info().n)));
            }
            ("server", server_rows(lines, file, scene.kind, n, m)?)
        } else {
            ("client", client_rows(lines, file, scene.kind, geometry.as_mut())?)
        };
        let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
            return Err(ReplayError::Empty { file: file.into() });
        };
        let info = ReplayInfo { file: file.into(), source, t0: first.t_s, t1: last.t_s, rows: rows.len() };
        let users = if source == "client" {
            vec![UserInfo {
                id: 0,
                name: file.into(),
                device: "recorded".into(),
                op: geometry.info().ops.first().cloned().unwrap_or_default(),
                ..UserInfo::default()
            }]
        } else {
            Vec::new()
        };
        Ok(Replay { samples: thin(rows), geometry, info, users })
    }

    /// The recording's extent.
    pub fn info(&self) -> &ReplayInfo {
        &self.info
    }

    /// The scene it is drawn in.
    pub fn scene_info(&self) -> &SceneInfo {
        self.geometry.info()
    }

    /// Index of the row shown at time `t`: the last at or before it (the first before the start).
    pub fn index_at(&self, t: f64) -> usize {
        self.samples.partition_point(|s| s.t_s <= t).saturating_sub(1)
    }

    /// The row shown at time `t`.
    pub fn sample_at(&self, t: f64) -> &Sample {
        &self.samples[self.index_at(t)]
    }

    /// The frame message for time `t`.
    pub fn frame_text(&mut self, t: f64) -> String {
        let index = self.index_at(t);
        let frame = compose(index as u64, &self.samples[index], self.geometry.as_mut(), &self.users);
        serde_json::to_string(&ToPage::Frame(&frame)).unwrap_or_default()
    }
}

/// Keeps at most [`MAX_ROWS`] rows, evenly (the last one always).
fn thin(rows: Vec<Sample>) -> Vec<Sample> {
    if rows.len() <= MAX_ROWS {
        return rows;
    }
    let every = rows.len().div_ceil(MAX_ROWS);
    let last = rows.len() - 1;
    rows.into_iter().enumerate().filter(|(i, _)| i % every == 0 || *i == last).map(|(_, s)| s).collect()
}

fn numbers(line: &str, file: &str, index: usize) -> Result<Vec<f64>, ReplayError> {
    line.split(',').map(|v| v.trim().parse::<f64>()).collect::<Result<Vec<f64>, _>>().map_err(|e| ReplayError::BadRow {
        file: file.into(),
        line: index + 1,
        what: format!("not a number: {e}"),
    })
}

fn server_rows<'a>(
    lines: impl Iterator<Item = (usize, &'a str)>,
    file: &str,
    kind: SceneKind,
    n: usize,
    m: usize,
) -> Result<Vec<Sample>, ReplayError> {
    let (k, pose) = (kind.op_dim(), pose_len(kind));
    let group = 1 + pose + k + 1;
    let fixed = 2 + 2 * n + m + 2;
    let mut rows = Vec::new();
    for (index, line) in lines {
        let v = numbers(line, file, index)?;
        let bad = |what: String| ReplayError::BadRow { file: file.into(), line: index + 1, what };
        if v.len() < fixed {
            return Err(bad(format!("{} numbers; a row has at least {fixed}", v.len())));
        }
        let users = v[fixed - 1] as usize;
        if v.len() != fixed + users * group {
            return Err(bad(format!("{} numbers for {users} users; expected {}", v.len(), fixed + users * group)));
        }
        let users = v[fixed..]
            .chunks_exact(group)
            .map(|g| SampleUser {
                id: g[0] as u32,
                present: true,
                weight: 1.0,
                op_pose: g[1..1 + pose].to_vec(),
                wrench: g[1 + pose..1 + pose + k].to_vec(),
                constraint_count: g[group - 1] as u8,
                ..SampleUser::default()
            })
            .collect();
        rows.push(Sample {
            t_s: v[0],
            step: v[1] as u64,
            q: v[2..2 + n].to_vec(),
            closure_error: Some(v[fixed - 2]),
            timing: None,
            users,
        });
    }
    Ok(rows)
}

fn client_rows<'a>(
    lines: impl Iterator<Item = (usize, &'a str)>,
    file: &str,
    kind: SceneKind,
    geometry: &mut dyn Geometry,
) -> Result<Vec<Sample>, ReplayError> {
    let (k, pose) = (kind.op_dim(), pose_len(kind));
    let point = if kind == SceneKind::Planar { 2 } else { 3 };
    // time, device pose, model pose, six wrenches, count, snapshot age, gain.
    let len = 1 + 2 * pose + 6 * k + 3;
    let mut rows = Vec::new();
    let mut q: Vec<f64> = Vec::new();
    for (index, line) in lines {
        let v = numbers(line, file, index)?;
        if v.len() != len {
            let what = format!("{} numbers; a client row of this scene has {len}", v.len());
            return Err(ReplayError::BadRow { file: file.into(), line: index + 1, what });
        }
        let device = v[1..1 + pose].to_vec();
        let model = v[1 + pose..1 + 2 * pose].to_vec();
        if let Some(solved) = geometry.solve_for_op(&q, 0, &model[..point]) {
            q = solved;
        }
        rows.push(Sample {
            t_s: v[0],
            step: 0,
            q: q.clone(),
            closure_error: None,
            timing: None,
            users: vec![SampleUser {
                id: 0,
                present: true,
                weight: v[len - 1],
                op_pose: model.clone(),
                wrench: v[1 + 2 * pose..1 + 2 * pose + k].to_vec(),
                constraint_count: v[len - 3] as u8,
                device_pose: Some(device),
                model_pose: Some(model),
                ..SampleUser::default()
            }],
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use kinloop_linkage::algorithms::assemble::assemble;
    use kinloop_linkage::algorithms::kinematics::forward_kinematics;
    use kinloop_linkage::math::space::OpPose;
    use kinloop_linkage::{math::space::Planar, model::builtin, model::data::Data, model::Model};

    use super::*;

    fn testbed() -> Scene {
        builtin::scene("paper-testbed").unwrap().unwrap()
    }

    /// link2's OP at the closed configuration nearest `q`.
    fn op_near(model: &Model<Planar>, q: &[f64]) -> [f64; 2] {
        let closed = assemble(model, &nalgebra::DVector::from_column_slice(q), 1e-12).unwrap().q;
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, &closed);
        let p = OpPose::<Planar>::of_op(model, &data, 0).position;
        [p.x, p.y]
    }

    fn client_row(t: f64, op: [f64; 2]) -> String {
        let pose = format!("{},{},0.1", op[0], op[1]);
        format!("{t},{pose},{pose},{},2,0.001,1\n", ["0.5,0,0"; 6].join(","))
    }

    #[test]
    fn a_client_recording_is_drawn_with_the_linkage_posed_on_its_op() {
        let scene = testbed();
        let model = Model::<Planar>::compile(&scene, "t").unwrap();
        let a = op_near(&model, model.q0.as_slice());
        let moved: Vec<f64> = model.q0.iter().enumerate().map(|(i, q)| q + if i == 0 { 0.1 } else { 0.0 }).collect();
        let b = op_near(&model, &moved);
        let header = "time_s,device_x,device_y,device_theta,model_x,model_y,model_theta,hand_fx,hand_fy,hand_tz,\
                      pc_fx,pc_fy,pc_tz,jc_fx,jc_fy,jc_tz,imp_fx,imp_fy,imp_tz,contact_fx,contact_fy,contact_tz,\
                      cmd_fx,cmd_fy,cmd_tz,constraint_count,snapshot_age_s,gain\n";
        let text = format!("{header}{}{}", client_row(0.0, a), client_row(0.5, b));
        let mut replay = Replay::parse(&text, "user1.csv", &scene, "paper-testbed").unwrap();
        assert_eq!((replay.info().source, replay.info().rows, replay.info().t1), ("client", 2, 0.5));
        let frame: serde_json::Value = serde_json::from_str(&replay.frame_text(0.7)).unwrap();
        let drawn = &frame["linkage"]["ops"][0];
        let error = (drawn[0].as_f64().unwrap() - b[0]).hypot(drawn[1].as_f64().unwrap() - b[1]);
        assert!(error < 1e-6, "the drawn OP {drawn} is the recorded {b:?}");
        assert_eq!(frame["users"][0]["count"], 2);
        // serde_json reads floats to within an ulp.
        assert!((frame["users"][0]["device_pose"][0].as_f64().unwrap() - b[0]).abs() < 1e-15);
        assert_eq!(replay.index_at(-1.0), 0, "before the start: the first row");
    }

    #[test]
    fn recordings_that_do_not_fit_say_why() {
        let scene = testbed();
        let other = |text: &str| Replay::parse(text, "x.csv", &scene, "paper-testbed").unwrap_err().to_string();
        assert!(other("").contains("no rows"));
        assert!(other("a,b,c\n1,2,3\n").contains("not a kinloop recording"));
        let six = "t_s,step,q_0,q_1,q_2,q_3,q_4,q_5,op_x,op_y,op_theta\n";
        assert!(other(six).contains("6 coordinates"), "{}", other(six));
        let spatial = "time_s,device_x,device_y,device_z,device_qw\n";
        assert!(other(spatial).contains("Spatial"), "{}", other(spatial));
        let header = "t_s,step,q_0,q_1,q_2,q_3,qd_0,qd_1,qd_2,qd_3,lambda_0,lambda_1,closure_error_m,users,op_theta\n";
        let bad = other(&format!("{header}0,1,0,0,0,0,0,0,0,0,0,0,0,0\n0,2,x\n"));
        assert!(bad.starts_with("x.csv:3: not a number"), "{bad}");
        let short = other(&format!("{header}0,1,0,0,0,0,0,0,0,0,0,0,0,1\n"));
        assert!(short.contains("for 1 users"), "{short}");
    }
}
