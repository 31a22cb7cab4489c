//! A kinloop scene → an MJCF model MuJoCo loads and simulates, with the same joint coordinates.
//!
//! Encodings (MJCF has no universal joint, no revolute or slider equality, no planar scene):
//! - every body is written at its pose at q0 and each hinge or slide gets `ref` = q0, so MuJoCo's qpos0 is
//!   kinloop's q0 and a joint's qpos equals kinloop's q (equalities are then closed at qpos0);
//! - a universal joint is two hinges in one body: MuJoCo applies a body's joints in order, the second axis
//!   carried by the first turn, which is kinloop's cross-piece (no extra body);
//! - a spherical cut or planar pin is a `connect` between two sites (both points given, so nothing is
//!   recomputed); a spatial revolute cut is two connects, at its point and one length scale along its axis
//!   (six equations for five: MuJoCo's soft solver takes the redundant one);
//! - a weld is a `weld` (MuJoCo takes the relative pose at qpos0);
//! - a planar slider cut is a light guide body (10⁻⁶ of the linkage's mass) on a slide along the axis,
//!   welded to body b: one added body and joint;
//! - a planar scene is written in the x-y plane with hinges along z; a body's planar inertia I becomes
//!   `diaginertia="I/2 I/2 I"`, which motion in the plane never feels;
//! - operational points are sites; capsules and balls are geoms that neither collide nor weigh (every body
//!   has its `<inertial>`); contacts are disabled.
//!
//! Not carried (listed in the export's warnings): springs, dampers and ranges on cuts, obstacles, actuator
//! targets other than zero, initial velocities, Baumgarte gains (MuJoCo's constraints are soft instead).

use std::fmt::Write;

use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::math::space::{SceneKind, Spatial};
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::scene::{CutKindSpec, GeometrySpec, JointKindSpec, JointSpec, Scene, GROUND};
use kinloop_linkage::Model;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

use crate::error::MjcfError;

/// The mass of a guide body relative to the linkage's.
const GUIDE_MASS: f64 = 1e-6;

/// An exported model and what the scene held that it does not carry.
#[derive(Clone, Debug, PartialEq)]
pub struct Export {
    /// The MJCF text.
    pub xml: String,
    /// Items not carried, each named.
    pub dropped: Vec<String>,
}

/// Writes `scene` (from `file`) as MJCF.
pub fn export(scene: &Scene, file: &str) -> Result<Export, MjcfError> {
    let mut w = Writer { scene, planar: scene.kind == SceneKind::Planar, out: String::new(), dropped: Vec::new() };
    let poses = w.poses_at_q0(file)?;
    w.write(&poses);
    Ok(Export { xml: w.out, dropped: w.dropped })
}

/// Each scene body's pose at q0 (world), and each cut's two points in their bodies.
struct Poses {
    body: Vec<(Rotation3<f64>, Vector3<f64>)>,
    cut_b: Vec<Vector3<f64>>,
    cut_axis_b: Vec<Option<(Vector3<f64>, Vector3<f64>)>>,
}

struct Writer<'a> {
    scene: &'a Scene,
    planar: bool,
    out: String,
    dropped: Vec<String>,
}

fn v3(v: &[f64]) -> Vector3<f64> {
    Vector3::new(v.first().copied().unwrap_or(0.0), v.get(1).copied().unwrap_or(0.0), v.get(2).copied().unwrap_or(0.0))
}

fn nums(v: &[f64]) -> String {
    v.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(" ")
}

fn quat(r: &Rotation3<f64>) -> String {
    let q = UnitQuaternion::from_rotation_matrix(r);
    nums(&[q.w, q.i, q.j, q.k])
}

