//! Our own container for an encoded clip between episode end and the MP4 that joins a batch of
//! episodes: a magic naming the codec, a header, the decoder configuration (`av1C` or `avcC`
//! payload), then `(key, length, bytes)` per sample. Little endian; not meant for other tools.

use std::path::Path;

use super::{Codec, EncodedVideo, Sample, VideoError};

/// One magic per codec (AV1's is the format's first one, so older staged clips still load).
const MAGIC_AV1: &[u8; 8] = b"KRAV1\0\0\x01";
const MAGIC_H264: &[u8; 8] = b"KRH264\0\x01";

fn magic(codec: Codec) -> &'static [u8; 8] {
    match codec {
        Codec::Av1 => MAGIC_AV1,
        Codec::H264 => MAGIC_H264,
    }
}

pub(super) fn save(v: &EncodedVideo, path: &Path) -> Result<(), VideoError> {
    let payload: usize = v.samples.iter().map(|s| s.data.len() + 5).sum();
    let mut out = Vec::with_capacity(payload + v.config.len() + 32);
    out.extend(magic(v.codec));
    for x in [
        v.width,
        v.height,
        v.fps,
        v.config.len() as u32,
        v.samples.len() as u32,
    ] {
        out.extend(x.to_le_bytes());
    }
    out.extend(&v.config);
    for s in &v.samples {
        out.push(u8::from(s.key));
        out.extend((s.data.len() as u32).to_le_bytes());
        out.extend(&s.data);
    }
    std::fs::write(path, out).map_err(|source| VideoError::Io {
        path: path.to_path_buf(),
        source,
    })
}

pub(super) fn load(path: &Path) -> Result<EncodedVideo, VideoError> {
    let b = std::fs::read(path).map_err(|source| VideoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&b).ok_or_else(|| VideoError::Stored {
        path: path.to_path_buf(),
        message: "truncated or wrong magic".into(),
    })
}

fn parse(b: &[u8]) -> Option<EncodedVideo> {
    let mut at: usize = 0;
    let mut take = |n: usize| -> Option<&[u8]> {
        let s = b.get(at..at.checked_add(n)?)?;
        at += n;
        Some(s)
    };
    let head = take(8)?;
    let codec = [Codec::Av1, Codec::H264]
        .into_iter()
        .find(|c| head == magic(*c))?;
    let mut word = || -> Option<u32> { Some(u32::from_le_bytes(take(4)?.try_into().ok()?)) };
    let (width, height, fps, config_len, n) = (word()?, word()?, word()?, word()?, word()?);
    let config = take(config_len as usize)?.to_vec();
    let mut samples = Vec::with_capacity(n as usize);
    for _ in 0..n {
        let key = take(1)?[0] != 0;
        let len = u32::from_le_bytes(take(4)?.try_into().ok()?) as usize;
        samples.push(Sample {
            data: take(len)?.to_vec(),
            key,
        });
    }
    (at == b.len()).then_some(EncodedVideo {
        codec,
        width,
        height,
        fps,
        config,
        samples,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_saved_clip_loads_back_equal_and_a_truncated_one_is_refused() {
        for codec in [Codec::Av1, Codec::H264] {
            saved_clip_round_trips(codec);
        }
    }

    fn saved_clip_round_trips(codec: Codec) {
        let v = EncodedVideo {
            codec,
            width: 6,
            height: 4,
            fps: 10,
            config: vec![0x81, 1, 2, 3, 9],
            samples: vec![
                Sample {
                    data: vec![7; 11],
                    key: true,
                },
                Sample {
                    data: vec![],
                    key: false,
                },
            ],
        };
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("clip.krav1");
        save(&v, &p).unwrap();
        assert_eq!(load(&p).unwrap(), v);
        let b = std::fs::read(&p).unwrap();
        assert!(parse(&b[..b.len() - 1]).is_none());
    }
}
