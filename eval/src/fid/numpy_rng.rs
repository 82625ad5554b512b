//! numpy's legacy `np.random.RandomState(seed)`, as far as KID needs it: the MT19937 stream and
//! `choice(n, size, replace=False)`, drawing the same indices as numpy so that our KID subsets are
//! torch-fidelity's (held to numpy by `tests/fid_stats.rs`).

const N: usize = 624;
const M: usize = 397;

/// Mersenne Twister MT19937 as numpy's `RandomState` runs it.
pub struct RandomState {
    key: [u32; N],
    pos: usize,
}

impl RandomState {
    /// `RandomState(seed)` for an integer seed: numpy's `_legacy_seeding` calls `mt19937_seed`,
    /// which is the reference `init_genrand`.
    pub fn new(seed: u32) -> Self {
        let mut key = [0u32; N];
        key[0] = seed;
        for i in 1..N {
            let prev = key[i - 1];
            key[i] = 1_812_433_253u32.wrapping_mul(prev ^ (prev >> 30)).wrapping_add(i as u32);
        }
        RandomState { key, pos: N }
    }

    /// numpy's `next_uint32`: one tempered MT19937 output.
    pub fn next_u32(&mut self) -> u32 {
        if self.pos == N {
            self.generate();
        }
        let mut y = self.key[self.pos];
        self.pos += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^ (y >> 18)
    }

    fn generate(&mut self) {
        const UPPER: u32 = 0x8000_0000;
        const LOWER: u32 = 0x7fff_ffff;
        for i in 0..N {
            let y = (self.key[i] & UPPER) | (self.key[(i + 1) % N] & LOWER);
            let mag = if y & 1 == 1 { 0x9908_b0df } else { 0 };
            self.key[i] = self.key[(i + M) % N] ^ (y >> 1) ^ mag;
        }
        self.pos = 0;
    }

    /// numpy's `random_interval(max)`: uniform in `0..=max` by rejection under the smallest
    /// all-ones mask covering `max` (32-bit draws while `max` fits in 32 bits, as numpy does).
    fn interval(&mut self, max: usize) -> usize {
        if max == 0 {
            return 0;
        }
        let max = max as u64;
        let mask = u64::MAX >> max.leading_zeros();
        loop {
            let value = if max <= u32::MAX as u64 {
                (self.next_u32() as u64) & mask
            } else {
                (((self.next_u32() as u64) << 32) | self.next_u32() as u64) & mask
            };
            if value <= max {
                return value as usize;
            }
        }
    }

    /// `permutation(n)`: `arange(n)` shuffled by numpy's legacy Fisher–Yates (from the end).
    pub fn permutation(&mut self, n: usize) -> Vec<usize> {
        let mut p: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = self.interval(i);
            p.swap(i, j);
        }
        p
    }

    /// `choice(n, size, replace=False)`, which numpy computes as `permutation(n)[:size]`.
    /// Panics if `size > n` (numpy raises).
    pub fn choice_without_replacement(&mut self, n: usize, size: usize) -> Vec<usize> {
        assert!(size <= n, "cannot take {size} of {n} without replacement");
        let mut p = self.permutation(n);
        p.truncate(size);
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference MT19937's first output for `init_genrand(5489)`, its default seed.
    #[test]
    fn mt19937_reference_output() {
        let mut rng = RandomState::new(5489);
        assert_eq!(rng.next_u32(), 3_499_211_612);
    }
}
