//! What `--device` asks for: a simulated preset (`sim:paper`, `sim:falcon`, `sim:touch`), a Force Dimension
//! device through the DHD SDK (`dhd` or `dhd:INDEX`), a 3D Systems device through OpenHaptics (`hd` or
//! `hd:NAME`, the name Touch Setup gives it), or either with a simulated one to fall back on when the
//! vendor's library or device cannot be used (`dhd,sim:falcon`, `hd,sim:touch`): the fallback only when
//! asked.

use super::presets::{DevicePreset, PresetError};

/// A DHD device asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DhdRequest {
    /// `dhdOpenID`'s index (0: the first device).
    pub index: u8,
    /// The simulated device used instead when the DHD one cannot be opened.
    pub fallback: Option<DevicePreset>,
    /// Run `drdAutoInit` on an uncalibrated device (it moves on its own); never without the user's word
    /// (`--dhd-auto-init`), so never from the `--device` value alone.
    pub auto_init: bool,
}

/// An OpenHaptics device asked for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HdRequest {
    /// `hdInitDevice`'s name (None: `HD_DEFAULT_DEVICE`).
    pub name: Option<String>,
    /// The simulated device used instead when the HD one cannot be opened.
    pub fallback: Option<DevicePreset>,
    /// Run `hdUpdateCalibration` on a device that needs it; never without the user's word
    /// (`--hd-calibrate`).
    pub calibrate: bool,
}

/// A `--device` value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DeviceRequest {
    /// A simulated device.
    Simulated(DevicePreset),
    /// A DHD device.
    Dhd(DhdRequest),
    /// An OpenHaptics device.
    Hd(HdRequest),
}

/// A `--device` value that names no device.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DeviceRequestError {
    /// Not a preset, `dhd[:INDEX]` nor `hd[:NAME]`.
    #[error(
        "unknown device {0:?}; expected sim:paper, sim:falcon, sim:touch, dhd[:INDEX], hd[:NAME], or dhd or hd \
         followed by ,sim:NAME"
    )]
    Unknown(String),
    /// The index is not 0-255.
    #[error("device {0:?}: the DHD index must be a number from 0 to 255")]
    Index(String),
    /// The fallback is not a simulated preset.
    #[error("device {given:?}: the fallback must be a simulated device: {source}")]
    Fallback {
        /// As given.
        given: String,
        /// Why.
        source: PresetError,
    },
}

impl std::str::FromStr for DeviceRequest {
    type Err = DeviceRequestError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (first, fallback) = match s.split_once(',') {
            Some((first, fallback)) => (first, Some(fallback)),
            None => (s, None),
        };
        let fallback_preset = || {
            fallback
                .map(|f| f.parse::<DevicePreset>())
                .transpose()
                .map_err(|source| DeviceRequestError::Fallback { given: s.to_owned(), source })
        };
        if first == "hd" || first.starts_with("hd:") {
            let name = first.strip_prefix("hd:").filter(|n| !n.is_empty()).map(String::from);
            return Ok(DeviceRequest::Hd(HdRequest { name, fallback: fallback_preset()?, calibrate: false }));
        }
        let index = match first {
            "dhd" => 0,
            _ => match first.strip_prefix("dhd:") {
                Some(n) => n.parse().map_err(|_| DeviceRequestError::Index(s.to_owned()))?,
                None if fallback.is_none() => {
                    return s
                        .parse()
                        .map(DeviceRequest::Simulated)
                        .map_err(|_| DeviceRequestError::Unknown(s.to_owned()))
                }
                None => return Err(DeviceRequestError::Unknown(s.to_owned())),
            },
        };
        Ok(DeviceRequest::Dhd(DhdRequest { index, fallback: fallback_preset()?, auto_init: false }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_values_parse_to_what_they_say() {
        let parse = |s: &str| s.parse::<DeviceRequest>();
        assert_eq!(parse("sim:falcon"), Ok(DeviceRequest::Simulated(DevicePreset::Falcon)));
        assert_eq!(parse("dhd"), Ok(DeviceRequest::Dhd(DhdRequest { index: 0, fallback: None, auto_init: false })));
        assert_eq!(parse("dhd:2"), Ok(DeviceRequest::Dhd(DhdRequest { index: 2, fallback: None, auto_init: false })));
        assert_eq!(
            parse("dhd,sim:falcon"),
            Ok(DeviceRequest::Dhd(DhdRequest { index: 0, fallback: Some(DevicePreset::Falcon), auto_init: false }))
        );
        assert!(matches!(parse("dhd:300"), Err(DeviceRequestError::Index(_))));
        assert!(matches!(parse("dhd,dhd"), Err(DeviceRequestError::Fallback { .. })));
        assert!(matches!(parse("omega"), Err(DeviceRequestError::Unknown(_))));
        assert!(matches!(parse("sim:paper,sim:falcon"), Err(DeviceRequestError::Unknown(_))));
        let hd = |name: Option<&str>, fallback| {
            Ok(DeviceRequest::Hd(HdRequest { name: name.map(String::from), fallback, calibrate: false }))
        };
        assert_eq!(parse("hd"), hd(None, None));
        assert_eq!(parse("hd:Left Touch"), hd(Some("Left Touch"), None));
        assert_eq!(parse("hd,sim:touch"), hd(None, Some(DevicePreset::Touch)));
        assert!(matches!(parse("hd,hd"), Err(DeviceRequestError::Fallback { .. })));
        assert!(matches!(parse("hdx"), Err(DeviceRequestError::Unknown(_))));
    }
}
