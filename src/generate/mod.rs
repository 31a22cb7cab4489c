//! The linkage generator: seeded, reproducible scenes of many classes, written in random unit systems,
//! producing the same [`Scene`] the TOML reader does (and writing TOML it reads back).
//!
//! A seed draws a class (or takes the one asked for), a size (the longest link, log-uniform over 1 cm to
//! 1 m) and a mass per link (log-uniform over 5 g to 5 kg), lays the linkage out in SI with its loops
//! closed at q0 (planar classes by solving the loop at a drawn input, see [`planar`]; spatial ones from the
//! shipped templates at the drawn size and mass), adds gravity in a random direction, springs, dampers,
//! actuators and an obstacle at random, an operational point on every link, and rewrites the whole in a
//! random unit system ([`units`]).

pub mod layout;
pub mod planar;
pub mod units;

use std::fmt;
use std::str::FromStr;

use kinloop_linkage::math::rng::TestRng;
use kinloop_linkage::model::scene::{ActuatorSpec, GeometrySpec, JointKindSpec, ObstacleSpec, OpSpec, SpringSpec};
use kinloop_linkage::{math::space::SceneKind, model::builtin, model::scene::Scene};
use serde::{Deserialize, Serialize};

use planar::{uniform, SixBar};
use units::UnitSystem;

/// The classes of linkage the generator draws from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Class {
    /// Grashof four-bar, shortest link the crank.
    CrankRocker,
    /// Grashof four-bar, shortest link the ground.
    DoubleCrank,
    /// Grashof four-bar, shortest link the coupler.
    DoubleRocker,
    /// Non-Grashof four-bar.
    TripleRocker,
    /// Four-bar with s + l = p + q (its branches meet).
    ChangePoint,
    /// Parallelogram four-bar (a change-point linkage).
    Parallelogram,
    /// Slider-crank whose slider line misses the crank pivot.
    OffsetSliderCrank,
    /// Slider-crank whose slider line is inclined and offset.
    InclinedSliderCrank,
    /// Planar five-bar (two degrees of freedom).
    FiveBar,
    /// Watt II six-bar.
    WattSixBar,
    /// Stephenson III six-bar.
    StephensonSixBar,
    /// Spatial RSSR four-bar.
    Rssr,
    /// Spatial Bennett linkage.
    Bennett,
    /// Spherical four-bar.
    SphericalFourBar,
}

impl Class {
    /// Every class, in the order seeds cycle through them.
    pub const ALL: [Class; 14] = [
        Class::CrankRocker,
        Class::DoubleCrank,
        Class::DoubleRocker,
        Class::TripleRocker,
        Class::ChangePoint,
        Class::Parallelogram,
        Class::OffsetSliderCrank,
        Class::InclinedSliderCrank,
        Class::FiveBar,
        Class::WattSixBar,
        Class::StephensonSixBar,
        Class::Rssr,
        Class::Bennett,
        Class::SphericalFourBar,
    ];

    /// The name used on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Class::CrankRocker => "crank-rocker",
            Class::DoubleCrank => "double-crank",
            Class::DoubleRocker => "double-rocker",
            Class::TripleRocker => "triple-rocker",
            Class::ChangePoint => "change-point",
            Class::Parallelogram => "parallelogram",
            Class::OffsetSliderCrank => "offset-slider-crank",
            Class::InclinedSliderCrank => "inclined-slider-crank",
            Class::FiveBar => "five-bar",
            Class::WattSixBar => "watt-six-bar",
            Class::StephensonSixBar => "stephenson-six-bar",
            Class::Rssr => "rssr",
            Class::Bennett => "bennett",
            Class::SphericalFourBar => "spherical-four-bar",
        }
    }
}

