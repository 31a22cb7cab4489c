//! What one drawn frame is made of, whichever source it comes from: the live tap's ring
//! ([`take_latest`]) or a recording (`replay`).

use kinloop_linkage::math::space::SceneKind;
use rtrb::Consumer;

use super::tap::{user_group_len, HEAD};

/// One user in a [`Sample`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SampleUser {
    /// Id in the VE.
    pub id: u32,
    /// An observer (never pushes).
    pub observer: bool,
    /// Still present (not fading out after leaving).
    pub present: bool,
    /// Fade weight of the last step.
    pub weight: f64,
    /// The user's OP in the VE (x, y, θ or x, y, z, qw, qx, qy, qz).
    pub op_pose: Vec<f64>,
    /// The wrench the last step applied at the OP.
    pub wrench: Vec<f64>,
    /// Constraint count of the user's newest snapshot.
    pub constraint_count: u8,
    /// Singular values of the scaled Λ̃⁻¹, decreasing (empty when unknown).
    pub singular_values: Vec<f64>,
    /// Singular directions, column-major k×k in `(v, L ω)`; the last `constraint_count` are constrained
    /// (empty when unknown).
    pub directions: Vec<f64>,
    /// Device pose in the VE, when known (client uplinks, client recordings).
    pub device_pose: Option<Vec<f64>>,
    /// Local-model OP pose, when known.
    pub model_pose: Option<Vec<f64>>,
}

/// The VE loop's timing when the frame was taken.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleTiming {
    /// Median loop iteration (ns).
    pub p50_ns: f64,
    /// 99th percentile (ns).
    pub p99_ns: f64,
    /// Largest (ns).
    pub max_ns: f64,
    /// Deadline misses so far.
    pub misses: f64,
}

/// The state one frame draws.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sample {
    /// VE time (s).
    pub t_s: f64,
    /// VE step.
    pub step: u64,
    /// Generalized coordinates (empty when the source has none: the linkage is then not drawn).
    pub q: Vec<f64>,
    /// Closure residual (m), when known.
    pub closure_error: Option<f64>,
    /// Loop timing, when live.
    pub timing: Option<SampleTiming>,
    /// Users.
    pub users: Vec<SampleUser>,
}

/// Pose length of a scene kind on the wire.
pub fn pose_len(kind: SceneKind) -> usize {
    match kind {
        SceneKind::Planar => 3,
        SceneKind::Spatial => 7,
    }
}

/// Reads every complete frame from the tap's ring and decodes the newest; `None` when none was waiting or
/// the newest does not parse (which would be a bug in the tap: it is skipped, not trusted).
pub fn take_latest(ring: &mut Consumer<f64>, kind: SceneKind) -> Option<Sample> {
    let mut newest = None;
    while let Ok(&len) = ring.peek() {
        let len = len as usize;
        let is_last = ring.slots() == len + 1;
        let Ok(chunk) = ring.read_chunk(len + 1) else { break };
        if is_last {
            let (a, b) = chunk.as_slices();
            let values: Vec<f64> = a.iter().chain(b).skip(1).copied().collect();
            newest = decode(&values, kind);
        }
        chunk.commit_all();
    }
    newest
}

/// Decodes one frame (without its length prefix).
pub fn decode(v: &[f64], kind: SceneKind) -> Option<Sample> {
    let k = kind.op_dim();
    let pose = pose_len(kind);
    let n = *v.get(HEAD - 1)? as usize;
    let users = *v.get(HEAD + n)? as usize;
    let group = user_group_len(k, pose);
    if v.len() != HEAD + n + 1 + users * group {
        return None;
    }
    let mut sample = Sample {
        t_s: v[0],
        step: v[1] as u64,
        q: v[HEAD..HEAD + n].to_vec(),
        closure_error: Some(v[2]),
        timing: Some(SampleTiming { p50_ns: v[3], p99_ns: v[4], max_ns: v[5], misses: v[6] }),
        users: Vec::with_capacity(users),
    };
    for g in v[HEAD + n + 1..].chunks_exact(group) {
        let at = 4 + pose;
        let count = g[at + k] as u8;
        let known = g[at + k + 1..at + 2 * k + 1].iter().any(|s| *s != 0.0);
        sample.users.push(SampleUser {
            id: g[0] as u32,
            observer: g[1] != 0.0,
            present: g[2] != 0.0,
            weight: g[3],
            op_pose: g[4..at].to_vec(),
            wrench: g[at..at + k].to_vec(),
            constraint_count: count,
            singular_values: if known { g[at + k + 1..at + 2 * k + 1].to_vec() } else { Vec::new() },
            directions: if known { g[at + 2 * k + 1..].to_vec() } else { Vec::new() },
            device_pose: None,
            model_pose: None,
        });
    }
    Some(sample)
}
