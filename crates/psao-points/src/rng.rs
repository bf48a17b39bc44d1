//! Counter-based randomness: every random number is a pure function of (seed, stream, counter),
//! so results never depend on thread scheduling.

/// SplitMix64 finaliser: a bijective 64-bit mixer with good avalanche.
#[inline]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash two words into one (order matters).
#[cfg(feature = "generate")]
#[inline]
pub(crate) fn hash2(a: u64, b: u64) -> u64 {
    mix64(mix64(a ^ 0x9E37_79B9_7F4A_7C15).wrapping_add(b))
}

/// A tiny SplitMix64 stream seeded from a hash.
#[cfg(feature = "generate")]
pub(crate) struct Stream(u64);

#[cfg(feature = "generate")]
impl Stream {
    /// Stream number `counter` of generator `seed`.
    #[inline]
    pub(crate) fn new(seed: u64, counter: u64) -> Self {
        Self(hash2(seed, counter))
    }

    #[inline]
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// Uniform in [0, 1) with 24 bits of resolution.
    #[inline]
    pub(crate) fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Uniform in [0, 1) with 53 bits of resolution.
    #[inline]
    pub(crate) fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

#[cfg(all(test, feature = "generate"))]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<f32> = {
            let mut s = Stream::new(7, 3);
            (0..8).map(|_| s.next_f32()).collect()
        };
        let b: Vec<f32> = {
            let mut s = Stream::new(7, 3);
            (0..8).map(|_| s.next_f32()).collect()
        };
        let c: Vec<f32> = {
            let mut s = Stream::new(7, 4);
            (0..8).map(|_| s.next_f32()).collect()
        };
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(a.iter().all(|x| (0.0..1.0).contains(x)));
    }

    #[test]
    fn uniform_mean_is_one_half() {
        let mut s = Stream::new(1, 0);
        let n = 100_000;
        let mean: f64 = (0..n).map(|_| s.next_f64()).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
    }
}
