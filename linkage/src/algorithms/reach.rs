//! The reach of an operational point: where the closed linkage lets it go, how light it can feel there, and
//! the static load gravity puts on a hand that holds it still. A VE surveys each OP once, before its loop
//! starts, to fit a haptic device's workspace and force range to the linkage and to design the couplings
//! (server: coupling gains and scales; client: its own gains). Not a hot path: it allocates.
//!
//! **The walk.** The closed configurations form a manifold `h(q) = 0` of dimension `n − rank W`; the OP's
//! reach is its image. The survey walks that manifold from `q0` by tangent steps: the walk direction is
//! projected on the null space of W (eq 2's constraint Jacobian) at every step, so it follows the manifold
//! around bends, and each step is pulled back onto `h = 0` by Gauss-Newton (`Δq = −W⁺ h`, as `assemble`).
//! Starting from `q0` keeps the walk on q0's assembly branch: a four-bar's crossed branch, which no motion
//! reaches, is never visited. A walk that cannot close (a rocker at its dead point, a slider at the end of
//! its stroke) or that would push the linkage's geometry into an obstacle (the slider-crank's wall) or a
//! joint or cut past its `range` reverses, as the linkage itself would. (Through the wall, the
//! slider-crank's tour led the hand 22° of crank past where the slider meets it, and every device saturated
//! against a hand that pressed on for its waypoints.)
//! Walks leave `q0` in several directions of the null space (one back and forth on a 1-DOF linkage, a star
//! on a 2-DOF one).
//!
//! **Per sample** (at rest, so the loads are static): Λ⁻¹ with the loops closed (eq 9), the OP's
//! acceleration under gravity alone `a_g = J q̈_g` (eq 4 with q̇ = 0), and the static load: the OP wrench
//! that cancels `a_g` in the OP's free directions, `F = −(Λ̃⁻¹)⁺ ã_g` in the unit-consistent coordinates of
//! [`constraint_directions`] (eq 10), restricted to the directions not counted as constrained — along those
//! the joints carry the load, not the hand.

use std::cmp::Ordering;

use nalgebra::{DMatrix, DVector};

use crate::algorithms::assemble::ClosureScales;
use crate::algorithms::constraint_directions::scale_op;
use crate::algorithms::constraint_directions::{constraint_directions, ConstraintDirections, DEFAULT_THRESHOLD};
use crate::algorithms::contact::{contact_capacity, detect_contacts, Contact};
use crate::algorithms::dynamics::forward_dynamics;
use crate::algorithms::joint_limits::limit_wall_energy;
use crate::algorithms::kinematics::{forward_kinematics, forward_velocity};
use crate::algorithms::local_model::op_acceleration;
use crate::algorithms::loop_closure::loop_closure;
use crate::algorithms::op_path::{difference_neighbours, OpPath, PathShape};
use crate::algorithms::op_space::op_space_inertia;
use crate::error::DynamicsError;
use crate::math::space::OpPose;
use crate::math::space::{Space, VecOps};
use crate::model::data::Data;
use crate::model::{JointKind, Model};

/// A group of axes (linear or angular) whose largest inverse inertia is below this fraction of the other
/// group's (unit-consistent coordinates) does not move at all: what is left is round-off of eq 9's
/// cancellation, some 1e-16 relative.
pub const IMMOBILE_GROUP: f64 = 1e-9;

/// Tour waypoints keep to poses where the OP is at least this mobile, relative to the walk's median
/// (σ_max of Λ̃⁻¹): a twentieth keeps a rocker's swing but its last few degrees before the dead point.
pub const TOUR_MOBILITY: f64 = 0.05;

/// How far and how often a survey walks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurveyConfig {
    /// Walks leaving `q0` (each in its own direction of the null space).
    pub walks: usize,
    /// Steps per walk.
    pub steps: usize,
    /// Length of a step in joint space (rad; prismatic coordinates count in units of the length scale).
    pub step: f64,
    /// Λ⁻¹ and the static load are evaluated every this many steps (positions at every step).
    pub inertia_every: usize,
    /// Waypoints of the tour (at most).
    pub tour_points: usize,
}

impl Default for SurveyConfig {
    fn default() -> Self {
        SurveyConfig { walks: 6, steps: 360, step: 0.04, inertia_every: 3, tour_points: 24 }
    }
}

