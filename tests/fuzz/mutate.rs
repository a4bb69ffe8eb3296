//! The mutations of a fuzz input: byte-level changes (bits, bytes, little-endian integers with
//! values that sit on limits, ranges deleted, inserted, repeated or cut off), words of the
//! file's own language and numbers at the limits for text formats, and splices with another
//! input of the corpus. Several are stacked on one input.

use super::Input;
use rand::Rng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

/// No part grows beyond this.
pub const MAX_PART_BYTES: usize = 4 << 20;

const INTERESTING_U8: [u8; 9] = [0, 1, 2, 16, 32, 64, 127, 128, 255];
const INTERESTING_U32: [u32; 12] = [
    0,
    1,
    2,
    3,
    255,
    256,
    65_535,
    65_536,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_fffe,
    0xffff_ffff,
];
const INTERESTING_TEXT: [&str; 18] = [
    "0",
    "-1",
    "1",
    "65535",
    "65536",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775809",
    "1e308",
    "1e309",
    "-0.0",
    "nan",
    "inf",
    "0.5",
    "1.5e3",
    "99999999999999999999999999999",
];

/// Applies one to eight mutations to one part of `input`; `corpus` gives splice material and
/// `words` the target's dictionary.
pub fn mutate(input: &mut Input, corpus: &[Input], words: &[Vec<u8>], rng: &mut ChaCha8Rng) {
    if input.parts.is_empty() {
        return;
    }
    let stack = 1 << rng.gen_range(0..4);
    for _ in 0..stack {
        let p = rng.gen_range(0..input.parts.len());
        let donor = corpus
            .choose(rng)
            .and_then(|other| other.parts.iter().find(|q| q.0 == input.parts[p].0))
            .map(|q| q.1.clone());
        let bytes = &mut input.parts[p].1;
        mutate_bytes(bytes, donor.as_deref(), words, rng);
        bytes.truncate(MAX_PART_BYTES);
    }
}

fn mutate_bytes(b: &mut Vec<u8>, donor: Option<&[u8]>, words: &[Vec<u8>], rng: &mut ChaCha8Rng) {
    let len = b.len();
    let at = |rng: &mut ChaCha8Rng| if len == 0 { 0 } else { rng.gen_range(0..len) };
    match rng.gen_range(0..13) {
        0 if len > 0 => {
            let i = at(rng);
            b[i] ^= 1 << rng.gen_range(0..8);
        }
        1 if len > 0 => {
            let i = at(rng);
            b[i] = if rng.gen_bool(0.5) {
                rng.r#gen()
            } else {
                *INTERESTING_U8.choose(rng).unwrap_or(&0)
            };
        }
        2 if len >= 4 => {
            // A little-endian integer at a limit, 2, 4 or 8 bytes wide.
            let width = [2usize, 4, 8][rng.gen_range(0..3)].min(len);
            let i = rng.gen_range(0..=len - width);
            let v = u64::from(*INTERESTING_U32.choose(rng).unwrap_or(&0));
            let v = if width == 8 && rng.gen_bool(0.3) { !v } else { v };
            b[i..i + width].copy_from_slice(&v.to_le_bytes()[..width]);
        }
        3 if len >= 4 => {
            // Arithmetic on a little-endian u32.
            let i = rng.gen_range(0..=len - 4);
            let v = u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
            let delta = rng.gen_range(1..=35u32);
            let v = if rng.gen_bool(0.5) {
                v.wrapping_add(delta)
            } else {
                v.wrapping_sub(delta)
            };
            b[i..i + 4].copy_from_slice(&v.to_le_bytes());
        }
        4 if len > 0 => {
            let i = at(rng);
            let most = if rng.gen_bool(0.8) { 16 } else { len };
            let n = rng.gen_range(1..=(len - i).min(most));
            b.drain(i..i + n);
        }
        5 => {
            let i = if len == 0 { 0 } else { rng.gen_range(0..=len) };
            let n = rng.gen_range(1..=16);
            let fill: Vec<u8> = (0..n).map(|_| rng.r#gen()).collect();
            b.splice(i..i, fill);
        }
        6 if len > 0 => {
            // A range repeated in place, up to 64 times (deep nesting, long lists).
            let i = at(rng);
            let n = rng.gen_range(1..=(len - i).min(256));
            let times = rng.gen_range(1..=64);
            let chunk = b[i..i + n].repeat(times);
            b.splice(i..i, chunk);
        }
        7 if len > 1 => {
            // A range copied over another place.
            let (from, to) = (at(rng), at(rng));
            let n = rng.gen_range(1..=(len - from).min(len - to).min(64));
            let chunk = b[from..from + n].to_vec();
            b[to..to + n].copy_from_slice(&chunk);
        }
        8 if !words.is_empty() => {
            let word = words.choose(rng).cloned().unwrap_or_default();
            let i = if len == 0 { 0 } else { rng.gen_range(0..=len) };
            if rng.gen_bool(0.5) || len == 0 {
                b.splice(i..i, word);
            } else {
                let end = (i + word.len()).min(len);
                b.splice(i..end, word);
            }
        }
        9 => replace_number(b, rng),
        10 if len > 0 => b.truncate(at(rng)),
        11 => {
            if let Some(d) = donor.filter(|d| !d.is_empty()) {
                // The head of this part and the tail of another input's same part.
                let cut = if len == 0 { 0 } else { rng.gen_range(0..=len) };
                let from = rng.gen_range(0..d.len());
                b.truncate(cut);
                b.extend_from_slice(&d[from..]);
            }
        }
        _ => {
            // A run of one byte value over a range (zeroed or filled sectors).
            if len > 0 {
                let i = at(rng);
                let n = rng.gen_range(1..=(len - i).min(4096));
                let v = if rng.gen_bool(0.5) { 0 } else { 0xff };
                b[i..i + n].fill(v);
            }
        }
    }
}

/// Replaces a run of ASCII digits with a number at a limit.
fn replace_number(b: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    let starts: Vec<usize> = (0..b.len())
        .filter(|&i| b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_digit()))
        .collect();
    let Some(&i) = starts.choose(rng) else {
        return;
    };
    let end = (i..b.len()).find(|&j| !b[j].is_ascii_digit()).unwrap_or(b.len());
    let text = INTERESTING_TEXT.choose(rng).copied().unwrap_or("0");
    b.splice(i..end, text.bytes());
}

/// The words of text seeds (identifiers, tags, punctuation runs) for the dictionary.
pub fn words_of(inputs: &[Input]) -> Vec<Vec<u8>> {
    let mut words: Vec<Vec<u8>> = Vec::new();
    for (_, bytes) in inputs.iter().flat_map(|i| &i.parts) {
        let Ok(text) = std::str::from_utf8(bytes) else {
            continue;
        };
        let mut word = String::new();
        for c in text.chars().chain(std::iter::once(' ')) {
            if c.is_ascii_alphanumeric() || c == '_' {
                word.push(c);
            } else {
                if word.len() >= 2 && word.len() <= 40 {
                    words.push(word.clone().into_bytes());
                }
                word.clear();
                if "<>[]{}=\":,/!-#&'".contains(c) {
                    words.push(vec![c as u8]);
                }
            }
        }
    }
    words.sort();
    words.dedup();
    words
}
