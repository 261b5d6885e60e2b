//! The numbers of a plain CSV row in their most common written form, read eight digits at a
//! time: `-` or nothing, 1 to 7 digits, then `.` and more digits or nothing, at most 19
//! digits in all, no exponent. That is how Rust's `{}`, numpy's `repr` and most writers
//! write a float of a log, and `0` or a small whole number is half the values of a covariance
//! log. Everything else is left to fast-float2, which reads the full grammar.
//!
//! The value is the one fast-float2 gives, bit for bit: the same mantissa (the digits as one
//! integer) and decimal exponent, turned into a float by the same two exact methods: one
//! correctly rounded division when the mantissa is at most 2^53 (Clinger's fast path), else
//! the Eisel-Lemire product with a 128-bit power of ten (this module's table holds the powers
//! 10^0 to 10^-19 only, computed at compile time). The tests
//! `quick_numbers_are_fast_float2_numbers` and `powers_of_five_match_fast_float2` check it.

/// The powers of ten `10^0 .. 10^19`, exact in `f64` (below 2^53 · 2^22) and in `u64`.
const POW10_F64: [f64; 20] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19,
];
const POW10_U64: [u64; 20] = {
    let mut t = [1_u64; 20];
    let mut i = 1;
    while i < 20 {
        t[i] = t[i - 1] * 10;
        i += 1;
    }
    t
};

/// The most digits read here: their integer fits a `u64`.
const MAX_DIGITS: u32 = 19;

/// For `k` in `0..=19`, `5^-k` as fast-float2's table holds it: the 128 bits of
/// `floor(2^b / 5^k) + 1` (`5^0` itself for `k = 0`) shifted to have its top bit set, with
/// `b = z + 127` and `2^z` the least power of two at least `5^k`; as (high, low) words.
const POW5_INV: [(u64, u64); 20] = {
    let mut t = [(0_u64, 0_u64); 20];
    let mut k = 0;
    while k < 20 {
        let mut p5: u128 = 1;
        let mut j = 0;
        while j < k {
            p5 *= 5;
            j += 1;
        }
        let mut c: u128 = if k == 0 {
            1
        } else {
            let mut z = 0;
            while (1_u128 << z) < p5 {
                z += 1;
            }
            // floor(2^(z + 127) / p5) by long division, one bit at a time; the quotient is
            // below 2^128 since 2^z < 2 p5.
            let b = z + 127;
            let mut rem: u128 = 0;
            let mut quo: u128 = 0;
            let mut bit = b;
            while bit >= 0 {
                rem = (rem << 1) | (bit == b) as u128;
                quo <<= 1;
                if rem >= p5 {
                    rem -= p5;
                    quo |= 1;
                }
                bit -= 1;
            }
            quo + 1
        };
        while c < (1_u128 << 127) {
            c <<= 1;
        }
        t[k] = ((c >> 64) as u64, c as u64);
        k += 1;
    }
    t
};

/// The 8 bytes of `block` from `i`, the first one lowest.
#[inline(always)]
fn word(window: &[u8; 40], i: usize) -> u64 {
    let mut w = [0_u8; 8];
    w.copy_from_slice(&window[i..i + 8]);
    u64::from_le_bytes(w)
}

/// How many of the 8 bytes of `x` (first byte lowest) are digits before the first
/// non-digit. A byte below `0` borrows into, and one above `9` carries into, only the bytes
/// after it, so the first non-digit's high bit is set whatever follows it.
#[inline(always)]
fn leading_digits(x: u64) -> u32 {
    let above = x.wrapping_add(0x4646_4646_4646_4646);
    let below = x.wrapping_sub(0x3030_3030_3030_3030);
    ((above | below) & 0x8080_8080_8080_8080).trailing_zeros() / 8
}

/// The value of the 8 digits `x`, first digit lowest (fast-float2's `parse_8digits`).
#[inline(always)]
fn eight_digits(mut v: u64) -> u64 {
    const MASK: u64 = 0x0000_00FF_0000_00FF;
    const MUL1: u64 = 0x000F_4240_0000_0064;
    const MUL2: u64 = 0x0000_2710_0000_0001;
    v -= 0x3030_3030_3030_3030;
    v = (v * 10) + (v >> 8);
    let v1 = (v & MASK).wrapping_mul(MUL1);
    let v2 = ((v >> 16) & MASK).wrapping_mul(MUL2);
    (v1.wrapping_add(v2) >> 32) & 0xFFFF_FFFF
}

