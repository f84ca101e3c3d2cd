//! Collision detection: analytic obstacles (signed distance and normal) and node-node
//! self-collision found with a spatial hash. Contacts act on nodes only (paper Sec. 3.2).

mod obstacle;
mod self_collision;
mod shape;
mod sweep;

pub use obstacle::{Motion, Obstacle};
pub use self_collision::{HashScratch, SelfCollision};
pub use shape::Shape;
