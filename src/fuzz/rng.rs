//! The fuzzer's random stream: SplitMix64, written out here rather than
//! taken from a crate, because `rendiff fuzz --seed S` promises the same
//! scene files byte for byte forever, and general-purpose generators
//! (rand's `StdRng` among them) reserve the right to change their stream
//! between versions. Every number the grammar draws comes from integer
//! arithmetic and exact float operations (no `powf`, `sin`, `tan`: libm's
//! last bit differs between platforms), so a seed names the same scenes on
//! every machine.

/// A seeded SplitMix64 stream (Steele, Lea and Flood, 2014): 64-bit state,
/// every state visited once per period of 2^64, good enough statistics for
/// choosing shapes, and trivially reproducible.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// The stream of scene `index` of run `seed`: each scene has a stream of
    /// its own, so scene 7 of seed 3 is the same file whatever `--count` says.
    pub fn for_scene(seed: u64, index: u64) -> Rng {
        let mut r = Rng {
            state: seed ^ 0x6a09_e667_f3bc_c908,
        };
        let a = r.next_u64();
        Rng {
            state: a ^ index.wrapping_mul(0x9e37_79b9_7f4a_7c15),
        }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`, 53 random bits (exact).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform integer in `lo..=hi`.
    pub fn int(&mut self, lo: i64, hi: i64) -> i64 {
        debug_assert!(lo <= hi);
        let span = (hi - lo) as u64 + 1;
        lo + (self.next_u64() % span) as i64
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    /// One of `items`, uniformly.
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.int(0, items.len() as i64 - 1) as usize]
    }

    /// Log-uniform in `[2^lo, 2^hi)`: an integer power of two times a
    /// mantissa in `[1, 2)`, so that no `powf` is needed (see the module doc).
    pub fn log2_uniform(&mut self, lo: i32, hi: i32) -> f64 {
        let k = self.int(i64::from(lo), i64::from(hi) - 1) as i32;
        pow2(k) * (1.0 + self.unit())
    }

    /// -1 or +1.
    pub fn sign(&mut self) -> f64 {
        if self.chance(0.5) {
            -1.0
        } else {
            1.0
        }
    }
}

/// `2^k`, exactly (a power of two is built from its bits, never by `powi`).
pub fn pow2(k: i32) -> f64 {
    debug_assert!((-1022..=1023).contains(&k));
    f64::from_bits(((1023 + k) as u64) << 52)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stream_is_splitmix64_and_scenes_have_their_own() {
        // SplitMix64's published first output for state 0 (its `next` adds
        // the increment first): 0xe220a8397b1dcdaf.
        let mut r = Rng { state: 0 };
        assert_eq!(r.next_u64(), 0xe220_a839_7b1d_cdaf);
        let a: Vec<u64> = (0..4).map(|_| Rng::for_scene(3, 7).next_u64()).collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        assert_ne!(
            Rng::for_scene(3, 7).next_u64(),
            Rng::for_scene(3, 8).next_u64()
        );
        assert_ne!(
            Rng::for_scene(3, 7).next_u64(),
            Rng::for_scene(4, 7).next_u64()
        );
    }

    #[test]
    fn powers_and_ranges_are_exact_and_in_bounds() {
        assert_eq!(pow2(0), 1.0);
        assert_eq!(pow2(-3), 0.125);
        assert_eq!(pow2(10), 1024.0);
        let mut r = Rng::for_scene(1, 1);
        for _ in 0..10_000 {
            let x = r.log2_uniform(-4, 3);
            assert!((0.0625..8.0).contains(&x), "{x}");
            let i = r.int(-2, 5);
            assert!((-2..=5).contains(&i));
            let u = r.unit();
            assert!((0.0..1.0).contains(&u));
        }
    }
}
