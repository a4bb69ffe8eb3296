//! Seeded random streams: every image, frame or tree draws from its own stream, so results do
//! not depend on the thread count or the order of work.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The RNG for item `index` of a run seeded with `seed`: every image or frame draws from its
/// own stream, so output does not depend on the thread count or the order of work.
pub fn item_rng(seed: u64, stream: u64, index: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ stream.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(index);
    rng
}
