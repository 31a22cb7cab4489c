//! Small fixed-size vectors and matrices: the arithmetic the generic algorithms need.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Index, IndexMut, Mul, Neg, Sub, SubAssign};

use nalgebra::{Matrix3, Matrix6, Vector2, Vector3, Vector6};

/// Small fixed-size vectors: the arithmetic the generic algorithms need.
pub trait VecOps:
    Copy
    + Debug
    + PartialEq
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Neg<Output = Self>
    + Mul<f64, Output = Self>
    + AddAssign
    + SubAssign
{
    /// Number of components.
    const LEN: usize;
    /// The zero vector.
    fn zero() -> Self;
    /// Euclidean dot product.
    fn dot(&self, other: &Self) -> f64;
    /// Components, in order.
    fn as_slice(&self) -> &[f64];
    /// Mutable components, in order.
    fn as_mut_slice(&mut self) -> &mut [f64];
    /// Builds from exactly `LEN` components (callers guarantee the length).
    #[inline]
    fn from_slice(v: &[f64]) -> Self {
        let mut out = Self::zero();
        out.as_mut_slice().copy_from_slice(&v[..Self::LEN]);
        out
    }
    /// Euclidean norm.
    #[inline]
    fn norm(&self) -> f64 {
        self.dot(self).sqrt()
    }
    /// True when every component is finite.
    #[inline]
    fn is_finite(&self) -> bool {
        self.as_slice().iter().all(|x| f64::is_finite(*x))
    }
}

impl VecOps for f64 {
    const LEN: usize = 1;
    #[inline]
    fn zero() -> Self {
        0.0
    }
    #[inline]
    fn dot(&self, other: &Self) -> f64 {
        self * other
    }
    #[inline]
    fn as_slice(&self) -> &[f64] {
        std::slice::from_ref(self)
    }
    #[inline]
    fn as_mut_slice(&mut self) -> &mut [f64] {
        std::slice::from_mut(self)
    }
}

macro_rules! impl_vec_ops {
    ($t:ty, $n:expr) => {
        impl VecOps for $t {
            const LEN: usize = $n;
            #[inline]
            fn zero() -> Self {
                <$t>::zeros()
            }
            #[inline]
            fn dot(&self, other: &Self) -> f64 {
                nalgebra::Matrix::dot(self, other)
            }
            #[inline]
            fn as_slice(&self) -> &[f64] {
                nalgebra::Matrix::as_slice(self)
            }
            #[inline]
            fn as_mut_slice(&mut self) -> &mut [f64] {
                nalgebra::Matrix::as_mut_slice(self)
            }
        }
    };
}
impl_vec_ops!(Vector2<f64>, 2);
impl_vec_ops!(Vector3<f64>, 3);
impl_vec_ops!(Vector6<f64>, 6);

/// Small fixed-size square matrices used for spatial inertias and operational-space inertias.
pub trait MatOps:
    Copy
    + Debug
    + PartialEq
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + AddAssign
    + Mul<f64, Output = Self>
    + Index<(usize, usize), Output = f64>
    + IndexMut<(usize, usize)>
{
    /// Number of rows (= columns).
    const DIM: usize;
    /// The zero matrix.
    fn zero() -> Self;
    /// The identity matrix.
    fn identity() -> Self;
    /// Components, column-major.
    fn as_slice(&self) -> &[f64];
    /// Mutable components, column-major.
    fn as_mut_slice(&mut self) -> &mut [f64];
    /// Transpose.
    fn transpose(&self) -> Self;
    /// True when every component is finite.
    #[inline]
    fn is_finite(&self) -> bool {
        self.as_slice().iter().all(|x| f64::is_finite(*x))
    }
}

macro_rules! impl_mat_ops {
    ($t:ty, $n:expr) => {
        impl MatOps for $t {
            const DIM: usize = $n;
            #[inline]
            fn zero() -> Self {
                <$t>::zeros()
            }
            #[inline]
            fn identity() -> Self {
                <$t>::identity()
            }
            #[inline]
            fn as_slice(&self) -> &[f64] {
                nalgebra::Matrix::as_slice(self)
            }
            #[inline]
            fn as_mut_slice(&mut self) -> &mut [f64] {
                nalgebra::Matrix::as_mut_slice(self)
            }
            #[inline]
            fn transpose(&self) -> Self {
                nalgebra::Matrix::transpose(self)
            }
        }
    };
}
impl_mat_ops!(Matrix3<f64>, 3);
impl_mat_ops!(Matrix6<f64>, 6);
