//! # kinloop-linkage
//!
//! Linkages with kinematic loops, simulated exactly and fast, and what a haptic controller needs to render
//! them at an operational point (OP): the inertia there and the directions the joints resist.
//!
//! Following Pinocchio and MuJoCo, an immutable [`Model`] is compiled once from a [`Scene`] and every
//! algorithm writes into a preallocated [`Data`]; hot paths take `(&Model, &mut Data)` and allocate nothing.
//!
//! **Layers.** As Pinocchio separates spatial algebra, the multibody model and the algorithms, the sources
//! sit in three folders whose uses point one way (`tests/layers.rs` checks it, and that no files import
//! each other in a circle):
//! - [`math`]: spatial algebra ([`space`]), trigonometry ([`trig`]), dense kernels and their SIMD lanes
//!   ([`dense`]), the fixed-size factorizations and KKT kernels for small linkages, a symmetric
//!   eigensolver ([`eigen`]). Uses nothing of the layers above.
//! - [`model`]: the scene file ([`scene`]), the built-in scenes ([`builtin`]), the [`Model`] and the
//!   [`Data`] workspace ([`data`]). Uses only `math`.
//! - [`algorithms`]: one algorithm per module, named for what it computes, each citing the paper's
//!   equation (table below), and the compilation of a scene into a [`Model`] ([`Model::compile`]), which
//!   needs poses at q0 and assembly. Uses `math` and `model`.
//!
//! [`error`] is a leaf every layer reports through; [`bench`](mod@bench) (the benchmark cases) sits on top. Every
//! module is also re-exported at the crate root (`kinloop_linkage::kinematics`, `::space`, `::data`, ...).
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
//! | [`reach`] | an OP's reachable region, lightest effective masses, static gravity load | eq 4, 9, 10 |
//! | [`op_path`] | a 1-DOF linkage's OP path: nearest point, tangent (the free direction), turning a frame along it | eq 10 |
//! | `algorithms::compile` | scene → [`Model`]: validation, topological order, cut primitives, closure rank | |
//!
//! Planar scenes use 3-D spatial algebra and a 3-DOF operational space (x, y, θ); spatial scenes 6-D
//! (see [`space`]). A scene without loops takes the plain path (no KKT, no multipliers); a scene without
//! obstacles builds no contact terms.

#![warn(missing_docs)]

pub mod algorithms;
pub mod bench;
pub mod error;
pub mod math;
pub mod model;

/// Test fixtures shared by the unit tests and the integration tests (not part of the API).
#[doc(hidden)]
pub mod testing;

// Every module keeps its path from before the layers (`kinloop_linkage::kinematics`, `::space`, ...).
pub use algorithms::{
    articulated, assemble, bias, constraint_directions, contact, dynamics, gravity, integrator, jacobian, joint_forces,
    kinematics, kkt, local_model, loop_closure, ltl, mass_matrix, op_path, op_space, passivity, reach,
};
pub use math::{dense, eigen, space, trig};
pub use model::{builtin, data, scene};

pub use algorithms::dynamics::{forward_dynamics, Forces, OpWrench};
pub use algorithms::integrator::{step, Integrator, StepConfig, StepReport};
pub use error::{DynamicsError, SceneError};
pub use math::space::{MatOps, Planar, SceneKind, Space, Spatial, VecOps};
pub use model::data::Data;
pub use model::scene::Scene;
pub use model::Model;
