//! PNG output of camera frames (for `kitchen-r sim render`; never on the per-step path).

use std::path::Path;

use image::{GrayImage, Luma, RgbImage};

use super::CameraImage;
use crate::error::SimError;

fn save_err(path: &Path, e: impl std::fmt::Display) -> SimError {
    SimError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Write the RGB image.
pub fn write_rgb(img: &CameraImage, path: &Path) -> Result<(), SimError> {
    let buf = RgbImage::from_raw(img.width, img.height, img.rgb.clone())
        .ok_or_else(|| save_err(path, "buffer size does not match the image size"))?;
    buf.save(path).map_err(|e| save_err(path, e))
}

/// Write depth as 8-bit grey, near = bright, scaled to `max_depth`; no return is black.
pub fn write_depth(img: &CameraImage, max_depth: f32, path: &Path) -> Result<(), SimError> {
    let mut buf = GrayImage::new(img.width, img.height);
    for (i, d) in img.depth.iter().enumerate() {
        let v = if *d <= 0.0 {
            0
        } else {
            (255.0 * (1.0 - (d / max_depth).clamp(0.0, 1.0))).round() as u8
        };
        buf.put_pixel(i as u32 % img.width, i as u32 / img.width, Luma([v]));
    }
    buf.save(path).map_err(|e| save_err(path, e))
}
