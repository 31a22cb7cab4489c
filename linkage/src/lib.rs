//! # kinloop-linkage
//!
//! Linkages with kinematic loops, simulated exactly and fast, and what a haptic controller needs to render
//! them at an operational point (OP): the inertia there and the directions the joints resist.
//!
//! Following Pinocchio and MuJoCo, an immutable [`Model`] is compiled once from a [`Scene`] and every
//! algorithm writes into a preallocated [`Data`]; hot paths take `(&Model, &mut Data)` and allocate nothing.
//! One algorithm per module, named for what it computes, each citing the paper's equation:
//!
//! | module | computes | paper |
//! |---|---|---|
//! | [`kinematics`] | body poses, world-frame motion subspaces, velocities | |
//! | [`jacobian`] | point/frame Jacobians, J̇q̇, Jᵀ F | |
//! | [`mass_matrix`] | D(q) by composite rigid bodies | eq 1 |
//! | [`bias`] | B(q, q̇) by Newton-Euler | eq 1 |
//! | [`gravity`] | G(q): gravity and springs; energies | eq 1 |
//! | [`joint_forces`] | damping, PD actuators (active linkages) | eq 1 |
//! | [`loop_closure`] | h, W, w = Ẇq̇ (analytic), Baumgarte w_stab | eq 2, 3 |
//! | [`ltl`] | tree-sparse factorization D = U Uᵀ | |
//! | [`articulated`] | the same U from articulated-body inertias, without D | |
//! | [`kkt`] | the KKT solve, rank-revealing for redundant closures | eq 4 |
//! | [`dynamics`] | the forward-dynamics pipeline, external forces | eq 1-4 |
//! | [`integrator`] | Euler, semi-implicit Euler, RK4, projection | |
//! | [`op_space`] | Λ⁻¹ with loops closed and open | eq 5-9 |
//! | [`constraint_directions`] | SVD of Λ⁻¹, unit-consistent constraint count | eq 10, 12 |
//! | [`local_model`] | configuration-space and reduced operational-space local models | eq 11, 13 |
//! | [`contact`] | obstacle contacts, penalty forces | eq 1 (Fᵢ) |
//! | [`assemble`] | the nearest closed configuration | |
//!
//! Planar scenes use 3-D spatial algebra and a 3-DOF operational space (x, y, θ); spatial scenes 6-D
//! (see [`space`]). A scene without loops takes the plain path (no KKT, no multipliers); a scene without
//! obstacles builds no contact terms.

#![warn(missing_docs)]

pub mod articulated;
pub mod assemble;
pub mod bench;
pub mod bias;
pub mod builtin;
mod compile;
pub mod constraint_directions;
pub mod contact;
pub mod data;
pub mod dense;
pub mod dynamics;
pub mod eigen;
pub mod error;
pub mod gravity;
pub mod integrator;
pub mod jacobian;
pub mod joint_forces;
pub mod kinematics;
pub mod kkt;
mod kkt_factors;
mod kkt_small;
pub mod local_model;
pub mod loop_closure;
pub mod ltl;
mod ltl_small;
pub mod mass_matrix;
pub mod model;
pub mod op_space;
#[doc(hidden)]
pub mod rng;
pub mod scene;
mod simd;
pub mod space;
mod tree;
pub mod trig;

/// Test fixtures shared by the unit tests and the integration tests (not part of the API).
#[doc(hidden)]
pub mod testing;

pub use data::Data;
pub use dynamics::{forward_dynamics, Forces, OpWrench};
pub use error::{DynamicsError, SceneError};
pub use integrator::{step, Integrator, StepConfig, StepReport};
pub use model::Model;
pub use scene::Scene;
pub use space::{MatOps, Planar, SceneKind, Space, Spatial, VecOps};
