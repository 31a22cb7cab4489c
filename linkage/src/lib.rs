//! # kinloop-linkage
//!
//! Linkages with kinematic loops, simulated exactly and fast, and what a haptic controller needs to render
//! them at an operational point (OP): the inertia there and the directions the joints resist.
//!
//! Following Pinocchio and MuJoCo, an immutable [`Model`] is compiled once from a [`Scene`](model::scene::Scene) and every
//! algorithm writes into a preallocated [`Data`](model::data::Data); hot paths take `(&Model, &mut Data)` and allocate nothing.
//!
//! **Layers.** As Pinocchio separates spatial algebra, the multibody model and the algorithms, the sources
//! sit in three folders whose uses point one way (`tests/layers.rs` checks it, and that no files import
//! each other in a circle):
//! - [`math`]: spatial algebra ([`space`](math::space)), the ball joints' unit quaternions ([`quaternion`](math::quaternion)), trigonometry ([`trig`](math::trig)), dense kernels and their SIMD lanes
//!   ([`dense`](math::dense)), the fixed-size factorizations and KKT kernels for small linkages, a symmetric
//!   eigensolver ([`eigen`](math::eigen)). Uses nothing of the layers above.
//! - [`model`]: the scene file ([`scene`](model::scene)), the built-in scenes ([`builtin`](model::builtin)), the [`Model`] and the
//!   [`Data`](model::data::Data) workspace ([`data`](model::data)). Uses only `math`.
//! - [`algorithms`]: one algorithm per module, named for what it computes, each citing the paper's
//!   equation (table below), and the compilation of a scene into a [`Model`] ([`Model::compile`]), which
//!   needs poses at q0 and assembly. Uses `math` and `model`.
//!
//! [`error`] is a leaf every layer reports through; [`bench`](mod@bench) (the benchmark cases) sits on top.
//! Every module has one path, through its layer (`kinloop_linkage::algorithms::kinematics`,
//! `kinloop_linkage::math::space`); the crate root re-exports nothing else but [`Model`], whose module is the
//! `model` layer itself.
//!
//! | module | computes | paper |
//! |---|---|---|
//! | [`configuration`](algorithms::configuration) | q ⊕ v on the manifold (ball joints' quaternions), its inverse | |
//! | [`kinematics`](algorithms::kinematics) | body poses, world-frame motion subspaces, velocities | |
//! | [`jacobian`](algorithms::jacobian) | point/frame Jacobians, J̇q̇, Jᵀ F | |
//! | [`mass_matrix`](algorithms::mass_matrix) | D(q) by composite rigid bodies | eq 1 |
//! | [`bias`](algorithms::bias) | B(q, q̇) by Newton-Euler | eq 1 |
//! | [`gravity`](algorithms::gravity) | G(q): gravity and springs; energies | eq 1 |
//! | [`joint_forces`](algorithms::joint_forces) | damping, PD actuators (active linkages) | eq 1 |
//! | [`cut_forces`](algorithms::cut_forces) | springs and dampers on the cuts' freedoms | eq 1 |
//! | [`joint_limits`](algorithms::joint_limits) | range walls of joints and cuts | eq 1 |
//! | [`loop_closure`](algorithms::loop_closure) | h, W, w = Ẇq̇ (analytic), Baumgarte w_stab | eq 2, 3 |
//! | [`ltl`](algorithms::ltl) | tree-sparse factorization D = U Uᵀ | |
//! | [`articulated`](algorithms::articulated) | the same U from articulated-body inertias, without D | |
//! | [`kkt`](algorithms::kkt) | the KKT solve, rank-revealing for redundant closures | eq 4 |
//! | [`dynamics`](algorithms::dynamics) | the forward-dynamics pipeline, external forces | eq 1-4 |
//! | [`integrator`](algorithms::integrator) | Euler, semi-implicit Euler, RK4, projection | |
//! | [`energy_guard`](algorithms::energy_guard) | the step's energy account: what the step makes, taken back out | |
//! | [`op_space`](algorithms::op_space) | Λ⁻¹ with loops closed and open | eq 5-9 |
//! | [`constraint_directions`](algorithms::constraint_directions) | SVD of Λ⁻¹, unit-consistent constraint count | eq 10, 12 |
//! | [`local_model`](algorithms::local_model) | configuration-space and reduced operational-space local models | eq 11, 13 |
//! | [`velocity_product`](algorithms::velocity_product) | the part of an OP's free acceleration quadratic in the velocity | eq 11, 13 (b̂) |
//! | [`contact`](algorithms::contact) | obstacle contacts, penalty forces | eq 1 (Fᵢ) |
//! | [`penalty`](algorithms::penalty) | the push-only penalty law of contacts and range walls | eq 1 (Fᵢ) |
//! | [`assemble`](algorithms::assemble) | the nearest closed configuration | |
//! | [`idle_freedoms`](algorithms::idle_freedoms) | freedoms turning one body and moving nothing else (a rod's spin between two balls) | eq 2 |
//! | [`reach`](algorithms::reach) | an OP's reachable region, lightest effective masses, static gravity load | eq 4, 9, 10 |
//! | [`op_path`](algorithms::op_path) | a 1-DOF linkage's OP path: nearest point, tangent (the free direction), turning a frame along it | eq 10 |
//! | `algorithms::compile` | scene → [`Model`]: validation, topological order, cut primitives, closure rank | |
//!
//! Tree joints are revolute, prismatic, universal (two revolute entries around a massless cross-piece) or ball
//! (three entries sharing a unit quaternion): q has `Model::nq` coordinates and q̇, q̈, D and W's columns
//! `Model::nv`, equal without ball joints; every update of q by a velocity goes through `configuration`.
//!
//! Planar scenes use 3-D spatial algebra and a 3-DOF operational space (x, y, θ); spatial scenes 6-D
//! (see [`space`](math::space)). A scene without loops takes the plain path (no KKT, no multipliers); a scene without
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

pub use model::Model;
