//! A synthetic user: the in-process stand-in for a client that `kinloop bench`'s VE tick and
//! `kinloop-server --synthetic-users` drive. It follows the VE (each uplink puts its local model where its
//! newest snapshot put the OP), pushes an equal share of the paper's hand wrench, and keeps a client's
//! energy books (`kinloop_protocol::passivity::PortBooks`, booked as a client's local model books them), so
//! the server checks and accepts its reports as it does a real client's rather than refusing them all.

use kinloop_linkage::model::builtin::PAPER_WRENCH;
use kinloop_protocol::passivity::{PortBooks, MAX_AXES};
use kinloop_protocol::Snapshot;

use crate::core::UplinkSample;

/// One synthetic user's state between uplinks (see the module documentation).
#[derive(Clone, Debug)]
pub struct SyntheticUser {
    /// The next uplink, once a snapshot has come (`None` before: a client sends nothing it could follow).
    sample: Option<UplinkSample>,
    /// Its share of the paper's hand wrench: 1 / users.
    share: f64,
    books: PortBooks,
    /// Client clock of the last uplink (s).
    last_uplink_s: Option<f64>,
}

impl SyntheticUser {
    /// One of `users` synthetic users sharing the paper's push (shares of alternating sign would cancel
    /// exactly on one OP and leave the linkage standing still).
    pub fn new(users: usize) -> Self {
        SyntheticUser {
            sample: None,
            share: 1.0 / users.max(1) as f64,
            books: PortBooks::default(),
            last_uplink_s: None,
        }
    }

    /// Takes a snapshot in: the next uplink answers it, with the local model where the VE put the OP.
    pub fn on_snapshot(&mut self, snapshot: &Snapshot) {
        let k = snapshot.op_twist.len().min(MAX_AXES);
        let share = self.share;
        let sample = self.sample.get_or_insert_with(|| {
            let mut sample = UplinkSample::zeroed(k as u8, snapshot.op_pose.len() as u8);
            for (a, w) in PAPER_WRENCH.iter().enumerate().take(k) {
                sample.hand_wrench[a] = w * share;
            }
            sample
        });
        sample.last_snapshot_seq = snapshot.seq;
        sample.model_pose[..snapshot.op_pose.len()].copy_from_slice(&snapshot.op_pose);
        sample.model_twist[..k].copy_from_slice(&snapshot.op_twist[..k]);
    }

    /// The uplink numbered `seq` sent at client time `time_s` (after the last one's), its books grown by what
    /// its hand put into its local model since the last uplink; `None` before the first snapshot.
    pub fn uplink(&mut self, seq: u64, time_s: f64) -> Option<&UplinkSample> {
        let sample = self.sample.as_mut()?;
        let k = usize::from(sample.op_dim);
        if let Some(last_s) = self.last_uplink_s {
            let mut power_out = [0.0; MAX_AXES];
            for (a, p) in power_out.iter_mut().enumerate().take(k) {
                // Power into the local model is energy this end of the two-port received.
                *p = -sample.hand_wrench[a] * sample.model_twist[a];
            }
            self.books.book(&power_out[..k], time_s - last_s);
        }
        self.last_uplink_s = Some(time_s);
        sample.seq = seq;
        sample.client_time_s = time_s;
        sample.energy_received_j[..k].copy_from_slice(&self.books.received_j[..k]);
        sample.energy_emitted_j[..k].copy_from_slice(&self.books.emitted_j[..k]);
        Some(sample)
    }

    /// The books so far.
    pub fn books(&self) -> &PortBooks {
        &self.books
    }
}
