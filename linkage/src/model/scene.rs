//! Scene files: the TOML description of a linkage, parsed with serde and validated with errors that name
//! the file and the key.
//!
//! A scene lists bodies, the tree joints that connect each body to its parent (from `ground` outwards),
//! the cut joints that close kinematic loops, named operational points, and obstacles. `docs/scene-format.md`
//! gives every key with its unit and default; [`Scene::from_toml_str`] parses, [`crate::Model::compile`]
//! validates and compiles.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::SceneError;
use crate::math::space::SceneKind;

/// The reserved name of the fixed base.
pub const GROUND: &str = "ground";

/// A scene as written in a file (validated later, by [`crate::Model::compile`]).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Human-readable name.
    #[serde(default)]
    pub name: String,
    /// `planar` or `spatial`.
    pub kind: SceneKind,
    /// Gravity acceleration in world axes, m/s² (2 or 3 numbers; default zero).
    #[serde(default)]
    pub gravity: Vec<f64>,
    /// Characteristic length L used to make rotational and translational quantities commensurate when
    /// counting constraints (default: the linkage's mass-weighted radius of gyration, see `constraint_directions`).
    #[serde(default)]
    pub length_scale: Option<f64>,
    /// Baumgarte stabilization of the loop closures (eq 3).
    #[serde(default)]
    pub baumgarte: Baumgarte,
    /// Penalty contact parameters for the obstacles.
    #[serde(default)]
    pub contact: ContactParams,
    /// Tolerance on the loop-closure residual at q0, in units of `length_scale` (default 1e-6).
    #[serde(default)]
    pub closure_tolerance: Option<f64>,
    /// Rigid bodies (`[[body]]`).
    #[serde(default, rename = "body")]
    pub bodies: Vec<BodySpec>,
    /// Tree joints (`[[joint]]`), one per body, each connecting it to its parent.
    #[serde(default, rename = "joint")]
    pub joints: Vec<JointSpec>,
    /// Cut joints closing loops (`[[cut]]`).
    #[serde(default, rename = "cut")]
    pub cuts: Vec<CutSpec>,
    /// Named operational points (`[[op]]`).
    #[serde(default, rename = "op")]
    pub ops: Vec<OpSpec>,
    /// Obstacles the linkage can touch (`[[obstacle]]`).
    #[serde(default, rename = "obstacle")]
    pub obstacles: Vec<ObstacleSpec>,
}

/// Baumgarte stabilization gains: `ḧ + 2αβ ḣ + α² h = 0` (eq 3).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Baumgarte {
    /// Natural frequency of the closure-error dynamics, 1/s.
    pub alpha: f64,
    /// Damping ratio of the closure-error dynamics.
    pub beta: f64,
}

impl Default for Baumgarte {
    fn default() -> Self {
        // Critically damped, about 8 Hz: fast enough to bound drift, slow enough to be stable with
        // explicit steps up to ~20 ms (α·dt < 1). Projection does the fine work.
        Baumgarte { alpha: 50.0, beta: 1.0 }
    }
}

/// Penalty contact model for obstacles (the paper's values by default).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ContactParams {
    /// Normal stiffness, N/m.
    pub stiffness: f64,
    /// Normal damping, N s/m.
    pub damping: f64,
}

impl Default for ContactParams {
    fn default() -> Self {
        ContactParams { stiffness: 15_000.0, damping: 300.0 }
    }
}

/// One number or a list of numbers (a planar inertia is a number, a spatial one a list).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum Numbers {
    /// A single number.
    One(f64),
    /// A list of numbers.
    Many(Vec<f64>),
}

impl Numbers {
    /// The numbers as a slice.
    pub fn as_slice(&self) -> &[f64] {
        match self {
            Numbers::One(x) => std::slice::from_ref(x),
            Numbers::Many(v) => v,
        }
    }
}

/// A rigid body.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// Unique name (not `ground`).
    pub name: String,
    /// Mass, kg (> 0).
    pub mass: f64,
    /// Centre of mass in the body frame, m.
    #[serde(default)]
    pub com: Vec<f64>,
    /// Rotational inertia about the COM in body axes, kg m²: planar one number; spatial
    /// `[ixx, iyy, izz]` or `[ixx, iyy, izz, ixy, ixz, iyz]`.
    pub inertia: Numbers,
    /// Drawing and contact geometry, in the body frame.
    #[serde(default)]
    pub geometry: Vec<GeometrySpec>,
}

