//! Which seed an episode is drawn with: "same seed, same episode" rests on these rules, so each
//! is written once.

use kitchen_r_sim::generator::splitmix;

/// The seed of an instruction's episode: stable per (run seed, instruction id).
pub fn instruction_seed(seed: u64, id: &str) -> u64 {
    let fnv = id.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    splitmix(seed ^ fnv)
}
