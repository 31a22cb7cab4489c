//! The body tree: each MJCF body with one joint (or a pair of hinges at one point: a universal joint) becomes
//! a kinloop body and its tree joint; a body without joints is welded to its parent (its mass, geoms and
//! sites join the body that carries it). A kinloop body's frame is its MJCF body's frame moved to the joint's
//! `pos`, because a kinloop joint turns about its frame's origin; every point of the body is shifted to match.

use std::collections::HashMap;

use kinloop_linkage::model::scene::{
    BodySpec, GeometrySpec, JointKindSpec, JointSpec, Numbers, OpSpec, SpringSpec, GROUND,
};
use nalgebra::{Rotation3, Vector3};

use crate::defaults::{Defaults, MAIN};
use crate::error::MjcfError;
use crate::frames::{Compiler, InertiaFromGeom, Pose};
use crate::inertia::{geom_mass, read_geom, read_inertial, MassProps, Solid};
use crate::warnings::Warnings;
use crate::xml::Element;

/// Where an MJCF body's frame sits: the kinloop body that carries it (`None`: ground) and its pose there.
#[derive(Clone, Copy, Debug)]
pub struct Carrier {
    /// Index into the scene's bodies, or `None` for ground.
    pub body: Option<usize>,
    /// The MJCF frame's pose in the carrier's kinloop frame.
    pub pose: Pose,
}

/// What the tree walk produces besides the scene's bodies and joints.
#[derive(Default)]
pub struct Tree {
    /// Scene bodies, in MJCF order (parents first).
    pub bodies: Vec<BodySpec>,
    /// Their mass properties, summed over welded bodies and geoms.
    pub mass: Vec<MassProps>,
    /// Scene joints, one per body.
    pub joints: Vec<JointSpec>,
    /// Sites as operational points (those on ground are kept in `sites` only).
    pub ops: Vec<OpSpec>,
    /// Every MJCF body by name (`world` included).
    pub carriers: HashMap<String, Carrier>,
    /// Every site by name: its carrier and position there.
    pub sites: HashMap<String, (Option<usize>, Vector3<f64>)>,
    /// MJCF joint name → scene joint index and whether an actuator can drive it (hinge or slide).
    pub joint_index: HashMap<String, (usize, bool)>,
    /// Each scene body's element (file and line), for messages.
    pub body_at: Vec<(String, u32)>,
}

/// Walks `<worldbody>` into bodies, joints and operational points.
pub fn read_tree(
    world: &Element,
    compiler: &Compiler,
    defaults: &Defaults,
    warnings: &mut Warnings,
) -> Result<Tree, MjcfError> {
    let mut walk = Walk { compiler, defaults, warnings, tree: Tree::default() };
    let ground = Carrier { body: None, pose: Pose::identity() };
    walk.tree.carriers.insert("world".to_string(), ground);
    walk.children(world, ground, MAIN)?;
    Ok(walk.tree)
}

struct Walk<'a> {
    compiler: &'a Compiler,
    defaults: &'a Defaults,
    warnings: &'a mut Warnings,
    tree: Tree,
}

/// A name for an unnamed element: its tag and line.
fn name_of(e: &Element) -> String {
    e.attr("name").map_or_else(|| format!("{}@{}", e.tag, e.line), str::to_string)
}

