//! Mass properties: a body's explicit `<inertial>`, or the sum of its geoms' as MuJoCo computes them
//! (`density` default 1000 or `mass=`, solids of uniform density; a capsule is a cylinder and two hemispheres).

use std::f64::consts::PI;

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

use crate::error::MjcfError;
use crate::frames::{z_to, Compiler, Pose};
use crate::xml::Element;

/// Mass, centre of mass and rotational inertia about the centre of mass, in some frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProps {
    /// Mass, kg.
    pub mass: f64,
    /// Centre of mass.
    pub com: Vector3<f64>,
    /// Inertia about the centre of mass, in the frame's axes.
    pub inertia: Matrix3<f64>,
}

impl MassProps {
    /// Nothing.
    pub fn zero() -> MassProps {
        MassProps { mass: 0.0, com: Vector3::zeros(), inertia: Matrix3::zeros() }
    }

    /// These properties seen from an outer frame in which this frame has pose `pose`.
    pub fn moved(&self, pose: &Pose) -> MassProps {
        let r = pose.rot.matrix();
        MassProps { mass: self.mass, com: pose.point(&self.com), inertia: r * self.inertia * r.transpose() }
    }

    /// The sum of two bodies rigidly joined (parallel-axis theorem about the joint centre of mass).
    pub fn plus(&self, other: &MassProps) -> MassProps {
        let mass = self.mass + other.mass;
        if mass == 0.0 {
            return MassProps::zero();
        }
        let com = (self.com * self.mass + other.com * other.mass) / mass;
        let shift = |p: &MassProps| {
            let d = p.com - com;
            p.inertia + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * p.mass
        };
        MassProps { mass, com, inertia: shift(self) + shift(other) }
    }
}

/// A geom's shape as MuJoCo sizes it, in the geom's own frame (axis z for capsules and cylinders).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solid {
    /// Radius.
    Sphere(f64),
    /// Radius and half-length of the cylindrical part.
    Capsule(f64, f64),
    /// Radius and half-length.
    Cylinder(f64, f64),
    /// Half-sizes along x, y, z.
    Box([f64; 3]),
    /// Semi-axes.
    Ellipsoid([f64; 3]),
}

impl Solid {
    /// Volume, m³.
    pub fn volume(&self) -> f64 {
        match *self {
            Solid::Sphere(r) => 4.0 / 3.0 * PI * r.powi(3),
            Solid::Capsule(r, h) => PI * r * r * 2.0 * h + 4.0 / 3.0 * PI * r.powi(3),
            Solid::Cylinder(r, h) => PI * r * r * 2.0 * h,
            Solid::Box([a, b, c]) => 8.0 * a * b * c,
            Solid::Ellipsoid([a, b, c]) => 4.0 / 3.0 * PI * a * b * c,
        }
    }

    /// Principal moments about the centre for uniform `density` (the diagonal in the geom frame).
    pub fn moments(&self, density: f64) -> Vector3<f64> {
        let m = density * self.volume();
        match *self {
            Solid::Sphere(r) => Vector3::repeat(0.4 * m * r * r),
            Solid::Capsule(r, h) => {
                // Cylinder of height 2h plus two hemispheres, each about the capsule's centre: a hemisphere's
                // own moment 83/320 m r², its centre of mass 3r/8 beyond the cylinder's end.
                let len = 2.0 * h;
                let cyl = density * PI * r * r * len;
                let sph = density * 4.0 / 3.0 * PI * r.powi(3);
                let across = cyl * (3.0 * r * r + len * len) / 12.0
                    + sph * (0.4 * r * r + len * len / 4.0 + 3.0 * r * len / 8.0);
                Vector3::new(across, across, (cyl / 2.0 + 0.4 * sph) * r * r)
            }
            Solid::Cylinder(r, h) => {
                let across = m * (3.0 * r * r + 4.0 * h * h) / 12.0;
                Vector3::new(across, across, m * r * r / 2.0)
            }
            Solid::Box([a, b, c]) => Vector3::new(b * b + c * c, a * a + c * c, a * a + b * b) * (m / 3.0),
            Solid::Ellipsoid([a, b, c]) => Vector3::new(b * b + c * c, a * a + c * c, a * a + b * b) * (m / 5.0),
        }
    }
}

/// A geom with its frame in the body and its solid (`None` for shapes kinloop does not weigh: planes,
/// meshes, height fields).
#[derive(Clone, Debug)]
pub struct Geom {
    /// Pose in the (MJCF) body frame.
    pub pose: Pose,
    /// The solid, if one kinloop can weigh.
    pub solid: Option<Solid>,
    /// The geom's `type`.
    pub kind: String,
}

