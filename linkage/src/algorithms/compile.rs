//! Scene → [`Model`]: validation (every error names the file and the key), the bodies in topological
//! order, the cut joints' closure primitives completed so the loops close at q0, and the generic rank of
//! the closure Jacobian. It needs the algorithms (poses at q0, assembly near q0), so it lives above them,
//! apart from the model's definition.

mod freedoms;
mod multi_rate;
mod multi_rate_keys;

use nalgebra::DVector;

use crate::algorithms::assemble::assemble;
use crate::algorithms::configuration;
use crate::algorithms::kinematics::forward_kinematics;
use crate::algorithms::loop_closure::closure_residual_and_jacobian;
use crate::error::SceneError;
use crate::math::space::{SceneKind, Space, VecOps};
use crate::model::data::Data;
use crate::model::scene::{
    ActuatorSpec, Baumgarte, ContactParams, CutKindSpec, GeometrySpec, JointKindSpec, ObstacleSpec, Scene, GROUND,
};
use crate::model::{
    Actuator, Attachment, Body, ClosurePrimitive, Cut, Joint, JointKind, Model, Obstacle, OpPoint, Shape, NO_PARENT,
};
use multi_rate::Entries;

impl<S: Space> Model<S> {
    /// Validates and compiles a scene; `file` names the source in errors.
    pub fn compile(scene: &Scene, file: &str) -> Result<Model<S>, SceneError> {
        Compiler::<S> { scene, file, check_closure: true, _s: std::marker::PhantomData }.compile()
    }

    /// As [`Model::compile`] but accepts loops that are not closed at q0 (for `inspect --assemble`).
    pub fn compile_unclosed(scene: &Scene, file: &str) -> Result<Model<S>, SceneError> {
        Compiler::<S> { scene, file, check_closure: false, _s: std::marker::PhantomData }.compile()
    }
}

struct Compiler<'a, S: Space> {
    scene: &'a Scene,
    file: &'a str,
    check_closure: bool,
    _s: std::marker::PhantomData<S>,
}

