//! Frames as MJCF writes them: `pos` and one of `quat`, `axisangle`, `euler`, `xyaxes`, `zaxis`, read with the
//! `<compiler>`'s angle unit and Euler sequence (MuJoCo's XML reference, "Frame orientations").

use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};

use crate::error::MjcfError;
use crate::xml::Element;

/// The `<compiler>` settings the reader uses.
#[derive(Clone, Debug, PartialEq)]
pub struct Compiler {
    /// Radians per unit of the model's angles (π/180 for `angle="degree"`, MuJoCo's default).
    pub angle_unit: f64,
    /// The Euler sequence: three of `xyzXYZ`; lowercase axes rotate with the frame (intrinsic).
    pub eulerseq: [u8; 3],
    /// `inertiafromgeom`: `auto` (geoms only for bodies without `<inertial>`), `true` (always) or `false`.
    pub inertia_from_geom: InertiaFromGeom,
}

/// Where body inertia comes from (`<compiler inertiafromgeom>`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InertiaFromGeom {
    /// From `<inertial>` when present, else the geoms.
    Auto,
    /// Always from the geoms.
    Always,
    /// Only from `<inertial>`.
    Never,
}

impl Compiler {
    /// Reads the `<compiler>` elements under `<mujoco>` (later ones override earlier ones).
    pub fn read(root: &Element) -> Result<Compiler, MjcfError> {
        let mut c = Compiler {
            angle_unit: std::f64::consts::PI / 180.0,
            eulerseq: *b"xyz",
            inertia_from_geom: InertiaFromGeom::Auto,
        };
        for e in root.children_named("compiler") {
            match e.attr("angle") {
                None => {}
                Some("degree") => c.angle_unit = std::f64::consts::PI / 180.0,
                Some("radian") => c.angle_unit = 1.0,
                Some(other) => return Err(e.error(format!("angle=\"{other}\": expected degree or radian"))),
            }
            if let Some(seq) = e.attr("eulerseq") {
                let bytes = seq.as_bytes();
                if bytes.len() != 3 || !bytes.iter().all(|b| b"xyzXYZ".contains(b)) {
                    return Err(e.error(format!("eulerseq=\"{seq}\": expected three of x, y, z, X, Y, Z")));
                }
                c.eulerseq = [bytes[0], bytes[1], bytes[2]];
            }
            match e.attr("inertiafromgeom") {
                None => {}
                Some("auto") => c.inertia_from_geom = InertiaFromGeom::Auto,
                Some("true") => c.inertia_from_geom = InertiaFromGeom::Always,
                Some("false") => c.inertia_from_geom = InertiaFromGeom::Never,
                Some(other) => {
                    return Err(e.error(format!("inertiafromgeom=\"{other}\": expected auto, true or false")))
                }
            }
        }
        Ok(c)
    }

    /// The orientation `e` gives with `keys` (`quat`, `axisangle`, `euler`, `xyaxes`, `zaxis`, or with a
    /// prefix such as `iquat`); identity when none is given, an error when two are.
    pub fn orientation(&self, e: &Element, prefix: &str) -> Result<Rotation3<f64>, MjcfError> {
        let key = |k: &str| format!("{prefix}{k}");
        let given: Vec<String> = ["quat", "axisangle", "euler", "xyaxes", "zaxis"]
            .iter()
            .map(|k| key(k))
            .filter(|k| e.attr(k).is_some())
            .collect();
        if given.len() > 1 {
            return Err(e.error(format!("give one orientation, not {}", given.join(" and "))));
        }
        if let Some([w, x, y, z]) = e.fixed::<4>(&key("quat"))? {
            let q = nalgebra::Quaternion::new(w, x, y, z);
            if q.norm() == 0.0 {
                return Err(e.error(format!("{}: a zero quaternion is no orientation", key("quat"))));
            }
            return Ok(UnitQuaternion::from_quaternion(q).to_rotation_matrix());
        }
        if let Some([x, y, z, a]) = e.fixed::<4>(&key("axisangle"))? {
            let axis = nonzero(e, &key("axisangle"), Vector3::new(x, y, z))?;
            return Ok(Rotation3::from_axis_angle(&axis, a * self.angle_unit));
        }
        if let Some(angles) = e.fixed::<3>(&key("euler"))? {
            return Ok(self.euler(angles));
        }
        if let Some(v) = e.fixed::<6>(&key("xyaxes"))? {
            let x = nonzero(e, &key("xyaxes"), Vector3::new(v[0], v[1], v[2]))?.into_inner();
            let y = Vector3::new(v[3], v[4], v[5]);
            let y = nonzero(e, &key("xyaxes"), y - x * x.dot(&y))?.into_inner();
            return Ok(Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, x.cross(&y)])));
        }
        if let Some([x, y, z]) = e.fixed::<3>(&key("zaxis"))? {
            let z = nonzero(e, &key("zaxis"), Vector3::new(x, y, z))?;
            return Ok(z_to(&z));
        }
        Ok(Rotation3::identity())
    }

    /// Euler angles in the model's unit and sequence: a lowercase axis turns about the frame as already
    /// turned (post-multiplied), an uppercase one about the fixed frame (pre-multiplied).
    pub fn euler(&self, angles: [f64; 3]) -> Rotation3<f64> {
        let mut r = Rotation3::identity();
        for (axis, angle) in self.eulerseq.iter().zip(angles) {
            let unit = match axis.to_ascii_lowercase() {
                b'x' => Vector3::x_axis(),
                b'y' => Vector3::y_axis(),
                _ => Vector3::z_axis(),
            };
            let turn = Rotation3::from_axis_angle(&unit, angle * self.angle_unit);
            r = if axis.is_ascii_lowercase() { r * turn } else { turn * r };
        }
        r
    }
}

/// The smallest rotation taking +z to `z` (MuJoCo's `zaxis` and `fromto` frames).
pub fn z_to(z: &Unit<Vector3<f64>>) -> Rotation3<f64> {
    Rotation3::rotation_between(&Vector3::z(), z).unwrap_or_else(|| {
        // Opposite to +z: any half turn about a perpendicular axis; MuJoCo turns about x.
        Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    })
}

fn nonzero(e: &Element, key: &str, v: Vector3<f64>) -> Result<Unit<Vector3<f64>>, MjcfError> {
    Unit::try_new(v, 1e-300).ok_or_else(|| e.error(format!("{key}: a zero vector has no direction")))
}

/// A rigid transform (rotation then translation): `x ↦ rot x + pos`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Rotation.
    pub rot: Rotation3<f64>,
    /// Translation.
    pub pos: Vector3<f64>,
}

impl Pose {
    /// The identity.
    pub fn identity() -> Pose {
        Pose { rot: Rotation3::identity(), pos: Vector3::zeros() }
    }

    /// The pose an element gives with `pos` and its orientation.
    pub fn of(e: &Element, compiler: &Compiler) -> Result<Pose, MjcfError> {
        let pos = e.fixed::<3>("pos")?.map_or_else(Vector3::zeros, Vector3::from);
        Ok(Pose { rot: compiler.orientation(e, "")?, pos })
    }

    /// `self ∘ other`: other's frame expressed where self's is.
    pub fn then(&self, other: &Pose) -> Pose {
        Pose { rot: self.rot * other.rot, pos: self.pos + self.rot * other.pos }
    }

    /// A point of this frame in the outer frame.
    pub fn point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.pos + self.rot * p
    }
}