/// Reads a resolved `<geom>`: its type, size or `fromto`, and frame.
pub fn read_geom(e: &Element, compiler: &Compiler) -> Result<Geom, MjcfError> {
    let kind = e.attr("type").unwrap_or("sphere").to_string();
    let size = e.numbers("size")?.unwrap_or_default();
    let size_at = |i: usize| -> Result<f64, MjcfError> {
        match size.get(i) {
            Some(&s) if s > 0.0 => Ok(s),
            Some(&s) => Err(e.error(format!("size[{i}] = {s} must be > 0"))),
            None => Err(e.error(format!("a {kind} needs size[{i}]"))),
        }
    };
    let mut pose = Pose::of(e, compiler)?;
    let mut half_length = None;
    if let Some(ft) = e.fixed::<6>("fromto")? {
        if !matches!(kind.as_str(), "capsule" | "cylinder" | "box" | "ellipsoid") {
            return Err(e.error(format!("fromto is for capsules, cylinders, boxes and ellipsoids, not a {kind}")));
        }
        let (a, b) = (Vector3::new(ft[0], ft[1], ft[2]), Vector3::new(ft[3], ft[4], ft[5]));
        let axis = Unit::try_new(b - a, 1e-300).ok_or_else(|| e.error("fromto: the two ends coincide"))?;
        pose = Pose { rot: z_to(&axis), pos: (a + b) / 2.0 };
        half_length = Some((b - a).norm() / 2.0);
    }
    let solid = match kind.as_str() {
        "sphere" => Some(Solid::Sphere(size_at(0)?)),
        "capsule" => Some(Solid::Capsule(size_at(0)?, half_length.map_or_else(|| size_at(1), Ok)?)),
        "cylinder" => Some(Solid::Cylinder(size_at(0)?, half_length.map_or_else(|| size_at(1), Ok)?)),
        "box" => {
            let (a, b) = (size_at(0)?, size_at(1)?);
            Some(Solid::Box([a, b, half_length.map_or_else(|| size_at(2), Ok)?]))
        }
        "ellipsoid" => {
            let (a, b) = (size_at(0)?, size_at(1)?);
            Some(Solid::Ellipsoid([a, b, half_length.map_or_else(|| size_at(2), Ok)?]))
        }
        "plane" | "mesh" | "hfield" | "sdf" => None,
        other => return Err(e.error(format!("unknown geom type '{other}'"))),
    };
    Ok(Geom { pose, solid, kind })
}

/// A geom's mass properties in the body frame: `mass=` if given, else `density` (default 1000) × volume.
pub fn geom_mass(e: &Element, geom: &Geom) -> Result<Option<MassProps>, MjcfError> {
    let Some(solid) = geom.solid else { return Ok(None) };
    let density = match e.fixed::<1>("mass")? {
        Some([m]) if m < 0.0 => return Err(e.error(format!("mass = {m} must be ≥ 0"))),
        Some([m]) => m / solid.volume(),
        None => e.number("density", 1000.0)?,
    };
    if density < 0.0 {
        return Err(e.error(format!("density = {density} must be ≥ 0")));
    }
    let local = MassProps {
        mass: density * solid.volume(),
        com: Vector3::zeros(),
        inertia: Matrix3::from_diagonal(&solid.moments(density)),
    };
    Ok(Some(local.moved(&geom.pose)))
}

/// An explicit `<inertial pos mass (diaginertia | fullinertia) [quat ...]>` in the body frame.
pub fn read_inertial(e: &Element, compiler: &Compiler) -> Result<MassProps, MjcfError> {
    let mass = e.fixed::<1>("mass")?.ok_or_else(|| e.error("needs a mass"))?[0];
    if mass <= 0.0 {
        return Err(e.error(format!("mass = {mass} must be > 0")));
    }
    let pos = e.fixed::<3>("pos")?.ok_or_else(|| e.error("needs a pos"))?;
    let inertia = match (e.fixed::<3>("diaginertia")?, e.fixed::<6>("fullinertia")?) {
        (Some(d), None) => {
            let rot: Rotation3<f64> = compiler.orientation(e, "")?;
            rot.matrix() * Matrix3::from_diagonal(&Vector3::from(d)) * rot.matrix().transpose()
        }
        (None, Some([xx, yy, zz, xy, xz, yz])) => {
            if ["quat", "axisangle", "euler", "xyaxes", "zaxis"].iter().any(|k| e.attr(k).is_some()) {
                return Err(e.error("fullinertia is in the body frame already: give no orientation with it"));
            }
            Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
        }
        (Some(_), Some(_)) => return Err(e.error("give diaginertia or fullinertia, not both")),
        (None, None) => return Err(e.error("needs diaginertia or fullinertia")),
    };
    Ok(MassProps { mass, com: Vector3::from(pos), inertia })
}