/// Geometry attached to a body (used for drawing and for contacts with obstacles).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "shape", rename_all = "lowercase", deny_unknown_fields)]
pub enum GeometrySpec {
    /// A segment swept by a disc/sphere of `radius`.
    Capsule {
        /// Segment start in the body frame.
        from: Vec<f64>,
        /// Segment end in the body frame.
        to: Vec<f64>,
        /// Radius, m (≥ 0).
        radius: f64,
    },
    /// A disc (planar) or sphere (spatial).
    Ball {
        /// Centre in the body frame.
        center: Vec<f64>,
        /// Radius, m (> 0).
        radius: f64,
    },
}

/// Kind of a tree joint.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum JointKindSpec {
    /// Rotation about the joint axis (planar: about z).
    Revolute,
    /// Translation along the joint axis.
    Prismatic,
    /// Spatial only: free rotation about the joint frame's origin (a unit quaternion, no axis; starts at
    /// the joint frame's `rotation`).
    Ball,
    /// Spatial only: a Hooke joint, rotation about `axes[0]` (fixed in the parent) then `axes[1]` (carried by
    /// the cross-piece), two non-parallel axes in the joint frame.
    Universal,
}

/// A tree joint: connects `child` to `parent` (a body or `ground`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Unique name.
    pub name: String,
    /// `revolute`, `prismatic`, `ball` or `universal`.
    pub kind: JointKindSpec,
    /// Parent body or `ground`.
    pub parent: String,
    /// Child body (each body is the child of exactly one joint).
    pub child: String,
    /// Joint frame origin in the parent frame, m (default zero).
    #[serde(default)]
    pub origin: Vec<f64>,
    /// Joint frame orientation in the parent frame: planar an angle (rad), spatial roll-pitch-yaw
    /// `[r, p, y]` (rad, applied about x, then y, then z of the parent frame).
    #[serde(default)]
    pub rotation: Option<Numbers>,
    /// Joint axis in the joint frame (spatial: 3 numbers, default z; planar prismatic: 2 numbers, default x;
    /// planar revolute: always z, must be omitted).
    #[serde(default)]
    pub axis: Option<Vec<f64>>,
    /// Universal joints only: their two axes in the joint frame, `[[x, y, z], [x, y, z]]` (not parallel).
    #[serde(default)]
    pub axes: Option<Vec<Vec<f64>>>,
    /// Initial position, rad or m.
    #[serde(default)]
    pub q0: f64,
    /// Initial velocity, rad/s or m/s.
    #[serde(default)]
    pub qd0: f64,
    /// A spring acting on this joint.
    #[serde(default)]
    pub spring: Option<SpringSpec>,
    /// Viscous damping, N m s/rad or N s/m (≥ 0).
    #[serde(default)]
    pub damping: f64,
    /// Armature (a rotor's reflected inertia, MJCF's `armature`): added to this joint's diagonal entry of the
    /// mass matrix D, kg m² (revolute; each rate of a ball or universal joint) or kg (prismatic), ≥ 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub armature: f64,
    /// A PD actuator (makes the linkage active).
    #[serde(default)]
    pub actuator: Option<ActuatorSpec>,
    /// `[lo, hi]`: the positions the joint is kept within by penalty walls, rad or m (lo < hi; q0 inside).
    #[serde(default)]
    pub range: Option<[f64; 2]>,
}

/// A linear joint spring `τ = -k (q - rest)`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpringSpec {
    /// Stiffness, N m/rad or N/m (≥ 0).
    pub stiffness: f64,
    /// Rest position.
    #[serde(default)]
    pub rest: f64,
}

/// A joint PD actuator `τ = clamp(kp (target - q) - kd q̇, ±max_effort)`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ActuatorSpec {
    /// Proportional gain (≥ 0).
    pub kp: f64,
    /// Derivative gain (≥ 0).
    #[serde(default)]
    pub kd: f64,
    /// Target position.
    #[serde(default)]
    pub target: f64,
    /// Effort limit (> 0; default unlimited).
    #[serde(default)]
    pub max_effort: Option<f64>,
}

/// Kind of a cut joint (a loop closure).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum CutKindSpec {
    /// Planar pin: the two points coincide (2 equations).
    Pin,
    /// Planar slider: point b on the line through point a along `axis` (in body a), no relative
    /// rotation (2 equations).
    Slider,
    /// Weld: points coincide and no relative rotation (planar 3 equations, spatial 6).
    Weld,
    /// Spatial ball joint: the two points coincide (3 equations).
    Spherical,
    /// Spatial revolute: points coincide and the axes stay parallel (5 equations).
    Revolute,
}

impl CutKindSpec {
    /// Number of closure equations for this kind in a scene of `kind`, or `None` if not allowed there.
    pub fn equations(self, kind: SceneKind) -> Option<usize> {
        match (kind, self) {
            (SceneKind::Planar, CutKindSpec::Pin) => Some(2),
            (SceneKind::Planar, CutKindSpec::Slider) => Some(2),
            (SceneKind::Planar, CutKindSpec::Weld) => Some(3),
            (SceneKind::Spatial, CutKindSpec::Spherical) => Some(3),
            (SceneKind::Spatial, CutKindSpec::Revolute) => Some(5),
            (SceneKind::Spatial, CutKindSpec::Weld) => Some(6),
            _ => None,
        }
    }
}

