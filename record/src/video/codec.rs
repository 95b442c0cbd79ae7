//! The codec choice, by name in configs and flags (a leaf: the encoders and the container
//! name it, it names none of them).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The video codec: see the module doc of [`super`] for the trade.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Codec {
    #[default]
    H264,
    Av1,
}

impl Codec {
    /// The name in configs, flags and LeRobot's `video.codec`: `h264` or `av1`.
    pub const fn name(self) -> &'static str {
        match self {
            Codec::H264 => "h264",
            Codec::Av1 => "av1",
        }
    }
}

impl fmt::Display for Codec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Codec {
    type Err = String;

    fn from_str(s: &str) -> Result<Codec, String> {
        match s.to_ascii_lowercase().as_str() {
            "h264" | "h.264" | "avc" => Ok(Codec::H264),
            "av1" => Ok(Codec::Av1),
            other => Err(format!("unknown video codec {other:?}: use h264 or av1")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codec_names_parse_back_and_unknown_ones_say_which_exist() {
        for c in [Codec::H264, Codec::Av1] {
            assert_eq!(c.name().parse::<Codec>(), Ok(c));
        }
        assert!("vp9".parse::<Codec>().unwrap_err().contains("h264 or av1"));
    }
}
