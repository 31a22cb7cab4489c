//! Unit systems a scene can be written in, and the rewriting of an SI scene into one of them: lengths in
//! m, cm or mm, masses in kg or g, time always in seconds. The physics is unit-invariant; what a rewritten
//! scene tests is whether the code's defaults are.

use std::fmt;

use kinloop_linkage::model::scene::Numbers;
use kinloop_linkage::model::scene::Scene;
use serde::{Deserialize, Serialize};

/// The unit of length a scene is written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    /// Metre.
    M,
    /// Centimetre.
    Cm,
    /// Millimetre.
    Mm,
}

/// The unit of mass a scene is written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MassUnit {
    /// Kilogram.
    Kg,
    /// Gram.
    G,
}

/// A unit system: one unit of length and one of mass (seconds for time).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct UnitSystem {
    /// Unit of length.
    pub length: LengthUnit,
    /// Unit of mass.
    pub mass: MassUnit,
}

impl UnitSystem {
    /// SI: metres and kilograms.
    pub const SI: UnitSystem = UnitSystem { length: LengthUnit::M, mass: MassUnit::Kg };

    /// Every unit system the generator writes in.
    pub const ALL: [UnitSystem; 6] = [
        UnitSystem { length: LengthUnit::M, mass: MassUnit::Kg },
        UnitSystem { length: LengthUnit::M, mass: MassUnit::G },
        UnitSystem { length: LengthUnit::Cm, mass: MassUnit::Kg },
        UnitSystem { length: LengthUnit::Cm, mass: MassUnit::G },
        UnitSystem { length: LengthUnit::Mm, mass: MassUnit::Kg },
        UnitSystem { length: LengthUnit::Mm, mass: MassUnit::G },
    ];

    /// How many of this system's length units make a metre.
    pub fn per_metre(self) -> f64 {
        match self.length {
            LengthUnit::M => 1.0,
            LengthUnit::Cm => 100.0,
            LengthUnit::Mm => 1000.0,
        }
    }

    /// How many of this system's mass units make a kilogram.
    pub fn per_kilogram(self) -> f64 {
        match self.mass {
            MassUnit::Kg => 1.0,
            MassUnit::G => 1000.0,
        }
    }

    /// `scene` (written in SI) rewritten in this unit system: lengths (and gravity, the length scale,
    /// prismatic positions) times [`Self::per_metre`], inertias times its square, and every mass-bearing
    /// quantity (masses, inertias, stiffnesses, dampings, gains, effort limits, contact parameters) times
    /// [`Self::per_kilogram`].
    pub fn rewrite(self, scene: &Scene) -> Scene {
        let mut s = scene.scaled_lengths(self.per_metre());
        scale_masses(&mut s, self.per_kilogram());
        s
    }
}

impl fmt::Display for UnitSystem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let length = match self.length {
            LengthUnit::M => "m",
            LengthUnit::Cm => "cm",
            LengthUnit::Mm => "mm",
        };
        let mass = match self.mass {
            MassUnit::Kg => "kg",
            MassUnit::G => "g",
        };
        write!(f, "{length}+{mass}")
    }
}

/// Multiplies every quantity whose unit holds the kilogram once by `factor`; time and length keep theirs,
/// so forces, torques, stiffnesses and dampings all scale as the mass does.
pub fn scale_masses(s: &mut Scene, factor: f64) {
    s.contact.stiffness *= factor;
    s.contact.damping *= factor;
    for b in &mut s.bodies {
        b.mass *= factor;
        b.inertia = match &b.inertia {
            Numbers::One(x) => Numbers::One(x * factor),
            Numbers::Many(v) => Numbers::Many(v.iter().map(|x| x * factor).collect()),
        };
    }
    for j in &mut s.joints {
        if let Some(spring) = &mut j.spring {
            spring.stiffness *= factor;
        }
        j.damping *= factor;
        if let Some(a) = &mut j.actuator {
            a.kp *= factor;
            a.kd *= factor;
            a.max_effort = a.max_effort.map(|e| e * factor);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::model::builtin;

    /// The testbed in mm+g: link 1 is 45 mm long, weighs 1000 g and has 0.0021 kg m² = 0.0021 × 1e3 g × 1e6 mm² = 2.1e6 g mm².
    #[test]
    fn the_testbed_in_millimetres_and_grams_has_the_hand_computed_numbers() {
        let si = builtin::scene("paper-testbed").expect("built in").expect("parses");
        let mm_g = UnitSystem { length: LengthUnit::Mm, mass: MassUnit::G }.rewrite(&si);
        assert_eq!(mm_g.bodies[0].mass, 1000.0);
        assert!((mm_g.bodies[0].com[0] - 22.5).abs() < 1e-12);
        assert!((mm_g.bodies[0].inertia.as_slice()[0] - 2.1e6).abs() < 1e-6);
        assert!((mm_g.joints[1].origin[0] - 45.0).abs() < 1e-12);
        assert_eq!(mm_g.joints[1].q0, si.joints[1].q0, "angles keep their unit");
        assert_eq!(UnitSystem::SI.rewrite(&si), si);
        assert_eq!(mm_g.contact.stiffness, si.contact.stiffness * 1000.0);
    }
}