impl<S: Space> Compiler<'_, S> {
    fn invalid(&self, key: String, problem: impl Into<String>) -> SceneError {
        SceneError::Invalid { file: self.file.to_string(), key, problem: problem.into() }
    }

    fn finite(&self, key: &str, v: f64) -> Result<f64, SceneError> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.invalid(key.to_string(), format!("must be a finite number, got {v}")))
        }
    }

    fn non_negative(&self, key: &str, v: f64) -> Result<f64, SceneError> {
        let v = self.finite(key, v)?;
        if v >= 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(key.to_string(), format!("must be ≥ 0, got {v}")))
        }
    }

    fn point(&self, key: &str, v: &[f64], default_zero: bool) -> Result<S::Point, SceneError> {
        let n = <S::Point as VecOps>::LEN;
        if v.is_empty() && default_zero {
            return Ok(S::Point::zero());
        }
        if v.len() != n {
            return Err(self.invalid(
                key.to_string(),
                format!("expected {n} numbers for a {:?} scene, got {}", S::KIND, v.len()).to_lowercase(),
            ));
        }
        for (i, x) in v.iter().enumerate() {
            self.finite(&format!("{key}[{i}]"), *x)?;
        }
        Ok(S::Point::from_slice(v))
    }

    fn unit(&self, key: &str, v: &[f64]) -> Result<S::Point, SceneError> {
        let p = self.point(key, v, false)?;
        let n = p.norm();
        if n < 1e-12 {
            return Err(self.invalid(key.to_string(), "must be a non-zero direction"));
        }
        Ok(p * (1.0 / n))
    }

    fn body_ref(&self, key: &str, name: &str, names: &[&str]) -> Result<Option<usize>, SceneError> {
        if name == GROUND {
            return Ok(None);
        }
        names.iter().position(|n| *n == name).map(Some).ok_or_else(|| SceneError::UnknownName {
            file: self.file.to_string(),
            key: key.to_string(),
            what: "body",
            name: name.to_string(),
            known: std::iter::once(GROUND).chain(names.iter().copied()).collect::<Vec<_>>().join(", "),
        })
    }

    fn check_unique<'n>(&self, section: &str, names: impl Iterator<Item = &'n str>) -> Result<(), SceneError> {
        let mut seen: Vec<&str> = Vec::new();
        for (i, n) in names.enumerate() {
            if n.is_empty() {
                return Err(self.invalid(format!("{section}[{i}].name"), "must not be empty"));
            }
            if seen.contains(&n) || (section == "body" && n == GROUND) {
                return Err(SceneError::Duplicate {
                    file: self.file.to_string(),
                    key: format!("{section}[{i}].name"),
                    name: n.to_string(),
                });
            }
            seen.push(n);
        }
        Ok(())
    }

    /// The stages in order; each validates its part of the file, so the first error met is the one a reader
    /// of the file meets first (names, tree, bodies and joints in tree order, globals, ops, obstacles).
    fn compile(&self) -> Result<Model<S>, SceneError> {
        let sc = self.scene;
        self.check_names()?;
        let file_names: Vec<&str> = sc.bodies.iter().map(|b| b.name.as_str()).collect();
        let tree = self.tree(&file_names)?;

        // The entry carrying each file body, once placed (parents come first in `tree.order`).
        let mut entry_of = vec![NO_PARENT; file_names.len()];
        let mut entries = Entries::with_capacity(tree.order.len());
        for &fb in &tree.order {
            let body = self.body(fb)?;
            let ji = tree.carrier[fb].unwrap_or(0);
            let (joint, q, qd) = self.joint(ji, tree.parent_of[fb].map_or(NO_PARENT, |p| entry_of[p]))?;
            let axes = self.multi_rate_axes(ji)?;
            entry_of[fb] = entries.push(ji, joint, (q, qd), body, axes);
        }
        let (q0, qd0) = entries.initial_state();
        let Entries { bodies, mut joints, file_joint, .. } = entries;

        let gravity = self.point("gravity", &sc.gravity, true)?;
        let baumgarte = Baumgarte {
            alpha: self.non_negative("baumgarte.alpha", sc.baumgarte.alpha)?,
            beta: self.non_negative("baumgarte.beta", sc.baumgarte.beta)?,
        };
        let contact = ContactParams {
            stiffness: self.non_negative("contact.stiffness", sc.contact.stiffness)?,
            damping: self.non_negative("contact.damping", sc.contact.damping)?,
        };
        let length_scale = self.length_scale(&bodies)?;
        self.joint_ranges(&mut joints, file_joint.into_iter(), &q0, length_scale)?;
        let new_names: Vec<String> = bodies.iter().map(|b| b.name.clone()).collect();
        let new_names: Vec<&str> = new_names.iter().map(|s| s.as_str()).collect();
        let ops = self.ops(&new_names)?;
        let obstacles = self.obstacles()?;
        let chain_prefix = chain_prefix(&joints);

        let mut model = Model {
            name: if sc.name.is_empty() { self.file.to_string() } else { sc.name.clone() },
            has_springs: joints.iter().any(|j| j.spring.is_some_and(|s| s.stiffness > 0.0)),
            has_joint_forces: joints.iter().any(|j| j.damping > 0.0 || j.actuator.is_some()),
            has_gravity: gravity.norm() > 0.0,
            bodies,
            joints,
            chain_prefix_len: chain_prefix.iter().take_while(|c| **c).count(),
            chain_prefix,
            cuts: Vec::new(),
            closure_rows: 0,
            closure_rank: 0,
            closure_row_weights: Vec::new(),
            ops,
            obstacles,
            gravity,
            baumgarte,
            contact,
            length_scale,
            q0,
            qd0,
        };
        self.compile_cuts(&mut model, &new_names)?;
        model.has_springs |= model.cuts.iter().any(|c| c.spring.is_some_and(|s| s.stiffness > 0.0));
        model.has_joint_forces |= model.joints.iter().any(|j| j.range.is_some())
            || model.cuts.iter().any(|c| c.damping > 0.0 || c.range.is_some());
        model.closure_row_weights = closure_row_weights(&model);
        model.closure_rank = generic_closure_rank(&model);
        Ok(model)
    }

    /// The scene's kind matches `S`, names are unique and non-empty per section, and there is a body.
    fn check_names(&self) -> Result<(), SceneError> {
        let sc = self.scene;
        if sc.kind != S::KIND {
            return Err(self.invalid("kind".into(), format!("expected a {:?} scene, got {:?}", S::KIND, sc.kind)));
        }
        self.check_unique("body", sc.bodies.iter().map(|b| b.name.as_str()))?;
        self.check_unique("joint", sc.joints.iter().map(|j| j.name.as_str()))?;
        self.check_unique("cut", sc.cuts.iter().map(|c| c.name.as_str()))?;
        self.check_unique("op", sc.ops.iter().map(|o| o.name.as_str()))?;
        self.check_unique("obstacle", sc.obstacles.iter().map(|o| o.name()))?;
        if sc.bodies.is_empty() {
            return Err(self.invalid("body".into(), "a scene needs at least one body"));
        }
        Ok(())
    }

    /// The kinematic tree: which joint carries each body (exactly one) and its parent, with no cycle, and
    /// the bodies in a stable topological order following the file's joint order.
    fn tree(&self, file_names: &[&str]) -> Result<Tree, SceneError> {
        let sc = self.scene;
        let mut carrier: Vec<Option<usize>> = vec![None; sc.bodies.len()];
        let mut parent_of: Vec<Option<usize>> = vec![None; sc.bodies.len()];
        for (ji, j) in sc.joints.iter().enumerate() {
            let key = format!("joint[{ji}] ({})", j.name);
            let child = self
                .body_ref(&format!("{key}.child"), &j.child, file_names)?
                .ok_or_else(|| self.invalid(format!("{key}.child"), "ground cannot be a child"))?;
            let parent = self.body_ref(&format!("{key}.parent"), &j.parent, file_names)?;
            if parent == Some(child) {
                return Err(SceneError::Cycle { file: self.file.into(), key, body: j.child.clone() });
            }
            if let Some(prev) = carrier[child] {
                return Err(self.invalid(
                    format!("{key}.child"),
                    format!("body '{}' is already the child of joint '{}'", j.child, sc.joints[prev].name),
                ));
            }
            carrier[child] = Some(ji);
            parent_of[child] = parent;
        }
        for (bi, c) in carrier.iter().enumerate() {
            if c.is_none() {
                return Err(self.invalid(
                    format!("body[{bi}] ({})", sc.bodies[bi].name),
                    "no [[joint]] has this body as child; every body hangs from ground or another body by one joint",
                ));
            }
        }
        // Cycle detection: walking parents from any body must reach ground within n steps.
        for start in 0..sc.bodies.len() {
            let mut b = start;
            for _ in 0..=sc.bodies.len() {
                match parent_of[b] {
                    None => break,
                    Some(p) => b = p,
                }
            }
            if parent_of[b].is_some() {
                let ji = carrier[b].unwrap_or(0);
                return Err(SceneError::Cycle {
                    file: self.file.into(),
                    key: format!("joint[{ji}] ({})", sc.joints[ji].name),
                    body: sc.bodies[b].name.clone(),
                });
            }
        }
        let mut order: Vec<usize> = Vec::with_capacity(sc.bodies.len()); // file body indices
        let mut placed = vec![false; sc.bodies.len()];
        while order.len() < sc.bodies.len() {
            for j in &sc.joints {
                let child = file_names.iter().position(|n| *n == j.child).unwrap_or(0);
                if placed[child] {
                    continue;
                }
                if parent_of[child].is_none_or(|p| placed[p]) {
                    placed[child] = true;
                    order.push(child);
                }
            }
        }
        Ok(Tree { carrier, parent_of, order })
    }

    /// The body at file index `fb`: mass, inertia, centre of mass and geometry.
    fn body(&self, fb: usize) -> Result<Body<S>, SceneError> {
        let b = &self.scene.bodies[fb];
        let bkey = format!("body[{fb}] ({})", b.name);
        let mass = self.finite(&format!("{bkey}.mass"), b.mass)?;
        if mass <= 0.0 {
            return Err(self.invalid(format!("{bkey}.mass"), format!("must be positive, got {mass}")));
        }
        for (k, x) in b.inertia.as_slice().iter().enumerate() {
            self.finite(&format!("{bkey}.inertia[{k}]"), *x)?;
        }
        let inertia =
            S::rot_inertia_from_scene(b.inertia.as_slice()).map_err(|p| self.invalid(format!("{bkey}.inertia"), p))?;
        let com = self.point(&format!("{bkey}.com"), &b.com, true)?;
        let mut geometry = Vec::with_capacity(b.geometry.len());
        for (gi, g) in b.geometry.iter().enumerate() {
            let gkey = format!("{bkey}.geometry[{gi}]");
            geometry.push(match g {
                GeometrySpec::Capsule { from, to, radius } => Shape::Capsule {
                    from: self.point(&format!("{gkey}.from"), from, false)?,
                    to: self.point(&format!("{gkey}.to"), to, false)?,
                    radius: self.non_negative(&format!("{gkey}.radius"), *radius)?,
                },
                GeometrySpec::Ball { center, radius } => Shape::Ball {
                    center: self.point(&format!("{gkey}.center"), center, false)?,
                    radius: self.non_negative(&format!("{gkey}.radius"), *radius)?,
                },
            });
        }
        Ok(Body { name: b.name.clone(), mass, com, inertia, geometry })
    }

    /// The joint at file index `ji` (its parent already in tree indices), with its q0 and q̇0.
    fn joint(&self, ji: usize, parent: usize) -> Result<(Joint<S>, f64, f64), SceneError> {
        let j = &self.scene.joints[ji];
        let jkey = format!("joint[{ji}] ({})", j.name);
        let kind = match j.kind {
            JointKindSpec::Revolute | JointKindSpec::Universal => JointKind::Revolute,
            JointKindSpec::Prismatic => JointKind::Prismatic,
            JointKindSpec::Ball => JointKind::Ball { slot: 0 },
        };
        let placement_pos = self.point(&format!("{jkey}.origin"), &j.origin, true)?;
        let placement_rot = match &j.rotation {
            None => S::rot_identity(),
            Some(r) => {
                for (k, x) in r.as_slice().iter().enumerate() {
                    self.finite(&format!("{jkey}.rotation[{k}]"), *x)?;
                }
                S::rot_from_scene(r.as_slice()).map_err(|p| self.invalid(format!("{jkey}.rotation"), p))?
            }
        };
        let axis = match (&j.axis, S::KIND, kind) {
            (Some(_), SceneKind::Planar, JointKind::Revolute) => {
                return Err(
                    self.invalid(format!("{jkey}.axis"), "planar revolute joints always turn about z; remove `axis`")
                )
            }
            // Ball and universal joints reject `axis` in `multi_rate_axes`.
            (Some(a), _, _) if matches!(j.kind, JointKindSpec::Revolute | JointKindSpec::Prismatic) => {
                self.unit(&format!("{jkey}.axis"), a)?
            }
            _ => S::default_axis(),
        };
        let spring = match &j.spring {
            None => None,
            Some(s) => Some(self.spring(&format!("{jkey}.spring"), s)?),
        };
        let actuator = match &j.actuator {
            None => None,
            Some(a) => Some(self.actuator(&jkey, a)?),
        };
        let q0 = self.finite(&format!("{jkey}.q0"), j.q0)?;
        let qd0 = self.finite(&format!("{jkey}.qd0"), j.qd0)?;
        let joint = Joint {
            name: j.name.clone(),
            kind,
            q_index: 0,
            parent,
            placement_rot,
            placement_pos,
            axis,
            spring,
            damping: self.non_negative(&format!("{jkey}.damping"), j.damping)?,
            armature: self.non_negative(&format!("{jkey}.armature"), j.armature)?,
            actuator,
            range: None,
        };
        Ok((joint, q0, qd0))
    }

    /// A joint's PD actuator; an omitted effort limit is unlimited.
    fn actuator(&self, jkey: &str, a: &ActuatorSpec) -> Result<Actuator, SceneError> {
        let max_effort = match a.max_effort {
            None => f64::INFINITY,
            Some(e) => {
                let e = self.finite(&format!("{jkey}.actuator.max_effort"), e)?;
                if e <= 0.0 {
                    return Err(self.invalid(format!("{jkey}.actuator.max_effort"), "must be positive"));
                }
                e
            }
        };
        Ok(Actuator {
            kp: self.non_negative(&format!("{jkey}.actuator.kp"), a.kp)?,
            kd: self.non_negative(&format!("{jkey}.actuator.kd"), a.kd)?,
            target: self.finite(&format!("{jkey}.actuator.target"), a.target)?,
            max_effort,
        })
    }

    /// The scene's `length_scale`, or the default from the bodies when omitted.
    fn length_scale(&self, bodies: &[Body<S>]) -> Result<f64, SceneError> {
        match self.scene.length_scale {
            Some(l) => {
                let l = self.finite("length_scale", l)?;
                if l <= 0.0 {
                    return Err(self.invalid("length_scale".into(), format!("must be positive, got {l}")));
                }
                Ok(l)
            }
            None => Ok(default_length_scale::<S>(bodies)),
        }
    }

    /// The operational points, each on a moving body (`names` in tree order).
    fn ops(&self, names: &[&str]) -> Result<Vec<OpPoint<S>>, SceneError> {
        let mut ops = Vec::with_capacity(self.scene.ops.len());
        for (oi, o) in self.scene.ops.iter().enumerate() {
            let key = format!("op[{oi}] ({})", o.name);
            let body = self
                .body_ref(&format!("{key}.body"), &o.body, names)?
                .ok_or_else(|| self.invalid(format!("{key}.body"), "an operational point must be on a moving body"))?;
            ops.push(OpPoint {
                name: o.name.clone(),
                body,
                point: self.point(&format!("{key}.point"), &o.point, true)?,
            });
        }
        Ok(ops)
    }

    /// The obstacles, each of a shape the scene's kind has.
    fn obstacles(&self) -> Result<Vec<Obstacle<S>>, SceneError> {
        let mut obstacles = Vec::with_capacity(self.scene.obstacles.len());
        for (oi, o) in self.scene.obstacles.iter().enumerate() {
            let key = format!("obstacle[{oi}] ({})", o.name());
            let wrong_kind = || self.invalid(format!("{key}.shape"), format!("not available in a {:?} scene", S::KIND));
            obstacles.push(match o {
                ObstacleSpec::HalfPlane { name, normal, offset } | ObstacleSpec::Plane { name, normal, offset } => {
                    let planar_shape = matches!(o, ObstacleSpec::HalfPlane { .. });
                    if planar_shape != (S::KIND == SceneKind::Planar) {
                        return Err(wrong_kind());
                    }
                    Obstacle::HalfSpace {
                        name: name.clone(),
                        normal: self.unit(&format!("{key}.normal"), normal)?,
                        offset: self.finite(&format!("{key}.offset"), *offset)?,
                    }
                }
                ObstacleSpec::Circle { name, center, radius } | ObstacleSpec::Sphere { name, center, radius } => {
                    let planar_shape = matches!(o, ObstacleSpec::Circle { .. });
                    if planar_shape != (S::KIND == SceneKind::Planar) {
                        return Err(wrong_kind());
                    }
                    let r = self.non_negative(&format!("{key}.radius"), *radius)?;
                    Obstacle::Ball {
                        name: name.clone(),
                        center: self.point(&format!("{key}.center"), center, false)?,
                        radius: r,
                    }
                }
            });
        }
        Ok(obstacles)
    }

    /// Builds the closure primitives of every cut from the tree's kinematics at q0, filling in omitted
    /// reference data (point b, axis and angle offsets) so the loop is closed there, and rejecting explicit
    /// data that leaves a residual.
    fn compile_cuts(&self, model: &mut Model<S>, names: &[&str]) -> Result<(), SceneError> {
        let sc = self.scene;
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, &model.q0.clone());
        let at_q0 = PosesAtQ0 { data: &data };
        let tolerance = sc.closure_tolerance.unwrap_or(1e-6) * model.length_scale;

        let mut row = 0;
        let mut cuts = Vec::with_capacity(sc.cuts.len());
        for (ci, c) in sc.cuts.iter().enumerate() {
            let key = format!("cut[{ci}] ({})", c.name);
            if c.kind.equations(S::KIND).is_none() {
                return Err(self.invalid(
                    format!("{key}.kind"),
                    format!(
                        "a {:?} cut is not available in a {:?} scene (planar: pin, slider, weld; spatial: spherical, revolute, weld)",
                        c.kind, S::KIND
                    )
                    .to_lowercase(),
                ));
            }
            let body_a = self.body_ref(&format!("{key}.body_a"), &c.body_a, names)?;
            let body_b = self.body_ref(&format!("{key}.body_b"), &c.body_b, names)?;
            if body_a == body_b {
                return Err(self.invalid(format!("{key}.body_b"), "a cut joint must connect two different bodies"));
            }
            let point_a = self.point(&format!("{key}.point_a"), &c.point_a, true)?;
            let world_a = at_q0.to_world(body_a, &point_a);
            let (point_b, explicit_b) = match &c.point_b {
                Some(p) => (self.point(&format!("{key}.point_b"), p, false)?, true),
                None => (at_q0.to_local(body_b, &world_a), false),
            };
            let a = Attachment { body: body_a, point: point_a };
            let b = Attachment { body: body_b, point: point_b };
            let axis_a = match (&c.axis, c.kind) {
                (Some(ax), CutKindSpec::Slider | CutKindSpec::Revolute) => Some(self.unit(&format!("{key}.axis"), ax)?),
                (Some(_), _) => {
                    return Err(self.invalid(format!("{key}.axis"), "only slider and revolute cuts take an axis"))
                }
                (None, CutKindSpec::Slider | CutKindSpec::Revolute) => {
                    return Err(self.invalid(format!("{key}.axis"), "this cut needs an axis (in body a's frame)"))
                }
                (None, _) => None,
            };
            let primitives = cut_primitives(c.kind, a, b, axis_a.as_ref(), &at_q0);
            if explicit_b && self.check_closure {
                let gap = at_q0.to_world(body_b, &point_b) - world_a;
                let residual = match c.kind {
                    CutKindSpec::Slider => {
                        let n = match &primitives[0] {
                            ClosurePrimitive::OnPlane { normal_a, .. } => at_q0.dir_to_world(body_a, normal_a),
                            _ => S::Point::zero(),
                        };
                        n.dot(&gap).abs()
                    }
                    _ => gap.norm(),
                };
                if residual > tolerance || !residual.is_finite() {
                    return Err(SceneError::NotClosed {
                        file: self.file.to_string(),
                        key,
                        cut: c.name.clone(),
                        residual,
                        tolerance,
                    });
                }
            }
            if self.check_closure {
                self.check_axis_b(&key, c, (body_a, body_b), axis_a.as_ref(), &at_q0)?;
            }
            let loads = self.cut_loads(&key, c, (a, b), axis_a.as_ref(), &at_q0, model.length_scale)?;
            let rows = primitives.iter().map(|p| p.rows()).sum();
            let (freedom, spring, damping, range) = (loads.freedom, loads.spring, loads.damping, loads.range);
            cuts.push(Cut {
                name: c.name.clone(),
                kind: c.kind,
                primitives,
                row,
                rows,
                freedom,
                spring,
                damping,
                range,
            });
            row += rows;
        }
        model.cuts = cuts;
        model.closure_rows = row;
        Ok(())
    }
}

