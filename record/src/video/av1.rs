//! The AV1 encoder: RGB8 → YUV 4:2:0 (BT.601, limited range, signalled in the stream) → rav1e.
//!
//! `low_latency` keeps frames in display order with no hidden reference frames, so every packet
//! is exactly one shown frame: one MP4 sample per input frame, timestamps by index.

use rav1e::color::{
    ChromaSampling, ColorDescription, ColorPrimaries, MatrixCoefficients, PixelRange, TransferCharacteristics,
};
use rav1e::config::SpeedSettings;
use rav1e::data::{FrameType, Rational};
use rav1e::prelude::{SceneDetectionSpeed, Tune};
use rav1e::{Config, Context, EncoderConfig, EncoderStatus};

use super::yuv::{chroma_size, rgb_to_yuv420};
use super::{Codec, EncodedVideo, Sample, VideoError, VideoSettings};

/// OBU types we look for in rav1e's packets (AV1 spec 5.3.1).
const OBU_SEQUENCE_HEADER: u8 = 1;
const OBU_TEMPORAL_DELIMITER: u8 = 2;

/// Encodes RGB8 frames of one size at one frame rate into an AV1 [`EncodedVideo`].
pub(super) struct Av1Encoder {
    ctx: Context<u8>,
    width: u32,
    height: u32,
    fps: u32,
    header: Vec<u8>,
    sequence_header: Option<Vec<u8>>,
    samples: Vec<Sample>,
    pushed: usize,
    yuv: [Vec<u8>; 3],
}

impl std::fmt::Debug for Av1Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Av1Encoder")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("fps", &self.fps)
            .field("pushed", &self.pushed)
            .finish()
    }
}

impl Av1Encoder {
    /// An encoder for `width`×`height` frames (each at least 16, rav1e's minimum) at `fps`.
    pub(super) fn new(width: u32, height: u32, fps: u32, s: VideoSettings) -> Result<Self, VideoError> {
        if width < 16 || height < 16 || fps == 0 {
            return Err(VideoError::Config(format!(
                "{width}x{height} at {fps} fps: frames must be at least 16x16 and fps positive"
            )));
        }
        let enc = EncoderConfig {
            width: width as usize,
            height: height as usize,
            time_base: Rational::new(1, u64::from(fps)),
            bit_depth: 8,
            chroma_sampling: ChromaSampling::Cs420,
            pixel_range: PixelRange::Limited,
            color_description: Some(ColorDescription {
                color_primaries: ColorPrimaries::BT601,
                transfer_characteristics: TransferCharacteristics::BT601,
                matrix_coefficients: MatrixCoefficients::BT601,
            }),
            speed_settings: speed_settings(s.speed),
            tune: Tune::Psnr,
            quantizer: usize::from(s.quantizer),
            min_key_frame_interval: 1,
            max_key_frame_interval: u64::from(s.key_interval.max(1)),
            low_latency: true,
            ..EncoderConfig::default()
        };
        // One thread: collection already runs one episode per core.
        let cfg = Config::new().with_encoder_config(enc).with_threads(1);
        let ctx: Context<u8> = cfg.new_context().map_err(|e| VideoError::Config(e.to_string()))?;
        let header = ctx.container_sequence_header();
        let (cw, ch) = chroma_size(width, height);
        Ok(Av1Encoder {
            ctx,
            width,
            height,
            fps,
            header,
            sequence_header: None,
            samples: Vec::new(),
            pushed: 0,
            yuv: [
                vec![0; (width * height) as usize],
                vec![0; cw * ch],
                vec![0; cw * ch],
            ],
        })
    }

    /// Add a frame: `rgb` is `width * height * 3` bytes, row-major.
    pub(super) fn push_rgb(&mut self, rgb: &[u8]) -> Result<(), VideoError> {
        let n = (self.width * self.height) as usize;
        if rgb.len() != 3 * n {
            return Err(VideoError::Frame {
                index: self.pushed,
                message: format!(
                    "{} bytes for {}x{} RGB8 (want {})",
                    rgb.len(),
                    self.width,
                    self.height,
                    3 * n
                ),
            });
        }
        rgb_to_yuv420(rgb, self.width as usize, self.height as usize, &mut self.yuv);
        let mut frame = self.ctx.new_frame();
        let (cw, _) = chroma_size(self.width, self.height);
        let strides = [self.width as usize, cw, cw];
        for (plane, (data, stride)) in frame.planes.iter_mut().zip(self.yuv.iter().zip(strides)) {
            plane.copy_from_raw_u8(data, stride, 1);
        }
        self.ctx
            .send_frame(frame)
            .map_err(|e| VideoError::Encoder(e.to_string()))?;
        self.pushed += 1;
        self.drain()
    }

    /// Flush the encoder and return the clip.
    pub(super) fn finish(mut self) -> Result<EncodedVideo, VideoError> {
        self.ctx.flush();
        self.drain()?;
        if self.samples.len() != self.pushed {
            return Err(VideoError::Encoder(format!(
                "{} frames in, {} packets out",
                self.pushed,
                self.samples.len()
            )));
        }
        let mut config = self.header;
        config.extend(self.sequence_header.unwrap_or_default());
        Ok(EncodedVideo {
            codec: Codec::Av1,
            width: self.width,
            height: self.height,
            fps: self.fps,
            config,
            samples: self.samples,
        })
    }