/// What a survey found at one operational point.
#[derive(Clone, Debug, PartialEq)]
pub struct OpReach<S: Space> {
    /// The operational point.
    pub op: usize,
    /// Closed configurations visited.
    pub samples: usize,
    /// Smallest coordinates the OP's position reached (world, m).
    pub position_min: S::Point,
    /// Largest coordinates the OP's position reached (world, m).
    pub position_max: S::Point,
    /// Largest rotation of the OP's frame away from its orientation at `q0` (rad).
    pub rotation_range: f64,
    /// Reachable poses along the first walks, in order (an intended motion that stays inside the reach).
    pub tour: Vec<OpPose<S>>,
    /// Static load at the OP: the 90th percentile over the samples of the force (N) and torque (N m) a hand
    /// must apply to hold the linkage still against gravity (see the module documentation). The percentile
    /// rather than the maximum: next to a singular configuration a free direction's inverse inertia tends to
    /// zero and the load there to infinity, which no device renders and no scale should be set by.
    pub static_force_n: f64,
    /// See `static_force_n` (N m).
    pub static_torque_nm: f64,
    /// The static load as a grasp that passes no torque holds it: the 90th percentile over the samples of
    /// [`pin_force`] (N). A device that renders no torque (a Falcon, a Touch) holds a crank off its pivot by
    /// force alone, the link's gravity torque through the lever, where `static_force_n` shares it with a
    /// torque the device does not have.
    pub static_pin_force_n: f64,
    /// Largest static force over the samples (N).
    pub static_force_max_n: f64,
    /// Largest eigenvalue of the linear block of Λ⁻¹ over the samples (1/kg): the inverse of the lightest
    /// translational effective mass the OP shows.
    pub inverse_mass_max: f64,
    /// Largest eigenvalue of the angular block of Λ⁻¹ over the samples (1/(kg m²)).
    pub inverse_rotational_inertia_max: f64,
    /// Smallest turning radius of the OP over the samples (m; see `turning_radius_min`): on a linkage of one
    /// degree of freedom, the OP's smallest distance from the instant centre of its motion. Infinite for an OP
    /// that never turns.
    pub turning_radius_min_m: f64,
    /// Dimension of the closed configuration manifold at `q0` (the linkage's degrees of freedom).
    pub dof: usize,
    /// On a linkage of one degree of freedom, the OP's whole path in order, one walk step apart: one lap of
    /// a closed path (a crank's coupler curve), or end to end of an open one (between dead points, stroke
    /// ends or obstacles), with the OP's acceleration at rest at each pose (the forces at rest: gravity,
    /// springs, actuators). Every pose the OP can take lies on it, so a client that knows it knows where the
    /// joints hold the OP far from where a snapshot linearized them (the constrained directions turn along
    /// the path; `kinloop_client`'s local model follows them), and what the forces at rest do there. `None`
    /// on other linkages, whose reach is a surface or more. Where the OP turns back along its path while the
    /// linkage moves on (a rocker's output: one pose, two configurations), one sweep of it, limit to limit,
    /// without forces at rest ([`PathShape::Swing`]).
    pub path: Option<OpPath<S>>,
    /// At each pose of `path` (not a swing's), the OP's inertia along the path and how stiff the forces at
    /// rest are there ([`PathMode`]): what the coupling's damping must hold (`kinloop_server`'s design).
    /// Empty without such a path.
    pub path_modes: Vec<PathMode>,
}

/// How the OP moves about one pose of its path under the linkage's own forces at rest, the hand away.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathMode {
    /// Inertia along the path's unit tangent (unit-consistent coordinates, kg): `1 / σ` of Λ̃⁻¹ (eq 9), whose
    /// only nonzero singular value `σ` on one degree of freedom is the tangent's inverse inertia.
    pub mass: f64,
    /// `−dF/ds`, the change of the force at rest along the path (`F = m a`, the inertia times the
    /// acceleration at rest along the tangent) per unit of its length (unit-consistent, N/m): how stiffly
    /// springs, actuators and gravity through the loops hold the OP about the pose, a hill where negative.
    pub rest_stiffness: f64,
}

impl<S: Space> OpReach<S> {
    /// Extent of the reach along each world axis (m).
    pub fn extent(&self) -> S::Point {
        self.position_max - self.position_min
    }

    /// The largest extent (m).
    pub fn largest_extent(&self) -> f64 {
        self.extent().as_slice().iter().fold(0.0, |a, b| a.max(*b))
    }
}

/// Why a survey failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SurveyError {
    /// No such operational point.
    #[error("no operational point {index} (the scene has {count})")]
    UnknownOp {
        /// Index asked for.
        index: usize,
        /// How many there are.
        count: usize,
    },
    /// The dynamics failed at the starting configuration.
    #[error("the dynamics failed at q0: {0}")]
    Dynamics(#[from] DynamicsError),
}

/// Joint-space weights: 1 for revolute coordinates, 1/L for prismatic ones, so a step of `step` moves every
/// joint by a comparable amount.
fn joint_weights<S: Space>(model: &Model<S>) -> DVector<f64> {
    DVector::from_iterator(
        model.nv(),
        model.joints.iter().map(|j| match j.kind {
            JointKind::Revolute | JointKind::Ball { .. } => 1.0,
            JointKind::Prismatic => 1.0 / model.length_scale,
        }),
    )
}