impl Writer<'_> {
    /// The scene compiled as a spatial model (a planar one lifted into the x-y plane) at q0.
    fn poses_at_q0(&self, file: &str) -> Result<Poses, MjcfError> {
        let spatial = if self.planar { lift(self.scene) } else { self.scene.clone() };
        let model = Model::<Spatial>::compile(&spatial, file)
            .map_err(|e| MjcfError::Scene { file: file.to_string(), message: e.to_string() })?;
        let mut data = Data::new(&model);
        forward_kinematics(&model, &mut data, &model.q0);
        let pose = |name: &str| match model.body_index(name) {
            None => (Rotation3::identity(), Vector3::zeros()),
            Some(b) => (data.kin.body_rot[b], data.kin.body_pos[b]),
        };
        let body = self.scene.bodies.iter().map(|b| pose(&b.name)).collect();
        let mut cut_b = Vec::new();
        let mut cut_axis_b = Vec::new();
        for c in &spatial.cuts {
            let (ra, pa) = pose(&c.body_a);
            let (rb, pb) = pose(&c.body_b);
            let world_a = pa + ra * v3(&c.point_a);
            cut_b.push(c.point_b.as_ref().map_or_else(|| rb.inverse() * (world_a - pb), |p| v3(p)));
            cut_axis_b.push(c.axis.as_ref().filter(|_| c.kind == CutKindSpec::Revolute).map(|axis| {
                let along = v3(&c.point_a) + v3(axis).normalize() * model.length_scale;
                (along, rb.inverse() * (pa + ra * along - pb))
            }));
        }
        Ok(Poses { body, cut_b, cut_axis_b })
    }

    fn write(&mut self, poses: &Poses) {
        let s = self.scene;
        let g = v3(&s.gravity);
        let _ = writeln!(self.out, "<mujoco model=\"{}\">", escape(&s.name));
        let _ =
            writeln!(self.out, "  <!-- Exported by kinloop (export to MJCF); the encodings are in docs/mjcf.md. -->");
        let _ = writeln!(self.out, "  <compiler angle=\"radian\" autolimits=\"true\"/>");
        let _ = writeln!(
            self.out,
            "  <option gravity=\"{}\">\n    <flag contact=\"disable\"/>\n  </option>",
            nums(g.as_slice())
        );
        self.out.push_str("  <worldbody>\n");
        self.children(GROUND, (Rotation3::identity(), Vector3::zeros()), poses, 2);
        for ci in 0..s.cuts.len() {
            if s.cuts[ci].kind == CutKindSpec::Slider && s.cuts[ci].body_a == GROUND {
                self.guide(ci, "  ");
            }
        }
        self.out.push_str("  </worldbody>\n");
        self.equalities(poses);
        self.actuators();
        self.out.push_str("</mujoco>\n");
        if !s.obstacles.is_empty() {
            self.dropped.push(format!("{} obstacles", s.obstacles.len()));
        }
    }

    fn children(&mut self, parent: &str, parent_pose: (Rotation3<f64>, Vector3<f64>), poses: &Poses, depth: usize) {
        let joints: Vec<&JointSpec> = self.scene.joints.iter().filter(|j| j.parent == parent).collect();
        for j in joints {
            let Some(bi) = self.scene.bodies.iter().position(|b| b.name == j.child) else { continue };
            let (rot, pos) = poses.body[bi];
            let local_rot = parent_pose.0.inverse() * rot;
            let local_pos = parent_pose.0.inverse() * (pos - parent_pose.1);
            let pad = " ".repeat(depth * 2);
            let _ = writeln!(
                self.out,
                "{pad}<body name=\"{}\" pos=\"{}\" quat=\"{}\">",
                escape(&j.child),
                nums(local_pos.as_slice()),
                quat(&local_rot)
            );
            self.joint(j, &pad);
            self.body_contents(bi, &pad);
            self.children(&j.child, (rot, pos), poses, depth + 1);
            let _ = writeln!(self.out, "{pad}</body>");
        }
    }

    fn joint(&mut self, j: &JointSpec, pad: &str) {
        let mut attrs = format!("name=\"{}\"", escape(&j.name));
        match j.kind {
            JointKindSpec::Revolute | JointKindSpec::Prismatic => {
                let kind = if j.kind == JointKindSpec::Revolute { "hinge" } else { "slide" };
                let axis = match (&j.axis, self.planar, j.kind) {
                    (_, true, JointKindSpec::Revolute) => Vector3::z(),
                    (Some(a), _, _) => v3(a).normalize(),
                    (None, true, _) => Vector3::x(),
                    (None, false, _) => Vector3::z(),
                };
                let _ = write!(attrs, " type=\"{kind}\" axis=\"{}\" ref=\"{:?}\"", nums(axis.as_slice()), j.q0);
                if let Some(sp) = j.spring {
                    let _ = write!(attrs, " stiffness=\"{:?}\" springref=\"{:?}\"", sp.stiffness, sp.rest);
                }
                if let Some([lo, hi]) = j.range {
                    let _ = write!(attrs, " range=\"{lo:?} {hi:?}\"");
                }
            }
            JointKindSpec::Ball => attrs.push_str(" type=\"ball\""),
            JointKindSpec::Universal => {
                let axes = j.axes.clone().unwrap_or_default();
                for (k, a) in axes.iter().enumerate() {
                    let suffix = if k == 0 { String::new() } else { format!(".{k}") };
                    let _ = writeln!(
                        self.out,
                        "{pad}  <joint name=\"{}{suffix}\" type=\"hinge\" axis=\"{}\"{}/>",
                        escape(&j.name),
                        nums(v3(a).normalize().as_slice()),
                        armature(j)
                    );
                }
                return;
            }
        }
        if j.damping > 0.0 {
            let _ = write!(attrs, " damping=\"{:?}\"", j.damping);
        }
        attrs.push_str(&armature(j));
        if j.qd0 != 0.0 {
            self.dropped.push(format!("initial velocity of joint '{}'", j.name));
        }
        let _ = writeln!(self.out, "{pad}  <joint {attrs}/>");
    }

    fn body_contents(&mut self, bi: usize, pad: &str) {
        let b = &self.scene.bodies[bi];
        let i = b.inertia.as_slice();
        let inertia = match (self.planar, i) {
            (true, [izz]) => format!("diaginertia=\"{}\"", nums(&[izz / 2.0, izz / 2.0, *izz])),
            (_, [xx, yy, zz]) => format!("diaginertia=\"{}\"", nums(&[*xx, *yy, *zz])),
            (_, six) => format!("fullinertia=\"{}\"", nums(six)),
        };
        let _ = writeln!(
            self.out,
            "{pad}  <inertial pos=\"{}\" mass=\"{:?}\" {inertia}/>",
            nums(v3(&b.com).as_slice()),
            b.mass
        );
        for g in &b.geometry {
            let geom = match g {
                GeometrySpec::Capsule { from, to, radius } if v3(from) != v3(to) => format!(
                    "type=\"capsule\" fromto=\"{} {}\" size=\"{radius:?}\"",
                    nums(v3(from).as_slice()),
                    nums(v3(to).as_slice())
                ),
                GeometrySpec::Capsule { from: center, radius, .. } | GeometrySpec::Ball { center, radius } => {
                    format!("type=\"sphere\" pos=\"{}\" size=\"{radius:?}\"", nums(v3(center).as_slice()))
                }
            };
            let _ = writeln!(self.out, "{pad}  <geom {geom} contype=\"0\" conaffinity=\"0\" mass=\"0\"/>");
        }
        for op in self.scene.ops.iter().filter(|o| o.body == b.name) {
            let _ = writeln!(
                self.out,
                "{pad}  <site name=\"{}\" pos=\"{}\"/>",
                escape(&op.name),
                nums(v3(&op.point).as_slice())
            );
        }
        for (ci, c) in self.scene.cuts.iter().enumerate() {
            if c.kind == CutKindSpec::Slider && c.body_a == b.name {
                self.guide(ci, pad);
            }
        }
    }

    /// The light body a planar slider cut slides on, child of body a.
    fn guide(&mut self, ci: usize, pad: &str) {
        let c = &self.scene.cuts[ci];
        let total: f64 = self.scene.bodies.iter().map(|b| b.mass).sum();
        let m = GUIDE_MASS * total;
        let axis = v3(c.axis.as_deref().unwrap_or(&[1.0, 0.0])).normalize();
        let _ = writeln!(
            self.out,
            "{pad}  <body name=\"{}.guide\" pos=\"{}\">",
            escape(&c.name),
            nums(v3(&c.point_a).as_slice())
        );
        let _ = writeln!(
            self.out,
            "{pad}    <joint name=\"{}.slide\" type=\"slide\" axis=\"{}\"/>",
            escape(&c.name),
            nums(axis.as_slice())
        );
        let _ = writeln!(
            self.out,
            "{pad}    <inertial pos=\"0 0 0\" mass=\"{m:?}\" diaginertia=\"{}\"/>",
            nums(&[m * 1e-4; 3])
        );
        let _ = writeln!(self.out, "{pad}  </body>");
    }

    fn equalities(&mut self, poses: &Poses) {
        let mut eq = String::new();
        let mut sites: Vec<(String, String, Vector3<f64>)> = Vec::new();
        for (ci, c) in self.scene.cuts.iter().enumerate() {
            let name = escape(&c.name);
            if c.spring.is_some() || c.damping > 0.0 || c.range.is_some() {
                self.dropped.push(format!("spring, damper or range of cut '{}'", c.name));
            }
            let mut connect = |tag: &str, pa: Vector3<f64>, pb: Vector3<f64>, eq: &mut String| {
                let (sa, sb) = (format!("{name}.{tag}a"), format!("{name}.{tag}b"));
                sites.push((c.body_a.clone(), sa.clone(), pa));
                sites.push((c.body_b.clone(), sb.clone(), pb));
                let _ = writeln!(eq, "    <connect name=\"{name}{tag}\" site1=\"{sa}\" site2=\"{sb}\"/>");
            };
            match c.kind {
                CutKindSpec::Pin | CutKindSpec::Spherical => connect("", v3(&c.point_a), poses.cut_b[ci], &mut eq),
                CutKindSpec::Revolute => {
                    connect("", v3(&c.point_a), poses.cut_b[ci], &mut eq);
                    if let Some((along_a, along_b)) = poses.cut_axis_b[ci] {
                        connect(".axis", along_a, along_b, &mut eq);
                    }
                }
                CutKindSpec::Weld => {
                    let _ = writeln!(
                        eq,
                        "    <weld name=\"{name}\" body1=\"{}\" body2=\"{}\"/>",
                        world(&c.body_a),
                        world(&c.body_b)
                    );
                }
                CutKindSpec::Slider => {
                    let _ = writeln!(
                        eq,
                        "    <weld name=\"{name}\" body1=\"{name}.guide\" body2=\"{}\"/>",
                        world(&c.body_b)
                    );
                }
            }
        }
        self.place_sites(&sites);
        if !eq.is_empty() {
            let _ = write!(self.out, "  <equality>\n{eq}  </equality>\n");
        }
    }

    /// Puts each cut's site into its body (or the world body) by inserting it after the body's opening tag.
    fn place_sites(&mut self, sites: &[(String, String, Vector3<f64>)]) {
        for (body, name, p) in sites {
            let site = format!("<site name=\"{name}\" pos=\"{}\"/>", nums(p.as_slice()));
            let open = if body == GROUND {
                "  <worldbody>\n".to_string()
            } else {
                format!("<body name=\"{}\" ", escape(body))
            };
            if let Some(at) = self.out.find(&open) {
                let end = at + self.out[at..].find('\n').unwrap_or(0) + 1;
                self.out.insert_str(end, &format!("    {site}\n"));
            }
        }
    }

    fn actuators(&mut self) {
        let mut act = String::new();
        for j in &self.scene.joints {
            if let Some(a) = j.actuator {
                let mut attrs = format!(
                    "name=\"{}.pd\" joint=\"{}\" kp=\"{:?}\" kv=\"{:?}\"",
                    escape(&j.name),
                    escape(&j.name),
                    a.kp,
                    a.kd
                );
                if let Some(e) = a.max_effort {
                    let _ = write!(attrs, " forcerange=\"{:?} {e:?}\"", -e);
                }
                if a.target != 0.0 {
                    self.dropped
                        .push(format!("target of the actuator on '{}' (MuJoCo's ctrl is zero at start)", j.name));
                }
                let _ = writeln!(act, "    <position {attrs}/>");
            }
        }
        if !act.is_empty() {
            let _ = write!(self.out, "  <actuator>\n{act}  </actuator>\n");
        }
    }
}

