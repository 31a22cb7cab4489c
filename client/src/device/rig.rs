//! A simulated device held by a simulated user: the [`HapticDevice`] the driver runs when `--device sim:...`.

use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};

use super::{DeviceError, DeviceSpec, DeviceState, HapticDevice, SimulatedDevice};

/// A [`SimulatedDevice`] and the [`SimulatedUser`] holding it. Each `read(now)` integrates the plant from
/// the previous read to `now` under the held command and the hand wrench of the previous read, then samples
/// the encoders and asks the user for the hand wrench of the coming period (the force sensor, when the
/// device has one, reports that wrench) and for the mass its hand adds to the handle.
pub struct SimulatedRig<S: Space> {
    device: SimulatedDevice<S>,
    user: Box<dyn SimulatedUser<S>>,
    last_read: Option<Duration>,
    hand: S::OpVec,
}

impl<S: Space> SimulatedRig<S> {
    /// A rig of `device` and `user`.
    pub fn new(device: SimulatedDevice<S>, user: Box<dyn SimulatedUser<S>>) -> Self {
        SimulatedRig { device, user, last_read: None, hand: S::OpVec::zero() }
    }

    /// Hands the device to `user` from the next read on.
    pub fn set_user(&mut self, user: Box<dyn SimulatedUser<S>>) {
        self.user = user;
    }

    /// The simulated device (exact state, applied command).
    pub fn device(&self) -> &SimulatedDevice<S> {
        &self.device
    }

    /// The hand wrench applied during the current period.
    pub fn hand_wrench(&self) -> S::OpVec {
        self.hand
    }

    /// The exact handle pose (no quantization).
    pub fn true_pose(&self) -> OpPose<S> {
        self.device.true_pose()
    }
}

impl<S: Space> HapticDevice<S> for SimulatedRig<S> {
    fn spec(&self) -> &DeviceSpec {
        self.device.spec()
    }

    fn read(&mut self, now: Duration) -> Result<DeviceState<S>, DeviceError> {
        if let Some(last) = self.last_read {
            self.device.advance(now.saturating_sub(last).as_secs_f64(), &self.hand);
        }
        self.last_read = Some(now);
        let (pose, twist) = self.device.sample();
        let mut state = DeviceState { pose, twist, hand_wrench: None, grasped: None };
        // The hand feels the handle itself, not its encoders.
        let held = DeviceState {
            pose: self.device.true_pose(),
            twist: self.device.true_twist(),
            hand_wrench: None,
            grasped: None,
        };
        self.hand = self.user.wrench(now, &held);
        self.device.attach_mass(&self.user.attached_mass(now));
        if self.device.spec().has_force_sensor {
            state.hand_wrench = Some(self.hand);
        }
        if self.device.spec().has_presence_sensor {
            state.grasped = Some(self.user.holds(now));
        }
        Ok(state)
    }

    fn command(&mut self, _now: Duration, wrench: &S::OpVec) -> Result<(), DeviceError> {
        if !wrench.is_finite() {
            return Err(DeviceError::Force {
                device: self.device.spec().name.clone(),
                reason: "non-finite wrench refused".into(),
            });
        }
        self.device.set_command(wrench);
        Ok(())
    }
}

/// A simulated hand: what holds a [`SimulatedRig`]'s handle (the simulated users of `crate::user` implement
/// it).
pub trait SimulatedUser<S: Space>: Send {
    /// The wrench the hand applies to the handle at `now`, given the device's state (the rig passes the
    /// handle's true pose and twist: a hand feels the handle, not its encoders).
    fn wrench(&mut self, now: Duration, device: &DeviceState<S>) -> S::OpVec;

    /// Mass (and inertia) the hand adds to the handle per axis at `now`: a hand that holds it moves with it.
    fn attached_mass(&self, _now: Duration) -> S::OpVec {
        S::OpVec::zero()
    }

    /// Whether the hand holds the handle at `now` (what a presence sensor in the handle reports).
    fn holds(&self, _now: Duration) -> bool {
        true
    }
}
