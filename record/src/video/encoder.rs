//! The encoder that dispatches to the settings' codec.

use super::av1::Av1Encoder;
use super::codec::Codec;
use super::h264::H264Encoder;
use super::{EncodedVideo, VideoError, VideoSettings};

/// Encodes RGB8 frames of one size at one frame rate into an [`EncodedVideo`] with the
/// settings' codec.
#[derive(Debug)]
pub struct VideoEncoder(Inner);

#[derive(Debug)]
enum Inner {
    H264(Box<H264Encoder>),
    Av1(Box<Av1Encoder>),
}

impl VideoEncoder {
    /// An encoder for `width`×`height` frames at `fps` (at least 16×16; even sizes for H.264).
    pub fn new(width: u32, height: u32, fps: u32, s: VideoSettings) -> Result<Self, VideoError> {
        Ok(VideoEncoder(match s.codec {
            Codec::H264 => Inner::H264(Box::new(H264Encoder::new(width, height, fps, s)?)),
            Codec::Av1 => Inner::Av1(Box::new(Av1Encoder::new(width, height, fps, s)?)),
        }))
    }

    /// Add a frame: `rgb` is `width * height * 3` bytes, row-major.
    pub fn push_rgb(&mut self, rgb: &[u8]) -> Result<(), VideoError> {
        match &mut self.0 {
            Inner::H264(e) => e.push_rgb(rgb),
            Inner::Av1(e) => e.push_rgb(rgb),
        }
    }

    /// Flush the encoder and return the clip.
    pub fn finish(self) -> Result<EncodedVideo, VideoError> {
        match self.0 {
            Inner::H264(e) => e.finish(),
            Inner::Av1(e) => e.finish(),
        }
    }
}