/// The value of the first `n` (1 to 7) digits of `x`: the others replaced by leading zeros.
#[inline(always)]
fn first_digits(x: u64, n: u32) -> u64 {
    let shift = 8 * (8 - n);
    eight_digits((x << shift) | (0x3030_3030_3030_3030 >> (64 - shift)))
}

/// The number at `i` of `block` in the form this module reads, and the index just after it;
/// `None` for any other form (or fewer than 40 bytes from `i`), which the caller reads with
/// fast-float2. Where it gives a value, `fast_float2::parse_partial` of `&block[i..]` gives
/// the same value and length.
#[inline(always)]
pub(crate) fn quick_number(block: &[u8], i: usize) -> Option<(f64, usize)> {
    let window: &[u8; 40] = block.get(i..i + 40)?.try_into().ok()?;
    let negative = window[0] == b'-';
    let mut at = usize::from(negative);
    let x = word(window, at);
    let whole = leading_digits(x);
    if whole == 0 || whole == 8 {
        return None;
    }
    let mut mantissa = first_digits(x, whole);
    at += whole as usize;
    let mut fraction = 0;
    if window[at] == b'.' {
        at += 1;
        // At most 19 digits, so at most two full words after the point.
        let mut x = word(window, at);
        let mut n = leading_digits(x);
        while n == 8 {
            if whole + fraction + 8 > MAX_DIGITS {
                return None;
            }
            mantissa = mantissa * 100_000_000 + eight_digits(x);
            at += 8;
            fraction += 8;
            x = word(window, at);
            n = leading_digits(x);
        }
        if n > 0 {
            if whole + fraction + n > MAX_DIGITS {
                return None;
            }
            mantissa = mantissa * POW10_U64[n as usize] + first_digits(x, n);
            at += n as usize;
            fraction += n;
        } else if fraction == 0 {
            // `5.`, which fast-float2 reads too, but rare: left to it.
            return None;
        }
    }
    if window[at] | 0x20 == b'e' {
        return None;
    }
    let value = if mantissa <= 1 << 53 {
        // Clinger's fast path, as fast-float2 takes it: both exact, one rounding.
        let v = mantissa as f64 / POW10_F64[fraction as usize];
        if negative { -v } else { v }
    } else {
        eisel_lemire(mantissa, fraction, negative)?
    };
    Some((value, i + at))
}

