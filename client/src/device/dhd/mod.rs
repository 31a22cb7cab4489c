//! Force Dimension devices (omega, delta, sigma, lambda, Novint Falcon) through the DHD SDK, loaded at run
//! time: [`library`] finds and checks the vendor library, [`specs`] maps `dhdGetSystemType` to published
//! specs, [`frames`] converts the device's frame and units to kinloop's, [`device`] is the [`HapticDevice`]
//! the loop drives.
//!
//! [`HapticDevice`]: super::HapticDevice

pub mod device;
pub mod frames;
pub mod library;
pub mod specs;

use std::path::PathBuf;

pub use device::{DhdDevice, OpenedDhd};
pub use library::DhdLibrary;

/// Why the DHD library or a device behind it cannot be used. Each message names the library.
#[derive(Debug, thiserror::Error)]
pub enum DhdError {
    /// No candidate exists.
    #[error(
        "no Force Dimension DHD library found (looked for {}); install the Force Dimension SDK, or set {} to the \
         library's path (or FORCEDIM_SDK to the SDK's folder)",
        looked.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        library::LIBRARY_VARIABLE
    )]
    NotFound {
        /// Where kinloop looked.
        looked: Vec<PathBuf>,
    },
    /// The file is not a loadable library.
    #[error("DHD library {library}: cannot be loaded: {reason}")]
    Load {
        /// The library.
        library: String,
        /// The loader's reason.
        reason: String,
    },
    /// Required calls are absent.
    #[error("DHD library {library}: lacks required symbols {symbols}; it is not a Force Dimension DHD/DRD library")]
    MissingSymbols {
        /// The library.
        library: String,
        /// The missing names, comma-separated.
        symbols: String,
    },
    /// The SDK is older than kinloop supports.
    #[error("DHD library {library}: SDK version {found} is older than {minimum}; install a newer Force Dimension SDK")]
    TooOld {
        /// The library.
        library: String,
        /// Its version.
        found: String,
        /// The oldest accepted.
        minimum: String,
    },
    /// `dhdOpenID` failed.
    #[error("DHD library {library}: cannot open device {index}: {reason} (is it plugged in and powered, and may this user open its USB device? see `kinloop devices`)")]
    Open {
        /// The library.
        library: String,
        /// The device index asked for.
        index: u8,
        /// The SDK's last error.
        reason: String,
    },
    /// The device is of a type kinloop has no spec for.
    #[error("DHD library {library}: device {index} reports system type {system}, which kinloop has no published spec for; known: {known}")]
    UnknownSystem {
        /// The library.
        library: String,
        /// The device index.
        index: u8,
        /// What `dhdGetSystemType` said.
        system: i32,
        /// The known types.
        known: String,
    },
    /// The device's first reading is not usable.
    #[error("DHD library {library}: device {index} reads garbage ({what}); no force will be sent to it")]
    Garbage {
        /// The library.
        library: String,
        /// The device index.
        index: u8,
        /// What was wrong.
        what: String,
    },
}
