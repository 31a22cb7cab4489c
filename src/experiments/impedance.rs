//! Felt against rendered impedance: how far what the hand feels at the handle is from what the linkage in the
//! VE presents at the operational point, per frequency.
//!
//! **Rendered**: the VE's linkage driven through the user's coupling, `Z_r(f) = W(f) / v_op(f)`, with W the
//! wrench the coupling applied to the linkage at the OP and v_op the OP's velocity (from its positions).
//! **Felt**: the handle as the hand meets it, `Z_f(f) = F_h(f) / v_d(f)`, with F_h the hand's wrench on the
//! handle and v_d the handle's velocity, both in VE units (the device's own mass and the controllers
//! together). A transparent rendering has `Z_f = Z_r`: the hand pushes the handle as it would push the
//! linkage.
//!
//! Both are H1 estimates, `Z = Σ F V̄ / Σ |V|²` over Hann-windowed segments of [`SEGMENT_S`] overlapping by
//! half, per linear axis, at [`FREQUENCIES_HZ`] (the band a touring hand and a jab excite; the estimate needs
//! motion, so a frequency where the hand moved the handle less than [`MIN_VELOCITY_M_S`] RMS is skipped). The
//! error of a session is the median over axes and frequencies of `|Z_f − Z_r| / |Z_r|`. The first
//! [`SETTLE_S`] are left out (the join, the output's ramp-in).

use kinloop_harness::Recording;

/// Frequencies of the estimate (Hz); each a whole, even number of cycles per segment, so a Hann window (whose
/// spectrum is zero two bins away) keeps them apart.
pub const FREQUENCIES_HZ: [f64; 4] = [0.5, 1.0, 2.0, 4.0];
/// Segment length of the estimate (s).
pub const SEGMENT_S: f64 = 4.0;
/// Time left out at the start (s).
pub const SETTLE_S: f64 = 1.0;
/// Smallest RMS velocity component at a frequency for it to be estimated (m/s).
pub const MIN_VELOCITY_M_S: f64 = 1e-4;

/// One frequency's cross and auto spectra summed over segments.
#[derive(Clone, Copy, Debug, Default)]
struct Spectra {
    /// Σ F V̄ (real, imaginary).
    cross: (f64, f64),
    /// Σ |V|².
    auto: f64,
}

/// The impedance estimate `(re, im)` of force over velocity at each of [`FREQUENCIES_HZ`], sampled every
/// `dt` s, or `None` where the velocity's content is below [`MIN_VELOCITY_M_S`].
fn impedance(force: &[f64], velocity: &[f64], dt: f64) -> [Option<(f64, f64)>; FREQUENCIES_HZ.len()] {
    let n = (SEGMENT_S / dt).round() as usize;
    let mut spectra = [Spectra::default(); FREQUENCIES_HZ.len()];
    let len = force.len().min(velocity.len());
    if n < 8 || len < n {
        return [None; FREQUENCIES_HZ.len()];
    }
    let window: Vec<f64> = (0..n).map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / n as f64).cos()).collect();
    // Σ w² over a segment, to turn `auto` into a mean square.
    let window_power: f64 = window.iter().map(|w| w * w).sum();
    let (mut start, mut segments) = (0, 0);
    while start + n <= len {
        for (s, &f_hz) in spectra.iter_mut().zip(&FREQUENCIES_HZ) {
            let omega = std::f64::consts::TAU * f_hz * dt;
            let (mut fr, mut fi, mut vr, mut vi) = (0.0, 0.0, 0.0, 0.0);
            for i in 0..n {
                let (sin, cos) = (omega * i as f64).sin_cos();
                let w = window[i];
                fr += w * force[start + i] * cos;
                fi -= w * force[start + i] * sin;
                vr += w * velocity[start + i] * cos;
                vi -= w * velocity[start + i] * sin;
            }
            // F V̄ = (fr + i fi)(vr − i vi).
            s.cross.0 += fr * vr + fi * vi;
            s.cross.1 += fi * vr - fr * vi;
            s.auto += vr * vr + vi * vi;
        }
        start += n / 2;
        segments += 1;
    }
    spectra.map(|s| {
        // The velocity's mean square at this frequency: |V|² over the window's power, times 2 for the negative
        // frequency, per sample.
        let mean_square = 2.0 * s.auto / (segments as f64 * window_power);
        (mean_square.sqrt() >= MIN_VELOCITY_M_S && s.auto > 0.0).then(|| (s.cross.0 / s.auto, s.cross.1 / s.auto))
    })
}

