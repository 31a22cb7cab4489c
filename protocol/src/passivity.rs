//! Time-domain passivity across the network: the energy books each end of the two-port keeps, the check a
//! receiver makes of the other end's books, and the output scale both ends' controllers use.
//!
//! **The two-port.** Between a user's device and the VE lies the network (and, on the client, the local model
//! that mediates it). Each end books, per operational axis, the energy that has entered the network there
//! (*received*) and the energy that has left it there (*emitted*); both only grow. The two-port is passive
//! when, at every instant, what has left at both ends is no more than what has entered at both ends (Ryu,
//! Artigas & Preusche, "A passive bilateral control scheme for a teleoperator with time-varying communication
//! delay", Mechatronics 20(7), 2010; per axis as in Ryu, Kwon & Hannaford 2004). Each end learns the other's
//! books late, by the network's delay, which only makes its bound stricter: the energy the other end had
//! received *then* is at most what it has received now.
//!
//! **Trust.** A peer's books are a claim. [`EnergyReports`] accepts one only when it is finite, non-negative,
//! never decreasing and no faster than `max_power_w` since the last accepted one; otherwise the report is
//! refused and counted, and the receiver keeps the last good one (it never grants more on a bad report). A
//! receiver that can measure the same flow itself takes the smaller of the claim and its measurement, so a peer
//! that overstates what it received cannot buy itself energy.
//!
//! **The controller.** [`output_scale`] is the per-axis scale β ∈ [0, 1] an end applies to its output while the
//! axis's account (received − emitted, plus the credit from the other end) is in deficit: full while in credit,
//! fading linearly to zero as the deficit reaches the allowance (a smooth dissipation rather than a switch, so
//! it does not chatter), and full while the output is about to absorb energy so the account can recover.

/// Most operational axes a port has (spatial).
pub const MAX_AXES: usize = 6;

/// The energy books of one end of the two-port, per axis (J), since the session began.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PortBooks {
    /// Energy that entered the network at this end.
    pub received_j: [f64; MAX_AXES],
    /// Energy that left the network at this end.
    pub emitted_j: [f64; MAX_AXES],
}

impl PortBooks {
    /// What entered the network at this end, net of what left it there, over all axes (J; negative: this end
    /// gave out more than it took in).
    pub fn net_received_j(&self) -> f64 {
        self.received_j.iter().zip(&self.emitted_j).map(|(r, e)| r - e).sum()
    }

    /// Books one step of `dt` in which the port put `power_out[a]` watts out of the network on axis `a`
    /// (negative: it took energy in). A step with a non-finite power is not booked.
    pub fn book(&mut self, power_out: &[f64], dt: f64) {
        if !(dt.is_finite() && dt > 0.0) || power_out.len() > MAX_AXES || !power_out.iter().all(|p| p.is_finite()) {
            return;
        }
        for (a, p) in power_out.iter().enumerate() {
            if *p > 0.0 {
                self.emitted_j[a] += p * dt;
            } else {
                self.received_j[a] -= p * dt;
            }
        }
    }
}

/// Why a peer's energy report was refused.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum EnergyReportError {
    /// A value is NaN or infinite.
    #[error("energy {field}[{axis}] is not finite")]
    NonFinite {
        /// `received` or `emitted`.
        field: &'static str,
        /// The axis.
        axis: usize,
    },
    /// A value is negative: energy that crossed a port cannot be.
    #[error("energy {field}[{axis}] = {value} J is negative")]
    Negative {
        /// `received` or `emitted`.
        field: &'static str,
        /// The axis.
        axis: usize,
        /// The value.
        value: f64,
    },
    /// A value went down since the last accepted report: the books only grow.
    #[error("energy {field}[{axis}] went down from {before} J to {now} J")]
    Decreased {
        /// `received` or `emitted`.
        field: &'static str,
        /// The axis.
        axis: usize,
        /// Last accepted value.
        before: f64,
        /// This report's value.
        now: f64,
    },
    /// A value grew faster than the port can carry power.
    #[error("energy {field}[{axis}] grew by {growth} J in {seconds} s, more than {max_power_w} W can carry")]
    TooFast {
        /// `received` or `emitted`.
        field: &'static str,
        /// The axis.
        axis: usize,
        /// The growth (J).
        growth: f64,
        /// Over this time (s).
        seconds: f64,
        /// The port's power bound (W).
        max_power_w: f64,
    },
    /// The report's time is not after the last accepted one's.
    #[error("energy report at {now} s is not after the last one at {before} s")]
    TimeWentBack {
        /// Last accepted report's time (s).
        before: f64,
        /// This report's time (s).
        now: f64,
    },
}

/// The last accepted energy report of a peer, and the count of refused ones.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergyReports {
    /// The peer's books as last accepted (zero before the first).
    pub accepted: PortBooks,
    /// The peer's clock at the last accepted report (s); `None` before the first.
    pub accepted_at_s: Option<f64>,
    /// Reports refused so far.
    pub refused: u64,
}