/// The bodies' poses at q0, which the cuts' reference data is completed from (`None`: ground).
struct PosesAtQ0<'d, S: Space> {
    data: &'d Data<S>,
}

impl<S: Space> PosesAtQ0<'_, S> {
    fn pose(&self, body: Option<usize>) -> (S::Rot, S::Point) {
        match body {
            None => (S::rot_identity(), S::Point::zero()),
            Some(b) => (self.data.kin.body_rot[b], self.data.kin.body_pos[b]),
        }
    }

    fn to_world(&self, body: Option<usize>, p: &S::Point) -> S::Point {
        let (r, o) = self.pose(body);
        o + S::rotate(&r, p)
    }

    fn to_local(&self, body: Option<usize>, p: &S::Point) -> S::Point {
        let (r, o) = self.pose(body);
        S::rotate(&S::rot_inverse(&r), &(*p - o))
    }

    fn dir_to_local(&self, body: Option<usize>, d: &S::Point) -> S::Point {
        S::rotate(&S::rot_inverse(&self.pose(body).0), d)
    }

    fn dir_to_world(&self, body: Option<usize>, d: &S::Point) -> S::Point {
        S::rotate(&self.pose(body).0, d)
    }
}

/// The closure primitives of one cut of `kind` between attachments `a` and `b`, with the angle offsets and
/// b's directions taken from the poses at q0 so the loop is closed there.
fn cut_primitives<S: Space>(
    kind: CutKindSpec,
    a: Attachment<S>,
    b: Attachment<S>,
    axis_a: Option<&S::Point>,
    at_q0: &PosesAtQ0<'_, S>,
) -> Vec<ClosurePrimitive<S>> {
    let (body_a, body_b) = (a.body, b.body);
    let (rot_a, _) = at_q0.pose(body_a);
    let (rot_b, _) = at_q0.pose(body_b);
    let relative = S::rot_mul(&S::rot_inverse(&rot_b), &rot_a);
    let mut primitives = Vec::new();
    match kind {
        CutKindSpec::Pin | CutKindSpec::Spherical => primitives.push(ClosurePrimitive::Coincident { a, b }),
        CutKindSpec::Weld if S::KIND == SceneKind::Planar => {
            primitives.push(ClosurePrimitive::Coincident { a, b });
            primitives.push(ClosurePrimitive::SameAngle { body_a, body_b, offset: relative });
        }
        CutKindSpec::Slider => {
            let u = axis_a.copied().unwrap_or_else(S::default_axis);
            // Planar normal: u turned by +90°.
            let n = S::ang_cross_point(&S::axis_as_angular(&u), &u);
            primitives.push(ClosurePrimitive::OnPlane { a, normal_a: n, b });
            primitives.push(ClosurePrimitive::SameAngle { body_a, body_b, offset: relative });
        }
        CutKindSpec::Weld | CutKindSpec::Revolute => {
            primitives.push(ClosurePrimitive::Coincident { a, b });
            // Directions fixed in a, and the matching directions in b at q0.
            let basis = orthonormal_basis::<S>(axis_a);
            let in_b = |d: &S::Point| at_q0.dir_to_local(body_b, &at_q0.dir_to_world(body_a, d));
            if kind == CutKindSpec::Revolute {
                // The axis (basis[0]) stays perpendicular to the two directions normal to it in b.
                for e in &basis[1..] {
                    primitives.push(ClosurePrimitive::Perpendicular {
                        body_a,
                        dir_a: basis[0],
                        body_b,
                        dir_b: in_b(e),
                    });
                }
            } else {
                // x_a ⟂ y_b, y_a ⟂ z_b, z_a ⟂ x_b: independent rows near alignment.
                for k in 0..3 {
                    primitives.push(ClosurePrimitive::Perpendicular {
                        body_a,
                        dir_a: basis[k],
                        body_b,
                        dir_b: in_b(&basis[(k + 1) % 3]),
                    });
                }
            }
        }
    }
    primitives
}

