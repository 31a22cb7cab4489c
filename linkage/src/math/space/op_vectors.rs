//! Operational-space vectors (linear part first) generic over the space: keeping a path's rotation
//! vectors continuous, and limiting a wrench's force and torque apart.

use super::algebra::VecOps;
use super::definition::Space;

/// The rotation-vector part of the displacement `d` (angle θ about u, θ ≤ π as a logarithm gives it) turned
/// into the equivalent `u (θ + 2πk)` nearest `previous`'s: consecutive displacements along a path that turns
/// through ±π then stay continuous instead of jumping by 2π (a tour interpolated between the jumps would
/// spin the long way round).
pub fn unwrap_rotation_near<S: Space>(d: &mut S::OpVec, previous: &S::OpVec) {
    let lin = <S::Point as VecOps>::LEN;
    let theta = (lin..S::DIM).map(|i| d[i] * d[i]).sum::<f64>().sqrt();
    if !(theta.is_finite() && theta > 0.0) {
        return;
    }
    // `previous` along u, in turns of 2π beyond θ.
    let along = (lin..S::DIM).map(|i| previous[i] * d[i] / theta).sum::<f64>();
    let turns = ((along - theta) / std::f64::consts::TAU).round();
    if turns.is_finite() && turns != 0.0 {
        let scale = (theta + turns * std::f64::consts::TAU) / theta;
        for i in lin..S::DIM {
            d[i] *= scale;
        }
    }
}

/// The wrench with its force and its torque each scaled back to at most `max_force` and `max_torque`
/// (each keeps its direction), and the scales applied. Force and torque are limited apart, as a force sensor
/// saturates and as a device's peaks are rated: a wrist torque past its range says nothing about the force.
pub fn clip_wrench_parts<S: Space>(wrench: &S::OpVec, max_force: f64, max_torque: f64) -> (S::OpVec, PartScales) {
    let scale = |magnitude: f64, limit: f64| if magnitude > limit { limit / magnitude } else { 1.0 };
    let scales = PartScales {
        force: scale(S::op_lin(wrench).norm(), max_force),
        torque: scale(S::op_ang(wrench).norm(), max_torque),
    };
    (scales.apply::<S>(wrench), scales)
}

/// Separate scales on a wrench's force (linear part) and torque (angular part).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PartScales {
    /// On the force.
    pub force: f64,
    /// On the torque.
    pub torque: f64,
}

impl PartScales {
    /// The smaller: 1 when nothing was cut.
    pub fn min(self) -> f64 {
        self.force.min(self.torque)
    }

    /// Whether either part was cut.
    pub fn clipped(self) -> bool {
        self.min() < 1.0
    }

    /// `w` with its force and torque scaled as these say.
    pub fn apply<S: Space>(self, w: &S::OpVec) -> S::OpVec {
        let linear = <S::Point as VecOps>::LEN;
        let mut out = *w;
        for i in 0..S::DIM {
            out[i] *= if i < linear { self.force } else { self.torque };
        }
        out
    }
}
