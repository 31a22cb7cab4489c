//! Recordings in the page (`kinloop view FILE.csv`): a server's `--record` CSV (one row per VE step: q and
//! every user's OP, wrench and constraint count) or a client's (one row per haptic tick: device and
//! local-model poses, hand wrench, constraint count). The page's timeline slider asks for a time
//! (`seek`); the row at or before it is drawn like a live frame.
//!
//! A client's recording holds the OP but not q: the linkage is drawn at the coordinates that close the
//! loops and put the scene's first OP on the recorded local-model OP (see [`Geometry::solve_for_op`]).

use std::path::Path;

use kinloop_linkage::{math::space::SceneKind, model::scene::Scene};
use kinloop_record::{ReadError, Recording, TickRecord, VeRow};

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
    /// The file is not a recording, or a row of it does not parse.
    #[error(transparent)]
    Record(#[from] ReadError),
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
        let recording = kinloop_record::parse(text, file)?;
        let mismatch = |what: String| ReplayError::SceneMismatch { file: file.into(), what, scene: scene_label.into() };
        if recording.kind() != scene.kind {
            return Err(mismatch(format!("it was recorded on a {:?} scene", recording.kind())));
        }
        let (source, rows) = match recording {
            Recording::Ve { schema, rows } => {
                if schema.nq != geometry.info().n {
                    return Err(mismatch(format!("it has {} coordinates, the scene {}", schema.nq, geometry.info().n)));
                }
                ("server", rows.iter().map(|r| server_sample(r, scene.kind)).collect())
            }
            Recording::Client { rows, .. } => ("client", client_samples(&rows, scene.kind, geometry.as_mut())),
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

/// A server's row as a frame's sample.
fn server_sample(r: &VeRow, kind: SceneKind) -> Sample {
    let (k, pose) = (kind.op_dim(), pose_len(kind));
    let users = r
        .users
        .iter()
        .map(|u| SampleUser {
            id: u.user_id,
            present: true,
            weight: 1.0,
            op_pose: u.op_pose[..pose].to_vec(),
            wrench: u.wrench[..k].to_vec(),
            constraint_count: u.constraint_count,
            ..SampleUser::default()
        })
        .collect();
    Sample { t_s: r.t_s, step: r.step, q: r.q.clone(), closure_error: Some(r.closure_error), timing: None, users }
}

/// A client's rows as frames' samples: the linkage posed so that its first OP is on the recorded
/// local-model OP, each row starting from the previous row's coordinates.
fn client_samples(rows: &[TickRecord], kind: SceneKind, geometry: &mut dyn Geometry) -> Vec<Sample> {
    let (k, pose) = (kind.op_dim(), pose_len(kind));
    let point = kind.point_dim();
    let mut q: Vec<f64> = Vec::new();
    let mut samples = Vec::with_capacity(rows.len());
    for r in rows {
        let model = r.model_pose[..pose].to_vec();
        if let Some(solved) = geometry.solve_for_op(&q, 0, &model[..point]) {
            q = solved;
        }
        samples.push(Sample {
            t_s: r.time_s,
            step: 0,
            q: q.clone(),
            closure_error: None,
            timing: None,
            users: vec![SampleUser {
                id: 0,
                present: true,
                weight: r.gain,
                op_pose: model.clone(),
                wrench: r.hand[..k].to_vec(),
                constraint_count: r.constraint_count,
                device_pose: Some(r.device_pose[..pose].to_vec()),
                model_pose: Some(model),
                ..SampleUser::default()
            }],
        });
    }
    samples
}

#[cfg(test)]
mod tests {
    use kinloop_linkage::algorithms::assemble::assemble;
    use kinloop_linkage::algorithms::kinematics::forward_kinematics;
    use kinloop_linkage::math::space::OpPose;
    use kinloop_linkage::{math::space::Planar, model::builtin, model::data::Data, model::Model};

    use kinloop_record::{ClientSchema, VeSchema};

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
        let six = VeSchema { kind: SceneKind::Planar, nq: 6, n: 6, m: 4 }.header();
        assert!(other(&six).contains("6 coordinates"), "{}", other(&six));
        let spatial = ClientSchema { kind: SceneKind::Spatial }.header();
        assert!(other(&spatial).contains("Spatial"), "{}", other(&spatial));
        let header = VeSchema { kind: SceneKind::Planar, nq: 4, n: 4, m: 2 }.header();
        let header_row = "0,1,0,0,0,0,0,0,0,0,0,0,0,0";
        let bad = other(&format!("{header}\n{header_row}\n0,2,x\n"));
        assert!(bad.starts_with("x.csv:3: column q_0: \"x\" is not a number"), "{bad}");
        let short = other(&format!("{header}\n0,1,0,0,0,0,0,0,0,0,0,0,0,1\n"));
        assert!(short.contains("14 fields, expected 22"), "{short}");
    }
}
