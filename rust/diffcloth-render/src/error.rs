//! Typed errors of the renderer: every one is bad input, named by the argument at fault. The
//! binding maps them to `diffcloth_gym.errors.InputError`.

/// What the renderer refuses, with a message naming the argument.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// A frame size outside `1..=MAX_SIZE` pixels.
    #[error("{name} must be between 1 and {max} pixels, got {value}")]
    Size {
        name: &'static str,
        value: usize,
        max: usize,
    },
    /// A camera that cannot define a view (non-finite, eye on the target, fov out of range).
    #[error("camera.{field}: {message}")]
    Camera {
        field: &'static str,
        message: String,
    },
    /// The output slice does not hold `height * width * 3` bytes.
    #[error("output buffer has {got} bytes, expected {expected} (height x width x 3)")]
    Output { got: usize, expected: usize },
}
