//! The H.264 encoder: RGB8 → YUV 4:2:0 (the same conversion as AV1's) → Cisco's OpenH264,
//! built from source by the `openh264` crate.
//!
//! About twelve times faster than rav1e on our small frames (docs/measured/video.md), which is what
//! lets a failing policy's ten-minute episode video render within a request's patience and LeRobot
//! export keep up with the simulator. The settings make the stream a pure function of the
//! frames, as the episodes are:
//! - rate control either off (every frame at OpenH264's base QP 26, with its adaptive
//!   quantisation) or by bit rate over the frames' own timestamps (`h264_kbps`), never the
//!   wall clock; frame skipping is off, so there is one sample per frame;
//! - one thread (more would cut the frame into slices by core count);
//! - a fixed SPS/PPS id, so every IDR frame repeats the same parameter sets and clips encoded
//!   apart can be joined ([`super::EncodedVideo::concat`]).
//!
//! OpenH264 writes Annex B (start codes); MP4 wants each NAL unit length-prefixed and the
//! parameter sets in the `avcC` box, so [`avcc_sample`] and [`avc_config`] convert.

use openh264::OpenH264API;
use openh264::Timestamp;
use openh264::encoder::{
    BitRate, Complexity, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, RateControlMode,
    SpsPpsStrategy, UsageType, VuiConfig,
};
use openh264::formats::YUVSlices;

use super::yuv::{chroma_size, rgb_to_yuv420};
use super::{Codec, EncodedVideo, Sample, VideoError, VideoSettings};

/// NAL unit types (H.264 Table 7-1) that go into `avcC` rather than into samples.
const NAL_SPS: u8 = 7;
const NAL_PPS: u8 = 8;

/// Encodes RGB8 frames of one size at one frame rate into an H.264 [`EncodedVideo`].
pub(super) struct H264Encoder {
    enc: Encoder,
    width: u32,
    height: u32,
    fps: u32,
    sps: Option<Vec<u8>>,
    pps: Option<Vec<u8>>,
    samples: Vec<Sample>,
    yuv: [Vec<u8>; 3],
}

impl std::fmt::Debug for H264Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("H264Encoder")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("fps", &self.fps)
            .field("frames", &self.samples.len())
            .finish()
    }
}

impl H264Encoder {
    /// An encoder for `width`×`height` frames (even, at least 16) at `fps`.
    pub(super) fn new(width: u32, height: u32, fps: u32, s: VideoSettings) -> Result<Self, VideoError> {
        if width < 16 || height < 16 || fps == 0 || width % 2 == 1 || height % 2 == 1 {
            return Err(VideoError::Config(format!(
                "{width}x{height} at {fps} fps: H.264 frames must be at least 16x16 with an even width \
                 and height, and fps positive (choose an even camera size, or the AV1 codec)"
            )));
        }
        if width > 3840 || height > 2160 {
            return Err(VideoError::Config(format!(
                "{width}x{height}: OpenH264 encodes at most 3840x2160"
            )));
        }
        let config = EncoderConfig::new()
            .usage_type(UsageType::CameraVideoRealTime)
            .debug(false)
            .rate_control_mode(match s.h264_kbps {
                0 => RateControlMode::Off,
                _ => RateControlMode::Bitrate,
            })
            // With frame skipping off, OpenH264 warns once on stderr at start that it cannot
            // hold the bit rate exactly; it holds it within a few percent through the QP
            // (59 kbit/s measured for 60), and skipping frames would break one sample a frame.
            // The warning comes before the crate applies `debug(false)`, and silencing it
            // would take the raw API's `unsafe`, which the workspace forbids.
            .bitrate(BitRate::from_bps(s.h264_kbps.saturating_mul(1000).max(1000)))
            .skip_frames(false)
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            .sps_pps_strategy(SpsPpsStrategy::ConstantId)
            .complexity(Complexity::Low)
            .scene_change_detect(false)
            .intra_frame_period(IntraFramePeriod::from_num_frames(s.key_interval.max(1)))
            .num_threads(1)
            .vui(VuiConfig::bt601());
        let enc = Encoder::with_api_config(OpenH264API::from_source(), config)
            .map_err(|e| VideoError::Config(e.to_string()))?;
        let (cw, ch) = chroma_size(width, height);
        Ok(H264Encoder {
            enc,
            width,
            height,
            fps,
            sps: None,
            pps: None,
            samples: Vec::new(),
            yuv: [
                vec![0; (width * height) as usize],
                vec![0; cw * ch],
                vec![0; cw * ch],
            ],
        })
    }

