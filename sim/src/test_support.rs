//! Helpers the sim crate's unit tests share; compiled only for tests.

use crate::sensors::camera::CameraImage;

/// FNV-1a over the images' colour bytes and depth bits, in order: a render pinned by value.
pub(crate) fn image_hash<'a>(images: impl IntoIterator<Item = &'a CameraImage>) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for im in images {
        let depth = im.depth.iter().flat_map(|d| d.to_bits().to_le_bytes());
        for b in im.rgb.iter().copied().chain(depth) {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    }
    h
}
