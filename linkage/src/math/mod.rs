//! The mathematics below the linkage: spatial algebra (planar and spatial), trigonometry, small dense
//! linear algebra and its SIMD lanes, the fixed-size factorizations and solves the algorithms dispatch to
//! for small linkages, and a small symmetric eigensolver. Nothing here knows a body, a joint or a scene:
//! this layer imports nothing from `model` or `algorithms` (`tests/layers.rs` checks).

pub mod dense;
pub mod eigen;
pub(crate) mod kkt_factors;
pub(crate) mod kkt_small;
pub(crate) mod ltl_small;
pub mod quaternion;
#[doc(hidden)]
pub mod rng;
pub(crate) mod simd;
pub mod space;
pub mod trig;