    /// Add a frame: `rgb` is `width * height * 3` bytes, row-major.
    pub(super) fn push_rgb(&mut self, rgb: &[u8]) -> Result<(), VideoError> {
        let index = self.samples.len();
        let (w, h) = (self.width as usize, self.height as usize);
        if rgb.len() != 3 * w * h {
            return Err(VideoError::Frame {
                index,
                message: format!("{} bytes for {w}x{h} RGB8 (want {})", rgb.len(), 3 * w * h),
            });
        }
        rgb_to_yuv420(rgb, w, h, &mut self.yuv);
        let source = YUVSlices::new(
            (&self.yuv[0], &self.yuv[1], &self.yuv[2]),
            (w, h),
            (w, w / 2, w / 2),
        );
        let millis = index as u64 * 1000 / u64::from(self.fps);
        let stream = self
            .enc
            .encode_at(&source, Timestamp::from_millis(millis))
            .map_err(|e| VideoError::Encoder(e.to_string()))?;
        let key = stream.frame_type() == FrameType::IDR;
        let mut nals = Vec::new();
        for l in 0..stream.num_layers() {
            let Some(layer) = stream.layer(l) else { continue };
            for n in 0..layer.nal_count() {
                if let Some(nal) = layer.nal_unit(n) {
                    nals.push(strip_start_code(nal).to_vec());
                }
            }
        }
        let data = avcc_sample(&nals, &mut self.sps, &mut self.pps);
        if data.is_empty() {
            return Err(VideoError::Frame {
                index,
                message: format!("OpenH264 coded no picture ({:?} frame)", stream.frame_type()),
            });
        }
        self.samples.push(Sample { data, key });
        Ok(())
    }

    /// The clip (OpenH264 holds no frames back, so there is nothing to flush).
    pub(super) fn finish(self) -> Result<EncodedVideo, VideoError> {
        let (Some(sps), Some(pps)) = (&self.sps, &self.pps) else {
            return Err(VideoError::Encoder(
                "no parameter sets: no frame was encoded".into(),
            ));
        };
        Ok(EncodedVideo {
            codec: Codec::H264,
            width: self.width,
            height: self.height,
            fps: self.fps,
            config: avc_config(sps, pps),
            samples: self.samples,
        })
    }
}

/// The NAL unit without its Annex B start code (`00 00 01` or `00 00 00 01`).
fn strip_start_code(nal: &[u8]) -> &[u8] {
    if nal.starts_with(&[0, 0, 0, 1]) {
        &nal[4..]
    } else if nal.starts_with(&[0, 0, 1]) {
        &nal[3..]
    } else {
        nal
    }
}

/// One MP4 sample: every NAL unit but the parameter sets, each after its 4-byte length; the
/// first SPS and PPS seen are kept for `avcC` (ConstantId repeats the same ones at each IDR).
fn avcc_sample(nals: &[Vec<u8>], sps: &mut Option<Vec<u8>>, pps: &mut Option<Vec<u8>>) -> Vec<u8> {
    let mut out = Vec::new();
    for nal in nals {
        let Some(&header) = nal.first() else { continue };
        match header & 0x1f {
            NAL_SPS => {
                sps.get_or_insert_with(|| nal.clone());
            }
            NAL_PPS => {
                pps.get_or_insert_with(|| nal.clone());
            }
            _ => {
                out.extend((nal.len() as u32).to_be_bytes());
                out.extend_from_slice(nal);
            }
        }
    }
    out
}

