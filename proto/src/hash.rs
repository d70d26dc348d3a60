//! FNV-1a, a tiny stable hash for content identity (not for integrity: chunks use CRC-32).

/// An FNV-1a 64-bit hasher.
pub struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a {
    /// Hashes `bytes`.
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// Hashes each value's bit pattern, little-endian (so −0.0 and 0.0 differ).
    pub fn write_f32s(&mut self, v: &[f32]) {
        for x in v {
            self.write(&x.to_bits().to_le_bytes());
        }
    }

    /// The hash of everything written so far.
    pub fn finish(&self) -> u64 {
        self.0
    }
}
