//! The local model of interaction (paper section V, Fig 3) as the core runs it: the reduced form by
//! default, the paper's configuration-space form (eq 11/13) when configured and the snapshot carries its
//! terms, and the pull toward the VE that keeps it near the simulation without stepping the force.

use kinloop_linkage::math::space::{MatOps, Space, VecOps};
use kinloop_linkage::{
    algorithms::configuration::ConfigLayout,
    algorithms::local_model::{
        ConfigSpaceLocalModel, ContactTerm, OpSpaceLocalModel, OpSpaceTerms, MAX_LOCAL_CONTACTS,
    },
    math::space::OpPose,
};

use super::controllers::project_twist;
use super::intake::SnapshotTerms;

/// The local model in use.
#[derive(Clone, Debug)]
pub(crate) struct LocalModel<S: Space> {
    reduced: OpSpaceLocalModel<S>,
    config: Option<ConfigSpaceLocalModel<S>>,
    using_config: bool,
    /// Snapshots whose configuration terms could not be factored (D̂ not positive definite).
    pub config_refusals: u64,
}

impl<S: Space> LocalModel<S> {
    /// A model at rest at the origin; `config_shape = Some((layout, m))` allocates the configuration form.
    pub fn new(config_shape: Option<(ConfigLayout, usize)>) -> Self {
        let terms = OpSpaceTerms { inverse_inertia: S::OpMat::zero(), bias: S::OpVec::zero() };
        LocalModel {
            reduced: OpSpaceLocalModel::new(terms, OpPose::identity()),
            config: config_shape.map(|(layout, m)| ConfigSpaceLocalModel::with_layout(layout, m)),
            using_config: false,
            config_refusals: 0,
        }
    }

    /// True when the configuration-space form steps the model.
    pub fn using_config(&self) -> bool {
        self.using_config
    }

    /// The configuration-space form while it steps the model.
    pub fn config_in_use(&self) -> Option<&ConfigSpaceLocalModel<S>> {
        self.config.as_ref().filter(|_| self.using_config)
    }

    pub fn pose(&self) -> OpPose<S> {
        match (&self.config, self.using_config) {
            (Some(c), true) => c.pose,
            _ => self.reduced.pose,
        }
    }

    pub fn twist(&self) -> S::OpVec {
        match (&self.config, self.using_config) {
            (Some(c), true) => c.twist,
            _ => self.reduced.twist,
        }
    }

    pub fn set_state(&mut self, pose: OpPose<S>, twist: S::OpVec) {
        self.reduced.pose = pose;
        self.reduced.twist = twist;
        if let Some(c) = self.config.as_mut() {
            c.pose = pose;
            c.twist = twist;
        }
    }

    /// Takes the snapshot's frozen terms, keeping the model's own OP state (the pull toward the VE moves
    /// it, not the update).
    pub fn update(&mut self, terms: &SnapshotTerms<S>) {
        let (pose, twist) = (self.pose(), self.twist());
        self.reduced.terms.bias = terms.bias;
        self.reduced.contacts = terms.contacts;
        self.reduced.contact_count = terms.contact_count;
        self.using_config = false;
        if let (Some(model), Some(config_terms), true) = (self.config.as_mut(), terms.config.as_ref(), terms.has_config)
        {
            // `update` resets q, q̇ and the OP state to the snapshot's; only the OP state matters to the step
            // (q̈ = M F + c is frozen), and it is restored below.
            if model.update(config_terms, pose) {
                self.using_config = true;
            } else {
                self.config_refusals += 1;
            }
        }
        self.set_state(pose, twist);
    }

    /// Λ̂⁻¹ for the reduced form (filtered by the caller).
    pub fn set_inverse_inertia(&mut self, inverse_inertia: &S::OpMat) {
        self.reduced.terms.inverse_inertia = *inverse_inertia;
    }

    /// b̂ for the reduced form: the snapshot's, as the caller carries it to where the model is.
    pub fn set_bias(&mut self, bias: &S::OpVec) {
        self.reduced.terms.bias = *bias;
    }

    /// What a step of `dt_s` under `wrench` does, by the form that steps the model: its Λ̂⁻¹ and the twist
    /// the step reaches (what the channels' reaction at the end of the step is solved from,
    /// `channel_reaction`).
    pub fn step_response(&self, dt_s: f64, wrench: &S::OpVec) -> (S::OpMat, S::OpVec) {
        match (&self.config, self.using_config) {
            (Some(c), true) => {
                let inverse = c.inverse_inertia();
                (inverse, c.twist + (c.free_op_acceleration() + inverse * *wrench) * dt_s)
            }
            _ => (self.reduced.terms.inverse_inertia, self.reduced.twist + self.reduced.acceleration(wrench) * dt_s),
        }
    }

    /// One step of `dt_s` under the OP wrench `wrench`.
    pub fn step(&mut self, dt_s: f64, wrench: &S::OpVec) {
        match (&mut self.config, self.using_config) {
            (Some(c), true) => {
                c.step(dt_s, wrench);
            }
            _ => {
                self.reduced.step(dt_s, wrench);
            }
        }
    }

    /// Moves the OP state by `moved` (a displacement) and `sped` (a twist change), as [`split_correction`]
    /// gives them.
    pub fn apply_correction(&mut self, moved: &S::OpVec, sped: &S::OpVec) {
        let mut own = self.pose();
        own.integrate(moved, 1.0);
        self.set_state(own, self.twist() + *sped);
    }

    /// The live contacts of the reduced form (the configuration form tracks none: the paper's eq 13 testbed
    /// has no contacts, and its eq 11 contact Jacobians are not sent).
    pub fn contacts(&self) -> (&[ContactTerm<S>; MAX_LOCAL_CONTACTS], usize) {
        let live = if self.using_config { 0 } else { self.reduced.contact_count };
        (&self.reduced.contacts, live)
    }
}

/// The fractions of the pose and twist discrepancies `pose` and `twist` to correct in one tick: the part
/// along the constrained directions by `constrained`, the rest by `free`. Returns (displacement, twist change).
pub(crate) fn split_correction<S: Space>(
    pose: &S::OpVec,
    twist: &S::OpVec,
    projector: &S::OpMat,
    length_scale: f64,
    constrained: f64,
    free: f64,
) -> (S::OpVec, S::OpVec) {
    let split = |d: &S::OpVec| {
        let along = project_twist::<S>(projector, length_scale, d);
        along * constrained + (*d - along) * free
    };
    (split(pose), split(twist))
}
