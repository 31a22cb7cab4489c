//! The penalty law shared by the obstacle contacts (`contact`) and the range walls (`joint_limits`): a
//! spring-damper that only pushes.

/// The penalty law of contacts and of the joints' range walls: the push `max(0, −k gap − b ġap)` (≥ 0) of a
/// wall penetrated by `−gap` (zero when `gap ≥ 0`). The clamp keeps the wall from pulling, so with the damper
/// it only ever takes energy: its work is the spring's `−d(½ k gap²)` plus a part that is never positive.
pub fn penalty_force(stiffness: f64, damping: f64, gap: f64, gap_rate: f64) -> f64 {
    if gap >= 0.0 {
        return 0.0;
    }
    (-stiffness * gap - damping * gap_rate).max(0.0)
}