impl fmt::Display for Class {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A `--kind` that names no class.
#[derive(Debug, thiserror::Error)]
#[error("no linkage class {given:?} (classes: {})", Class::ALL.map(Class::name).join(", "))]
pub struct UnknownClass {
    /// What was given.
    pub given: String,
}

impl FromStr for Class {
    type Err = UnknownClass;
    fn from_str(s: &str) -> Result<Class, UnknownClass> {
        Class::ALL.into_iter().find(|c| c.name() == s).ok_or_else(|| UnknownClass { given: s.to_string() })
    }
}

/// What a seed produced, and what it covers.
#[derive(Clone, Debug)]
pub struct Generated {
    /// The seed.
    pub seed: u64,
    /// The class drawn.
    pub class: Class,
    /// The unit system the scene is written in.
    pub units: UnitSystem,
    /// Whether the configuration at q0 lies near a dead centre or singular configuration.
    pub near_singular: bool,
    /// Which extras were added (`spring`, `damper`, `actuator`, `obstacle`, `gravity`).
    pub extras: Vec<&'static str>,
    /// The scene, in [`Self::units`].
    pub scene: Scene,
}

/// The linkage of `seed`, of class `class` if given (else drawn from the seed).
pub fn generate(seed: u64, class: Option<Class>) -> Generated {
    // Decorrelates neighbouring seeds (SplitMix64 would otherwise start from neighbouring states).
    let mut rng = TestRng(seed.wrapping_mul(0xD1B5_4A32_D192_ED03) ^ 0x5851_F42D_4C95_7F2D);
    let class = class.unwrap_or_else(|| Class::ALL[rng.below(Class::ALL.len())]);
    let near_singular = rng.chance(0.25);
    let size = 10f64.powf(uniform(&mut rng, -2.0, 0.0));
    let mass = |rng: &mut TestRng| 10f64.powf(uniform(rng, -2.3, 0.7));
    let masses: [f64; 5] = std::array::from_fn(|_| mass(&mut rng));
    let (mut scene, near_singular) = linkage(&mut rng, class, size, masses, near_singular);
    scene.name = format!("generated-{seed}-{class}");
    let extras = decorate(&mut rng, &mut scene, size);
    let units = UnitSystem::ALL[rng.below(UnitSystem::ALL.len())];
    Generated { seed, class, units, near_singular, extras, scene: units.rewrite(&scene) }
}

/// The bare linkage of `class` in SI, and whether it lies near a singular configuration. A near-singular
/// draw that finds no configuration falls back to a regular one.
fn linkage(rng: &mut TestRng, class: Class, size: f64, m: [f64; 5], near: bool) -> (Scene, bool) {
    let laid = |rng: &mut TestRng, near: bool| -> Option<layout::Layout> {
        let u = |rng: &mut TestRng, lo: f64, hi: f64| size * uniform(rng, lo, hi);
        let three = [m[0], m[1], m[2]];
        match class {
            Class::CrankRocker | Class::DoubleCrank | Class::DoubleRocker => {
                // s < p, q < l = size, s + l < p + q (Grashof).
                let s = u(rng, 0.25, 0.45);
                let p = u(rng, 0.6, 0.95);
                let q = uniform(rng, (s + size - p + 0.05 * size).max(p), 0.98 * size);
                let lengths = match class {
                    Class::CrankRocker => [p, s, size, q],
                    Class::DoubleCrank => [s, p, size, q],
                    _ => [size, p, s, q],
                };
                planar::four_bar(rng, lengths, three, near, false)
            }
            Class::TripleRocker => {
                let (s, p, q) = (u(rng, 0.5, 0.55), u(rng, 0.56, 0.7), u(rng, 0.56, 0.7));
                planar::four_bar(rng, [size, s, p, q], three, near, false)
            }
            Class::ChangePoint => {
                let s = u(rng, 0.3, 0.5);
                let p = u(rng, 0.55, 0.95);
                planar::four_bar(rng, [size, s, p, s + size - p], three, near, false)
            }
            Class::Parallelogram => {
                let a = u(rng, 0.3, 0.8);
                planar::four_bar(rng, [size, a, size, a], three, near, true)
            }
            Class::OffsetSliderCrank | Class::InclinedSliderCrank => {
                let a = u(rng, 0.2, 0.35);
                let b = size;
                let offset = (b - a) * uniform(rng, -0.5, 0.5);
                let incline = if class == Class::InclinedSliderCrank { uniform(rng, -1.2, 1.2) } else { 0.0 };
                planar::slider_crank(rng, a, b, offset, incline, three, near)
            }
            Class::FiveBar => {
                let lengths = [u(rng, 0.3, 0.5), u(rng, 0.3, 0.5), u(rng, 0.7, 1.0), u(rng, 0.7, 1.0)];
                let ground = u(rng, 0.2, 0.6);
                planar::five_bar(rng, ground, lengths, [m[0], m[1], m[2], m[3]], near)
            }
            Class::WattSixBar => Some(planar::six_bar(rng, SixBar::WattII, size, m)),
            Class::StephensonSixBar => Some(planar::six_bar(rng, SixBar::StephensonIII, size, m)),
            Class::Rssr | Class::Bennett | Class::SphericalFourBar => None,
        }
    };
    let template = match class {
        Class::Rssr => Some("rssr-four-bar"),
        Class::Bennett => Some("bennett-linkage"),
        Class::SphericalFourBar => Some("spherical-four-bar"),
        _ => None,
    };
    if let Some(name) = template {
        return (spatial_template(name, size, m[0]), false);
    }
    let six_bar = matches!(class, Class::WattSixBar | Class::StephensonSixBar);
    let (layout, near) = match laid(rng, near && !six_bar) {
        Some(layout) => (layout, near && !six_bar),
        None => (laid(rng, false).unwrap_or_else(|| planar::six_bar(rng, SixBar::WattII, size, m)), false),
    };
    let mut scene = layout.scene(class.name());
    for (i, b) in layout.bodies.iter().enumerate() {
        // On every link: at its far end, its middle or a point off its axis.
        let far = b.toward;
        let at = match rng.below(3) {
            0 => far,
            1 => [(b.pivot[0] + far[0]) * 0.5, (b.pivot[1] + far[1]) * 0.5],
            _ => {
                let (dx, dy) = (far[0] - b.pivot[0], far[1] - b.pivot[1]);
                [b.pivot[0] + 0.5 * dx - 0.2 * dy, b.pivot[1] + 0.5 * dy + 0.2 * dx]
            }
        };
        scene.ops.push(OpSpec {
            name: format!("op-{}", b.name),
            body: b.name.clone(),
            point: layout.body_point(i, at),
        });
    }
    (scene, near)
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// How far a body's geometry reaches from its origin.
fn body_reach(b: &kinloop_linkage::model::scene::BodySpec) -> f64 {
    b.geometry
        .iter()
        .map(|g| match g {
            GeometrySpec::Capsule { from, to, radius } => norm(from).max(norm(to)) + radius,
            GeometrySpec::Ball { center, radius } => norm(center) + radius,
        })
        .fold(0.0, f64::max)
}

/// A shipped spatial scene with its lengths scaled to `size` (against its longest joint offset or body) and its
/// masses to `mass` (against its heaviest body), with an operational point on every body.
fn spatial_template(name: &str, size: f64, mass: f64) -> Scene {
    let shipped = builtin::scene(name).and_then(Result::ok).unwrap_or_else(|| {
        // The built-in scenes are part of the binary; their absence is a build defect.
        panic!("the built-in scene {name} is missing")
    });
    // A spherical linkage's joints all sit at the origin: its size is its bodies' reach.
    let longest =
        shipped.joints.iter().map(|j| norm(&j.origin)).chain(shipped.bodies.iter().map(body_reach)).fold(0.0, f64::max);
    let heaviest = shipped.bodies.iter().map(|b| b.mass).fold(f64::MIN_POSITIVE, f64::max);
    let mut scene = shipped.scaled_lengths(size / longest);
    units::scale_masses(&mut scene, mass / heaviest);
    scene.ops = scene
        .bodies
        .iter()
        .map(|b| OpSpec { name: format!("op-{}", b.name), body: b.name.clone(), point: b.com.clone() })
        .collect();
    scene
}

/// Adds gravity (in a random direction, or none), springs, dampers, an actuator and an obstacle at random;
/// their magnitudes follow the linkage's own (a spring's torque at a radian is of the order of the
/// heaviest link's weight times the size). Returns which extras were added.
fn decorate(rng: &mut TestRng, scene: &mut Scene, size: f64) -> Vec<&'static str> {
    let mut extras = Vec::new();
    let heaviest = scene.bodies.iter().map(|b| b.mass).fold(0.0, f64::max);
    if rng.chance(0.8) {
        let g = 9.81;
        scene.gravity = match scene.kind {
            SceneKind::Planar => {
                let angle = uniform(rng, -std::f64::consts::PI, std::f64::consts::PI);
                vec![g * angle.cos(), g * angle.sin()]
            }
            SceneKind::Spatial => {
                let (az, el) = (uniform(rng, -std::f64::consts::PI, std::f64::consts::PI), uniform(rng, -1.5, 1.5));
                vec![g * el.cos() * az.cos(), g * el.cos() * az.sin(), g * el.sin()]
            }
        };
        extras.push("gravity");
    } else {
        scene.gravity = vec![0.0; if scene.kind == SceneKind::Planar { 2 } else { 3 }];
    }
    let load = heaviest * 9.81 * size;
    let count = scene.joints.len();
    let revolute = |scene: &Scene, i: usize| scene.joints[i].kind == JointKindSpec::Revolute;
    if rng.chance(0.35) {
        let i = rng.below(count);
        let rest = scene.joints[i].q0 + uniform(rng, -0.5, 0.5) * if revolute(scene, i) { 1.0 } else { size };
        let per = if revolute(scene, i) { 1.0 } else { 1.0 / (size * size) };
        scene.joints[i].spring = Some(SpringSpec { stiffness: load * per * uniform(rng, 0.2, 3.0), rest });
        extras.push("spring");
    }
    if rng.chance(0.35) {
        let i = rng.below(count);
        let per = if revolute(scene, i) { size * size } else { 1.0 };
        scene.joints[i].damping = heaviest * per * uniform(rng, 0.5, 5.0);
        extras.push("damper");
    }
    if rng.chance(0.1) {
        let i = rng.below(count);
        let per = if revolute(scene, i) { 1.0 } else { 1.0 / (size * size) };
        let kp = load * per * uniform(rng, 1.0, 5.0);
        let target = scene.joints[i].q0;
        let effort = if revolute(scene, i) { 3.0 * load } else { 3.0 * load / size };
        scene.joints[i].actuator = Some(ActuatorSpec { kp, kd: 0.1 * kp, target, max_effort: Some(effort) });
        extras.push("actuator");
    }
    if scene.kind == SceneKind::Planar && rng.chance(0.25) {
        // A floor below every joint site and op, clear of the linkage by a tenth of its size.
        let angle = uniform(rng, -std::f64::consts::PI, std::f64::consts::PI);
        let normal = vec![angle.cos(), angle.sin()];
        let lowest = -farthest_reach(scene);
        scene.obstacles.push(ObstacleSpec::HalfPlane { name: "floor".into(), normal, offset: lowest - 0.2 * size });
        extras.push("obstacle");
    }
    extras
}

/// An upper bound of how far from the origin any point of the linkage lies at q0 (the joint offsets and
/// prismatic positions summed along any path, plus the longest reach of a body's geometry), so that a
/// half-plane at that distance along any normal is clear of it.
fn farthest_reach(scene: &Scene) -> f64 {
    let offsets: f64 = scene.joints.iter().map(|j| norm(&j.origin)).sum();
    let geometry = scene.bodies.iter().map(body_reach).fold(0.0, f64::max);
    let prismatic: f64 = scene.joints.iter().filter(|j| j.kind == JointKindSpec::Prismatic).map(|j| j.q0.abs()).sum();
    offsets + geometry + prismatic
}