impl EnergyReports {
    /// Judges a report the peer made at its clock `time_s`, of `k = received.len()` axes, against the last
    /// accepted one: finite, non-negative, not decreasing, and grown by at most `max_power_w` times the
    /// elapsed time plus `slack_j` (the first report by at most `slack_j` plus the power times its time,
    /// counted from the peer's clock zero). Accepted reports replace the books; refused ones are counted and
    /// change nothing.
    pub fn check(
        &mut self,
        time_s: f64,
        received: &[f64],
        emitted: &[f64],
        max_power_w: f64,
        slack_j: f64,
    ) -> Result<(), EnergyReportError> {
        let verdict = (|| {
            let before_s = self.accepted_at_s.unwrap_or(0.0);
            if !time_s.is_finite() || self.accepted_at_s.is_some_and(|before| time_s <= before) {
                return Err(EnergyReportError::TimeWentBack { before: before_s, now: time_s });
            }
            let seconds = (time_s - before_s).max(0.0);
            let books =
                [("received", received, &self.accepted.received_j), ("emitted", emitted, &self.accepted.emitted_j)];
            for (field, values, before) in books {
                for (axis, (&now, &was)) in values.iter().zip(before.iter()).enumerate() {
                    if !now.is_finite() {
                        return Err(EnergyReportError::NonFinite { field, axis });
                    }
                    if now < 0.0 {
                        return Err(EnergyReportError::Negative { field, axis, value: now });
                    }
                    if now < was {
                        return Err(EnergyReportError::Decreased { field, axis, before: was, now });
                    }
                    let growth = now - was;
                    if growth > max_power_w * seconds + slack_j {
                        return Err(EnergyReportError::TooFast { field, axis, growth, seconds, max_power_w });
                    }
                }
            }
            Ok(())
        })();
        match verdict {
            Ok(()) => {
                let k = received.len().min(MAX_AXES);
                self.accepted.received_j[..k].copy_from_slice(&received[..k]);
                self.accepted.emitted_j[..k].copy_from_slice(&emitted[..k]);
                self.accepted_at_s = Some(time_s);
            }
            Err(_) => self.refused += 1,
        }
        verdict
    }
}

/// The output scale β for one axis whose account (energy absorbed by the network there, plus any credit) is
/// `account_j`, when the output is about to absorb energy (`absorbing`) or not, with allowance `allowance_j`
/// (≥ 0; zero: off as soon as the account is in deficit). Full strength while the account is in credit, and
/// while it absorbs with a deficit under the allowance; otherwise `1 + account / allowance`, clamped to [0, 1].
/// Below `−allowance` the axis is off whatever the prediction: a stiff coupling can reverse within a tick, and
/// an axis must not keep generating on wrong predictions.
pub fn output_scale(account_j: f64, absorbing: bool, allowance_j: f64) -> f64 {
    if account_j >= 0.0 || (absorbing && account_j > -allowance_j) {
        1.0
    } else if allowance_j > 0.0 {
        (1.0 + account_j / allowance_j).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn books_split_power_by_direction_and_skip_bad_steps() {
        let mut books = PortBooks::default();
        books.book(&[2.0, -3.0, 0.0], 0.5);
        assert_eq!(books.emitted_j[..3], [1.0, 0.0, 0.0]);
        assert_eq!(books.received_j[..3], [0.0, 1.5, 0.0]);
        let absorbed = |a: usize| books.received_j[a] - books.emitted_j[a];
        assert_eq!((absorbed(0), absorbed(1)), (-1.0, 1.5));
        assert_eq!(books.net_received_j(), 0.5);
        let before = books;
        books.book(&[f64::NAN, 1.0, 1.0], 0.1);
        books.book(&[1.0, 1.0, 1.0], f64::INFINITY);
        books.book(&[1.0; 7], 0.1);
        assert_eq!(books, before, "non-finite power, time, or too many axes: nothing booked");
    }

    #[test]
    fn reports_must_be_finite_non_negative_growing_and_no_faster_than_the_port() {
        let mut r = EnergyReports::default();
        // 10 W for 0.1 s carries at most 1 J (+ 0.01 J slack).
        assert_eq!(r.check(0.1, &[0.5, 0.0], &[0.2, 0.0], 10.0, 0.01), Ok(()));
        assert_eq!(r.check(0.2, &[1.5, 0.0], &[0.2, 0.0], 10.0, 0.01), Ok(()));
        let good = r.accepted;
        let cases: [(f64, [f64; 2], [f64; 2]); 6] = [
            (0.3, [f64::NAN, 0.0], [0.2, 0.0]),
            (0.3, [1.5, 0.0], [0.2, -1e-3]),
            (0.3, [1.4, 0.0], [0.2, 0.0]),
            (0.3, [1.5, 0.0], [1.3, 0.0]),
            (0.2, [1.5, 0.0], [0.2, 0.0]),
            (f64::NAN, [1.5, 0.0], [0.2, 0.0]),
        ];
        for (t, received, emitted) in cases {
            assert!(r.check(t, &received, &emitted, 10.0, 0.01).is_err(), "{t} {received:?} {emitted:?}");
            assert_eq!(r.accepted, good, "a refused report changes nothing");
        }
        assert_eq!(r.refused, 6);
        assert!(matches!(
            r.check(0.3, &[1.5, 0.0], &[1.3, 0.0], 10.0, 0.01),
            Err(EnergyReportError::TooFast { axis: 0, .. })
        ));
        assert_eq!(r.check(0.3, &[2.5, 0.0], &[0.2, 0.0], 10.0, 0.01), Ok(()), "1 J in 0.1 s at 10 W: allowed");
    }

    #[test]
    fn the_scale_is_full_in_credit_and_fades_with_the_deficit() {
        assert_eq!(output_scale(0.5, false, 2.0), 1.0);
        assert_eq!(output_scale(-0.5, true, 2.0), 1.0, "absorbing within the allowance: let it recover");
        assert_eq!(output_scale(-0.5, false, 2.0), 0.75);
        assert_eq!(output_scale(-3.0, true, 2.0), 0.0, "beyond the allowance: off whatever the prediction");
        assert_eq!(output_scale(-1e-9, false, 0.0), 0.0, "strict limit");
        // Continuous in the account: no step as the deficit grows.
        let steps: Vec<f64> = (0..=200).map(|i| output_scale(-(i as f64) * 0.01, false, 2.0)).collect();
        assert!(steps.windows(2).all(|w| (w[0] - w[1]).abs() <= 0.005 + 1e-12));
    }
}
