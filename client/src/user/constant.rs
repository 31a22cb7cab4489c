//! The paper's user (section VI): a constant wrench, "a worst case approximation of the user for stability"
//! on an impedance device, and the same user in every manipulation.

use std::marker::PhantomData;
use std::time::Duration;

use kinloop_linkage::math::space::{Space, VecOps};

use super::{SimulatedUser, UserError};
use crate::device::DeviceState;

/// A constant wrench in world axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantWrench<S: Space> {
    /// The wrench (force, then torque).
    pub wrench: S::OpVec,
    _space: PhantomData<S>,
}

impl<S: Space> ConstantWrench<S> {
    /// A constant `wrench`.
    pub fn new(wrench: S::OpVec) -> Self {
        ConstantWrench { wrench, _space: PhantomData }
    }

    /// From `k` numbers in operational order.
    pub fn from_values(values: &[f64]) -> Result<Self, UserError> {
        if values.len() != S::DIM {
            return Err(UserError::Count {
                what: "a constant wrench",
                expected: format!("{} (the operational space of a {:?} scene)", S::DIM, S::KIND),
                got: values.len(),
            });
        }
        Ok(Self::new(S::OpVec::from_slice(values)))
    }
}

impl<S: Space> SimulatedUser<S> for ConstantWrench<S> {
    fn wrench(&mut self, _now: Duration, _device: &DeviceState<S>) -> S::OpVec {
        self.wrench
    }
}
