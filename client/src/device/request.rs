//! What `--device` asks for: a simulated preset (`sim:paper`, `sim:falcon`, `sim:touch`), a Force Dimension
//! device through the DHD SDK (`dhd` or `dhd:INDEX`), or a DHD device with a simulated one to fall back on
//! when the DHD library or device cannot be used (`dhd,sim:falcon`): the fallback only when asked.

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

/// A `--device` value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeviceRequest {
    /// A simulated device.
    Simulated(DevicePreset),
    /// A DHD device.
    Dhd(DhdRequest),
}

/// A `--device` value that names no device.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DeviceRequestError {
    /// Not a preset nor `dhd[:INDEX]`.
    #[error("unknown device {0:?}; expected sim:paper, sim:falcon, sim:touch, dhd[:INDEX] or dhd[:INDEX],sim:NAME")]
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
        let fallback = fallback
            .map(|f| f.parse::<DevicePreset>())
            .transpose()
            .map_err(|source| DeviceRequestError::Fallback { given: s.to_owned(), source })?;
        Ok(DeviceRequest::Dhd(DhdRequest { index, fallback, auto_init: false }))
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
    }
}
