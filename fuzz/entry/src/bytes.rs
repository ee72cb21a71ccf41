//! Reads fuzzer bytes as values, so that each target sees structured input without a derive.

/// Takes values off the front of the fuzzer's bytes; zeros once they run out.
pub struct Bytes<'a>(pub &'a [u8]);

impl Bytes<'_> {
    /// The next byte.
    pub fn u8(&mut self) -> u8 {
        let Some((&b, rest)) = self.0.split_first() else {
            return 0;
        };
        self.0 = rest;
        b
    }

    /// The next four bytes, little-endian.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }

    /// A value below `n` (n > 0), small values likely.
    pub fn below(&mut self, n: u32) -> u32 {
        if self.u8() & 1 == 0 {
            u32::from(self.u8()) % n
        } else {
            self.u32() % n
        }
    }

    /// A float: special values (NaN, infinities, zero, huge) or one from the bytes.
    pub fn f64(&mut self) -> f64 {
        match self.u8() % 8 {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => -1e30,
            3 => 0.0,
            _ => f64::from(self.u32() as i32) / 1024.0,
        }
    }

    /// What is left.
    pub fn rest(&mut self) -> &[u8] {
        std::mem::take(&mut self.0)
    }
}

/// The FFI's contract: a typed error for bad input, never `Internal` (a caught panic).
pub fn typed<T>(what: &str, r: Result<T, monotrack_ffi::MonotrackError>) {
    if let Err(monotrack_ffi::MonotrackError::Internal { msg }) = r {
        panic!("{what}: internal error (a caught panic): {msg}");
    }
}
