//! Mutations of an input, chosen by a seeded generator (the same seed gives the same inputs).
//!
//! Bit flips, byte insertion and deletion, truncation, splicing with another corpus file, numeric
//! tokens replaced by extreme values, little-endian integers overwritten with extreme values
//! (binary headers and counts), and duplicated lines or byte ranges (repeated structures).

use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Text replacements for a numeric token.
const EXTREME_TOKENS: &[&str] = &[
    "0",
    "-1",
    "1",
    "2147483647",
    "2147483648",
    "4294967295",
    "4294967296",
    "9223372036854775807",
    "9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "1000000000000",
    "-9223372036854775808",
    "1e308",
    "-1e308",
    "1e-320",
    "3.4e38",
    "1e200",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "-0",
    "0.0",
    "1.5",
    "00000000000000000000000000000001",
];

/// Little-endian integers written over binary fields.
const EXTREME_INTS: &[u64] = &[
    0,
    1,
    0x7f,
    0x80,
    0xff,
    0x7fff,
    0x8000,
    0xffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    0x1_0000_0000,
    0x7fff_ffff_ffff_ffff,
    u64::MAX,
];

/// Applies 1–4 random mutations to `input`; `other` is a second corpus file for splicing.
/// The result is at most `max_len` bytes.
pub fn mutate(input: &[u8], other: &[u8], rng: &mut ChaCha8Rng, max_len: usize) -> Vec<u8> {
    let mut d = input.to_vec();
    let rounds = rng.random_range(1..=4);
    for _ in 0..rounds {
        match rng.random_range(0..9) {
            0 => bit_flips(&mut d, rng),
            1 => insert_bytes(&mut d, rng),
            2 => delete_range(&mut d, rng),
            3 => {
                if !d.is_empty() {
                    let n = rng.random_range(0..d.len());
                    d.truncate(n);
                }
            }
            4 => d = splice(&d, other, rng),
            5 | 6 => replace_number(&mut d, rng),
            7 => overwrite_int(&mut d, rng),
            _ => duplicate(&mut d, rng),
        }
        d.truncate(max_len);
    }
    d
}

fn bit_flips(d: &mut [u8], rng: &mut ChaCha8Rng) {
    if d.is_empty() {
        return;
    }
    for _ in 0..rng.random_range(1..=8) {
        let i = rng.random_range(0..d.len());
        d[i] ^= 1 << rng.random_range(0..8);
    }
}

fn insert_bytes(d: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    let at = rng.random_range(0..=d.len());
    let n = rng.random_range(1..=16);
    let special = [
        0u8, 0xff, b'\n', b' ', b'-', b'.', b'#', b'/', b'"', b'{', 0xef,
    ];
    let bytes: Vec<u8> = (0..n)
        .map(|_| {
            if rng.random_bool(0.5) {
                special[rng.random_range(0..special.len())]
            } else {
                rng.random()
            }
        })
        .collect();
    d.splice(at..at, bytes);
}

fn delete_range(d: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    if d.is_empty() {
        return;
    }
    let at = rng.random_range(0..d.len());
    let n = rng.random_range(1..=64.min(d.len() - at));
    d.drain(at..at + n);
}

fn splice(a: &[u8], b: &[u8], rng: &mut ChaCha8Rng) -> Vec<u8> {
    let cut_a = rng.random_range(0..=a.len());
    let cut_b = rng.random_range(0..=b.len());
    let mut out = a[..cut_a].to_vec();
    out.extend_from_slice(&b[cut_b..]);
    out
}

/// The byte ranges of ASCII numeric tokens (`[-+]?[0-9.]…` with exponents).
fn numeric_tokens(d: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < d.len() {
        let starts = d[i].is_ascii_digit()
            || ((d[i] == b'-' || d[i] == b'+' || d[i] == b'.')
                && d.get(i + 1).is_some_and(u8::is_ascii_digit));
        if starts && (i == 0 || !d[i - 1].is_ascii_alphanumeric()) {
            let s = i;
            i += 1;
            while i < d.len()
                && (d[i].is_ascii_digit()
                    || matches!(d[i], b'.' | b'e' | b'E')
                    || ((d[i] == b'-' || d[i] == b'+') && matches!(d[i - 1], b'e' | b'E')))
            {
                i += 1;
            }
            out.push((s, i));
        } else {
            i += 1;
        }
    }
    out
}

fn replace_number(d: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    let toks = numeric_tokens(d);
    if toks.is_empty() {
        return overwrite_int(d, rng);
    }
    let (s, e) = toks[rng.random_range(0..toks.len())];
    let rep = EXTREME_TOKENS[rng.random_range(0..EXTREME_TOKENS.len())];
    d.splice(s..e, rep.bytes());
}

fn overwrite_int(d: &mut [u8], rng: &mut ChaCha8Rng) {
    let width = [1usize, 2, 4, 8][rng.random_range(0..4)];
    if d.len() < width {
        return;
    }
    let at = rng.random_range(0..=d.len() - width);
    let v = EXTREME_INTS[rng.random_range(0..EXTREME_INTS.len())];
    d[at..at + width].copy_from_slice(&v.to_le_bytes()[..width]);
}

/// Duplicates a line (text) or a byte range, a few times, right after itself.
fn duplicate(d: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    if d.is_empty() {
        return;
    }
    let lines: Vec<usize> = d
        .iter()
        .enumerate()
        .filter(|(_, b)| **b == b'\n')
        .map(|(i, _)| i + 1)
        .collect();
    let (s, e) = if lines.len() >= 2 && rng.random_bool(0.7) {
        let k = rng.random_range(0..lines.len() - 1);
        (lines[k], lines[k + 1])
    } else {
        let s = rng.random_range(0..d.len());
        (s, (s + rng.random_range(1..=256)).min(d.len()))
    };
    let copy = d[s..e].to_vec();
    for _ in 0..rng.random_range(1..=4) {
        d.splice(e..e, copy.iter().copied());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn same_seed_same_mutants_and_numbers_found() {
        let input = b"v 1.5 -2 3e-4\nf 1 2 3\n";
        let a: Vec<Vec<u8>> = {
            let mut r = ChaCha8Rng::seed_from_u64(7);
            (0..50)
                .map(|_| mutate(input, b"xyz", &mut r, 1 << 16))
                .collect()
        };
        let mut r = ChaCha8Rng::seed_from_u64(7);
        let b: Vec<Vec<u8>> = (0..50)
            .map(|_| mutate(input, b"xyz", &mut r, 1 << 16))
            .collect();
        assert_eq!(a, b);
        assert!(a.iter().any(|m| m != input));
        let toks: Vec<&[u8]> = numeric_tokens(input)
            .into_iter()
            .map(|(s, e)| &input[s..e])
            .collect();
        assert_eq!(toks, vec![&b"1.5"[..], b"-2", b"3e-4", b"1", b"2", b"3"]);
    }
}
