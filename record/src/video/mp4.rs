//! A minimal ISO-BMFF (MP4) writer for one video track, AV1 ("AV1 Codec ISO Media File Format
//! Binding" v1.2.0: `av01` with `av1C`) or H.264 (ISO/IEC 14496-15: `avc1` with `avcC`):
//! `ftyp`, `moov` before `mdat` ("fast start"), all samples in one chunk.
//!
//! The media timescale is `fps * 512` with every sample lasting 512 ticks (ffmpeg's choice for
//! constant-rate video), so frame `k` starts at exactly `k / fps` seconds: LeRobot looks frames
//! up by timestamp.

use super::{Codec, EncodedVideo};

/// Ticks per frame; see the module doc.
const TICKS_PER_FRAME: u32 = 512;

/// `colr` `nclx` values (ISO/IEC 23091-2): BT.601 525 primaries, transfer and matrix, limited
/// range — what the encoder converts with and signals in the sequence header.
const NCLX_BT601: u16 = 6;

pub(super) fn mux(v: &EncodedVideo) -> Vec<u8> {
    let ftyp = ftyp(v.codec);
    let payload: usize = v.samples.iter().map(|s| s.data.len()).sum();
    // The chunk offset depends on moov's size, which depends on whether offsets need 64 bits.
    let wide = ftyp.len() + payload + 4096 + 64 * v.samples.len() > u32::MAX as usize;
    let probe = moov(v, 0, wide);
    let mdat_header = if payload + 8 > u32::MAX as usize { 16 } else { 8 };
    let offset = (ftyp.len() + probe.len() + mdat_header) as u64;
    let moov = moov(v, offset, wide);
    debug_assert_eq!(moov.len(), probe.len());
    let mut out = Vec::with_capacity(offset as usize + payload);
    out.extend(ftyp);
    out.extend(moov);
    if mdat_header == 16 {
        out.extend(1u32.to_be_bytes());
        out.extend(*b"mdat");
        out.extend((payload as u64 + 16).to_be_bytes());
    } else {
        out.extend((payload as u32 + 8).to_be_bytes());
        out.extend(*b"mdat");
    }
    for s in &v.samples {
        out.extend_from_slice(&s.data);
    }
    out
}

/// A box: size, type, body.
fn bx(kind: &[u8; 4], body: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(body.len() + 8);
    out.extend((body.len() as u32 + 8).to_be_bytes());
    out.extend(kind);
    out.extend(body);
    out
}

/// A full box: version and flags, then body.
fn full(kind: &[u8; 4], version: u8, flags: u32, body: &[u8]) -> Vec<u8> {
    let mut b = Vec::with_capacity(body.len() + 4);
    b.extend(((u32::from(version) << 24) | (flags & 0xff_ffff)).to_be_bytes());
    b.extend(body);
    bx(kind, &b)
}

/// Concatenated boxes.
fn cat(parts: &[Vec<u8>]) -> Vec<u8> {
    parts.concat()
}

#[derive(Default)]
struct Body(Vec<u8>);

impl Body {
    fn u8(mut self, v: u8) -> Self {
        self.0.push(v);
        self
    }
    fn u16(mut self, v: u16) -> Self {
        self.0.extend(v.to_be_bytes());
        self
    }
    fn u32(mut self, v: u32) -> Self {
        self.0.extend(v.to_be_bytes());
        self
    }
    fn u64(mut self, v: u64) -> Self {
        self.0.extend(v.to_be_bytes());
        self
    }
    fn zeros(mut self, n: usize) -> Self {
        self.0.extend(std::iter::repeat_n(0u8, n));
        self
    }
    fn bytes(mut self, b: &[u8]) -> Self {
        self.0.extend_from_slice(b);
        self
    }
    /// The identity transformation matrix of `mvhd`/`tkhd`.
    fn matrix(self) -> Self {
        [0x0001_0000u32, 0, 0, 0, 0x0001_0000, 0, 0, 0, 0x4000_0000]
            .into_iter()
            .fold(self, |b, v| b.u32(v))
    }
}

fn ftyp(codec: Codec) -> Vec<u8> {
    let brand = match codec {
        Codec::Av1 => b"av01",
        Codec::H264 => b"avc1",
    };
    let body = Body::default()
        .bytes(b"isom")
        .u32(0x200)
        .bytes(b"isom")
        .bytes(b"iso6")
        .bytes(brand)
        .bytes(b"mp41");
    bx(b"ftyp", &body.0)
}

fn moov(v: &EncodedVideo, offset: u64, wide: bool) -> Vec<u8> {
    let timescale = v.fps * TICKS_PER_FRAME;
    let duration = v.samples.len() as u32 * TICKS_PER_FRAME;
    let mvhd = Body::default()
        .u32(0)
        .u32(0)
        .u32(timescale)
        .u32(duration)
        .u32(0x0001_0000) // rate 1.0
        .u16(0x0100) // volume 1.0
        .zeros(10)
        .matrix()
        .zeros(24)
        .u32(2); // next track id
    let tkhd = Body::default()
        .u32(0)
        .u32(0)
        .u32(1) // track id
        .u32(0)
        .u32(duration)
        .zeros(8)
        .u16(0) // layer
        .u16(0) // alternate group
        .u16(0) // volume: video
        .u16(0)
        .matrix()
        .u32(v.width << 16)
        .u32(v.height << 16);
    let mdhd = Body::default()
        .u32(0)
        .u32(0)
        .u32(timescale)
        .u32(duration)
        .u16(0x55c4) // "und"
        .u16(0);
    let hdlr = Body::default()
        .u32(0)
        .bytes(b"vide")
        .zeros(12)
        .bytes(b"VideoHandler\0");
    let dref = full(
        b"dref",
        0,
        0,
        &cat(&[1u32.to_be_bytes().to_vec(), full(b"url ", 0, 1, &[])]),
    );
    let minf = bx(
        b"minf",
        &cat(&[
            full(b"vmhd", 0, 1, &[0; 8]),
            bx(b"dinf", &dref),
            bx(b"stbl", &stbl(v, offset, wide)),
        ]),
    );
    let mdia = bx(
        b"mdia",
        &cat(&[full(b"mdhd", 0, 0, &mdhd.0), full(b"hdlr", 0, 0, &hdlr.0), minf]),
    );
    let trak = bx(b"trak", &cat(&[full(b"tkhd", 0, 3, &tkhd.0), mdia]));
    bx(b"moov", &cat(&[full(b"mvhd", 0, 0, &mvhd.0), trak]))
}

