//! Serde forms of the accumulators' number arrays: a sequence of numbers in human-readable
//! formats (JSON), and in binary formats (CBOR, which the shard files use) one byte string of
//! little-endian 8-byte values. A shard's partial result is mostly such arrays, and reading a
//! byte string is a copy where a sequence costs a decoder call per number (`cargo xtask bench
//! shards` times the merge of shard files).
//!
//! Public so that other crates' serialised accumulators (the evaluator's state in
//! `kalibra-eval`) share the one encoding: `#[serde(with = "kalibra_metrics::packed")]` on a
//! `Vec<f64>` or `Vec<u64>` field.

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serializer};

/// A value of 8 little-endian bytes (`f64` and `u64`; an `f64` keeps every bit, NaN's too).
pub trait Packed: Sized + Copy {
    /// The value's 8 little-endian bytes.
    fn to_le(self) -> [u8; 8];
    /// The value of 8 little-endian bytes.
    fn from_le(bytes: [u8; 8]) -> Self;
}

impl Packed for f64 {
    fn to_le(self) -> [u8; 8] {
        self.to_le_bytes()
    }
    fn from_le(bytes: [u8; 8]) -> Self {
        f64::from_le_bytes(bytes)
    }
}

impl Packed for u64 {
    fn to_le(self) -> [u8; 8] {
        self.to_le_bytes()
    }
    fn from_le(bytes: [u8; 8]) -> Self {
        u64::from_le_bytes(bytes)
    }
}

/// Serialises `values` as a sequence (human-readable formats) or one byte string.
///
/// # Errors
/// The format's error.
pub fn serialize<T, S>(values: &[T], serializer: S) -> Result<S::Ok, S::Error>
where
    T: Packed + serde::Serialize,
    S: Serializer,
{
    if serializer.is_human_readable() {
        serializer.collect_seq(values)
    } else {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le()).collect();
        serializer.serialize_bytes(&bytes)
    }
}

/// Reads what [`serialize`] writes.
///
/// # Errors
/// The format's error for a value of another type or a byte string whose length is not a
/// multiple of 8.
pub fn deserialize<'de, T, D>(deserializer: D) -> Result<Vec<T>, D::Error>
where
    T: Packed + Deserialize<'de>,
    D: Deserializer<'de>,
{
    if deserializer.is_human_readable() {
        return Vec::<T>::deserialize(deserializer);
    }
    let bytes = serde_bytes_buf(deserializer)?;
    if bytes.len() % 8 != 0 {
        return Err(D::Error::custom(format!(
            "{} bytes are not a whole number of 8-byte values",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(8)
        .map(|c| {
            let mut b = [0u8; 8];
            b.copy_from_slice(c);
            T::from_le(b)
        })
        .collect())
}

/// A byte string, borrowed or owned, as the format hands it over.
fn serde_bytes_buf<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Vec<u8>, D::Error> {
    struct Bytes;
    impl<'de> serde::de::Visitor<'de> for Bytes {
        type Value = Vec<u8>;
        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("a byte string of little-endian 8-byte values")
        }
        fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<Vec<u8>, E> {
            Ok(v.to_vec())
        }
        fn visit_byte_buf<E: serde::de::Error>(self, v: Vec<u8>) -> Result<Vec<u8>, E> {
            Ok(v)
        }
    }
    deserializer.deserialize_byte_buf(Bytes)
}
