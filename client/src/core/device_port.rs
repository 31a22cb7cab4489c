//! The client's two-port checked at the device's own port: a time-domain passivity controller (Hannaford &
//! Ryu 2002) whose observer is the work the motors did on the device, and whose controller is a damper at the
//! device.
//!
//! **Why at the device.** `port_passivity` checks the local model's port: what the hand's sensed wrench and
//! the channels' reaction did to the model, against what the VE's coupling did to the linkage. Between the
//! model and the device lie elements that are passive only in the ideal: the channels' springs along
//! directions that turn as the frame is carried, the force channel (the hand's wrench drives the model, while
//! the hand works on the device, which moves otherwise), the pull's corrections, the load feedforward. Any
//! of them can hand the device energy that neither port's books show. Seen from the hand, what counts is the
//! device: the energy the motors put into it may not exceed what the hand put into the client there, plus what
//! the VE's coupling took from the linkage. Held at the device, the bound covers every element between the
//! two ends, whatever it is.
//!
//! **The account.** `A = R_d − E_d + (R_VE − E_VE) + E_allow`: what the motors took from the device net (the
//! work of the commanded wrench on the device's measured twist, booked each tick with the command the device
//! held over it), plus what the VE's coupling took from the linkage net (the snapshots' checked books, a
//! downlink late), plus the allowance ([`DEVICE_PORT_ALLOWANCE_J`] at the device). The damper's own work is
//! in the device's books, so there is nothing else to keep.
//!
//! **The controller.** While `A < 0` the device is damped, `−s b ẋ_d`, with `b` the device's largest damping
//! per axis (`DeviceSpec::max_damping`, `max_angular_damping`) and `s ∈ [0, 1]` the share that takes the
//! deficit out in one tick, `s Σ b_a ẋ_a² dt = −A`; what the device's damping cannot take out stays owed. A
//! still device cannot give energy back, and is left alone. (Withholding, beyond the damper, the power the
//! command itself puts into the device was measured too: no better on the tuning seeds, and its wrench is
//! not bounded by the device's damping; see docs/robustness.md, "The device's own port".)
//!
//! **A user alone.** As `port_passivity`: with others on the linkage, the VE's books also carry what the
//! other hands did through it, which this end's books never see.

use kinloop_linkage::math::space::{PartScales, Space, VecOps};
use kinloop_protocol::passivity::{PortBooks, MAX_AXES};
use kinloop_protocol::wrench_limits::WrenchLimits;

use super::safety::full_damping;
use crate::device::DeviceSpec;

/// Energy the client may give the device beyond what the hand and the linkage gave the client, before the
/// device is damped (J at the device).
pub const DEVICE_PORT_ALLOWANCE_J: f64 = 2.0e-3;

/// The device port's books and its allowance (device units: joules at the device).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct DevicePort {
    books: PortBooks,
    allowance_j: f64,
}

impl DevicePort {
    pub fn new(allowance_j: f64) -> Self {
        DevicePort { books: PortBooks::default(), allowance_j }
    }

    /// Books a tick of `dt_s` over which the device held `command` (device units) and moved at `twist`.
    pub fn book<S: Space>(&mut self, command: &S::OpVec, twist: &S::OpVec, dt_s: f64) {
        let mut power_out = [0.0; MAX_AXES];
        for (a, p) in power_out.iter_mut().enumerate().take(S::DIM) {
            // The motors' power on the device is energy that left the client at this end.
            *p = command[a] * twist[a];
        }
        self.books.book(&power_out[..S::DIM], dt_s);
    }

    /// The account `A` (J at the device), the VE's books `remote` (VE units) brought to the device by
    /// `device_per_ve` (the mapping's `c_f c_p`).
    pub fn account(&self, remote: &PortBooks, device_per_ve: f64) -> f64 {
        self.books.net_received_j() + remote.net_received_j() * device_per_ve + self.allowance_j
    }

