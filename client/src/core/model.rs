//! The local model of interaction (paper section V, Fig 3) as the core runs it: the reduced form by
//! default, the paper's configuration-space form (eq 11/13) when configured and the snapshot carries its
//! terms, and the pull toward the VE that keeps it near the simulation without stepping the force.

use kinloop_linkage::math::eigen::symmetric_eigen;
use kinloop_linkage::math::space::{MatOps, Space, VecOps};
use kinloop_linkage::{
    algorithms::configuration::ConfigLayout,
    algorithms::local_model::{
        ConfigSpaceLocalModel, ContactTerm, OpSpaceLocalModel, OpSpaceTerms, MAX_LOCAL_CONTACTS,
    },
    math::space::OpPose,
};

use super::controllers::{force_response, project_twist};
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

    /// On a pinned grasp (a device that renders no torque): the reduced model's angular twist set to the
    /// turning its linear twist makes through the pin, `ω = (Λ̂⁻¹)_ωf (Λ̂⁻¹)_ff⁺ v` (the forces that move the OP
    /// by `v`, and how the linkage turns the OP under them). No controller acts on the angular axes there,
    /// so nothing else holds the model's turning to its motion: b̂'s angular part, taken at the VE's state a
    /// round trip behind, and the frame carried along the path each leave a little turning the linkage does
    /// not make, which then sums without bound until the VE refuses the uplinks as too fast
    /// (docs/robustness.md, "The static load a device without torque holds").
    /// Turning the OP makes without moving it (a link spun about the grasped point) is left out: the pin
    /// neither feels nor drives it; an OP that forces do not move at all keeps the model's own turning.
    pub fn turn_as_pinned(&mut self) {
        if self.using_config {
            return;
        }
        let m = &self.reduced.terms.inverse_inertia;
        let twist = pinned_turning::<S>(m, &self.reduced.twist);
        self.reduced.twist = twist;
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

/// Below this fraction of the largest response to forces, a direction of `(Λ̂⁻¹)_ff` is one forces do not
/// move the OP in.
const PIN_RESPONSE_FLOOR: f64 = 1e-9;

/// `twist` with its angular part replaced by the turning its linear part makes through a pin:
/// `(Λ̂⁻¹)_ωf (Λ̂⁻¹)_ff⁺ v` (see [`LocalModel::turn_as_pinned`]). Allocates nothing.
pub(crate) fn pinned_turning<S: Space>(inverse_inertia: &S::OpMat, twist: &S::OpVec) -> S::OpVec {
    let lin = <S::Point as VecOps>::LEN;
    let (values, vectors) = symmetric_eigen::<S>(&force_response::<S>(inverse_inertia));
    let largest = (0..S::DIM).map(|i| values[i]).fold(0.0, f64::max);
    // A response too small to divide by (terms fading from zero, subnormal) moves nothing through the pin.
    if !largest.is_normal() {
        return *twist;
    }
    let mut linear = S::OpVec::zero();
    for i in 0..lin {
        linear[i] = twist[i];
    }
    // The forces that move the OP by the linear twist: (Λ̂⁻¹)_ff⁺ v.
    let mut force = S::OpVec::zero();
    for k in 0..S::DIM {
        if values[k] > largest * PIN_RESPONSE_FLOOR && values[k] > 0.0 {
            let mut e = S::OpVec::zero();
            for r in 0..S::DIM {
                e[r] = vectors[(r, k)];
            }
            force += e * (e.dot(&linear) / values[k]);
        }
    }
    let response = *inverse_inertia * force;
    if !response.as_slice().iter().all(|x| x.is_finite()) {
        return *twist;
    }
    let mut out = *twist;
    for a in lin..S::DIM {
        out[a] = response[a];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::{Matrix3, Vector3};

    /// A link of inertia `I` about a fixed pivot, held at radius `r`: its OP twist is `u θ̇` with
    /// `u = (−r sin θ, r cos θ, 1)`, so `Λ⁻¹ = u uᵀ / I`. Through a pin the OP turns at the speed its motion
    /// along the circle gives, `ω = (u_lin · v) / r²`, whatever the model's angular twist was; the linear
    /// twist (off the circle included) is the model's own.
    #[test]
    fn a_crank_held_through_a_pin_turns_as_its_point_moves_along_the_circle() {
        let (inertia, r, theta) = (0.3, 0.041, 0.7_f64);
        let u = Vector3::new(-r * theta.sin(), r * theta.cos(), 1.0);
        let inverse: Matrix3<f64> = u * u.transpose() / inertia;
        let twist = Vector3::new(0.012, -0.004, 280.0);
        let turned = pinned_turning::<Planar>(&inverse, &twist);
        let along = (u[0] * twist[0] + u[1] * twist[1]) / (r * r);
        assert!((turned[2] - along).abs() < 1e-9 * along.abs().max(1.0), "{} against {along}", turned[2]);
        assert_eq!((turned[0], turned[1]), (twist[0], twist[1]));
    }

    /// An OP that forces do not move (held at the pivot of a spinning link): nothing ties its turning to a
    /// motion, and the model keeps the turning it has. Where forces move it, turning without moving (a
    /// second, pure-turning free direction) is left out: the pin neither feels nor drives it.
    #[test]
    fn turning_that_forces_cannot_make_is_the_models_own_or_left_out() {
        let spinning = Matrix3::from_diagonal(&Vector3::new(0.0, 0.0, 4.0));
        let twist = Vector3::new(0.0, 0.0, 3.0);
        assert_eq!(pinned_turning::<Planar>(&spinning, &twist), twist);
        let sliding_and_spinning = Matrix3::from_diagonal(&Vector3::new(2.0, 0.0, 4.0));
        let turned = pinned_turning::<Planar>(&sliding_and_spinning, &Vector3::new(0.5, 0.0, 3.0));
        assert_eq!(turned, Vector3::new(0.5, 0.0, 0.0));
    }
}