/// Rows of W's right singular vectors with a singular value above `tol · σ_max`: W's row space. The null
/// space is its orthogonal complement.
fn row_space(w: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if w.nrows() == 0 {
        return Some(DMatrix::zeros(0, w.ncols()));
    }
    let svd = w.clone().svd(false, true);
    let v_t = svd.v_t?;
    let max = svd.singular_values.max();
    let keep: Vec<usize> = (0..svd.singular_values.len()).filter(|&i| svd.singular_values[i] > 1e-9 * max).collect();
    Some(DMatrix::from_fn(keep.len(), w.ncols(), |r, c| v_t[(keep[r], c)]))
}

/// `v` with its components in the row space `rows` (orthonormal rows) removed.
fn project_null(rows: &DMatrix<f64>, v: &DVector<f64>) -> DVector<f64> {
    if rows.nrows() == 0 {
        return v.clone();
    }
    v - rows.transpose() * (rows * v)
}

/// Residual norm of the loops at `q` (kinematics into `data`).
fn residual<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>, zero: &DVector<f64>) -> f64 {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, zero);
    loop_closure(model, data);
    data.closure_residual.norm()
}

/// Pulls `q` back onto the loops by Gauss-Newton, in length scales (`ClosureScales`); false when it does not
/// converge in a few iterations (a dead point, or a step too long for the curvature).
fn close<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &mut DVector<f64>, zero: &DVector<f64>) -> bool {
    let scales = ClosureScales::of(model);
    let tolerance = 1e-11;
    residual(model, data, q, zero);
    let mut r = scales.residual(&data.closure_residual);
    for _ in 0..12 {
        if r <= tolerance {
            return true;
        }
        let Ok(step) = scales.newton_step(&data.closure_jacobian(), &data.closure_residual) else {
            return false;
        };
        let mut trial = q.clone();
        crate::algorithms::configuration::integrate(model, &mut trial, &step, -1.0);
        residual(model, data, &trial, zero);
        let r_trial = scales.residual(&data.closure_residual);
        // No smaller (a NaN residual included): the step does not help.
        if r_trial.partial_cmp(&r) != Some(Ordering::Less) {
            return false;
        }
        *q = trial;
        r = r_trial;
    }
    r <= tolerance
}

/// The OP's static load and Λ⁻¹ at the closed configuration `q`, at rest: fills `data` (dynamics at `q`,
/// q̇ = `at_rest`, n zeros) and returns the static wrench and the constraint directions it was resolved with.
/// Allocates nothing (a VE holding a user's share of the weight calls it every snapshot round).
pub fn static_op_load<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &DVector<f64>,
    at_rest: &DVector<f64>,
    op: usize,
) -> Result<(S::OpVec, ConstraintDirections<S>), DynamicsError> {
    forward_dynamics(model, data, q, at_rest, &mut ())?;
    op_space_inertia(model, data, op)?;
    let directions = constraint_directions::<S>(&data.op.inverse_inertia, model.length_scale, DEFAULT_THRESHOLD);
    let load = static_wrench(&directions, &op_acceleration(data));
    Ok((load, directions))
}

/// `−(Λ̃⁻¹)⁺ ã` over the free directions of `directions`, in physical units: the OP wrench that cancels the
/// OP acceleration `accel` wherever the OP is free to move.
pub fn static_wrench<S: Space>(directions: &ConstraintDirections<S>, accel: &S::OpVec) -> S::OpVec {
    let scaled = directions.to_scaled(accel);
    let free = S::DIM - directions.count;
    let mut wrench = S::OpVec::zero();
    for i in 0..free {
        let sigma = directions.singular_values[i];
        if sigma > 0.0 {
            let u = directions.direction(i);
            wrench -= u * (u.dot(&scaled) / sigma);
        }
    }
    directions.wrench_from_scaled(&wrench)
}

/// Below this, a free direction's translation (squared, of a unit direction in unit-consistent coordinates)
/// counts as none: the OP turns there without moving, and no force through a pin holds it.
const PIN_TRANSLATION_FLOOR: f64 = 1e-6;

