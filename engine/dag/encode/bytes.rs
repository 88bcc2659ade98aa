//! Little-endian payload writer and a bounds-checked reader that names the offset of every error.

use super::{corrupt, EncodeError};

/// Appends little-endian values to a byte vector.
#[derive(Default)]
pub(crate) struct Writer {
    pub bytes: Vec<u8>,
}

impl Writer {
    pub fn u8(&mut self, v: u8) {
        self.bytes.push(v);
    }
    pub fn u16(&mut self, v: u16) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    pub fn u32(&mut self, v: u32) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    pub fn u64(&mut self, v: u64) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    pub fn u16s(&mut self, v: &[u16]) {
        self.bytes.reserve(v.len() * 2);
        for x in v {
            self.u16(*x);
        }
    }
    pub fn u64s(&mut self, v: &[u64]) {
        self.bytes.reserve(v.len() * 8);
        for x in v {
            self.u64(*x);
        }
    }
}

/// Reads little-endian values; every read checks the remaining length first.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
    pub at: usize,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Reader { bytes, at: 0 }
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], EncodeError> {
        if self.bytes.len() - self.at < n {
            return Err(corrupt(
                self.at as u64,
                format!(
                    "{what}: needs {n} bytes, {} left",
                    self.bytes.len() - self.at
                ),
            ));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    pub fn u8(&mut self, what: &str) -> Result<u8, EncodeError> {
        Ok(self.take(1, what)?[0])
    }
    pub fn u16(&mut self, what: &str) -> Result<u16, EncodeError> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    pub fn u32(&mut self, what: &str) -> Result<u32, EncodeError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes(b.try_into().expect("4 bytes")))
    }
    pub fn u64(&mut self, what: &str) -> Result<u64, EncodeError> {
        let b = self.take(8, what)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }
    /// Checks that `count` elements of `size` bytes remain before allocating them.
    fn check_len(&self, count: u64, size: u64, what: &str) -> Result<usize, EncodeError> {
        let left = (self.bytes.len() - self.at) as u64;
        match count.checked_mul(size) {
            Some(n) if n <= left => Ok(n as usize),
            _ => Err(corrupt(
                self.at as u64,
                format!("{what}: {count} entries of {size} bytes, only {left} bytes left"),
            )),
        }
    }
    pub fn u16s(&mut self, count: u64, what: &str) -> Result<Vec<u16>, EncodeError> {
        let n = self.check_len(count, 2, what)?;
        let b = self.take(n, what)?;
        Ok(b.chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect())
    }
    pub fn u64s(&mut self, count: u64, what: &str) -> Result<Vec<u64>, EncodeError> {
        let n = self.check_len(count, 8, what)?;
        let b = self.take(n, what)?;
        Ok(b.chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
    }
    pub fn finish(&self) -> Result<(), EncodeError> {
        if self.at != self.bytes.len() {
            return Err(corrupt(
                self.at as u64,
                format!("{} trailing bytes", self.bytes.len() - self.at),
            ));
        }
        Ok(())
    }
}