/// `mantissa · 10^-fraction` (mantissa above 2^53, so not zero; fraction at most 19),
/// rounded to nearest even, by fast-float2's `compute_float` for `f64`; `None` where that
/// would not decide (it then reads the digits again more slowly).
#[inline(always)]
fn eisel_lemire(mantissa: u64, fraction: u32, negative: bool) -> Option<f64> {
    const EXPLICIT_BITS: i32 = 52;
    let q = -(fraction as i32);
    let lz = mantissa.leading_zeros();
    let w = mantissa << lz;
    let (hi5, lo5) = POW5_INV[fraction as usize];
    // compute_product_approx(q, w, 52 + 3)
    let mask = u64::MAX >> (EXPLICIT_BITS + 3);
    let first = u128::from(w) * u128::from(hi5);
    let (mut lo, mut hi) = (first as u64, (first >> 64) as u64);
    if hi & mask == mask {
        let second_hi = ((u128::from(w) * u128::from(lo5)) >> 64) as u64;
        lo = lo.wrapping_add(second_hi);
        if second_hi > lo {
            hi += 1;
        }
    }
    // `lo == u64::MAX` decides too for q in -27..=55.
    let upperbit = (hi >> 63) as i32;
    let shift = upperbit + 64 - EXPLICIT_BITS - 3;
    let mut m = hi >> shift;
    let power = ((q.wrapping_mul(152_170 + 65_536)) >> 16) + 63;
    let mut power2 = power + upperbit - lz as i32 + 1023;
    if power2 <= 0 {
        // A subnormal: not reached from at most 19 digits above 2^53.
        return None;
    }
    if lo <= 1 && (-4..=23).contains(&q) && m & 3 == 1 && (m << shift) == hi {
        m &= !1;
    }
    m += m & 1;
    m >>= 1;
    if m >= 2 << EXPLICIT_BITS {
        m = 1 << EXPLICIT_BITS;
        power2 += 1;
    }
    m &= !(1 << EXPLICIT_BITS);
    let bits = m | (power2 as u64) << EXPLICIT_BITS | u64::from(negative) << 63;
    Some(f64::from_bits(bits))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A value's bits and the bytes read.
    type Outcome = Option<(u64, usize)>;

    /// This module's and fast-float2's reading of the number at the start of `text` (padded
    /// to 40 bytes).
    fn both(text: &str) -> (Outcome, Outcome) {
        let padded = format!("{text},{}", " ".repeat(40));
        let quick = quick_number(padded.as_bytes(), 0).map(|(v, n)| (v.to_bits(), n));
        let slow = fast_float2::parse_partial::<f64, _>(padded.as_bytes())
            .ok()
            .map(|(v, n)| (v.to_bits(), n));
        (quick, slow)
    }

    #[test]
    fn powers_of_five_match_fast_float2() {
        // fast-float2's POWER_OF_FIVE_128 from 5^0 down to 5^-19 (its entries 342 to 323).
        let table: [(u64, u64); 20] = [
            (0x8000000000000000, 0x0),
            (0xcccccccccccccccc, 0xcccccccccccccccd),
            (0xa3d70a3d70a3d70a, 0x3d70a3d70a3d70a4),
            (0x83126e978d4fdf3b, 0x645a1cac083126ea),
            (0xd1b71758e219652b, 0xd3c36113404ea4a9),
            (0xa7c5ac471b478423, 0xfcf80dc33721d54),
            (0x8637bd05af6c69b5, 0xa63f9a49c2c1b110),
            (0xd6bf94d5e57a42bc, 0x3d32907604691b4d),
            (0xabcc77118461cefc, 0xfdc20d2b36ba7c3e),
            (0x89705f4136b4a597, 0x31680a88f8953031),
            (0xdbe6fecebdedd5be, 0xb573440e5a884d1c),
            (0xafebff0bcb24aafe, 0xf78f69a51539d749),
            (0x8cbccc096f5088cb, 0xf93f87b7442e45d4),
            (0xe12e13424bb40e13, 0x2865a5f206b06fba),
            (0xb424dc35095cd80f, 0x538484c19ef38c95),
            (0x901d7cf73ab0acd9, 0xf9d37014bf60a11),
            (0xe69594bec44de15b, 0x4c2ebe687989a9b4),
            (0xb877aa3236a4b449, 0x9befeb9fad487c3),
            (0x9392ee8e921d5d07, 0x3aff322e62439fd0),
            (0xec1e4a7db69561a5, 0x2b31e9e3d06c32e6),
        ];
        assert_eq!(POW5_INV, table);
    }

    #[test]
    fn quick_numbers_are_fast_float2_numbers() {
        let mut texts: Vec<String> = [
            "0",
            "-0",
            "1",
            "7",
            "36",
            "1234567",
            "12345678",
            "0.5",
            "-0.5",
            "5.",
            ".5",
            "+1",
            "1e5",
            "1E5",
            "1.5e3",
            "-",
            "",
            "0.30000000000000004",
            "9007199254740993",
            "9007199254740992",
            "9007199254740991.5",
            "1234567.123456789012",
            "0.0000001",
            "0.1000000000000000055511151231257827021181583404541015625",
            "1.7976931348623157",
            "4.9e-324",
            "9999999.999999999999",
            "1999999.99999999999",
            "0.9999999999999999999",
            "1.0000000000000000001",
            "-9.999999999999999",
            "123.4x",
            "12,5",
        ]
        .map(String::from)
        .to_vec();
        // The shortest representations of floats across magnitudes, and digit strings of
        // every length in every position around the point.
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..200_000 {
            let unit = (next() >> 11) as f64 / (1_u64 << 53) as f64;
            texts.push(format!("{}", unit * 10f64.powi((next() % 12) as i32 - 4)));
            texts.push(format!("-{}", (unit * 1e7).round() / 64.0));
            let digits: String = (0..1 + next() % 21)
                .map(|_| char::from(b'0' + (next() % 10) as u8))
                .collect();
            let point = (next() % (digits.len() as u64 + 1)) as usize;
            texts.push(format!("{}.{}", &digits[..point], &digits[point..]));
            texts.push(format!("-{digits}"));
        }
        let mut quick = 0;
        for text in &texts {
            let (q, s) = both(text);
            if let Some(q) = q {
                quick += 1;
                assert_eq!(Some(q), s, "{text}");
            }
        }
        assert!(quick > texts.len() / 3, "{quick} of {}", texts.len());
    }
}
