//! Undoing the horizontal delta filter, one row at a time, in the decoder's pass over the
//! pixels: sixteen bytes or eight depth samples per SSE2 instruction where the target has
//! SSE2 (through `safe_arch`), eight bytes at a time inside a `u64` elsewhere. The filter
//! itself is applied by the encoder as it copies the pixels.

/// Undoes the horizontal delta filter on one row of bytes: each byte becomes the wrapping sum
/// of itself and every byte to its left. Sixteen bytes at a time with SSE2: a byte-wise prefix
/// sum in four shifted additions, plus the running total of the row so far, which is carried
/// in a register (one addition per sixteen bytes on the loop's critical path). Several times
/// faster than byte by byte.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(super) fn undo_byte_delta(line: &mut [u8]) {
    use safe_arch::{
        add_i8_m128i, byte_shl_imm_u128_m128i, m128i, shuffle_ai_f32_all_m128i, unpack_high_i8_m128i,
        unpack_high_i16_m128i, zeroed_m128i,
    };
    // Every byte of `carry` holds the row's sum up to the current chunk.
    let mut carry = zeroed_m128i();
    let mut left = 0u8;
    let mut chunks = line.chunks_exact_mut(16);
    for chunk in &mut chunks {
        let mut bytes = [0u8; 16];
        bytes.copy_from_slice(chunk);
        let mut x = m128i::from(bytes);
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<1>(x));
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<2>(x));
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<4>(x));
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<8>(x));
        chunk.copy_from_slice(&<[u8; 16]>::from(add_i8_m128i(x, carry)));
        left = chunk[15];
        // The chunk's own total (its last byte) in every byte.
        let high = unpack_high_i16_m128i(unpack_high_i8_m128i(x, x), unpack_high_i8_m128i(x, x));
        carry = add_i8_m128i(carry, shuffle_ai_f32_all_m128i::<0xFF>(high));
    }
    undo_byte_delta_tail(chunks.into_remainder(), left);
}

/// Undoes the horizontal delta filter on one row of bytes: each byte becomes the wrapping sum
/// of itself and every byte to its left. Eight bytes at a time (a byte-wise prefix sum inside
/// a `u64`, without carries between bytes), several times faster than byte by byte.
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
pub(super) fn undo_byte_delta(line: &mut [u8]) {
    /// Byte-wise wrapping addition of two `u64`s.
    fn add_bytes(a: u64, b: u64) -> u64 {
        const LOW: u64 = 0x7f7f_7f7f_7f7f_7f7f;
        ((a & LOW) + (b & LOW)) ^ ((a ^ b) & !LOW)
    }
    let mut left = 0u8;
    let mut chunks = line.chunks_exact_mut(8);
    for chunk in &mut chunks {
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(chunk);
        let mut x = u64::from_le_bytes(bytes);
        x = add_bytes(x, x << 8);
        x = add_bytes(x, x << 16);
        x = add_bytes(x, x << 32);
        x = add_bytes(x, u64::from_le_bytes([left; 8]));
        chunk.copy_from_slice(&x.to_le_bytes());
        left = chunk[7];
    }
    undo_byte_delta_tail(chunks.into_remainder(), left);
}

/// Undoes the horizontal delta filter on one row of depth samples: `bytes` holds the row's
/// little-endian `u16` differences, `out` receives the samples, each the wrapping sum of its
/// difference and every difference to its left. Eight samples at a time with SSE2, as
/// [`undo_byte_delta`] does sixteen bytes.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(super) fn undo_sample_delta(bytes: &[u8], out: &mut [u16]) {
    use safe_arch::{
        add_i16_m128i, byte_shl_imm_u128_m128i, m128i, shuffle_ai_f32_all_m128i, unpack_high_i16_m128i, zeroed_m128i,
    };
    let mut carry = zeroed_m128i();
    let mut left = 0u16;
    let mut chunks = bytes.chunks_exact(16);
    let mut outs = out.chunks_exact_mut(8);
    for (chunk, o) in (&mut chunks).zip(&mut outs) {
        let mut b = [0u8; 16];
        b.copy_from_slice(chunk);
        let mut x = m128i::from(b);
        x = add_i16_m128i(x, byte_shl_imm_u128_m128i::<2>(x));
        x = add_i16_m128i(x, byte_shl_imm_u128_m128i::<4>(x));
        x = add_i16_m128i(x, byte_shl_imm_u128_m128i::<8>(x));
        o.copy_from_slice(&<[u16; 8]>::from(add_i16_m128i(x, carry)));
        left = o[7];
        carry = add_i16_m128i(carry, shuffle_ai_f32_all_m128i::<0xFF>(unpack_high_i16_m128i(x, x)));
    }
    undo_sample_delta_tail(chunks.remainder(), outs.into_remainder(), left);
}

/// Undoes the horizontal delta filter on one row of depth samples (see the SSE2 version).
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
pub(super) fn undo_sample_delta(bytes: &[u8], out: &mut [u16]) {
    undo_sample_delta_tail(bytes, out, 0);
}

/// The last samples of a row that do not fill a vector, `left` the sample before them.
fn undo_sample_delta_tail(bytes: &[u8], out: &mut [u16], mut left: u16) {
    for (v, b) in out.iter_mut().zip(bytes.chunks_exact(2)) {
        left = left.wrapping_add(u16::from_le_bytes([b[0], b[1]]));
        *v = left;
    }
}

/// The last bytes of a row that do not fill a vector, `left` the byte before them.
fn undo_byte_delta_tail(rest: &mut [u8], mut left: u8) {
    for v in rest {
        *v = v.wrapping_add(left);
        left = *v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_sample_delta_undo_matches_the_sample_by_sample_one() {
        for len in [0usize, 1, 7, 8, 9, 17, 640, 1283] {
            let deltas: Vec<u16> = (0..len).map(|i| (i.wrapping_mul(2_654_435_761) >> 11) as u16).collect();
            let bytes: Vec<u8> = deltas.iter().flat_map(|d| d.to_le_bytes()).collect();
            let mut fast = vec![0u16; len];
            undo_sample_delta(&bytes, &mut fast);
            let mut left = 0u16;
            let slow: Vec<u16> = deltas
                .iter()
                .map(|&d| {
                    left = left.wrapping_add(d);
                    left
                })
                .collect();
            assert_eq!(fast, slow, "row of {len}");
        }
    }

    #[test]
    fn the_fast_delta_undo_matches_the_byte_by_byte_one() {
        for len in [0usize, 1, 7, 8, 9, 17, 640, 1283] {
            let deltas: Vec<u8> = (0..len).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
            let mut fast = deltas.clone();
            undo_byte_delta(&mut fast);
            let mut left = 0u8;
            let slow: Vec<u8> = deltas
                .iter()
                .map(|d| {
                    left = left.wrapping_add(*d);
                    left
                })
                .collect();
            assert_eq!(fast, slow, "{len} bytes");
        }
    }
}
