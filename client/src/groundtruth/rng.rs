//! A small, fast, reproducible random number generator: PCG32 (O'Neill 2014, "PCG: A Family of
//! Simple Fast Space-Efficient Statistically Good Algorithms for Random Number Generation",
//! the `pcg32` XSH-RR variant), with SplitMix64 to derive independent seeds.
//!
//! Every pixel of a Monte Carlo image gets its own generator, seeded from (image seed, pixel
//! index, round), so images are bit-identical whatever the thread count or scheduling.

/// PCG32: 64-bit state, 32-bit output, selectable stream.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

const MUL: u64 = 6_364_136_223_846_793_005;

impl Pcg32 {
    /// A generator for `seed` on stream `stream` (distinct streams are independent sequences).
    pub fn new(seed: u64, stream: u64) -> Pcg32 {
        let mut r = Pcg32 {
            state: 0,
            inc: (stream << 1) | 1,
        };
        r.next_u32();
        r.state = r.state.wrapping_add(seed);
        r.next_u32();
        r
    }

    /// A generator for `(seed, key)`: `key` (e.g. a pixel index) is mixed into both the seed and
    /// the stream.
    pub(crate) fn for_key(seed: u64, key: u64) -> Pcg32 {
        Pcg32::new(splitmix64(seed ^ splitmix64(key)), key)
    }

    /// The next 32 random bits (PCG-XSH-RR) [ONeill14].
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MUL).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1) with 53 random bits.
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        let hi = u64::from(self.next_u32()) << 21;
        let lo = u64::from(self.next_u32()) >> 11;
        (hi | lo) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    #[inline]
    pub(crate) fn next_2d(&mut self) -> [f64; 2] {
        [self.next_f64(), self.next_f64()]
    }
}

/// SplitMix64's finaliser (Steele, Lea, Flood 2014): a bijective 64-bit mixer.
#[inline]
pub(crate) fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproducible_and_uniform() {
        let mut a = Pcg32::for_key(7, 3);
        let mut b = Pcg32::for_key(7, 3);
        let mut c = Pcg32::for_key(7, 4);
        let (mut same, mut sum) = (0, 0.0);
        for _ in 0..10_000 {
            let x = a.next_f64();
            assert_eq!(x, b.next_f64());
            assert!((0.0..1.0).contains(&x));
            if x == c.next_f64() {
                same += 1;
            }
            sum += x;
        }
        assert_eq!(same, 0);
        assert!((sum / 10_000.0 - 0.5).abs() < 0.01);
    }
}