/// The least force, with no torque, that holds the OP still where the static wrench `load` does (N): the
/// same work as `load` along every free direction of `directions`, through a grasp that passes no torque.
/// With `(v, ω̃)` the unit free directions in unit-consistent coordinates and `w̃` the load there, it is the
/// least-norm `f` with `Vᵀ f = Uᵀ w̃`: `f = V (Vᵀ V)⁺ Uᵀ w̃`. A crank held at a point off its pivot carries
/// the link's gravity torque as this force times the lever. Free directions along which the OP turns without
/// translating (below [`PIN_TRANSLATION_FLOOR`]) cannot be held by a force and are left out. Allocates.
pub fn pin_force<S: Space>(directions: &ConstraintDirections<S>, load: &S::OpVec) -> f64 {
    let lin = <S::Point as VecOps>::LEN;
    let free: Vec<S::OpVec> = (0..S::DIM - directions.count)
        .filter(|&i| directions.singular_values[i] > 0.0)
        .map(|i| directions.direction(i))
        .collect();
    if free.is_empty() {
        return 0.0;
    }
    // The load in unit-consistent coordinates, where the directions are unit: `(f, τ / L)`.
    let scaled = scale_op::<S>(load, 1.0 / directions.length_scale);
    let v = DMatrix::from_fn(lin, free.len(), |r, c| free[c][r]);
    let work = DVector::from_iterator(free.len(), free.iter().map(|u| u.dot(&scaled)));
    let gram = v.transpose() * &v;
    match gram.pseudo_inverse(PIN_TRANSLATION_FLOOR) {
        Ok(inverse) => (v * (inverse * work)).norm(),
        Err(_) => f64::INFINITY,
    }
}

/// Largest eigenvalue of the symmetric block `range × range` of `m`.
fn block_max_eigenvalue<S: Space>(m: &S::OpMat, range: std::ops::Range<usize>) -> f64 {
    let len = range.len();
    if len == 0 {
        return 0.0;
    }
    let block = DMatrix::from_fn(len, len, |r, c| m[(range.start + r, range.start + c)]);
    block.symmetric_eigen().eigenvalues.max().max(0.0)
}

/// One step of a walk, `Some(direction)` on success (the new tangent direction, unit in the weighted norm).
struct Walker<'a, S: Space> {
    model: &'a Model<S>,
    data: Data<S>,
    weights: DVector<f64>,
    zero: DVector<f64>,
    /// Scratch for the obstacle check.
    contacts: Vec<Contact<S>>,
}

impl<S: Space> Walker<'_, S> {
    /// The null-space basis at the configuration of the last `residual` (its W).
    fn rows(&self) -> Option<DMatrix<f64>> {
        // Work in weighted coordinates q̃ = diag(weights) q, W̃ = W diag(1/weights), its length rows in length
        // scales (`ClosureScales`: its coordinate scales are 1 / weights).
        let scaled = ClosureScales::of(self.model).jacobian(&self.data.closure_jacobian());
        // The SVD panics on a NaN: a configuration blown up has no row space.
        if scaled.iter().any(|x| !x.is_finite()) {
            return None;
        }
        row_space(&scaled)
    }

    /// How deep the linkage's geometry is in the scene's obstacles at the kinematics in `data` (m, ≥ 0).
    fn penetration(&mut self) -> f64 {
        detect_contacts(self.model, &self.data.kin, 0.0, &mut self.contacts);
        self.contacts.iter().map(|c| -c.gap).fold(0.0, f64::max)
    }

    /// Moves `q` one step along `direction` (weighted coordinates), projected on the tangent space; the new
    /// direction, or `None` when the step does not close or would push the geometry deeper into an obstacle
    /// or a joint further past its range (a wall stops the linkage as a dead point does; a `q0` already in
    /// contact may still leave it).
    fn step(&mut self, q: &mut DVector<f64>, direction: &DVector<f64>, length: f64) -> Option<DVector<f64>> {
        residual(self.model, &mut self.data, q, &self.zero);
        let depth_before = self.penetration();
        let stops_before = limit_wall_energy(self.model, &self.data.kin, q);
        let rows = self.rows()?;
        let tangent = project_null(&rows, direction);
        let norm = tangent.norm();
        // Too short to normalise (or NaN).
        if norm.partial_cmp(&1e-9) != Some(Ordering::Greater) {
            return None;
        }
        let tangent = tangent / norm;
        let mut trial = q.clone();
        let displacement = tangent.component_div(&self.weights) * length;
        crate::algorithms::configuration::integrate(self.model, &mut trial, &displacement, 1.0);
        if !close(self.model, &mut self.data, &mut trial, &self.zero) {
            return None;
        }
        // `close` leaves the kinematics of `trial` in `data`.
        let depth = self.penetration();
        if depth > 0.0 && depth > depth_before {
            return None;
        }
        // Past a joint's or cut's range likewise: its walls' energy says how far, in one unit for all.
        let stops = limit_wall_energy(self.model, &self.data.kin, &trial);
        if stops > 0.0 && stops > stops_before {
            return None;
        }
        *q = trial;
        Some(tangent)
    }
}

