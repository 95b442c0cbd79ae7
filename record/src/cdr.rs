//! A minimal little-endian CDR (XCDR1) serializer, the payload encoding of ROS 2 messages.
//!
//! Alignment is relative to the start of the payload, after the 4-byte encapsulation header,
//! as ROS 2's Fast-CDR does; primitives align to their own size, strings carry a u32 length
//! that includes the terminating NUL, sequences a u32 element count.

pub(crate) struct CdrWriter {
    buf: Vec<u8>,
}

impl CdrWriter {
    pub(crate) fn with_capacity(n: usize) -> Self {
        let mut buf = Vec::with_capacity(n + 4);
        // CDR_LE encapsulation kind, options 0.
        buf.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
        CdrWriter { buf }
    }

    fn align(&mut self, n: usize) {
        let off = self.buf.len() - 4;
        let pad = (n - off % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    pub(crate) fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub(crate) fn bool(&mut self, v: bool) {
        self.buf.push(v as u8);
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A sequence length prefix.
    pub(crate) fn len(&mut self, n: usize) {
        self.u32(n as u32);
    }

    /// `uint8[]`.
    pub(crate) fn bytes(&mut self, b: &[u8]) {
        self.len(b.len());
        self.buf.extend_from_slice(b);
    }

    /// Bytes of a `uint8[]` whose length prefix was already written.
    pub(crate) fn u8_slice_raw(&mut self, b: &[u8]) {
        self.buf.extend_from_slice(b);
    }

    pub(crate) fn finish(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aligns_relative_to_payload_start() {
        let mut w = CdrWriter::with_capacity(0);
        w.u8(1);
        w.f64(2.0);
        let b = w.finish();
        // header (4) + u8 (1) + 7 padding + f64 (8)
        assert_eq!(b.len(), 4 + 16);
        assert_eq!(&b[12..20], &2.0f64.to_le_bytes());
    }

    #[test]
    fn strings_count_their_nul() {
        let mut w = CdrWriter::with_capacity(0);
        w.string("ab");
        assert_eq!(w.finish(), vec![0, 1, 0, 0, 3, 0, 0, 0, b'a', b'b', 0]);
    }
}
