//! x264's presets (`--preset`): encoding speed against bits at a quality.

use std::fmt;
use std::str::FromStr;

/// An x264 preset, fastest first (x264's own names).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(missing_docs)]
pub enum X264Preset {
    Ultrafast,
    Superfast,
    Veryfast,
    Faster,
    Fast,
    Medium,
    Slow,
    Slower,
    Veryslow,
}

/// Every preset's name, fastest first.
pub const X264_PRESETS: [&str; 9] = [
    "ultrafast",
    "superfast",
    "veryfast",
    "faster",
    "fast",
    "medium",
    "slow",
    "slower",
    "veryslow",
];

impl X264Preset {
    /// Files' default: measured in `docs/speed.md` (the encoder's share).
    pub const FILES: X264Preset = X264Preset::Veryfast;

    /// Its name, as x264 takes it.
    pub fn as_str(self) -> &'static str {
        X264_PRESETS[self as usize]
    }
}

impl fmt::Display for X264Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for X264Preset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        use X264Preset::*;
        let all = [
            Ultrafast, Superfast, Veryfast, Faster, Fast, Medium, Slow, Slower, Veryslow,
        ];
        all.into_iter()
            .find(|p| p.as_str().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                format!(
                    "unknown x264 preset {s:?} (allowed: {})",
                    X264_PRESETS.join(", ")
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_ones_list_the_allowed() {
        for name in X264_PRESETS {
            assert_eq!(name.parse::<X264Preset>().unwrap().as_str(), name);
        }
        let e = "quick".parse::<X264Preset>().unwrap_err();
        assert!(e.contains("ultrafast") && e.contains("veryslow"), "{e}");
    }
}