    fn drain(&mut self) -> Result<(), VideoError> {
        loop {
            match self.ctx.receive_packet() {
                Ok(pkt) => {
                    let key = pkt.frame_type == FrameType::KEY;
                    let (data, seq) = split_obus(&pkt.data);
                    if self.sequence_header.is_none() {
                        self.sequence_header = seq;
                    }
                    self.samples.push(Sample { data, key });
                }
                Err(EncoderStatus::Encoded) => {}
                Err(EncoderStatus::NeedMoreData | EncoderStatus::LimitReached) => return Ok(()),
                Err(e) => return Err(VideoError::Encoder(e.to_string())),
            }
        }
    }
}

/// rav1e's preset, less three costs that buy little on small robot-camera frames without
/// rav1e's assembly: scene-cut detection (key frames come every `key_interval` anyway), CDEF
/// and psychovisual tuning. Measured on 400 recorded 128×128 frames at speed 10: 131 → 226
/// frames/s on one core for 5% more bytes.
fn speed_settings(speed: u8) -> SpeedSettings {
    let mut s = SpeedSettings::from_preset(speed.min(10));
    s.scene_detection_mode = SceneDetectionSpeed::None;
    s.cdef = false;
    s
}

/// The packet without temporal delimiters (ISO-BMFF samples carry none), and its sequence
/// header OBU if it has one (for `av1C`'s configOBUs).
fn split_obus(packet: &[u8]) -> (Vec<u8>, Option<Vec<u8>>) {
    let mut out = Vec::with_capacity(packet.len());
    let mut seq = None;
    let mut at = 0;
    while at < packet.len() {
        let Some(len) = obu_len(&packet[at..]) else {
            // Not parseable as sized OBUs: keep the rest as it is.
            out.extend_from_slice(&packet[at..]);
            break;
        };
        let obu = &packet[at..at + len];
        match (obu[0] >> 3) & 0x0f {
            OBU_TEMPORAL_DELIMITER => {}
            OBU_SEQUENCE_HEADER => {
                seq.get_or_insert_with(|| obu.to_vec());
                out.extend_from_slice(obu);
            }
            _ => out.extend_from_slice(obu),
        }
        at += len;
    }
    (out, seq)
}

/// Total length of the OBU at the start of `b` (header, optional extension, leb128 size,
/// payload); `None` when it has no size field or runs past the end.
fn obu_len(b: &[u8]) -> Option<usize> {
    let h = *b.first()?;
    let has_ext = h & 0x04 != 0;
    let has_size = h & 0x02 != 0;
    if !has_size {
        return None;
    }
    let mut at = 1 + usize::from(has_ext);
    let mut size: usize = 0;
    for i in 0..8 {
        let byte = *b.get(at)?;
        at += 1;
        size |= usize::from(byte & 0x7f) << (7 * i);
        if byte & 0x80 == 0 {
            let total = at.checked_add(size)?;
            return (total <= b.len()).then_some(total);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporal_delimiters_are_dropped_and_the_sequence_header_kept() {
        // TD (type 2, size 0), sequence header (type 1, 2 bytes), frame (type 6, 1 byte).
        let pkt = [0x12, 0x00, 0x0a, 0x02, 0xaa, 0xbb, 0x32, 0x01, 0xcc];
        let (data, seq) = split_obus(&pkt);
        assert_eq!(data, vec![0x0a, 0x02, 0xaa, 0xbb, 0x32, 0x01, 0xcc]);
        assert_eq!(seq, Some(vec![0x0a, 0x02, 0xaa, 0xbb]));
    }

    #[test]
    fn every_frame_becomes_one_sample_starting_with_a_key_frame() {
        let settings = VideoSettings {
            key_interval: 4,
            ..VideoSettings::default()
        };
        assert!(
            Av1Encoder::new(18, 14, 10, settings).is_err(),
            "rav1e's minimum is 16"
        );
        // Odd sizes: chroma planes round up.
        let mut enc = Av1Encoder::new(17, 19, 10, settings).unwrap();
        for i in 0..9u8 {
            let rgb: Vec<u8> = (0..17 * 19 * 3).map(|k| (k as u8).wrapping_mul(i)).collect();
            enc.push_rgb(&rgb).unwrap();
        }
        assert!(enc.push_rgb(&[0; 5]).is_err());
        let v = enc.finish().unwrap();
        assert_eq!(v.samples.len(), 9);
        assert!(v.samples[0].key);
        assert!(
            v.samples.iter().filter(|s| s.key).count() >= 3,
            "a key frame every 4"
        );
        assert_eq!(v.config[0], 0x81, "av1C marker and version");
        assert_eq!((v.config[4] >> 3) & 0x0f, OBU_SEQUENCE_HEADER);
    }
}
