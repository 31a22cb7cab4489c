//! Smooth on/off of a coupling: a raised-cosine weight `w = ½ (1 − cos π φ)` of a phase φ ∈ [0, 1] that
//! moves toward 1 (fading in) or 0 (fading out) at `1 / fade_time`. The weight is continuous whatever the
//! order of joins, silences and leaves (a reversal mid-fade continues from the current phase), and changes by
//! at most `π/2 · dt / fade_time` per tick: a user appearing or vanishing never makes a wrench step.

use std::f64::consts::PI;

/// Phase and direction of one coupling's fade.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Fade {
    phase: f64,
}

impl Fade {
    /// Fully off.
    pub fn off() -> Self {
        Fade { phase: 0.0 }
    }

    /// Moves the phase by `dt / fade_time` toward fully on (`on`) or fully off.
    pub fn advance(&mut self, on: bool, dt: f64, fade_time: f64) {
        let delta = dt / fade_time;
        self.phase = if on { (self.phase + delta).min(1.0) } else { (self.phase - delta).max(0.0) };
    }

    /// The weight in [0, 1]. Fully on or off (nearly every tick of a session) costs no cosine: that library
    /// call was a sixtieth of a 16-user tick.
    pub fn weight(&self) -> f64 {
        if self.phase >= 1.0 {
            1.0
        } else if self.phase <= 0.0 {
            0.0
        } else {
            0.5 * (1.0 - (PI * self.phase).cos())
        }
    }

    /// True when fully off.
    pub fn is_off(&self) -> bool {
        self.phase <= 0.0
    }

    /// Largest change of the weight in one advance of `dt`.
    pub fn max_step(dt: f64, fade_time: f64) -> f64 {
        0.5 * PI * dt / fade_time
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weight_ramps_smoothly_and_reverses_without_a_jump() {
        let (dt, fade) = (1e-3, 0.2);
        let mut f = Fade::off();
        let mut last = f.weight();
        assert_eq!(last, 0.0);
        for tick in 0..400 {
            // In for 120 ticks, then out, mid-fade.
            f.advance(tick < 120, dt, fade);
            let w = f.weight();
            assert!((w - last).abs() <= Fade::max_step(dt, fade) + 1e-15, "tick {tick}: {last} -> {w}");
            last = w;
        }
        assert!(f.is_off());
        for _ in 0..250 {
            f.advance(true, dt, fade);
        }
        assert_eq!(f.weight(), 1.0);
    }

    /// The shortcuts at the ends give what the raised cosine gives there, so the weight stays continuous.
    #[test]
    fn the_ends_are_the_raised_cosines_values() {
        let cosine = |phase: f64| 0.5 * (1.0 - (PI * phase).cos());
        for (phase, end) in [(1.0, 1.0), (0.0, 0.0)] {
            assert_eq!(Fade { phase }.weight(), end);
            assert!((cosine(phase) - end).abs() <= f64::EPSILON);
            let inside = if end == 1.0 { 1.0 - 1e-9 } else { 1e-9 };
            assert!((Fade { phase: inside }.weight() - end).abs() <= 1e-15);
        }
    }
}