/// Surveys operational point `op` of `model` from its `q0` (see the module documentation).
pub fn survey_op<S: Space>(model: &Model<S>, op: usize, config: &SurveyConfig) -> Result<OpReach<S>, SurveyError> {
    if op >= model.ops.len() {
        return Err(SurveyError::UnknownOp { index: op, count: model.ops.len() });
    }
    let n = model.nv();
    let mut walker = Walker {
        model,
        data: Data::new(model),
        weights: joint_weights(model),
        zero: DVector::zeros(n),
        contacts: Vec::with_capacity(contact_capacity(model)),
    };
    let mut q0 = model.q0.clone();
    // A q0 that does not quite close (a hand-written scene) is closed first; if it cannot be, walk from it.
    close(model, &mut walker.data, &mut q0, &walker.zero);
    residual(model, &mut walker.data, &q0, &walker.zero);
    let start = OpPose::<S>::of_op(model, &walker.data, op);
    let null_basis = null_space_basis(&walker.rows().unwrap_or_else(|| DMatrix::zeros(0, n)), n);
    let dof = null_basis.len();

    let mut reach = OpReach {
        op,
        samples: 0,
        position_min: start.position,
        position_max: start.position,
        rotation_range: 0.0,
        tour: Vec::new(),
        static_force_n: 0.0,
        static_torque_nm: 0.0,
        static_pin_force_n: 0.0,
        static_force_max_n: 0.0,
        inverse_mass_max: 0.0,
        inverse_rotational_inertia_max: 0.0,
        turning_radius_min_m: f64::INFINITY,
        dof,
        path: None,
        path_modes: Vec::new(),
    };
    let zero_qd = DVector::zeros(n);
    let mut samples = Samples {
        model,
        op,
        start,
        zero_qd: zero_qd.clone(),
        data: Data::new(model),
        forces: Vec::new(),
        torques: Vec::new(),
        pin_forces: Vec::new(),
        inverse_inertias: Vec::new(),
    };
    samples.visit(&q0, &start, true, &mut reach);
    if dof == 0 {
        reach.tour.push(start);
    }
    // A 1-DOF linkage needs two walks (forth and back); more spread over the first two null directions.
    let walks = match dof {
        0 => 0,
        1 => config.walks.min(2),
        _ => config.walks,
    };
    let mut tour_data = Data::new(model);
    // On a 1-DOF linkage, each walk's poses up to its first turn: the OP's path forth and back from q0.
    let mut halves: Vec<Vec<PathSample<S>>> = Vec::new();
    for walk in 0..walks {
        let on_tour = walk == 0 || (dof > 1 && walk * 4 == walks);
        let angle = std::f64::consts::TAU * walk as f64 / walks as f64;
        let mut direction = &null_basis[0] * angle.cos();
        if dof > 1 {
            direction += &null_basis[1] * angle.sin();
        }
        let mut q = q0.clone();
        // The walk's poses, with how mobile the OP is there (σ_max of the unit-consistent Λ̃⁻¹) on the walks
        // the tour is taken from.
        // And, on a 1-DOF linkage, the OP's acceleration at rest there (the path's).
        let at_rest = |q: &DVector<f64>, data: &mut Data<S>| {
            if !(on_tour || dof == 1) {
                return (0.0, S::OpVec::zero());
            }
            static_op_load(model, data, q, &zero_qd, op)
                .map_or((0.0, S::OpVec::zero()), |(_, d)| (d.singular_values[0], op_acceleration(data)))
        };
        let (mobility, accel) = at_rest(&q0, &mut tour_data);
        let mut path = vec![(start, mobility, accel)];
        let mut failures = 0;
        let mut first_turn = None;
        for step in 1..=config.steps {
            match walker.step(&mut q, &direction, config.step) {
                Some(tangent) => {
                    direction = tangent;
                    failures = 0;
                    let pose = OpPose::<S>::of_op(model, &walker.data, op);
                    samples.visit(&q, &pose, step % config.inertia_every.max(1) == 0, &mut reach);
                    let (mobility, accel) = at_rest(&q, &mut tour_data);
                    path.push((pose, mobility, accel));
                }
                None => {
                    // A dead point or the end of a stroke: turn back, as the linkage would.
                    first_turn.get_or_insert(path.len());
                    failures += 1;
                    if failures > 2 {
                        break;
                    }
                    direction = -direction;
                }
            }
        }
        // The tour: the first walk (and, on a linkage of several DOF, the one leaving at a right angle), away
        // from the dead points where the OP itself jams (a rocker driven from its output at the ends of its
        // swing, Λ⁻¹ → 0 there): a hand that means to go there meets a toggle, not the linkage's motion.
        if on_tour {
            reach.tour.extend(mobile_waypoints(&path, config.tour_points));
        }
        if dof == 1 {
            halves.push(path[..first_turn.unwrap_or(path.len())].iter().map(|p| (p.0, p.2, p.1)).collect());
        }
    }
    if let [forth, back] = halves.as_slice() {
        if let Some((path, modes)) = one_dof_path(forth, back, model.length_scale) {
            reach.path = Some(path);
            reach.path_modes = modes;
        }
    }
    samples.settle(&mut reach);
    Ok(reach)
}

