//! Taking up a room's state offered by a reconnecting client (see `docs/resume.md`): the driver has checked
//! the room key's signature, the scene and the age; the VE checks that the state fits the linkage, closes
//! its loops (eq 2: h(q) = 0) and respects the wire's bounds, and starts from it.

use std::time::Duration;

use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::math::space::Space;
use kinloop_protocol::codec::limits::{MAX_POSITION, MAX_SPEED};
use kinloop_protocol::ResumeRefusal;
use nalgebra::DVector;

use super::closing::close_loops;
use super::{VeCore, VeEvent, BROKEN_CLOSURE_PER_LENGTH};

impl<S: Space> VeCore<S> {
    /// Resumes the room from an authenticated state `(q, q̇)`: refused while users are present (the live
    /// state wins), when the lengths do not fit the scene, a number is not finite or beyond the wire's bounds,
    /// or the loops are open by more than a step may start from (`BROKEN_CLOSURE_PER_LENGTH` of the length
    /// scale). A state slightly off is re-assembled onto the loops (Newton on h(q)); its velocities are
    /// projected by the first step as any step's are. Every refusal is counted.
    pub fn handle_resume_offer(&mut self, _now: Duration, q: &[f64], qd: &[f64]) -> Result<(), ResumeRefusal> {
        let outcome = self.resume_from(q, qd);
        match &outcome {
            Ok(()) => {
                self.metrics.resumes_accepted += 1;
                self.events.push(VeEvent::RoomResumed { step: self.step });
            }
            Err(_) => self.metrics.resumes_refused += 1,
        }
        outcome
    }

    fn resume_from(&mut self, q: &[f64], qd: &[f64]) -> Result<(), ResumeRefusal> {
        let users = self.present_users();
        if users > 0 {
            return Err(ResumeRefusal::RoomLive { users: users as u32 });
        }
        let (n, nv) = (self.q.len(), self.qd.len());
        if q.len() != n || qd.len() != nv {
            let what = format!("{} coordinates and {} velocities, the scene has {n} and {nv}", q.len(), qd.len());
            return Err(ResumeRefusal::Shape { what });
        }
        let beyond = |v: &[f64], bound: f64| v.iter().position(|x| !x.is_finite() || x.abs() > bound);
        if let Some(i) = beyond(q, MAX_POSITION) {
            return Err(ResumeRefusal::Shape { what: format!("q[{i}] = {} is beyond ±{MAX_POSITION}", q[i]) });
        }
        if let Some(i) = beyond(qd, MAX_SPEED) {
            return Err(ResumeRefusal::Shape { what: format!("qd[{i}] = {} is beyond ±{MAX_SPEED}", qd[i]) });
        }
        let q = match close_loops(&self.model, &mut self.data, &DVector::from_column_slice(q)) {
            Ok(closed) => closed.q,
            Err(residual_m) => {
                self.restore_kinematics();
                let tolerance_m = BROKEN_CLOSURE_PER_LENGTH * self.model.length_scale;
                return Err(ResumeRefusal::Loops { residual_m, tolerance_m });
            }
        };
        self.q.copy_from(&q);
        self.qd.copy_from_slice(qd);
        self.energy_guard.reset();
        self.checkpoint_q.copy_from(&q);
        self.step_start_q.copy_from(&q);
        self.lambda.fill(0.0);
        self.restore_kinematics();
        Ok(())
    }

    /// Body poses and velocities at the VE's own state again.
    fn restore_kinematics(&mut self) {
        forward_kinematics(&self.model, &mut self.data, &self.q);
        forward_velocity(&self.model, &mut self.data, &self.qd);
    }
}
