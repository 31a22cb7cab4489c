//! The position channels' reaction on the local model, taken at the end of the model's step.
//!
//! The channels are a spring-damper between the device and the local model, and the model is as light as the
//! OP's lightest direction. Taken at the start of the step (explicit Euler), that spring on that mass is stable
//! only for `K T² / m < 4` and `B T / m < 2`: on a light OP mapped to a stiff device the channels could then
//! keep only a fraction of the stiffness the device renders, and a hand holding the load stretched them by
//! centimetres. Taken at the end of the step (backward Euler on the spring and the damper, as the VE takes its
//! joint springs) the step is stable for any stiffness and damping, and the channels keep the device's budget,
//! bounded by the graphics controller's stiffness rather than the OP's mass (`design`).
//!
//! With `e = x_d ⊖ x_m` and the model's twist `v⁺ = u + T Λ̂⁻¹ F` after a step of `T` from the free twist `u`
//! (the model's own acceleration and every other wrench), the model receives `𝒦 e + ℬ ė` of the channels,
//! `𝒦` and `ℬ` linear (their stiffness and damping, through what the device renders: the gate's gain, the
//! limits' scales of the last tick, the unactuated axes, the softening along the constrained directions). At
//! the end of the step `e⁺ = e − T C v⁺` and `ė⁺ = C (v_d − v⁺)` (`C` zeroes the axes no controller acts
//! on), so `F = 𝒦 e + ℬ C v_d − A v⁺` with `A = (T 𝒦 + ℬ) C`, and `(I + T A Λ̂⁻¹) F = 𝒦 e + ℬ C v_d − A u`.
//! For diagonal `𝒦 = K`, `ℬ = B` and `C = I` this is the implicit spring-damper
//! `(I + T D Λ̂⁻¹) F = K e + B v_d − D u`, `D = T K + B`, whose matrix has the eigenvalues of
//! `I + T D^½ Λ̂⁻¹ D^½`, all at least one.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::passivity::MAX_AXES;
use nalgebra::{SMatrix, SVector};