/// `count` waypoints along the poses of a walk's `path` (pose, mobility, acceleration) where the OP is
/// mobile (at least [`TOUR_MOBILITY`] of the walk's median mobility).
fn mobile_waypoints<S: Space>(path: &[(OpPose<S>, f64, S::OpVec)], count: usize) -> Vec<OpPose<S>> {
    let mut mobilities: Vec<f64> = path.iter().map(|p| p.1).collect();
    mobilities.sort_by(f64::total_cmp);
    let median = mobilities[mobilities.len() / 2];
    let mobile: Vec<OpPose<S>> = path.iter().filter(|p| p.1 >= TOUR_MOBILITY * median).map(|p| p.0).collect();
    waypoints(&mobile, count)
}

/// An orthonormal basis of the null space of `rows` (`n` columns): the identity's columns projected and
/// orthonormalized.
fn null_space_basis(rows: &DMatrix<f64>, n: usize) -> Vec<DVector<f64>> {
    let mut basis: Vec<DVector<f64>> = Vec::new();
    for i in 0..n {
        let mut v = project_null(rows, &DVector::from_fn(n, |r, _| f64::from(u8::from(r == i))));
        for b in &basis {
            v -= b * b.dot(&v);
        }
        let norm = v.norm();
        if norm > 1e-6 {
            basis.push(v / norm);
        }
    }
    basis
}

/// The 90th percentile of `values` (sorted in place), 0 for none.
pub fn percentile_90(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * 0.9).round() as usize]
}

/// What a survey gathers at the poses it visits: the OP's extent, and at some the inertia and static load.
struct Samples<'m, S: Space> {
    model: &'m Model<S>,
    op: usize,
    start: OpPose<S>,
    zero_qd: DVector<f64>,
    data: Data<S>,
    forces: Vec<f64>,
    torques: Vec<f64>,
    pin_forces: Vec<f64>,
    /// The largest eigenvalues of Λ⁻¹'s linear and angular blocks at each sample with inertia.
    inverse_inertias: Vec<(f64, f64)>,
}

impl<S: Space> Samples<'_, S> {
    /// Books the pose at `q` into `reach`, with the OP's inertia and static load there when `with_inertia`.
    fn visit(&mut self, q: &DVector<f64>, pose: &OpPose<S>, with_inertia: bool, reach: &mut OpReach<S>) {
        let lin = <S::Point as VecOps>::LEN;
        reach.samples += 1;
        let p = pose.position.as_slice();
        for (i, x) in p.iter().enumerate() {
            let lo = &mut reach.position_min.as_mut_slice()[i];
            *lo = lo.min(*x);
            let hi = &mut reach.position_max.as_mut_slice()[i];
            *hi = hi.max(*x);
        }
        reach.rotation_range = reach.rotation_range.max(S::op_ang(&pose.difference(&self.start)).norm());
        if !with_inertia {
            return;
        }
        if let Ok((load, directions)) = static_op_load(self.model, &mut self.data, q, &self.zero_qd, self.op) {
            let inverse = self.data.op.inverse_inertia;
            let (lambda_v, lambda_w) =
                (block_max_eigenvalue::<S>(&inverse, 0..lin), block_max_eigenvalue::<S>(&inverse, lin..S::DIM));
            reach.inverse_mass_max = reach.inverse_mass_max.max(lambda_v);
            reach.inverse_rotational_inertia_max = reach.inverse_rotational_inertia_max.max(lambda_w);
            self.inverse_inertias.push((lambda_v, lambda_w));
            let (f, t) = (S::op_lin(&load).norm(), S::op_ang(&load).norm());
            if f.is_finite() && t.is_finite() {
                self.forces.push(f);
                self.torques.push(t);
            }
            let pinned = pin_force(&directions, &load);
            if pinned.is_finite() {
                self.pin_forces.push(pinned);
            }
        }
    }

    /// The survey's inertia bounds and static loads from what was visited.
    fn settle(mut self, reach: &mut OpReach<S>) {
        let model = self.model;
        // A group the OP does not move in at all (a parallelogram's coupler never turns) shows an inverse
        // inertia of round-off size, 1e-23 where the other group's is 1; read it as zero (an infinite inertia),
        // comparing the groups in the unit-consistent coordinates `(v, L ω)`.
        let l2 = model.length_scale * model.length_scale;
        let scaled_largest = reach.inverse_mass_max.max(reach.inverse_rotational_inertia_max * l2);
        if reach.inverse_mass_max <= IMMOBILE_GROUP * scaled_largest {
            reach.inverse_mass_max = 0.0;
        }
        if reach.inverse_rotational_inertia_max * l2 <= IMMOBILE_GROUP * scaled_largest {
            reach.inverse_rotational_inertia_max = 0.0;
        }
        reach.turning_radius_min_m = turning_radius_min(&self.inverse_inertias, l2);
        reach.static_force_max_n = self.forces.iter().fold(0.0, |a: f64, b| a.max(*b));
        reach.static_force_n = percentile_90(&mut self.forces);
        reach.static_torque_nm = percentile_90(&mut self.torques);
        reach.static_pin_force_n = percentile_90(&mut self.pin_forces);
    }
}

