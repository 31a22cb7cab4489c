//! Why a core could not be built for a session.

use kinloop_linkage::algorithms::configuration::LayoutError;
use kinloop_linkage::algorithms::op_path::PathError;
use kinloop_linkage::math::space::SceneKind;

/// Why a core could not be built for a session.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CoreError {
    /// The scene lives in another space than the core.
    #[error("the scene is {scene:?} but this client runs a {core:?} core")]
    WrongSpace {
        /// The scene's.
        scene: SceneKind,
        /// The core's.
        core: SceneKind,
    },
    /// The welcome's operational dimension disagrees with its kind.
    #[error("the welcome announces an operational space of dimension {got}, expected {expected}")]
    WrongOpDim {
        /// Announced.
        got: u8,
        /// Expected for the kind.
        expected: usize,
    },
    /// The device spec does not describe this space's axes.
    #[error("device {device}: {field} has {got} values, expected {expected}")]
    DeviceAxes {
        /// The device.
        device: String,
        /// Which list.
        field: &'static str,
        /// Its length.
        got: usize,
        /// Axes of the space.
        expected: usize,
    },
    /// The scene's length scale is unusable.
    #[error("the scene's length scale {0} is not a positive length")]
    LengthScale(f64),
    /// Gains that cannot be used.
    #[error("controller gains: {0}")]
    Gains(String),
    /// A mapping whose scales are not positive.
    #[error("the welcome's mapping (position scale {position}, force scale {force}) is not usable")]
    Mapping {
        /// Position scale.
        position: f64,
        /// Force scale.
        force: f64,
    },
    /// A tick period that is not positive.
    #[error("the tick period must be positive")]
    Period,
    /// The welcome's ball joints do not fit its rates (`welcome.scene.ball_rates`).
    #[error("welcome.scene.ball_rates: {0}")]
    BallRates(#[from] LayoutError),
    /// The welcome's OP path cannot be followed.
    #[error("the welcome's OP path: {0}")]
    Path(#[from] PathError),
}