/// One axis's impedance estimates `(re, im)` at [`FREQUENCIES_HZ`]; `None` where the motion was too small.
pub type AxisImpedance = [Option<(f64, f64)>; FREQUENCIES_HZ.len()];

/// The impedances of one session's user, per linear axis.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Impedances {
    /// At the handle: the hand's wrench over the handle's velocity (VE units).
    pub felt: Vec<AxisImpedance>,
    /// At the VE's OP: the coupling's wrench over the OP's velocity.
    pub rendered: Vec<AxisImpedance>,
}

/// The felt and rendered impedances of client `client` (user id `user_id` in the VE's samples); `None`
/// without samples enough.
pub fn estimate(rec: &Recording, client: usize, user_id: u32) -> Option<Impedances> {
    let samples = rec.clients.get(client)?;
    let samples: Vec<_> = samples.iter().filter(|s| s.t >= SETTLE_S).collect();
    let ve: Vec<_> = rec.ve.iter().filter(|v| v.t >= SETTLE_S).collect();
    if samples.len() < 3 || ve.len() < 3 {
        return None;
    }
    let dt_client = (samples[samples.len() - 1].t - samples[0].t) / (samples.len() - 1) as f64;
    let dt_ve = (ve[ve.len() - 1].t - ve[0].t) / (ve.len() - 1) as f64;
    let axes = samples[0].device.len();
    let mut impedances = Impedances::default();
    for axis in 0..axes {
        let felt_force: Vec<f64> = samples.iter().map(|s| s.hand.get(axis).copied().unwrap_or(0.0)).collect();
        let felt_velocity: Vec<f64> =
            samples.iter().map(|s| s.device_twist.get(axis).copied().unwrap_or(0.0)).collect();
        // The user's OP position and wrench at each VE tick (zero before it joined).
        let op =
            |v: &kinloop_harness::VeSample| v.users.iter().find(|u| u.0 == user_id).map(|u| (u.1[axis], u.2[axis]));
        let rows: Vec<(f64, f64)> = ve.iter().map(|v| op(v).unwrap_or((f64::NAN, 0.0))).collect();
        let rendered_force: Vec<f64> = rows.iter().map(|r| r.1).collect();
        // Central differences of the OP's position (one-sided at the ends).
        let rendered_velocity: Vec<f64> = (0..rows.len())
            .map(|i| {
                let (a, b) = (i.saturating_sub(1), (i + 1).min(rows.len() - 1));
                let v = (rows[b].0 - rows[a].0) / ((b - a) as f64 * dt_ve);
                if v.is_finite() {
                    v
                } else {
                    0.0
                }
            })
            .collect();
        impedances.felt.push(impedance(&felt_force, &felt_velocity, dt_client));
        impedances.rendered.push(impedance(&rendered_force, &rendered_velocity, dt_ve));
    }
    Some(impedances)
}

/// Median over axes and frequencies of `|Z − Z_ref| / |Z_ref|`, where both were estimated; `None` where
/// neither axis nor frequency had both.
pub fn relative_error(z: &[AxisImpedance], reference: &[AxisImpedance]) -> Option<f64> {
    let mut errors = Vec::new();
    for (axis, reference_axis) in z.iter().zip(reference) {
        for (z, r) in axis.iter().zip(reference_axis) {
            if let (Some(z), Some(r)) = (z, r) {
                let magnitude = r.0.hypot(r.1);
                if magnitude > 0.0 {
                    errors.push((z.0 - r.0).hypot(z.1 - r.1) / magnitude);
                }
            }
        }
    }
    if errors.is_empty() {
        return None;
    }
    errors.sort_by(f64::total_cmp);
    Some(errors[errors.len() / 2])
}