impl Walk<'_> {
    /// The contents of a body or `<frame>` whose frame is `here`.
    fn children(&mut self, e: &Element, here: Carrier, class: &str) -> Result<(), MjcfError> {
        let from_inertial = self.compiler.inertia_from_geom != InertiaFromGeom::Always
            && e.children.iter().any(|c| c.tag == "inertial");
        for c in &e.children {
            match c.tag.as_str() {
                "body" => self.body(c, here, class)?,
                "frame" => {
                    let class = c.attr("childclass").unwrap_or(class);
                    self.defaults.check_class(class, c)?;
                    let frame = Carrier { body: here.body, pose: here.pose.then(&Pose::of(c, self.compiler)?) };
                    self.children(c, frame, class)?;
                }
                "geom" => self.geom(&self.defaults.resolve(c, class)?, here, from_inertial)?,
                "site" => self.site(&self.defaults.resolve(c, class)?, here)?,
                "inertial" if self.compiler.inertia_from_geom != InertiaFromGeom::Always => {
                    if let Some(b) = here.body {
                        let m = read_inertial(c, self.compiler)?.moved(&here.pose);
                        self.tree.mass[b] = self.tree.mass[b].plus(&m);
                    }
                }
                // Read with their body; drawing-only elements.
                "joint" | "freejoint" | "inertial" | "camera" | "light" => {}
                "composite" | "flexcomp" | "replicate" | "attach" | "plugin" => {
                    self.warnings.unusable(format!("<{}> at line {}", c.tag, c.line))
                }
                other => self.warnings.unknown(other, c.line),
            }
        }
        Ok(())
    }

    fn body(&mut self, e: &Element, parent: Carrier, class: &str) -> Result<(), MjcfError> {
        let class = e.attr("childclass").unwrap_or(class);
        self.defaults.check_class(class, e)?;
        let name = name_of(e);
        if self.tree.carriers.contains_key(&name) {
            return Err(e.error(format!("a second body named '{name}'")));
        }
        if e.attr("mocap") == Some("true") {
            return Err(e.error("mocap bodies are moved by the user program, not by joints: kinloop cannot use them"));
        }
        let in_parent = parent.pose.then(&Pose::of(e, self.compiler)?);
        let joints = e
            .children
            .iter()
            .filter(|c| c.tag == "joint" || c.tag == "freejoint")
            .map(|c| self.defaults.resolve(c, class))
            .collect::<Result<Vec<_>, _>>()?;
        let here = if joints.is_empty() {
            Carrier { body: parent.body, pose: in_parent }
        } else {
            let (joint, shift) = self.joint(e, &joints, &name, parent, &in_parent)?;
            let index = self.tree.bodies.len();
            self.tree.bodies.push(BodySpec {
                name: name.clone(),
                mass: 0.0,
                com: Vec::new(),
                inertia: Numbers::Many(Vec::new()),
                geometry: Vec::new(),
            });
            self.tree.mass.push(MassProps::zero());
            self.tree.body_at.push((e.file.to_string(), e.line));
            self.tree.joints.push(joint);
            Carrier { body: Some(index), pose: Pose { rot: Rotation3::identity(), pos: -shift } }
        };
        self.tree.carriers.insert(name, here);
        self.children(e, here, class)
    }

    /// The scene joint for a body's joints, and the joint's `pos` in the body frame (where the kinloop frame
    /// moves to).
    fn joint(
        &mut self,
        body: &Element,
        joints: &[Element],
        child: &str,
        parent: Carrier,
        in_parent: &Pose,
    ) -> Result<(JointSpec, Vector3<f64>), MjcfError> {
        let first = &joints[0];
        let pos = first.fixed::<3>("pos")?.map_or_else(Vector3::zeros, Vector3::from);
        let rpy = in_parent.rot.euler_angles();
        let mut spec = JointSpec {
            name: name_of(first),
            kind: JointKindSpec::Revolute,
            parent: parent.body.map_or_else(|| GROUND.to_string(), |b| self.tree.bodies[b].name.clone()),
            child: child.to_string(),
            origin: in_parent.point(&pos).as_slice().to_vec(),
            rotation: Some(Numbers::Many(vec![rpy.0, rpy.1, rpy.2])),
            axis: None,
            axes: None,
            q0: 0.0,
            qd0: 0.0,
            spring: None,
            damping: 0.0,
            armature: 0.0,
            actuator: None,
            range: None,
        };
        let index = self.tree.joints.len();
        if let [a, b] = joints {
            // Two hinges through one point: a universal joint (MuJoCo has none, so models write it this way).
            let kinds = (a.attr("type").unwrap_or("hinge"), b.attr("type").unwrap_or("hinge"));
            let pos_b = b.fixed::<3>("pos")?.map_or_else(Vector3::zeros, Vector3::from);
            if kinds != ("hinge", "hinge") || (pos_b - pos).norm() > 1e-12 {
                return Err(body.error(
                    "two joints in one body are read only as two hinges through one point (a universal joint)",
                ));
            }
            let (axis_a, axis_b) = (self.axis(a)?, self.axis(b)?);
            if axis_a.cross(&axis_b).norm() < 1e-9 {
                return Err(b.error("the two hinges of a universal joint must not be parallel"));
            }
            // A universal joint's two rates share one armature: the hinges' own when they agree.
            let (arm_a, arm_b) = (non_negative(a, "armature")?, non_negative(b, "armature")?);
            if arm_a == arm_b {
                spec.armature = arm_a;
            } else {
                self.warnings.unusable(format!(
                    "armature = {arm_a} and {arm_b} of the hinges of universal joint '{}' (one armature for both rates)",
                    spec.name
                ));
            }
            for j in joints {
                self.unused(j, &["stiffness", "damping", "frictionloss", "ref"], "universal joint")?;
                if j.attr("range").is_some() && j.attr("limited") != Some("false") {
                    self.warnings.unusable(format!("range of joint '{}' (a universal joint takes none)", name_of(j)));
                }
                self.tree.joint_index.insert(name_of(j), (index, false));
            }
            spec.kind = JointKindSpec::Universal;
            spec.axes = Some(vec![axis_a.as_slice().to_vec(), axis_b.as_slice().to_vec()]);
            return Ok((spec, pos));
        }
        if joints.len() > 2 {
            return Err(body.error(format!("{} joints in one body: kinloop reads one, or two hinges", joints.len())));
        }
        let e = first;
        let kind = if e.tag == "freejoint" { "free" } else { e.attr("type").unwrap_or("hinge") };
        let angle = self.compiler.angle_unit;
        let (unit, actuable) = match kind {
            "hinge" => (angle, true),
            "slide" => (1.0, true),
            "ball" => (1.0, false),
            other => return Err(e.error(format!("a {other} joint is not a linkage joint kinloop can use"))),
        };
        spec.kind = match kind {
            "hinge" => JointKindSpec::Revolute,
            "slide" => JointKindSpec::Prismatic,
            _ => JointKindSpec::Ball,
        };
        spec.damping = non_negative(e, "damping")?;
        spec.armature = non_negative(e, "armature")?;
        if kind == "ball" {
            self.unused(e, &["stiffness", "frictionloss", "ref"], "ball joint")?;
            if e.attr("range").is_some() && e.attr("limited") != Some("false") {
                self.warnings.unusable(format!("range of ball joint '{}' (a cone limit)", spec.name));
            }
        } else {
            let axis = self.axis(e)?;
            spec.axis = Some(axis.as_slice().to_vec());
            self.unused(e, &["frictionloss"], "joint")?;
            // `ref`: the body as written is at qpos = ref, which is qpos0. kinloop's frame is the one at q = 0,
            // so it is turned (slid) back by ref, and q0 = ref.
            let reference = e.number("ref", 0.0)? * unit;
            spec.q0 = reference;
            if kind == "hinge" {
                let back = in_parent.rot * Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), -reference);
                let rpy = back.euler_angles();
                spec.rotation = Some(Numbers::Many(vec![rpy.0, rpy.1, rpy.2]));
            } else {
                let origin = in_parent.point(&(pos - axis * reference));
                spec.origin = origin.as_slice().to_vec();
            }
            let stiffness = non_negative(e, "stiffness")?;
            if stiffness > 0.0 {
                spec.spring = Some(SpringSpec { stiffness, rest: e.number("springref", 0.0)? * unit });
            }
            let limited = e.attr("limited").unwrap_or("auto");
            if let (Some([lo, hi]), true) = (e.fixed::<2>("range")?, limited != "false") {
                spec.range = Some([lo * unit, hi * unit]);
            }
        }
        self.tree.joint_index.insert(spec.name.clone(), (index, actuable));
        Ok((spec, pos))
    }

    fn axis(&self, e: &Element) -> Result<Vector3<f64>, MjcfError> {
        let a = e.fixed::<3>("axis")?.map_or_else(Vector3::z, Vector3::from);
        let n = a.norm();
        if n < 1e-12 {
            return Err(e.error("axis: a zero vector has no direction"));
        }
        Ok(a / n)
    }

    /// Lists each non-zero attribute of `keys` as unusable (kinloop's `what` has no such term).
    fn unused(&mut self, e: &Element, keys: &[&str], what: &str) -> Result<(), MjcfError> {
        for key in keys {
            let v = e.number(key, 0.0)?;
            if v != 0.0 {
                self.warnings.unusable(format!("{key} = {v} of joint '{}' (a kinloop {what} has none)", name_of(e)));
            }
        }
        Ok(())
    }

    fn geom(&mut self, e: &Element, here: Carrier, from_inertial: bool) -> Result<(), MjcfError> {
        let geom = read_geom(e, self.compiler)?;
        let Some(b) = here.body else { return Ok(()) };
        let pose = here.pose.then(&geom.pose);
        let body = &mut self.tree.bodies[b];
        let end = |h: f64| pose.point(&Vector3::new(0.0, 0.0, h)).as_slice().to_vec();
        match geom.solid {
            Some(Solid::Sphere(radius)) => body.geometry.push(GeometrySpec::Ball { center: end(0.0), radius }),
            Some(Solid::Capsule(radius, h) | Solid::Cylinder(radius, h)) => {
                body.geometry.push(GeometrySpec::Capsule { from: end(-h), to: end(h), radius })
            }
            _ => {}
        }
        if from_inertial || self.compiler.inertia_from_geom == InertiaFromGeom::Never {
            return Ok(());
        }
        if geom.solid.is_none() && geom.kind == "mesh" {
            self.warnings.unusable(format!("mesh inertia of geom '{}' (give the body an <inertial>)", name_of(e)));
        }
        if let Some(m) = geom_mass(e, &geom)? {
            self.tree.mass[b] = self.tree.mass[b].plus(&m.moved(&here.pose));
        }
        Ok(())
    }

    fn site(&mut self, e: &Element, here: Carrier) -> Result<(), MjcfError> {
        let name = name_of(e);
        let point = here.pose.point(&Pose::of(e, self.compiler)?.pos);
        if self.tree.sites.insert(name.clone(), (here.body, point)).is_some() {
            return Err(e.error(format!("a second site named '{name}'")));
        }
        if let Some(b) = here.body {
            self.tree.ops.push(OpSpec {
                name,
                body: self.tree.bodies[b].name.clone(),
                point: point.as_slice().to_vec(),
            });
        }
        Ok(())
    }
}

fn non_negative(e: &Element, key: &str) -> Result<f64, MjcfError> {
    let v = e.number(key, 0.0)?;
    if v < 0.0 {
        return Err(e.error(format!("{key} = {v} must be ≥ 0")));
    }
    Ok(v)
}

/// Fills each body's mass, centre of mass and inertia from its summed properties.
pub fn finish_bodies(tree: &mut Tree) -> Result<(), MjcfError> {
    for ((body, m), (file, line)) in tree.bodies.iter_mut().zip(&tree.mass).zip(&tree.body_at) {
        if m.mass <= 0.0 {
            return Err(MjcfError::Invalid {
                file: file.clone(),
                line: *line,
                element: format!("body '{}'", body.name),
                problem: "it moves but has no mass (no <inertial> and no geom with mass)".into(),
            });
        }
        let i = m.inertia;
        body.mass = m.mass;
        body.com = m.com.as_slice().to_vec();
        body.inertia = Numbers::Many(vec![i[(0, 0)], i[(1, 1)], i[(2, 2)], i[(0, 1)], i[(0, 2)], i[(1, 2)]]);
    }
    Ok(())
}