/// The kinematic tree read from the file, in file body indices.
struct Tree {
    /// The joint carrying each body.
    carrier: Vec<Option<usize>>,
    /// Each body's parent body (`None`: ground).
    parent_of: Vec<Option<usize>>,
    /// The bodies in topological order.
    order: Vec<usize>,
}

/// Whether joints `0..=k` form a serial chain from ground (each the child of the one before), per `k`.
fn chain_prefix<S: Space>(joints: &[Joint<S>]) -> Vec<bool> {
    (0..joints.len())
        .map(|k| {
            let mut expect = k;
            let mut b = joints[k].parent;
            while b != NO_PARENT {
                if expect == 0 || b != expect - 1 {
                    return false;
                }
                expect -= 1;
                b = joints[b].parent;
            }
            expect == 0
        })
        .collect()
}

/// `Model::closure_row_weights`: `1/L²` for each length row, 1 for each angle row, in the rows' order.
fn closure_row_weights<S: Space>(model: &Model<S>) -> Vec<f64> {
    let per_length = 1.0 / (model.length_scale * model.length_scale);
    let primitives = model.cuts.iter().flat_map(|c| &c.primitives);
    primitives
        .flat_map(|p| std::iter::repeat_n(if p.rows_are_lengths() { per_length } else { 1.0 }, p.rows()))
        .collect()
}

