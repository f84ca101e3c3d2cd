//! diffcloth-render: a headless software renderer for diffcloth scenes. No OpenGL, no system
//! libraries: a z-buffer rasterizer writes RGB8 frames (height x width x 3, row-major), fast
//! enough for video of the environments (hundreds of 480x480 frames/s on one core).
//!
//! - [`camera`]: the look-at camera and the default framing of a scene;
//! - [`scene`]: what a frame shows, borrowed from a [`diffcloth::Simulator`];
//! - [`tessellate`]: the analytic obstacle shapes and the floor as triangles;
//! - [`shading`]: colours, two-sided Lambert lighting, depth cue, background;
//! - [`raster`]: the triangle and disc rasterizer and near-plane clipping;
//! - [`renderer`]: the [`Renderer`] owning the buffers, and the frame pipeline.
//!
//! A crate of its own rather than a module of `diffcloth`: drawing is not physics, the
//! simulator crate stays free of it, and the binding is the only user.
//!
//! ```
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use diffcloth_render::{Renderer, SceneView};
//! let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../diffcloth_gym/configs/wind.toml");
//! let sim = diffcloth::Simulator::from_toml_file(std::path::Path::new(path))?;
//! let mut renderer = Renderer::new(480, 480)?;
//! let frame: Vec<u8> = renderer.render_to_vec(&SceneView::of(&sim), None)?;
//! assert_eq!(frame.len(), 480 * 480 * 3);
//! # Ok(()) }
//! ```

pub mod camera;
pub mod error;
pub mod raster;
pub mod renderer;
pub mod scene;
pub mod shading;
pub mod tessellate;

pub use camera::{Camera, DEFAULT_FOV_Y};
pub use error::RenderError;
pub use renderer::{Framing, Renderer, MAX_SIZE};
pub use scene::SceneView;
pub use shading::{Light, Palette};
