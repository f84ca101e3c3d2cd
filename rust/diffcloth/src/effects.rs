//! Which physical effects a scene simulates. An effect that is off is not computed: its
//! constraint set is not built, its forces are not evaluated, and it allocates nothing.

use crate::config::{Effect, SceneConfig};
use crate::error::{Error, Result};

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Effects {
    pub gravity: bool,
    pub stretch: bool,
    pub bend: bool,
    pub attachments: bool,
    pub wind: bool,
    pub external_forces: bool,
}

impl Effects {
    /// Reads the declared effects and checks that each effect's parameters are present
    /// exactly when the effect is declared (a parameter table for an undeclared effect is
    /// almost always a mistake in the config).
    pub fn from_config(cfg: &SceneConfig) -> Result<Self> {
        let e = Self {
            gravity: cfg.has(Effect::Gravity),
            stretch: cfg.has(Effect::Stretch),
            bend: cfg.has(Effect::Bend),
            attachments: cfg.has(Effect::Attachments),
            wind: cfg.has(Effect::Wind),
            external_forces: cfg.has(Effect::ExternalForces),
        };
        let pairs = [
            ("wind", e.wind, cfg.wind.is_some()),
            ("attachments", e.attachments, cfg.attachments.is_some()),
        ];
        for (name, declared, configured) in pairs {
            if declared && !configured {
                return Err(Error::Config(format!("effect '{name}' is declared but the [{name}] table is missing")));
            }
            if configured && !declared {
                return Err(Error::Config(format!(
                    "a [{name}] table is given but '{name}' is not in `effects`; add it or remove the table"
                )));
            }
        }
        Ok(e)
    }

    /// Names of the effects that are on, in a fixed order.
    pub fn names(&self) -> Vec<&'static str> {
        [
            ("gravity", self.gravity),
            ("stretch", self.stretch),
            ("bend", self.bend),
            ("attachments", self.attachments),
            ("wind", self.wind),
            ("external_forces", self.external_forces),
        ]
        .into_iter()
        .filter_map(|(n, on)| on.then_some(n))
        .collect()
    }
}