/// The OP's smallest turning radius over `samples`, each the largest eigenvalues `(λ_v, λ_ω)` of Λ⁻¹'s linear
/// and angular blocks at one pose (eq 9), `l2` the square of the model's length scale: `min √(λ_v / λ_ω)`.
/// On a linkage of one degree of freedom Λ⁻¹ = j jᵀ / m_s, with `j = (j_v, j_ω)` the OP's twist per unit of
/// the linkage's coordinate and `m_s` its inertia there, so `√(λ_v / λ_ω) = |j_v| / |j_ω|`: the ratio of the
/// OP's speed to its angular speed, its distance from the instant centre of its motion (a crank's tip turns
/// about the crank's pivot at the crank's length everywhere; a coupler point near the instant centre turns
/// more than it moves). On more degrees of freedom it compares the OP's most mobile translation with its most
/// mobile rotation. Poses where the OP barely moves at all (both groups below [`IMMOBILE_GROUP`] of the
/// largest over the samples, unit-consistent coordinates `(v, L ω)`: a jammed toggle, whose ratio is
/// round-off) are not counted; an OP that never turns has an infinite radius.
fn turning_radius_min(samples: &[(f64, f64)], l2: f64) -> f64 {
    let mobility = |&(v, w): &(f64, f64)| v.max(w * l2);
    let largest = samples.iter().map(mobility).fold(0.0, f64::max);
    samples
        .iter()
        .filter(|s| mobility(s) > IMMOBILE_GROUP * largest && s.1 * l2 > IMMOBILE_GROUP * largest)
        .map(|&(v, w)| (v / w).sqrt())
        .fold(f64::INFINITY, f64::min)
}

/// Where a walk's `path` first comes back near its start after having gone away (a crank-rocker's coupler
/// curve is walked around more than once): the index of that pose, or `None` for a path that never returns.
/// Also the OP's arc length at each pose up to there.
fn lap<S: Space>(path: &[OpPose<S>]) -> (Option<usize>, Vec<f64>) {
    let mut arc = vec![0.0];
    let mut far = 0.0f64;
    for i in 1..path.len() {
        let d = (path[i].position - path[i - 1].position).norm();
        arc.push(arc[i - 1] + d);
        let from_start = (path[i].position - path[0].position).norm();
        far = far.max(from_start);
        // Back where it started after having gone away: one lap.
        if far > 0.0 && from_start < 0.05 * far && arc[i] > 2.0 * far {
            return (Some(i), arc);
        }
    }
    (None, arc)
}

/// A pose of a walk on a 1-DOF linkage with the OP's acceleration at rest and its mobility there (`σ` of
/// the unit-consistent Λ̃⁻¹).
type PathSample<S> = (OpPose<S>, <S as Space>::OpVec, f64);

/// The OP's path on a 1-DOF linkage from the walks forth and back from q0 (each up to its first turn, both
/// starting at q0's pose), with its modes at each pose (none on a swing): one lap of the forth walk when it
/// comes back to its start, else the back walk reversed followed by the forth one; a swing ([`swing`]) when
/// the OP turns back along its path while the linkage moves on. `None` when the walks do not make a path
/// (fewer than two distinct poses, or an OP that comes back another way than it went).
fn one_dof_path<S: Space>(
    forth: &[PathSample<S>],
    back: &[PathSample<S>],
    length_scale: f64,
) -> Option<(OpPath<S>, Vec<PathMode>)> {
    let forth_poses: Vec<OpPose<S>> = forth.iter().map(|p| p.0).collect();
    let end_to_end = || -> Vec<PathSample<S>> { back.iter().skip(1).rev().chain(forth).copied().collect() };
    let (samples, shape) = match lap(&forth_poses) {
        (Some(mut end), _) => {
            // `lap` stops within 5 % of the extent of the start; the lap ends at the pose nearest to it.
            let from_start = |i: usize| (forth[i].0.position - forth[0].0.position).norm();
            while end + 1 < forth.len() && from_start(end + 1) < from_start(end) {
                end += 1;
            }
            (forth[..end].to_vec(), PathShape::Closed)
        }
        (None, _) => (end_to_end(), PathShape::Open),
    };
    let path = OpPath::new(samples.iter().map(|p| p.0).collect(), shape, length_scale).ok()?;
    // An OP that turns back along its path while the linkage moves on (a rocker's output swings forth and
    // back while the crank turns) has one pose for two configurations, with different forces at rest, on a
    // path that runs over itself: its pose does not say where the linkage is, but the curve it sweeps still
    // says where the OP can be.
    let n = path.poses().len();
    let closed = path.is_closed();
    let turns_back =
        (0..n).filter(|&k| closed || k + 1 < n).any(|k| path.tangent(k).dot(&path.tangent((k + 1) % n)) < 0.0);
    if turns_back {
        return swing(&end_to_end().iter().map(|p| p.0).collect::<Vec<_>>(), length_scale).map(|p| (p, Vec::new()));
    }
    // At rest the OP can only accelerate along the path: its acceleration is the tangent's multiple.
    let along: Vec<f64> =
        (0..samples.len()).map(|k| path.tangent(k).dot(&scale_op::<S>(&samples[k].1, length_scale))).collect();
    let modes = path_modes(&path, &along, &samples.iter().map(|p| p.2).collect::<Vec<_>>(), length_scale);
    Some((path.with_rest_acceleration(along).ok()?, modes))
}

