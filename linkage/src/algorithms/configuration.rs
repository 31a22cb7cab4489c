//! The configuration space: q (nq coordinates) moved by a velocity-space displacement (nv coordinates).
//! Revolute and prismatic joints add, `q_i ← q_i + h v_i`; a ball joint turns its unit quaternion by the
//! body-axes rotation vector `h (v_k, v_k+1, v_k+2)` (`math::quaternion::integrate`), so q stays on the
//! manifold of valid configurations whatever the step. As Pinocchio's `integrate` / `difference`: every
//! update of q by q̇, a Newton correction or a finite difference goes through here; models without ball
//! joints take a plain `axpy`.
//!
//! A client has no [`Model`], only the [`ConfigLayout`] its welcome carries (where the ball joints' rates
//! start); both step q through the same [`integrate_balls`], so the local model's configuration moves exactly
//! as the VE's does.

use nalgebra::{DVector, Vector3};

use crate::math::quaternion;
use crate::math::space::Space;
use crate::model::{JointKind, Model};

/// Where a configuration's ball joints sit, all [`integrate_balls`] needs beyond q and v: the velocity index
/// of each ball joint's first rate, ascending (its quaternion starts at that index plus the number of balls
/// before it, since every joint's positions follow in joint order).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ConfigLayout {
    nv: usize,
    ball_rates: Vec<usize>,
}

/// Why a [`ConfigLayout`] does not fit its velocities.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LayoutError {
    /// A ball joint's three rates do not fit in nv, or overlap the previous ball's (not ascending).
    #[error("ball joint {index} starts at rate {rate}, which does not fit {nv} rates after the previous ball")]
    BallOutOfPlace {
        /// Which ball joint (0-based, in order).
        index: usize,
        /// Its first rate.
        rate: usize,
        /// The number of velocity coordinates.
        nv: usize,
    },
}

impl ConfigLayout {
    /// The layout of `model`'s configuration.
    pub fn of<S: Space>(model: &Model<S>) -> Self {
        ConfigLayout { nv: model.nv(), ball_rates: ball_rates(model).collect() }
    }

    /// nv rates with no ball joint (nq = nv).
    pub fn flat(nv: usize) -> Self {
        ConfigLayout { nv, ball_rates: Vec::new() }
    }

    /// nv rates whose ball joints start at `ball_rates`; refused when one does not fit after the previous.
    pub fn new(nv: usize, ball_rates: Vec<usize>) -> Result<Self, LayoutError> {
        let mut free = 0;
        for (index, &rate) in ball_rates.iter().enumerate() {
            if rate < free || rate.checked_add(3).is_none_or(|end| end > nv) {
                return Err(LayoutError::BallOutOfPlace { index, rate, nv });
            }
            free = rate + 3;
        }
        Ok(ConfigLayout { nv, ball_rates })
    }

    /// Velocity coordinates nv.
    pub fn nv(&self) -> usize {
        self.nv
    }

    /// Configuration coordinates nq: one more per ball joint.
    pub fn nq(&self) -> usize {
        self.nv + self.ball_rates.len()
    }

    /// The first rate of each ball joint, ascending.
    pub fn ball_rates(&self) -> &[usize] {
        &self.ball_rates
    }

    /// `q ← q ⊕ h v` (lengths nq and nv). Allocation-free.
    pub fn integrate(&self, q: &mut [f64], v: &[f64], h: f64) {
        integrate_balls(self.ball_rates.iter().copied(), q, v, h);
    }

    /// The index in q of the first ball joint whose quaternion is not a unit one (to 1e-6, the wire's
    /// tolerance for orientations), if any.
    pub fn first_non_unit(&self, q: &[f64]) -> Option<usize> {
        self.ball_rates.iter().enumerate().map(|(before, rate)| rate + before).find(|&k| {
            let norm = q[k..k + 4].iter().map(|x| x * x).sum::<f64>().sqrt();
            norm.is_nan() || (norm - 1.0).abs() > 1e-6
        })
    }
}

/// The first rate of each of `model`'s ball joints, ascending.
fn ball_rates<S: Space>(model: &Model<S>) -> impl Iterator<Item = usize> + '_ {
    model.joints.iter().enumerate().filter(|(_, j)| j.kind == JointKind::Ball { slot: 0 }).map(|(i, _)| i)
}

/// `q ← q ⊕ h v` for a configuration whose ball joints' rates start at `balls` (ascending): revolute and
/// prismatic coordinates add, each ball's quaternion turns by the body-axes rotation vector of its three
/// rates (`math::quaternion::integrate`). The one configuration update of the VE and of the client's local
/// model.
pub fn integrate_balls(balls: impl IntoIterator<Item = usize>, q: &mut [f64], v: &[f64], h: f64) {
    let mut balls = balls.into_iter().peekable();
    let (mut i, mut k) = (0, 0);
    while i < v.len() {
        if balls.next_if_eq(&i).is_some() {
            let theta = Vector3::new(v[i], v[i + 1], v[i + 2]) * h;
            quaternion::integrate(&mut q[k..k + 4], &theta);
            i += 3;
            k += 4;
        } else {
            q[k] += h * v[i];
            i += 1;
            k += 1;
        }
    }
}

/// `q ← q ⊕ h v`. Allocation-free.
pub fn integrate<S: Space>(model: &Model<S>, q: &mut DVector<f64>, v: &DVector<f64>, h: f64) {
    integrate_slice(model, q.as_mut_slice(), v.as_slice(), h);
}

/// [`integrate`] on slices (q of length nq, v of length nv).
pub fn integrate_slice<S: Space>(model: &Model<S>, q: &mut [f64], v: &[f64], h: f64) {
    if !model.has_balls() {
        for (x, d) in q.iter_mut().zip(v) {
            *x += h * d;
        }
        return;
    }
    integrate_balls(ball_rates(model), q, v, h);
}

/// The displacement `d` (nv) with `b = a ⊕ d`: the inverse of [`integrate`] (ball joints: the short way round).
pub fn difference<S: Space>(model: &Model<S>, a: &DVector<f64>, b: &DVector<f64>, d: &mut DVector<f64>) {
    for (i, joint) in model.joints.iter().enumerate() {
        let k = joint.q_index;
        match joint.kind {
            JointKind::Ball { slot: 0 } => {
                let theta = quaternion::difference(&a.as_slice()[k..k + 4], &b.as_slice()[k..k + 4]);
                d.as_mut_slice()[i..i + 3].copy_from_slice(theta.as_slice());
            }
            JointKind::Ball { .. } => {}
            _ => d[i] = b[k] - a[k],
        }
    }
}

/// Checks q's length and that every number is finite and every ball joint's quaternion a unit one (to
/// 1e-6, the wire's tolerance for orientations); the message names the first coordinate at fault.
pub fn check<S: Space>(model: &Model<S>, q: &[f64]) -> Result<(), String> {
    if q.len() != model.nq() {
        return Err(format!("expected {} configuration coordinates, got {}", model.nq(), q.len()));
    }
    if let Some(i) = q.iter().position(|x| !x.is_finite()) {
        return Err(format!("q[{i}] is {}", q[i]));
    }
    for joint in model.joints.iter().filter(|j| j.kind == JointKind::Ball { slot: 0 }) {
        let k = joint.q_index;
        let norm = q[k..k + 4].iter().map(|x| x * x).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > 1e-6 {
            return Err(format!(
                "ball joint '{}': q[{k}..{}] has norm {norm}, not a unit quaternion",
                joint.name,
                k + 4
            ));
        }
    }
    Ok(())
}
