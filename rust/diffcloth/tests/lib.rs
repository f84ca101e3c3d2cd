//! Integration tests of the simulator: each checks a physical fact, not only that it runs.
mod bend_models;
mod common;
mod contact;
mod contact_response;
mod forward_physics;
mod gradients;
mod issue_11_cancel_backward;
mod issue_11_malformed_inputs;
mod model_sharing;
mod pd_solver;
mod scenes;
mod tape;