/// Median over linear axes and frequencies of the relative felt-vs-rendered impedance error of client
/// `client` (user id `user_id` in the VE's samples); `None` when no frequency had motion enough to estimate.
pub fn felt_vs_rendered_error(rec: &Recording, client: usize, user_id: u32) -> Option<f64> {
    let z = estimate(rec, client, user_id)?;
    relative_error(&z.felt, &z.rendered)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mass-damper driven by a sum of sines: the estimate recovers `Z = m (i ω) + b` at each frequency.
    #[test]
    fn the_estimate_recovers_a_mass_damper() {
        let (m, b, dt) = (0.3, 2.0, 1e-3);
        let n = 10_000;
        let mut velocity = Vec::with_capacity(n);
        let mut force = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 * dt;
            let (mut v, mut a) = (0.0, 0.0);
            for (k, &f_hz) in FREQUENCIES_HZ.iter().enumerate() {
                let w = std::f64::consts::TAU * f_hz;
                let phase = k as f64;
                v += 0.01 * (w * t + phase).sin();
                a += 0.01 * w * (w * t + phase).cos();
            }
            velocity.push(v);
            force.push(m * a + b * v);
        }
        let z = impedance(&force, &velocity, dt);
        for (estimate, &f_hz) in z.iter().zip(&FREQUENCIES_HZ) {
            let (re, im) = estimate.expect("excited");
            let w = std::f64::consts::TAU * f_hz;
            assert!((re - b).abs() < 0.02 * b, "{f_hz} Hz: re {re}");
            assert!((im - m * w).abs() < 0.02 * m * w, "{f_hz} Hz: im {im} vs {}", m * w);
        }
        // Without motion there is nothing to estimate.
        assert!(impedance(&force, &vec![0.0; n], dt).iter().all(Option::is_none));
    }

    /// The relative error is `|Z − Z_ref| / |Z_ref|` where both were estimated, its median over axes and
    /// frequencies: a reference scaled by `1 + 0.5 i` is off by 0.5 wherever it is, whatever its size.
    #[test]
    fn the_relative_error_is_the_median_where_both_were_estimated() {
        let reference: Vec<AxisImpedance> =
            vec![[Some((3.0, 4.0)), Some((-10.0, 2.0)), None, Some((0.5, 0.0))], [Some((1.0, 1.0)), None, None, None]];
        let scaled: Vec<AxisImpedance> =
            reference.iter().map(|axis| axis.map(|z| z.map(|(re, im)| (re - 0.5 * im, im + 0.5 * re)))).collect();
        let error = relative_error(&scaled, &reference).expect("estimated");
        assert!((error - 0.5).abs() < 1e-12, "{error}");
        assert_eq!(relative_error(&reference, &reference), Some(0.0));
        // Where one side has no estimate the frequency is left out; with none in common there is no error.
        // Doubled at three of the four estimated frequencies (error 1 there, 0 at the fourth); the added
        // estimates at frequencies the reference lacks do not count, so the median is 1.
        let mut doubled = reference.clone();
        for (axis, i) in [(0, 0), (0, 1), (1, 0)] {
            doubled[axis][i] = doubled[axis][i].map(|(re, im)| (2.0 * re, 2.0 * im));
        }
        doubled[1][1] = Some((100.0, 0.0));
        doubled[1][2] = Some((100.0, 0.0));
        assert_eq!(relative_error(&doubled, &reference), Some(1.0));
        let elsewhere: Vec<AxisImpedance> = vec![[None, None, Some((1.0, 0.0)), None]; 2];
        assert_eq!(relative_error(&elsewhere, &reference), None);
    }
}
