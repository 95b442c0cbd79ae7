//! Pure-Rust-built video: RGB8 frames in, an H.264 or AV1 stream in an MP4 (ISO-BMFF) file out.
//!
//! Two codecs, one container ([`Codec`]):
//! - **H.264** ([`h264`], Cisco's OpenH264 compiled from source by the `openh264` crate): the
//!   default, about twelve times faster than AV1 here (docs/measured/video.md). Chromium,
//!   Firefox and Safari play it inline; LeRobot (PyAV/torchcodec) decodes it. Note its patents:
//!   OpenH264 built from source is not covered by Cisco's licence for its own binaries.
//! - **AV1** ([`av1`], `rav1e`, with its assembly when the `asm` feature finds nasm):
//!   royalty-free and what LeRobot writes by default, but slow to encode.
//!
//! [`mp4`] writes the container by hand: `ftyp`, then `moov` (one `avc1`/`avcC` or `av01`/`av1C`
//! track with `colr`) before `mdat`, so a browser can start playing before the whole file has
//! arrived.
//!
//! ```no_run
//! use kitchen_r_record::video::{VideoEncoder, VideoSettings};
//! let mut enc = VideoEncoder::new(128, 128, 10, VideoSettings::default()).unwrap();
//! for _ in 0..20 {
//!     enc.push_rgb(&vec![128u8; 128 * 128 * 3]).unwrap();
//! }
//! enc.finish().unwrap().write_mp4(std::path::Path::new("clip.mp4")).unwrap();
//! ```
//!
//! An [`EncodedVideo`] can also be kept as samples ([`EncodedVideo::save`]/[`EncodedVideo::load`])
//! and several joined into one file ([`EncodedVideo::concat`]): every clip starts on a key frame
//! and the stream configuration is the same for equal settings and size, so joining is copying
//! samples.
//!
//! [`episode`] records an episode video (both cameras at the control rate with a [`caption`]
//! bar) for the submission pages and `kitchen-r eval --record`.

mod av1;
pub mod caption;
mod codec;
mod encoder;
pub mod episode;
mod h264;
mod mp4;
mod stored;
mod yuv;

use std::path::Path;

pub use codec::Codec;
pub use encoder::VideoEncoder;

#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error("video settings: {0}")]
    Config(String),
    #[error("frame {index}: {message}")]
    Frame { index: usize, message: String },
    #[error("video encoder: {0}")]
    Encoder(String),
    #[error("cannot join clips of different codec, size, rate or stream configuration")]
    Mismatch,
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a stored clip ({message})")]
    Stored {
        path: std::path::PathBuf,
        message: String,
    },
}

/// Encoder knobs; the defaults (H.264) suit small robot-camera frames at 10 fps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VideoSettings {
    pub codec: Codec,
    /// AV1 only: rav1e speed preset 0 (slowest, smallest) – 10 (fastest).
    pub speed: u8,
    /// AV1 only: rav1e base quantizer 0–255 (lower = better quality, larger files).
    pub quantizer: u8,
    /// H.264 only: a target bit rate in kbit/s for OpenH264's rate control, or 0 for every
    /// frame at its base QP 26 (best quality, most bytes).
    pub h264_kbps: u32,
    /// A key frame at least every this many frames: a decoder seeking to a frame decodes from
    /// the key frame before it, so this bounds a random-access read (LeRobot samples frames).
    pub key_interval: u32,
}

impl Default for VideoSettings {
    fn default() -> Self {
        VideoSettings::h264()
    }
}

impl VideoSettings {
    /// H.264 at its base QP (no rate control), a key frame every 10 frames (1 s at the control
    /// rate).
    pub const fn h264() -> Self {
        VideoSettings {
            codec: Codec::H264,
            ..VideoSettings::av1()
        }
    }

    /// AV1 at rav1e's fastest preset and quantizer 100, a key frame every 10 frames.
    pub const fn av1() -> Self {
        VideoSettings {
            codec: Codec::Av1,
            speed: 10,
            quantizer: 100,
            h264_kbps: 0,
            key_interval: 10,
        }
    }

    /// These settings with another codec.
    pub const fn with_codec(self, codec: Codec) -> Self {
        VideoSettings { codec, ..self }
    }
}

/// One coded frame as ISO-BMFF stores it: an AV1 temporal unit without its temporal delimiter,
/// or H.264 NAL units each after a 4-byte length.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Sample {
    pub data: Vec<u8>,
    pub key: bool,
}

/// An encoded clip: what an MP4 track needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EncodedVideo {
    pub codec: Codec,
    pub width: u32,
    pub height: u32,
    pub fps: u32,
    /// The decoder configuration: the `av1C` box payload (4 header bytes then the sequence
    /// header OBU) or the `avcC` one (profile, level, SPS and PPS).
    pub config: Vec<u8>,
    pub samples: Vec<Sample>,
}

impl EncodedVideo {
    /// Duration in seconds (frames are evenly spaced at `fps`).
    pub fn duration(&self) -> f64 {
        self.samples.len() as f64 / f64::from(self.fps.max(1))
    }

    /// Write the clip as an MP4 file at `path` (replacing it).
    pub fn write_mp4(&self, path: &Path) -> Result<(), VideoError> {
        let bytes = mp4::mux(self);
        std::fs::write(path, bytes).map_err(|source| VideoError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// The MP4 file's bytes.
    pub fn to_mp4(&self) -> Vec<u8> {
        mp4::mux(self)
    }

    /// The clips one after the other, as one clip (all of the same codec, size, rate and stream
    /// configuration; the first sample of each is a key frame).
    pub fn concat(clips: &[EncodedVideo]) -> Result<EncodedVideo, VideoError> {
        let Some(first) = clips.first() else {
            return Err(VideoError::Config("no clips to join".into()));
        };
        let same = |c: &EncodedVideo| {
            (c.codec, c.width, c.height, c.fps) == (first.codec, first.width, first.height, first.fps)
                && c.config == first.config
                && c.samples.first().is_none_or(|s| s.key)
        };
        if !clips.iter().all(same) {
            return Err(VideoError::Mismatch);
        }
        Ok(EncodedVideo {
            samples: clips.iter().flat_map(|c| c.samples.iter().cloned()).collect(),
            ..first.clone()
        })
    }

    /// Keep the samples in a small file of our own (cheaper to join than an MP4 is to parse).
    pub fn save(&self, path: &Path) -> Result<(), VideoError> {
        stored::save(self, path)
    }

    pub fn load(path: &Path) -> Result<EncodedVideo, VideoError> {
        stored::load(path)
    }
}