fn world(body: &str) -> String {
    if body == GROUND {
        "world".into()
    } else {
        escape(body)
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;").replace('>', "&gt;")
}

/// A planar scene as the spatial scene it is in the x-y plane: hinges along z, slides and points with z = 0,
/// pins as spherical cuts, planar inertia I as (I/2, I/2, I).
pub fn lift(scene: &Scene) -> Scene {
    let mut s = scene.clone();
    s.kind = SceneKind::Spatial;
    let lift3 = |v: &mut Vec<f64>| *v = v3(v).as_slice().to_vec();
    lift3(&mut s.gravity);
    for b in &mut s.bodies {
        lift3(&mut b.com);
        if let [izz] = b.inertia.as_slice() {
            b.inertia = kinloop_linkage::model::scene::Numbers::Many(vec![izz / 2.0, izz / 2.0, *izz]);
        }
        for g in &mut b.geometry {
            match g {
                GeometrySpec::Capsule { from, to, .. } => {
                    lift3(from);
                    lift3(to);
                }
                GeometrySpec::Ball { center, .. } => lift3(center),
            }
        }
    }
    for j in &mut s.joints {
        lift3(&mut j.origin);
        let angle = j.rotation.as_ref().map_or(0.0, |r| r.as_slice().first().copied().unwrap_or(0.0));
        j.rotation = Some(kinloop_linkage::model::scene::Numbers::Many(vec![0.0, 0.0, angle]));
        j.axis = Some(match j.kind {
            JointKindSpec::Prismatic => v3(j.axis.as_deref().unwrap_or(&[1.0, 0.0])).as_slice().to_vec(),
            _ => vec![0.0, 0.0, 1.0],
        });
    }
    for c in &mut s.cuts {
        lift3(&mut c.point_a);
        if let Some(p) = &mut c.point_b {
            lift3(p);
        }
        if let Some(a) = &mut c.axis {
            lift3(a);
        }
        // Only the points matter for the poses at q0; a slider becomes its guide's weld in the export.
        if c.kind == CutKindSpec::Slider {
            c.point_b = None;
        }
        c.kind = match c.kind {
            CutKindSpec::Pin | CutKindSpec::Slider => CutKindSpec::Spherical,
            k => k,
        };
        c.spring = None;
        c.damping = 0.0;
        c.range = None;
        c.axis = None;
    }
    for o in &mut s.ops {
        lift3(&mut o.point);
    }
    s.obstacles.clear();
    s
}

/// ` armature="a"` for a joint with an armature (each of a universal joint's hinges gets its own), else nothing.
fn armature(j: &JointSpec) -> String {
    if j.armature > 0.0 {
        format!(" armature=\"{:?}\"", j.armature)
    } else {
        String::new()
    }
}