/// A cut joint between point `point_a` of `body_a` and point `point_b` of `body_b` (either may be `ground`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CutSpec {
    /// Unique name.
    pub name: String,
    /// `pin`, `slider`, `weld` (planar); `spherical`, `revolute`, `weld` (spatial).
    pub kind: CutKindSpec,
    /// First body (or `ground`).
    pub body_a: String,
    /// Point on the first body, in its frame (default origin).
    #[serde(default)]
    pub point_a: Vec<f64>,
    /// Second body (or `ground`).
    pub body_b: String,
    /// Point on the second body, in its frame. Omitted: where `point_a` lies at q0, so the loop is
    /// closed at q0 by construction.
    #[serde(default)]
    pub point_b: Option<Vec<f64>>,
    /// Slider direction (planar, in body a) or revolute axis (spatial, in body a).
    #[serde(default)]
    pub axis: Option<Vec<f64>>,
    /// Spatial revolute only: the same axis in body b's frame. Omitted: `axis` carried into body b at q0;
    /// given: it must agree with `axis` at q0 (checked, so a typo does not lock the loop silently).
    #[serde(default)]
    pub axis_b: Option<Vec<f64>>,
    /// A spring on the cut's freedom: the slide along `axis` (slider), the angle about the hinge from q0
    /// (pin, revolute), or the rotation from q0 (spherical, with `rest` 0).
    #[serde(default)]
    pub spring: Option<SpringSpec>,
    /// Viscous damping on the same freedom, N s/m (slider) or N m s/rad (pin, revolute, spherical), ≥ 0.
    #[serde(default)]
    pub damping: f64,
    /// `[lo, hi]` on the freedom of a slider, pin or revolute cut, m or rad, kept by penalty walls.
    #[serde(default)]
    pub range: Option<[f64; 2]>,
}

impl CutSpec {
    /// A bare cut of `kind` between `point_a` of `body_a` and `body_b`: its point on `body_b` taken from q0, no
    /// axis, spring, damping or range. Set those with struct update syntax.
    pub fn between(name: String, kind: CutKindSpec, body_a: String, point_a: Vec<f64>, body_b: String) -> Self {
        CutSpec {
            name,
            kind,
            body_a,
            point_a,
            body_b,
            point_b: None,
            axis: None,
            axis_b: None,
            spring: None,
            damping: 0.0,
            range: None,
        }
    }
}

impl CutKindSpec {
    /// True when the cut's freedom is a translation (its springs and ranges are in metres).
    pub fn slides(self) -> bool {
        self == CutKindSpec::Slider
    }
}

/// A named operational point: where a user holds the linkage.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OpSpec {
    /// Unique name.
    pub name: String,
    /// The body it is fixed to.
    pub body: String,
    /// Position in the body frame (default origin).
    #[serde(default)]
    pub point: Vec<f64>,
}

/// An obstacle the linkage's geometry can touch.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "shape", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ObstacleSpec {
    /// Planar half-plane `{x : n·x ≥ offset}` is free space (n need not be unit; it is normalized).
    HalfPlane {
        /// Unique name.
        name: String,
        /// Outward normal of the solid (points into free space).
        normal: Vec<f64>,
        /// Offset along the unit normal, m.
        offset: f64,
    },
    /// Spatial plane `{x : n·x ≥ offset}` is free space.
    Plane {
        /// Unique name.
        name: String,
        /// Normal pointing into free space.
        normal: Vec<f64>,
        /// Offset along the unit normal, m.
        offset: f64,
    },
    /// A solid disc (planar).
    Circle {
        /// Unique name.
        name: String,
        /// Centre, m.
        center: Vec<f64>,
        /// Radius, m.
        radius: f64,
    },
    /// A solid sphere (spatial).
    Sphere {
        /// Unique name.
        name: String,
        /// Centre, m.
        center: Vec<f64>,
        /// Radius, m.
        radius: f64,
    },
}

impl ObstacleSpec {
    /// The obstacle's name.
    pub fn name(&self) -> &str {
        match self {
            ObstacleSpec::HalfPlane { name, .. }
            | ObstacleSpec::Plane { name, .. }
            | ObstacleSpec::Circle { name, .. }
            | ObstacleSpec::Sphere { name, .. } => name,
        }
    }
}

impl Scene {
    /// Parses a scene from TOML text; `file` names the source in errors.
    pub fn from_toml_str(text: &str, file: &str) -> Result<Scene, SceneError> {
        toml::from_str(text)
            .map_err(|e| SceneError::Syntax { file: file.to_string(), message: e.to_string().trim_end().to_string() })
    }