/// The channels' reaction on the model at the end of a step of `dt_s` (see the module documentation): the
/// model's inverse inertia `inverse_inertia` and its twist `free_twist` after the step without the reaction,
/// the error `error` and device twist `device_twist`, `controlled` (which zeroes the axes no controller acts
/// on), and the linear maps from an error to the reaction of the channels' springs (`springs`, `R K`) and from
/// an error rate to their dampers' (`dampers`, `R B`), as the model receives them. `None` when the system is
/// singular or the result not finite (the caller then takes no reaction this step).
#[allow(clippy::too_many_arguments)]
pub(crate) fn end_of_step_reaction<S: Space>(
    dt_s: f64,
    inverse_inertia: &S::OpMat,
    free_twist: &S::OpVec,
    error: &S::OpVec,
    device_twist: &S::OpVec,
    controlled: impl Fn(S::OpVec) -> S::OpVec,
    springs: impl Fn(&S::OpVec) -> S::OpVec,
    dampers: impl Fn(&S::OpVec) -> S::OpVec,
) -> Option<S::OpVec> {
    let n = S::DIM;
    let pulled = springs(error) + dampers(&controlled(*device_twist));
    // A = (T R K + R B) C, column by column; the padding beyond `n` is the identity, so the solve leaves it
    // alone.
    let mut system = SMatrix::<f64, MAX_AXES, MAX_AXES>::identity();
    let mut a_matrix = SMatrix::<f64, MAX_AXES, MAX_AXES>::zeros();
    for col in 0..n {
        let mut unit = S::OpVec::zero();
        unit[col] = 1.0;
        let unit = controlled(unit);
        let column = springs(&unit) * dt_s + dampers(&unit);
        for row in 0..n {
            a_matrix[(row, col)] = column[row];
        }
    }
    let mut rhs = SVector::<f64, MAX_AXES>::zeros();
    for row in 0..n {
        let a_u: f64 = (0..n).map(|k| a_matrix[(row, k)] * free_twist[k]).sum();
        rhs[row] = pulled[row] - a_u;
        for col in 0..n {
            let a_inv: f64 = (0..n).map(|k| a_matrix[(row, k)] * inverse_inertia[(k, col)]).sum();
            system[(row, col)] += dt_s * a_inv;
        }
    }
    let solved = system.lu().solve(&rhs)?;
    let mut reaction = S::OpVec::zero();
    for a in 0..n {
        reaction[a] = solved[a];
    }
    reaction.is_finite().then_some(reaction)
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::{Matrix3, Vector3};

    /// One axis, `R = C = I`: the reaction is the spring-damper at the end of the step, `K e⁺ + B ė⁺`, with
    /// the state the model reaches under it (checked by stepping the model with it).
    #[test]
    fn the_reaction_is_the_spring_damper_at_the_state_it_leads_to() {
        let (dt, m, k, b) = (1e-3, 1e-4, 1000.0, 5.0);
        let inverse = Matrix3::from_diagonal(&Vector3::new(1.0 / m, 1.0 / m, 0.0));
        let (x_m, v_m, x_d, v_d) = (0.0, 0.1, 0.01, -0.2);
        let free = Vector3::new(v_m, 0.0, 0.0);
        let f = end_of_step_reaction::<Planar>(
            dt,
            &inverse,
            &free,
            &Vector3::new(x_d - x_m, 0.0, 0.0),
            &Vector3::new(v_d, 0.0, 0.0),
            |v| v,
            |e| e * k,
            |r| r * b,
        )
        .expect("solvable");
        let v_after = v_m + dt * f[0] / m;
        let x_after = x_m + dt * v_after;
        let at_end = k * (x_d - x_after) + b * (v_d - v_after);
        assert!((f[0] - at_end).abs() <= 1e-9 * at_end.abs().max(1.0), "{} against {at_end}", f[0]);
    }

    /// A spring far too stiff for its mass at this step (`K T² / m` = 1000, explicit Euler diverges past
    /// 4) settles the model onto a still device, and the energy of spring and mass never grows.
    #[test]
    fn a_stiff_channel_on_a_light_model_settles_without_gaining_energy() {
        let (dt, m, k, b) = (1e-3, 1e-3, 1e6, 0.0);
        let inverse = Matrix3::from_diagonal(&Vector3::new(1.0 / m, 1.0 / m, 1.0 / m));
        let (mut x, mut v) = (0.02, 0.0);
        let energy = |x: f64, v: f64| 0.5 * k * x * x + 0.5 * m * v * v;
        let mut last = energy(x, v);
        for _ in 0..2000 {
            let f = end_of_step_reaction::<Planar>(
                dt,
                &inverse,
                &Vector3::new(v, 0.0, 0.0),
                &Vector3::new(-x, 0.0, 0.0),
                &Vector3::zeros(),
                |v| v,
                |e| e * k,
                |r| r * b,
            )
            .expect("solvable");
            v += dt * f[0] / m;
            x += dt * v;
            let now = energy(x, v);
            assert!(now <= last * (1.0 + 1e-12), "energy grew from {last} to {now}");
            last = now;
        }
        assert!(x.abs() < 1e-3 * 0.02, "the model did not settle: {x}");
    }

    /// A rendered map that passes nothing (the gate closed) gives no reaction, whatever the stretch.
    #[test]
    fn a_closed_gate_passes_no_reaction() {
        let inverse = Matrix3::identity();
        let f = end_of_step_reaction::<Planar>(
            1e-3,
            &inverse,
            &Vector3::new(1.0, 2.0, 3.0),
            &Vector3::new(0.1, 0.2, 0.3),
            &Vector3::new(1.0, 1.0, 1.0),
            |v| v,
            |e| e * 0.0,
            |r| r * 0.0,
        )
        .expect("solvable");
        assert_eq!(f, Vector3::zeros());
    }
}
