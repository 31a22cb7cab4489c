//! The algorithms: free functions `algo(&Model, &mut Data, ...)`, one per file, named for what they compute
//! (see the crate documentation's table), plus the scene compilation that needs them (`compile`: poses at q0,
//! assembly near q0) and the tree walks the recursions share (`tree`). They use `math` and `model`; nothing
//! below uses them.

pub mod articulated;
pub mod assemble;
pub mod bias;
mod compile;
pub mod configuration;
pub mod constraint_directions;
pub mod contact;
pub mod cut_forces;
pub mod dynamics;
pub mod energy_guard;
pub mod gravity;
pub mod idle_freedoms;
pub mod implicit_joint_forces;
pub mod integrator;
pub mod jacobian;
pub mod joint_forces;
pub mod joint_limits;
pub mod kinematics;
pub mod kkt;
pub mod local_model;
pub mod loop_closure;
pub mod ltl;
pub mod mass_matrix;
pub mod op_path;
pub mod op_space;
pub mod penalty;
pub mod reach;
pub(crate) mod tree;
pub mod velocity_product;