    /// Reads and parses a scene file.
    pub fn from_file(path: &Path) -> Result<Scene, SceneError> {
        let file = path.display().to_string();
        let text =
            std::fs::read_to_string(path).map_err(|e| SceneError::Io { file: file.clone(), message: e.to_string() })?;
        Scene::from_toml_str(&text, &file)
    }

    /// Serializes the scene back to TOML.
    pub fn to_toml_string(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot serialize scene: {e}\n"))
    }

    /// The same scene with every length multiplied by `factor` and masses unchanged (inertias scale by
    /// `factor²`, gravity by `factor`): the scene "written in other units". Used to check that results are
    /// unit-consistent.
    pub fn scaled_lengths(&self, factor: f64) -> Scene {
        let scale = |v: &Vec<f64>| v.iter().map(|x| x * factor).collect::<Vec<_>>();
        let mut s = self.clone();
        s.gravity = scale(&s.gravity);
        s.length_scale = s.length_scale.map(|l| l * factor);
        for b in &mut s.bodies {
            b.com = scale(&b.com);
            b.inertia = match &b.inertia {
                Numbers::One(x) => Numbers::One(x * factor * factor),
                Numbers::Many(v) => Numbers::Many(v.iter().map(|x| x * factor * factor).collect()),
            };
            for g in &mut b.geometry {
                match g {
                    GeometrySpec::Capsule { from, to, radius } => {
                        *from = scale(from);
                        *to = scale(to);
                        *radius *= factor;
                    }
                    GeometrySpec::Ball { center, radius } => {
                        *center = scale(center);
                        *radius *= factor;
                    }
                }
            }
        }
        // Mass and time keep their units, so forces scale by `factor` and torques by `factor²`:
        // translational stiffness and damping (kg/s², kg/s) are unchanged, rotational ones scale by factor².
        let f2 = factor * factor;
        s.contact = self.contact;
        for j in &mut s.joints {
            j.origin = scale(&j.origin);
            match j.kind {
                JointKindSpec::Prismatic => {
                    j.q0 *= factor;
                    j.qd0 *= factor;
                    j.range = j.range.map(|r| r.map(|x| x * factor));
                    if let Some(sp) = &mut j.spring {
                        sp.rest *= factor;
                    }
                    if let Some(a) = &mut j.actuator {
                        a.target *= factor;
                        a.max_effort = a.max_effort.map(|e| e * factor);
                    }
                }
                JointKindSpec::Revolute | JointKindSpec::Ball | JointKindSpec::Universal => {
                    if let Some(sp) = &mut j.spring {
                        sp.stiffness *= f2;
                    }
                    j.damping *= f2;
                    j.armature *= f2;
                    if let Some(a) = &mut j.actuator {
                        a.kp *= f2;
                        a.kd *= f2;
                        a.max_effort = a.max_effort.map(|e| e * f2);
                    }
                }
            }
        }
        for c in &mut s.cuts {
            c.point_a = scale(&c.point_a);
            c.point_b = c.point_b.as_ref().map(scale);
            if c.kind.slides() {
                c.range = c.range.map(|r| r.map(|x| x * factor));
                if let Some(sp) = &mut c.spring {
                    sp.rest *= factor;
                }
            } else {
                if let Some(sp) = &mut c.spring {
                    sp.stiffness *= f2;
                }
                c.damping *= f2;
            }
        }
        for o in &mut s.ops {
            o.point = scale(&o.point);
        }
        for o in &mut s.obstacles {
            match o {
                ObstacleSpec::HalfPlane { offset, .. } | ObstacleSpec::Plane { offset, .. } => *offset *= factor,
                ObstacleSpec::Circle { center, radius, .. } | ObstacleSpec::Sphere { center, radius, .. } => {
                    *center = scale(center);
                    *radius *= factor;
                }
            }
        }
        s
    }
}

/// For `skip_serializing_if`: a default of zero is left out of written scenes.
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn syntax_errors_name_the_file_and_the_line() {
        let err = Scene::from_toml_str("kind = \"planar\"\n[[body]]\nname = 3\n", "bad.toml").unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("bad.toml"), "{text}");
        assert!(text.contains("line 3"), "{text}");
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let err = Scene::from_toml_str("kind = \"planar\"\nmasss = 3\n", "typo.toml").unwrap_err();
        assert!(err.to_string().contains("masss"), "{err}");
    }

    #[test]
    fn unknown_kind_is_rejected() {
        let err = Scene::from_toml_str("kind = \"curved\"\n", "k.toml").unwrap_err();
        assert!(err.to_string().contains("curved"), "{err}");
    }
}
