//! Gzip for traces: a trace is JSON of many similar numbers and compresses about 7x, so it is
//! uploaded, stored and downloaded gzipped. A decompressed trace is capped, so a small upload
//! cannot expand into gigabytes on the machine that reads it.

use std::io::{Read, Write};

use flate2::Compression;
use flate2::read::GzDecoder;
use flate2::write::GzEncoder;

/// Largest trace accepted once decompressed (a failing policy's dev episode is about 2 MB).
pub const MAX_JSON_BYTES: u64 = 256 << 20;

/// Whether `bytes` start with the gzip magic number.
pub fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0x1f, 0x8b])
}

/// `bytes` gzipped (default level: traces are small, and the level barely changes their size).
pub fn compress(bytes: &[u8]) -> Vec<u8> {
    let mut enc = GzEncoder::new(Vec::with_capacity(bytes.len() / 4), Compression::default());
    // Writing to memory cannot fail.
    let _ = enc.write_all(bytes);
    enc.finish().unwrap_or_default()
}

/// `gz` decompressed, refused past [`MAX_JSON_BYTES`].
pub fn decompress(gz: &[u8]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    GzDecoder::new(gz)
        .take(MAX_JSON_BYTES + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("not a gzipped trace: {e}"))?;
    if out.len() as u64 > MAX_JSON_BYTES {
        return Err(format!("the trace is over {MAX_JSON_BYTES} bytes decompressed"));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gzip_round_trips_and_is_told_from_plain_json() {
        let json = br#"{"format":"kitchen-r-trace"}"#.repeat(100);
        let gz = compress(&json);
        assert!(is_gzip(&gz) && !is_gzip(&json));
        assert!(gz.len() < json.len() / 10);
        assert_eq!(decompress(&gz).unwrap(), json);
        assert!(decompress(b"\x1f\x8bnot gzip").is_err());
    }
}
