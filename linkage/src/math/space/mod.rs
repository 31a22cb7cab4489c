//! The two spaces a linkage can live in, and their spatial algebra.
//!
//! All rigid-body algorithms in this crate are written once, generic over [`Space`], and run in the
//! **world frame** (Featherstone's "ground frame" formulation, as MuJoCo does with its global `cdof` and
//! `cinert`): motion subspaces, velocities and composite inertias are all expressed at the world origin,
//! so composite inertias add without transforms and the mass matrix needs no Plücker transforms at all.
//!
//! Spatial vectors follow Featherstone's order, angular part first:
//! - planar: motion `(ω, vx, vy)`, force `(τ, fx, fy)`, 3-D;
//! - spatial: motion `(ω, v)`, force `(n, f)`, 6-D.
//!
//! Operational-space vectors (what a user or device sees) use the conventions of `docs/architecture.md`
//! instead, linear part first: planar `(x, y, θ)`, spatial `(v, ω)`.
//!
//! A planar scene never touches 6-D algebra: [`Planar`] works on 2-vectors, scalars and 3x3 matrices.
//!
//! Files: [`Space`] and [`SceneKind`] (`definition`), the fixed-size arithmetic [`VecOps`] and [`MatOps`]
//! (`algebra`), the two spaces [`Planar`] and [`Spatial`], an operational point's pose [`OpPose`] (`pose`),
//! and generic operational-space helpers (`op_vectors`).

mod algebra;
mod definition;
mod op_vectors;
mod planar;
mod pose;
mod spatial;
#[cfg(test)]
mod tests;

pub use algebra::{MatOps, VecOps};
pub use definition::{SceneKind, Space};
pub use op_vectors::{clip_wrench_parts, unwrap_rotation_near, PartScales};
pub use planar::{Planar, PlanarAngleMemo};
pub use pose::OpPose;
pub use spatial::{skew, Spatial};
