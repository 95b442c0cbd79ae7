//! How a camera's pixels become rays: the one type the camera, its ray caster and the
//! footprint of a ray bundle all read.

/// A ray-generation model: perspective (`pinhole`) or orthographic (top-down view).
#[derive(Debug, Clone, Copy)]
pub enum Projection {
    /// Horizontal field of view (rad).
    Pinhole { fov: f64 },
    /// Metres per pixel.
    Ortho { scale: f64 },
}
