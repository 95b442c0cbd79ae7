//! The seed rules. "Same seed, same episode" is the benchmark's core promise and rests on these,
//! so each is written once: the generator, the randomiser, `kitchen-r eval` and `episodes`, the
//! workers, expert samples and the Python environment all call them.

/// SplitMix64's increment (the golden ratio in 64 bits).
pub const GOLDEN_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// FNV-1a's offset basis and prime (64 bits).
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
pub const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

/// SplitMix64 finaliser: decorrelates nearby seeds.
pub fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(GOLDEN_GAMMA);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// FNV-1a of `bytes`, going on from the hash `h` (start from [`FNV_OFFSET`]).
pub fn fnv1a(h: u64, bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(h, |h, &b| (h ^ u64::from(b)).wrapping_mul(FNV_PRIME))
}

/// The seed of the `index`-th member of what `seed` draws: a batch's episode, a pass of
/// `kitchen-r episodes`, one randomised aspect's stream.
pub fn sub_seed(seed: u64, index: u64) -> u64 {
    splitmix(seed ^ splitmix(index))
}

/// The seed of an instruction's episode in a run seeded `seed`: stable per (seed, instruction id).
pub fn instruction_seed(seed: u64, id: &str) -> u64 {
    splitmix(seed ^ fnv1a(FNV_OFFSET, id.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rules_keep_their_values() {
        // Saved batches, committed figures and leaderboards depend on these exact numbers.
        assert_eq!(splitmix(0), 0xe220_a839_7b1d_cdaf);
        assert_eq!(fnv1a(FNV_OFFSET, b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(sub_seed(1, 2), splitmix(1 ^ splitmix(2)));
        assert_eq!(
            instruction_seed(0, "dev-0001"),
            splitmix(fnv1a(FNV_OFFSET, b"dev-0001"))
        );
    }
}
