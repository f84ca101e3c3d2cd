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
    pub obstacle_contact: bool,
    pub friction: bool,
    pub self_collision: bool,
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
            obstacle_contact: cfg.has(Effect::ObstacleContact),
            friction: cfg.has(Effect::Friction),
            self_collision: cfg.has(Effect::SelfCollision),
        };
        let pairs = [
            ("wind", "[wind]", e.wind, cfg.wind.is_some()),
            (
                "attachments",
                "[attachments]",
                e.attachments,
                cfg.attachments.is_some(),
            ),
            (
                "obstacle_contact",
                "[[obstacles]]",
                e.obstacle_contact,
                !cfg.obstacles.is_empty(),
            ),
            (
                "self_collision",
                "[self_collision]",
                e.self_collision,
                cfg.self_collision.is_some(),
            ),
        ];
        for (name, table, declared, configured) in pairs {
            if declared && !configured {
                return Err(Error::Config(format!(
                    "effect '{name}' is declared but the {table} table is missing"
                )));
            }
            if configured && !declared {
                return Err(Error::Config(format!(
                    "a {table} table is given but '{name}' is not in `effects`; add it or remove the table"
                )));
            }
        }
        if e.friction && !e.has_contact() {
            return Err(Error::Config(
                "effect 'friction' needs 'obstacle_contact' or 'self_collision'".into(),
            ));
        }
        if cfg.contact.is_some() && !e.has_contact() {
            return Err(Error::Config(
                "a [contact] table is given but neither 'obstacle_contact' nor 'self_collision' is in `effects`".into(),
            ));
        }
        Ok(e)
    }

    /// Any contact effect on (then collision detection and the contact solve run).
    pub fn has_contact(&self) -> bool {
        self.obstacle_contact || self.self_collision
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
            ("obstacle_contact", self.obstacle_contact),
            ("friction", self.friction),
            ("self_collision", self.self_collision),
        ]
        .into_iter()
        .filter_map(|(n, on)| on.then_some(n))
        .collect()
    }
}
