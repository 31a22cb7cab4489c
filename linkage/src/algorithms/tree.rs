//! What the recursive algorithms (kinematics, D, B, G, the articulated factor) share about walking the
//! tree: a parent handed on in registers, and the backward pass that turns per-body terms into subtree sums.

use crate::math::space::Space;
use crate::model::{Model, NO_PARENT};

/// True when joint i's parent is joint i - 1 (every link of a chain; the first child of a branch). The
/// recursions hand such a parent's or child's values on in registers: read back from memory just after
/// being stored, they would put a store-to-load wait on the recursion's path (on the testbed, a stall at
/// every joint; see the README's Benchmarks).
#[inline(always)]
pub(crate) fn follows_parent(parent: usize, i: usize) -> bool {
    parent.wrapping_add(1) == i && i > 0
}

/// Turns per-body `parts` into subtree sums in place, from the leaves: `parts[i]` becomes the sum over
/// body i and every body it carries (the composite inertias of D, the spatial forces the joints of B and G
/// transmit). Joint i + 1 is the last of i's children visited, so handing its sum on in a register and
/// adding it last gives the same sums in the same order as accumulating in memory. `visit(i, sum)` sees each
/// sum as it is made (using it there, rather than in a second pass, keeps the work beside the recursion).
#[inline]
pub(crate) fn subtree_sums<S: Space, T: Copy + std::ops::AddAssign>(
    model: &Model<S>,
    parts: &mut [T],
    mut visit: impl FnMut(usize, &T),
) {
    let mut from_next: Option<T> = None;
    for i in (0..model.nv()).rev() {
        let mut total = parts[i];
        if let Some(child) = from_next.take() {
            total += child;
        }
        parts[i] = total;
        visit(i, &total);
        let parent = model.joints[i].parent;
        if follows_parent(parent, i) {
            from_next = Some(total);
        } else if parent != NO_PARENT {
            parts[parent] += total;
        }
    }
}