    /// The damping wrench (device units) that takes this tick's deficit out of the device moving at `twist`
    /// over `dt_s`, up to the device's largest damping, or zero while the account is in credit. What the
    /// damper cannot take out this tick stays owed.
    pub fn damping<S: Space>(
        &self,
        remote: &PortBooks,
        device_per_ve: f64,
        device: &DeviceSpec,
        twist: &S::OpVec,
        dt_s: f64,
    ) -> S::OpVec {
        let deficit = -self.account(remote, device_per_ve);
        if deficit.is_nan() || deficit <= 0.0 || dt_s.is_nan() || dt_s <= 0.0 {
            return S::OpVec::zero();
        }
        let most = full_damping::<S>(device, twist);
        // The energy the device's full damping would take out this tick.
        let full = -most.dot(twist) * dt_s;
        if !full.is_finite() || full <= 0.0 {
            return S::OpVec::zero();
        }
        most * (deficit / full).min(1.0)
    }
}

/// `damping` scaled, force and torque apart, so that it never takes the command `command` (device units) past
/// `limits` where the command was within them, nor further past where it was not: the damper uses the
/// headroom the command leaves. A damper that clipped the command would have the device's limit bind on the
/// controllers' wrench too, and a hand held at the limit, not a passive one.
pub fn within_headroom<S: Space>(command: &S::OpVec, damping: &S::OpVec, limits: &WrenchLimits) -> S::OpVec {
    let share = |a: S::OpVec, d: S::OpVec, peak: f64| {
        // The largest λ in [0, 1] with |a + λ d| ≤ max(peak, |a|), a and d one part of the wrenches.
        let (dd, ad, aa) = (d.dot(&d), a.dot(&d), a.dot(&a));
        if dd.is_nan() || dd <= 0.0 {
            return 1.0;
        }
        // A hair under the peak, below where the limits clip (`limit_wrench_parts`).
        let reach = (peak * (1.0 - 1e-9)).max(aa.sqrt());
        let root = (ad * ad - dd * (aa - reach * reach)).max(0.0).sqrt();
        ((root - ad) / dd).clamp(0.0, 1.0)
    };
    let linear = <S::Point as VecOps>::LEN;
    let part = |w: &S::OpVec, angular: bool| {
        let mut out = S::OpVec::zero();
        for i in 0..S::DIM {
            if (i >= linear) == angular {
                out[i] = w[i];
            }
        }
        out
    };
    let scales = PartScales {
        force: share(part(command, false), part(damping, false), limits.max_force_n),
        torque: share(part(command, true), part(damping, true), limits.max_torque_nm),
    };
    scales.apply::<S>(damping)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::presets::DevicePreset;
    use kinloop_linkage::math::space::Planar;
    use kinloop_protocol::SceneKind;
    use nalgebra::Vector3;

    fn falcon() -> DeviceSpec {
        DevicePreset::Falcon.spec(SceneKind::Planar).expect("a planar Falcon")
    }

    /// The motors' work is booked as the energy that left the client at the device: a command along the
    /// motion spends the account, one against it fills it.
    #[test]
    fn the_books_hold_the_motors_work_on_the_device() {
        let mut port = DevicePort::new(0.0);
        let remote = PortBooks::default();
        // 2 N along 0.1 m/s for 0.5 s: 0.1 J out; then 1 N against 0.2 m/s for 0.25 s: 0.05 J back.
        port.book::<Planar>(&Vector3::new(2.0, 0.0, 0.0), &Vector3::new(0.1, 0.0, 0.0), 0.5);
        assert!((port.account(&remote, 1.0) + 0.1).abs() < 1e-12);
        port.book::<Planar>(&Vector3::new(0.0, -1.0, 0.0), &Vector3::new(0.0, 0.2, 0.0), 0.25);
        assert!((port.account(&remote, 1.0) + 0.05).abs() < 1e-12);
        // The VE's coupling took 10 VE units from the linkage, a thousandth of a joule each at the device.
        let mut took = PortBooks::default();
        took.received_j[0] = 10.0;
        assert!((port.account(&took, 1e-3) + 0.04).abs() < 1e-12);
    }

    /// In credit the device is left alone; in deficit the damper dissipates exactly the deficit in one tick
    /// (its power `−w · ẋ dt`), and never more damping than the device renders.
    #[test]
    fn a_deficit_is_damped_out_in_one_tick_within_the_devices_damping() {
        let device = falcon();
        let remote = PortBooks::default();
        let twist = Vector3::new(0.05, -0.02, 0.0);
        let dt = 1e-3;
        let mut port = DevicePort::new(DEVICE_PORT_ALLOWANCE_J);
        assert_eq!(port.damping::<Planar>(&remote, 1.0, &device, &twist, dt), Vector3::zeros(), "in credit");
        // 1 µJ over the allowance out: a small deficit.
        port.book::<Planar>(&Vector3::new(1.0, 0.0, 0.0), &Vector3::new(1.0, 0.0, 0.0), DEVICE_PORT_ALLOWANCE_J + 1e-6);
        let w = port.damping::<Planar>(&remote, 1.0, &device, &twist, dt);
        let dissipated = -w.dot(&twist) * dt;
        assert!((dissipated - 1e-6).abs() < 1e-15, "{dissipated}");
        // A large deficit: the device's full damping, no more.
        port.book::<Planar>(&Vector3::new(1.0, 0.0, 0.0), &Vector3::new(1.0, 0.0, 0.0), 1.0);
        let w = port.damping::<Planar>(&remote, 1.0, &device, &twist, dt);
        assert!((w.x + device.max_damping * twist.x).abs() < 1e-12, "{w:?}");
        assert!((w.y + device.max_damping * twist.y).abs() < 1e-12, "{w:?}");
        // A still device gives nothing back and is not pushed.
        assert_eq!(port.damping::<Planar>(&remote, 1.0, &device, &Vector3::zeros(), dt), Vector3::zeros());
    }

    /// The damper takes the headroom the command leaves, force and torque apart: never past a limit the
    /// command was within, never further past one it was over; within the headroom it is whole.
    #[test]
    fn the_damper_uses_the_headroom_the_command_leaves() {
        let limits = WrenchLimits::rated(10.0, 0.2);
        let command = Vector3::new(6.0, 0.0, -0.1);
        let damping = Vector3::new(2.0, 1.0, 0.05);
        assert_eq!(within_headroom::<Planar>(&command, &damping, &limits), damping, "within the headroom");
        let strong = Vector3::new(8.0, 0.0, -0.3);
        let taken = within_headroom::<Planar>(&command, &strong, &limits);
        let total = command + taken;
        assert!((total.x - 10.0).abs() < 1e-6 && total.x < 10.0, "{total:?}");
        assert!((total.z + 0.2).abs() < 1e-6 && total.z > -0.2, "{total:?}");
        // Both parts keep the damper's direction.
        assert!(taken.x > 0.0 && taken.z < 0.0 && taken.y == 0.0);
        // Over the force limit already: a damper pushing further out is dropped, one pulling back is whole.
        let over = Vector3::new(12.0, 0.0, 0.0);
        assert_eq!(within_headroom::<Planar>(&over, &Vector3::new(1.0, 0.0, 0.0), &limits).x, 0.0);
        assert_eq!(within_headroom::<Planar>(&over, &Vector3::new(-1.0, 0.0, 0.0), &limits).x, -1.0);
        // Nothing the device cannot answer leaks past a limit, whatever the damper asks.
        let (_, scales) = kinloop_protocol::wrench_limits::limit_wrench_parts::<Planar>(&total, &limits);
        assert!(!scales.clipped(), "{scales:?}");
    }
}