/// The OP's [`PathMode`] at each pose of `path`, from the acceleration at rest along it (`along`) and the
/// mobility (`σ` of Λ̃⁻¹) at each pose: central differences of the force at rest over the arc length inside,
/// one-sided at the ends of an open path. A pose where the OP does not move (`σ` 0: a dead point) has an
/// infinite inertia, and its neighbours no stiffness. `l`: the scene's length scale.
fn path_modes<S: Space>(path: &OpPath<S>, along: &[f64], mobility: &[f64], l: f64) -> Vec<PathMode> {
    let poses = path.poses();
    let n = poses.len();
    let closed = path.is_closed();
    let arc = |a: usize, b: usize| scale_op::<S>(&poses[b].difference(&poses[a]), l).norm();
    let mass = |k: usize| if mobility[k] > 0.0 { 1.0 / mobility[k] } else { f64::INFINITY };
    let force = |k: usize| mass(k) * along[k];
    (0..n)
        .map(|k| {
            let (before, after) = difference_neighbours(closed, n, k);
            let span = arc(before, k) + arc(k, after);
            let stiffness = (force(after) - force(before)) / span;
            PathMode { mass: mass(k), rest_stiffness: if stiffness.is_finite() { -stiffness } else { 0.0 } }
        })
        .collect()
}

/// Poses of a walk farther than this fraction of the length scale from the swing chosen from it mean the OP
/// comes back another way than it went (a survey step's chord sags far less than this off the curve).
const SWING_TOLERANCE: f64 = 0.01;

/// One sweep of an OP that swings forth and back while the linkage goes on (`PathShape::Swing`), from the
/// poses of a `walk` in order: the longest run between two turns (poses where the OP's motion reverses:
/// the limits where the linkage's map to the OP folds), when every pose of the walk lies on it (within
/// [`SWING_TOLERANCE`]: the OP sweeps one curve both ways, as a rocker's arc). `None` when the walk turns
/// fewer than twice or leaves the sweep.
fn swing<S: Space>(walk: &[OpPose<S>], length_scale: f64) -> Option<OpPath<S>> {
    let step = |k: usize| scale_op::<S>(&walk[k + 1].difference(&walk[k]), length_scale);
    let turns: Vec<usize> = (1..walk.len().saturating_sub(1)).filter(|&k| step(k - 1).dot(&step(k)) < 0.0).collect();
    let arc = |(a, b): (usize, usize)| (a..b).map(|k| step(k).norm()).sum::<f64>();
    let (a, b) = turns.windows(2).map(|w| (w[0], w[1])).max_by(|x, y| arc(*x).total_cmp(&arc(*y)))?;
    let path = OpPath::new(walk[a..=b].to_vec(), PathShape::Swing, length_scale).ok()?;
    walk.iter().all(|p| path.nearest(p, None).distance <= SWING_TOLERANCE * length_scale).then_some(path)
}

/// Up to `count` poses of `path` evenly spaced by the OP's arc length, stopping where a closed path comes
/// back to its start (see [`lap`]).
fn waypoints<S: Space>(path: &[OpPose<S>], count: usize) -> Vec<OpPose<S>> {
    if path.len() < 2 || count == 0 {
        return path.iter().take(1).copied().collect();
    }
    let (lap_end, arc) = lap(path);
    let end = lap_end.map_or(path.len(), |i| i + 1);
    let total = arc[end - 1];
    if total <= 0.0 {
        return vec![path[0]];
    }
    let mut out = Vec::with_capacity(count);
    let mut j = 0;
    for k in 1..=count {
        let s = total * k as f64 / count as f64;
        while j + 1 < end && arc[j] < s {
            j += 1;
        }
        out.push(path[j]);
    }
    out
}
