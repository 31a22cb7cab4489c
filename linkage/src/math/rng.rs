//! A deterministic generator for tests (not part of the API): the mathematics' own tests use it, and
//! `testing` hands it on to every other test.

/// A small deterministic generator (SplitMix64) so tests need no extra dependency.
pub struct TestRng(pub u64);

impl TestRng {
    /// Next uniform number in [-1, 1).
    pub fn signed(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// An index in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.signed() + 1.0) * 0.5 * n as f64) as usize % n
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        (self.signed() + 1.0) * 0.5 < p
    }

    /// One of [`ODD_NUMBERS`].
    pub fn odd(&mut self) -> f64 {
        ODD_NUMBERS[self.below(ODD_NUMBERS.len())]
    }
}

/// Numbers the random-input tests put where a sane one belongs: not finite, huge, tiny, zero, negative.
pub const ODD_NUMBERS: &[f64] = &[f64::NAN, f64::INFINITY, -f64::INFINITY, 1e300, -1e300, 1e-300, 0.0, -0.0, 1e6, -3.0];
