//! Four-lane `f64` vectors for the dense kernels of `ltl` and `dense`, and the scalar fused multiply-add
//! ([`mul_add`]) that they and every other kernel use.
//!
//! Why not plain loops: LLVM's loop vectorizer turns a loop into a wide main loop (16 lanes here) plus a
//! scalar epilogue, and the rows our kernels sweep are mostly shorter than that (a chain of 50 bodies
//! updates rows `0..k` for every k), so most of the work ran one lane at a time. Written with [`F64x4`],
//! every group of four rows is one vector operation whatever the length.
//!
//! On x86-64 with AVX and FMA (the workspace builds for x86-64-v3) this is `__m256d`; elsewhere a plain
//! array with the same operations, which LLVM vectorizes on its own where it can.

// SAFETY (every `unsafe` below, besides the loads and stores which say why): the intrinsics need AVX and
// FMA, which this module is compiled only with (the `cfg`); Rust still asks for `unsafe` when the caller
// is not itself marked `#[target_feature]`.
#[cfg(all(target_arch = "x86_64", target_feature = "avx", target_feature = "fma"))]
mod imp {
    use std::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_castpd256_pd128, _mm256_extractf128_pd, _mm256_fmadd_pd, _mm256_fnmadd_pd,
        _mm256_loadu_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd, _mm_add_pd, _mm_add_sd, _mm_cvtsd_f64,
        _mm_unpackhi_pd,
    };

    /// Four `f64` lanes.
    #[derive(Clone, Copy, Debug)]
    pub struct F64x4(__m256d);

    impl F64x4 {
        /// The first four entries of `s` (panics if shorter).
        #[inline(always)]
        pub fn load(s: &[f64]) -> Self {
            let s = &s[..4];
            // SAFETY: `s` has four readable f64; the load has no alignment requirement.
            F64x4(unsafe { _mm256_loadu_pd(s.as_ptr()) })
        }
        /// Writes the lanes to the first four entries of `s` (panics if shorter).
        #[inline(always)]
        pub fn store(self, s: &mut [f64]) {
            let s = &mut s[..4];
            // SAFETY: `s` has four writable f64; the store has no alignment requirement.
            unsafe { _mm256_storeu_pd(s.as_mut_ptr(), self.0) }
        }
        /// `x` in every lane.
        #[inline(always)]
        pub fn splat(x: f64) -> Self {
            F64x4(unsafe { _mm256_set1_pd(x) })
        }
        /// Zero in every lane.
        #[inline(always)]
        pub fn zero() -> Self {
            F64x4(unsafe { _mm256_setzero_pd() })
        }
        /// `self + a b`, fused.
        #[inline(always)]
        pub fn add_mul(self, a: Self, b: Self) -> Self {
            F64x4(unsafe { _mm256_fmadd_pd(a.0, b.0, self.0) })
        }
        /// `self - a b`, fused.
        #[inline(always)]
        pub fn sub_mul(self, a: Self, b: Self) -> Self {
            F64x4(unsafe { _mm256_fnmadd_pd(a.0, b.0, self.0) })
        }
        /// Lane-wise sum.
        #[inline(always)]
        pub fn add(self, b: Self) -> Self {
            F64x4(unsafe { _mm256_add_pd(self.0, b.0) })
        }
        /// `(l0 + l2) + (l1 + l3)`.
        #[inline(always)]
        pub fn sum(self) -> f64 {
            unsafe {
                let pair = _mm_add_pd(_mm256_castpd256_pd128(self.0), _mm256_extractf128_pd::<1>(self.0));
                _mm_cvtsd_f64(_mm_add_sd(pair, _mm_unpackhi_pd(pair, pair)))
            }
        }
    }
}

#[cfg(not(all(target_arch = "x86_64", target_feature = "avx", target_feature = "fma")))]
mod imp {
    use super::mul_add;

    /// Four `f64` lanes.
    #[derive(Clone, Copy, Debug)]
    pub struct F64x4([f64; 4]);

    impl F64x4 {
        /// The first four entries of `s` (panics if shorter).
        #[inline(always)]
        pub fn load(s: &[f64]) -> Self {
            F64x4(s[..4].try_into().expect("four entries"))
        }
        /// Writes the lanes to the first four entries of `s` (panics if shorter).
        #[inline(always)]
        pub fn store(self, s: &mut [f64]) {
            s[..4].copy_from_slice(&self.0);
        }
        /// `x` in every lane.
        #[inline(always)]
        pub fn splat(x: f64) -> Self {
            F64x4([x; 4])
        }
        /// Zero in every lane.
        #[inline(always)]
        pub fn zero() -> Self {
            F64x4([0.0; 4])
        }
        /// `self + a b`, fused where the target has FMA.
        #[inline(always)]
        pub fn add_mul(self, a: Self, b: Self) -> Self {
            F64x4(std::array::from_fn(|l| mul_add(a.0[l], b.0[l], self.0[l])))
        }
        /// `self - a b`, fused where the target has FMA.
        #[inline(always)]
        pub fn sub_mul(self, a: Self, b: Self) -> Self {
            F64x4(std::array::from_fn(|l| mul_add(-a.0[l], b.0[l], self.0[l])))
        }
        /// Lane-wise sum.
        #[inline(always)]
        pub fn add(self, b: Self) -> Self {
            F64x4(std::array::from_fn(|l| self.0[l] + b.0[l]))
        }
        /// `(l0 + l2) + (l1 + l3)`.
        #[inline(always)]
        pub fn sum(self) -> f64 {
            (self.0[0] + self.0[2]) + (self.0[1] + self.0[3])
        }
    }
}

pub use imp::F64x4;

/// `a * b + c`: one fused instruction with one rounding where the target has FMA (x86-64-v3, as this
/// workspace builds, and every aarch64). Without FMA hardware `f64::mul_add` becomes a libm call that is
/// far slower than the rounding it saves, so it falls back to the unfused form. Rust never contracts
/// `a * b + c` by itself, hence this helper in every kernel.
#[inline(always)]
pub fn mul_add(a: f64, b: f64, c: f64) -> f64 {
    #[cfg(target_feature = "fma")]
    {
        a.mul_add(b, c)
    }
    #[cfg(not(target_feature = "fma"))]
    {
        a * b + c
    }
}

#[cfg(test)]
mod tests {
    use super::F64x4;

    #[test]
    fn lanes_do_what_they_say() {
        let a = F64x4::load(&[1.0, 2.0, 3.0, 4.0, 99.0]);
        let b = F64x4::splat(0.5);
        let mut out = [0.0; 4];
        F64x4::zero().add_mul(a, b).add(F64x4::splat(1.0)).store(&mut out);
        assert_eq!(out, [1.5, 2.0, 2.5, 3.0]);
        F64x4::splat(10.0).sub_mul(a, b).store(&mut out);
        assert_eq!(out, [9.5, 9.0, 8.5, 8.0]);
        assert_eq!(a.sum(), 10.0);
    }
}
