//! The room's light switches over a recording: the ceiling panel switching off and the
//! lamp ([`super::lamp`]) switching on at given frames, the scene each frame is lit by,
//! and the provenance settings that say so.
//!
//! A recording made without a switch has no setting for it, so its header keeps the
//! bytes it had before the switch existed.

use super::interreflection::{self, RoomLights};
use super::scene::Scene;
use crate::types::Provenance;
use std::collections::BTreeMap;

/// The provenance setting naming [`LightSwitches::panel_off_at`].
pub const PANEL_OFF_AT_SETTING: &str = "panel_off_at";
/// The provenance setting naming [`LightSwitches::lamp_on_at`].
pub const LAMP_ON_AT_SETTING: &str = "lamp_on_at";

/// When the room's switchable lights change (`None`: never).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LightSwitches {
    /// The frame from which the ceiling panel is off (on before it). The room then
    /// darkens at once, its interreflection with it.
    pub panel_off_at: Option<usize>,
    /// The frame from which the lamp is on (off before it; 0: on throughout). Its light
    /// and shadows appear at once, its interreflection with them.
    pub lamp_on_at: Option<usize>,
}

impl LightSwitches {
    /// Which lights are on at `frame`.
    pub fn lights_at(&self, frame: usize) -> RoomLights {
        RoomLights {
            panel: self.panel_off_at.is_none_or(|off| frame < off),
            lamp: self.lamp_on_at.is_some_and(|on| frame >= on),
        }
    }

    /// The room as it is lit at `frame` ([`interreflection::room_lit`]).
    pub fn scene_at(&self, frame: usize) -> Scene {
        interreflection::room_lit(self.lights_at(frame))
    }

    /// The first frame at which a light changes, whose lag `relume eval` measures (a
    /// switch at frame 0 changes nothing: the light is so from the start).
    pub fn change_frame(&self) -> Option<usize> {
        [self.panel_off_at, self.lamp_on_at]
            .into_iter()
            .flatten()
            .filter(|&frame| frame > 0)
            .min()
    }

    /// Checks that every switch falls on one of `frames` frames.
    pub fn validate(&self, frames: usize) -> Result<(), String> {
        let last = frames.saturating_sub(1);
        if let Some(off) = self.panel_off_at
            && off >= frames
        {
            return Err(format!(
                "the panel cannot switch off at frame {off}: the recording's frames are 0 to {last}"
            ));
        }
        if let Some(on) = self.lamp_on_at
            && on >= frames
        {
            return Err(format!(
                "the lamp cannot switch on at frame {on}: the recording's frames are 0 to {last}"
            ));
        }
        Ok(())
    }

    /// Adds the switches that are set to a recording's provenance `settings`.
    pub fn write_settings(&self, settings: &mut BTreeMap<String, String>) {
        if let Some(off) = self.panel_off_at {
            settings.insert(PANEL_OFF_AT_SETTING.into(), off.to_string());
        }
        if let Some(on) = self.lamp_on_at {
            settings.insert(LAMP_ON_AT_SETTING.into(), on.to_string());
        }
    }

    /// The switches of the recording with `provenance`, as its settings say; an error
    /// naming the setting when one is not a frame number.
    pub fn of(provenance: &Provenance) -> Result<LightSwitches, String> {
        let frame = |key: &str| {
            provenance
                .settings
                .get(key)
                .map(|v| {
                    v.parse::<usize>().map_err(|_| {
                        format!("the recording's setting {key} = {v:?} is not a frame number")
                    })
                })
                .transpose()
        };
        Ok(LightSwitches {
            panel_off_at: frame(PANEL_OFF_AT_SETTING)?,
            lamp_on_at: frame(LAMP_ON_AT_SETTING)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lights_follow_their_switches_frame_by_frame() {
        let s = LightSwitches {
            panel_off_at: Some(4),
            lamp_on_at: Some(2),
        };
        let lit = |f| {
            let l = s.lights_at(f);
            (l.panel, l.lamp)
        };
        assert_eq!(
            [lit(0), lit(2), lit(4), lit(9)],
            [(true, false), (true, true), (false, true), (false, true)]
        );
        assert_eq!(s.change_frame(), Some(2));
        assert_eq!(LightSwitches::default().change_frame(), None);
        let from_the_start = LightSwitches {
            panel_off_at: Some(6),
            lamp_on_at: Some(0),
        };
        assert_eq!(from_the_start.change_frame(), Some(6));
        assert_eq!(
            LightSwitches::default().lights_at(100),
            RoomLights::default()
        );
    }

    #[test]
    fn settings_round_trip_and_bad_ones_are_named() {
        let s = LightSwitches {
            panel_off_at: None,
            lamp_on_at: Some(0),
        };
        let mut p = Provenance {
            tool: "relume synth".into(),
            tool_version: "0".into(),
            source: "synthetic room".into(),
            settings: BTreeMap::new(),
        };
        s.write_settings(&mut p.settings);
        assert_eq!(p.settings.keys().collect::<Vec<_>>(), [LAMP_ON_AT_SETTING]);
        assert_eq!(LightSwitches::of(&p), Ok(s));
        p.settings.insert(LAMP_ON_AT_SETTING.into(), "-1".into());
        assert_eq!(
            LightSwitches::of(&p),
            Err("the recording's setting lamp_on_at = \"-1\" is not a frame number".into())
        );
        assert_eq!(
            LightSwitches {
                lamp_on_at: Some(5),
                ..s
            }
            .validate(5),
            Err("the lamp cannot switch on at frame 5: the recording's frames are 0 to 4".into())
        );
    }
}
