//! # kinloop-mjcf
//!
//! MuJoCo models (MJCF) in and out of kinloop scenes. The importer produces the same
//! [`Scene`](kinloop_linkage::model::scene::Scene) the TOML reader does, so `Model::compile` stays the one
//! door into the mathematics; `docs/mjcf.md` lists what is read, what is warned about and how it maps.
//!
//! **Why roxmltree and not `mjcf-rs`.** dimforge's `mjcf-rs` (0.36) parses MJCF into its own typed model
//! with includes and defaults resolved, but the resolved model keeps no text positions, so an error about
//! a joint could not name the line it was written on; it also brings its own math types (glamx) and mesh
//! handling kinloop does not need. `roxmltree` (which `mjcf-rs` itself builds on) keeps every node's
//! position, is small and read-only; this crate resolves defaults, includes and frames itself, in a few
//! hundred lines that follow MuJoCo's XML reference, and reports each fault as `file:line: <element>:
//! problem`.
//!
//! | module | does |
//! |---|---|
//! | [`xml`] | the XML as an owned tree with file and line per element; `<include>` expanded |
//! | [`defaults`] | nested `<default>` classes, `childclass` |
//! | [`frames`] | `<compiler>` angle unit and Euler sequence; quat, axisangle, euler, xyaxes, zaxis |
//! | [`inertia`] | `<inertial>`, and mass properties from geoms and density as MuJoCo computes them |
//! | [`tree`] | bodies and joints (hinge, slide, ball; two hinges through a point as a universal joint), sites |
//! | [`equality`] | `connect` and `weld` as cuts |
//! | [`actuator`] | `position` actuators as joint PD actuators |
//! | [`import`] | the whole model → a scene that compiles |
//! | [`planar`] | a model that moves in one plane → a planar scene (redundant equations dropped) |
//! | [`export`] | a scene → MJCF, with the encodings MJCF needs (universal, revolute and slider cuts, planar) |
//! | [`warnings`] | what kinloop cannot use, listed by name in one warning |
//! | [`load`] | a command line's scene argument: `.xml` through the importer, anything else as before |

pub mod actuator;
pub mod defaults;
pub mod equality;
pub mod error;
pub mod export;
pub mod frames;
pub mod import;
pub mod inertia;
pub mod load;
pub mod planar;
pub mod tree;
pub mod warnings;
pub mod xml;

pub use error::MjcfError;
pub use export::{export, Export};
pub use import::{import_file, import_str, Import};