fn stbl(v: &EncodedVideo, offset: u64, wide: bool) -> Vec<u8> {
    let n = v.samples.len() as u32;
    let mut compressor = [0u8; 32];
    let (entry, config, name): (&[u8; 4], &[u8; 4], &[u8]) = match v.codec {
        Codec::Av1 => (b"av01", b"av1C", b"AOM Coding (rav1e)"),
        Codec::H264 => (b"avc1", b"avcC", b"AVC Coding (OpenH264)"),
    };
    compressor[0] = name.len() as u8;
    compressor[1..=name.len()].copy_from_slice(name);
    let colr = Body::default()
        .bytes(b"nclx")
        .u16(NCLX_BT601)
        .u16(NCLX_BT601)
        .u16(NCLX_BT601)
        .u8(0); // limited range
    let sample_entry = Body::default()
        .zeros(6)
        .u16(1) // data reference index
        .zeros(16)
        .u16(v.width as u16)
        .u16(v.height as u16)
        .u32(0x0048_0000) // 72 dpi
        .u32(0x0048_0000)
        .u32(0)
        .u16(1) // frame count
        .bytes(&compressor)
        .u16(0x0018) // depth
        .u16(0xffff) // pre_defined = -1
        .bytes(&bx(config, &v.config))
        .bytes(&bx(b"colr", &colr.0));
    let stsd = Body::default().u32(1).bytes(&bx(entry, &sample_entry.0));
    let stts = if n == 0 {
        Body::default().u32(0)
    } else {
        Body::default().u32(1).u32(n).u32(TICKS_PER_FRAME)
    };
    let keys: Vec<u32> = (1..=n)
        .zip(&v.samples)
        .filter_map(|(i, s)| s.key.then_some(i))
        .collect();
    let stss = keys
        .iter()
        .fold(Body::default().u32(keys.len() as u32), |b, k| b.u32(*k));
    let stsc = if n == 0 {
        Body::default().u32(0)
    } else {
        Body::default().u32(1).u32(1).u32(n).u32(1)
    };
    let stsz = v
        .samples
        .iter()
        .fold(Body::default().u32(0).u32(n), |b, s| b.u32(s.data.len() as u32));
    let chunks = u32::from(n > 0);
    let offsets = if wide {
        let b = Body::default().u32(chunks);
        full(b"co64", 0, 0, &if n > 0 { b.u64(offset) } else { b }.0)
    } else {
        let b = Body::default().u32(chunks);
        full(b"stco", 0, 0, &if n > 0 { b.u32(offset as u32) } else { b }.0)
    };
    cat(&[
        full(b"stsd", 0, 0, &stsd.0),
        full(b"stts", 0, 0, &stts.0),
        full(b"stss", 0, 0, &stss.0),
        full(b"stsc", 0, 0, &stsc.0),
        full(b"stsz", 0, 0, &stsz.0),
        offsets,
    ])
}

#[cfg(test)]
mod tests {
    use super::super::{EncodedVideo, Sample};
    use super::*;

    /// Top-level boxes as (type, start, size).
    fn boxes(b: &[u8]) -> Vec<(String, usize, usize)> {
        let mut out = Vec::new();
        let mut at = 0;
        while at + 8 <= b.len() {
            let size = u32::from_be_bytes(b[at..at + 4].try_into().unwrap()) as usize;
            out.push((String::from_utf8_lossy(&b[at + 4..at + 8]).into(), at, size));
            at += size;
        }
        out
    }

    #[test]
    fn moov_comes_first_and_the_chunk_offset_points_at_the_samples() {
        let v = EncodedVideo {
            codec: Codec::Av1,
            width: 4,
            height: 2,
            fps: 10,
            config: vec![0x81, 0, 0x0c, 0],
            samples: vec![
                Sample {
                    data: vec![1, 2, 3],
                    key: true,
                },
                Sample {
                    data: vec![4, 5],
                    key: false,
                },
            ],
        };
        let b = mux(&v);
        let top = boxes(&b);
        let kinds: Vec<&str> = top.iter().map(|t| t.0.as_str()).collect();
        assert_eq!(kinds, ["ftyp", "moov", "mdat"]);
        assert_eq!(top.iter().map(|t| t.2).sum::<usize>(), b.len());
        let stco = b.windows(4).position(|w| w == b"stco").unwrap();
        let offset = u32::from_be_bytes(b[stco + 12..stco + 16].try_into().unwrap()) as usize;
        assert_eq!(&b[offset..offset + 5], &[1, 2, 3, 4, 5]);
        let stss = b.windows(4).position(|w| w == b"stss").unwrap();
        assert_eq!(&b[stss + 8..stss + 16], &[0, 0, 0, 1, 0, 0, 0, 1]);
    }
}