/// The generic rank of W on the constraint manifold: the largest numerical rank (SVD, relative tolerance
/// 1e-8) at q0 and at a few closed configurations near it (q0 may sit at a singular configuration).
fn generic_closure_rank<S: Space>(model: &Model<S>) -> usize {
    let m = model.closure_rows;
    if m == 0 {
        return 0;
    }
    let rank_at = |q: &DVector<f64>| {
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, q);
        closure_residual_and_jacobian(model, &mut data);
        let sv = data.closure_jacobian_t.clone().svd(false, false).singular_values;
        let max = sv.max();
        sv.iter().filter(|s| **s > 1e-8 * max).count()
    };
    let mut rank = rank_at(&model.q0);
    for k in 1..=3 {
        let step = DVector::from_fn(model.nv(), |i, _| 0.02 * ((i * 7 + k * 13) % 11) as f64 / 11.0 - 0.01);
        let mut perturbed = model.q0.clone();
        configuration::integrate(model, &mut perturbed, &step, 1.0);
        if let Ok(a) = assemble(model, &perturbed, 1e-12 * model.length_scale) {
            rank = rank.max(rank_at(&a.q));
        }
    }
    rank.min(m)
}

/// An orthonormal basis whose first vector is `first` (or the standard basis).
fn orthonormal_basis<S: Space>(first: Option<&S::Point>) -> Vec<S::Point> {
    let n = <S::Point as VecOps>::LEN;
    let mut basis: Vec<S::Point> = Vec::with_capacity(n);
    if let Some(f) = first {
        basis.push(*f);
    }
    for k in 0..n {
        if basis.len() == n {
            break;
        }
        let mut e = S::Point::zero();
        e.as_mut_slice()[k] = 1.0;
        for b in &basis {
            e -= *b * e.dot(b);
        }
        if e.norm() > 1e-6 {
            let len = e.norm();
            basis.push(e * (1.0 / len));
        }
    }
    basis
}

/// The default characteristic length: the mass-weighted radius of gyration of the links about their own
/// centres of mass, `sqrt(Σ I_i / Σ m_i)`. It scales with the scene's unit of length, which is what makes
/// constraint counting unit-consistent. Falls back to the largest COM offset, then to 1.
fn default_length_scale<S: Space>(bodies: &[Body<S>]) -> f64 {
    let total_mass: f64 = bodies.iter().map(|b| b.mass).sum();
    let total_inertia: f64 = bodies.iter().map(|b| S::rot_inertia_size(&b.inertia)).sum();
    let gyration = (total_inertia / total_mass).sqrt();
    if gyration.is_finite() && gyration > 0.0 {
        return gyration;
    }
    let offset = bodies.iter().map(|b| b.com.norm()).fold(0.0, f64::max);
    if offset > 0.0 {
        offset
    } else {
        1.0
    }
}
