//! Integration tests of the simulator: each checks a physical fact, not only that it runs.
mod batch;
mod bend_models;
mod common;
mod contact;
mod contact_response;
mod forward_physics;
mod gradients;
mod issue_11_folded_cloth_energy;
mod issue_11_obstacle_tunnelling;
mod model_sharing;
mod pd_solver;
mod scenes;
mod tape;
