//! Integration tests of the simulator: each checks a physical fact, not only that it runs.
mod batch;
mod bend_models;
mod cancel_backward;
mod common;
mod contact;
mod contact_gradients;
mod contact_response;
mod folded_cloth;
mod forward_physics;
mod gradient_check;
mod gradients;
mod malformed_inputs;
mod model_sharing;
mod pd_solver;
mod scenes;
mod tape;
mod tunnelling;