/// The `avcC` box payload (ISO/IEC 14496-15 5.3.3.1): profile and level from the SPS, 4-byte
/// NAL lengths, one SPS and one PPS. OpenH264 codes the Baseline profile, so no High-profile
/// chroma fields follow.
fn avc_config(sps: &[u8], pps: &[u8]) -> Vec<u8> {
    let byte = |i: usize| sps.get(i).copied().unwrap_or(0);
    let mut c = vec![1, byte(1), byte(2), byte(3), 0xfc | 3, 0xe0 | 1];
    c.extend((sps.len() as u16).to_be_bytes());
    c.extend_from_slice(sps);
    c.push(1);
    c.extend((pps.len() as u16).to_be_bytes());
    c.extend_from_slice(pps);
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(n: u8, w: usize, h: usize) -> Vec<Vec<u8>> {
        (0..n)
            .map(|i| {
                (0..w * h * 3)
                    .map(|k| ((k / 3 % w + i as usize * 3) as u8).wrapping_mul(5))
                    .collect()
            })
            .collect()
    }

    fn encode(settings: VideoSettings) -> EncodedVideo {
        let mut enc = H264Encoder::new(32, 18, 10, settings).unwrap();
        for f in frames(9, 32, 18) {
            enc.push_rgb(&f).unwrap();
        }
        enc.finish().unwrap()
    }

    #[test]
    fn every_frame_becomes_one_length_prefixed_sample_and_key_frames_follow_the_interval() {
        let v = encode(VideoSettings {
            key_interval: 4,
            ..VideoSettings::h264()
        });
        assert_eq!(v.samples.len(), 9);
        assert!(v.samples[0].key);
        assert!(
            v.samples.iter().filter(|s| s.key).count() >= 3,
            "a key frame every 4"
        );
        for s in &v.samples {
            // Walk the length prefixes: they must cover the sample exactly, with no start code.
            let mut at = 0;
            while at < s.data.len() {
                let len = u32::from_be_bytes(s.data[at..at + 4].try_into().unwrap()) as usize;
                assert_ne!(s.data[at + 4] & 0x1f, NAL_SPS, "parameter sets live in avcC");
                at += 4 + len;
            }
            assert_eq!(at, s.data.len());
        }
        assert_eq!(v.config[0], 1, "avcC version");
        assert_eq!(v.config[4], 0xff, "4-byte NAL lengths");
        assert_eq!(v.config[8] & 0x1f, NAL_SPS);
    }

    #[test]
    fn the_same_frames_give_the_same_bytes_with_and_without_rate_control() {
        for s in [
            VideoSettings::h264(),
            VideoSettings {
                h264_kbps: 20,
                ..VideoSettings::h264()
            },
        ] {
            assert_eq!(encode(s), encode(s));
        }
    }

    #[test]
    fn odd_and_tiny_sizes_are_refused_with_what_to_do() {
        let e = H264Encoder::new(17, 18, 10, VideoSettings::h264()).unwrap_err();
        assert!(e.to_string().contains("even width"), "{e}");
        assert!(H264Encoder::new(14, 14, 10, VideoSettings::h264()).is_err());
        let mut enc = H264Encoder::new(16, 16, 10, VideoSettings::h264()).unwrap();
        assert!(enc.push_rgb(&[0; 5]).is_err());
    }

    #[test]
    fn annex_b_start_codes_are_stripped() {
        assert_eq!(strip_start_code(&[0, 0, 0, 1, 0x65, 9]), &[0x65, 9]);
        assert_eq!(strip_start_code(&[0, 0, 1, 0x41]), &[0x41]);
        let mut sps = None;
        let mut pps = None;
        let out = avcc_sample(
            &[vec![0x67, 1, 2, 3], vec![0x68, 4], vec![0x65, 7, 7]],
            &mut sps,
            &mut pps,
        );
        assert_eq!(out, vec![0, 0, 0, 3, 0x65, 7, 7]);
        assert_eq!(
            avc_config(sps.as_deref().unwrap(), pps.as_deref().unwrap())[1..4],
            [1, 2, 3]
        );
    }
}
