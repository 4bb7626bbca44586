//! Bounded text and lists for messages: heapless containers with a postcard [`MaxSize`] bound, so
//! every message has a compile-time worst-case size. Decoding more than the capacity fails cleanly.

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

/// Bytes of postcard's varint encoding of `n` (a length prefix).
pub const fn varint_len(n: usize) -> usize {
    let mut len = 1;
    let mut v = n >> 7;
    while v != 0 {
        len += 1;
        v >>= 7;
    }
    len
}

/// UTF-8 text of at most `N` bytes.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Text<const N: usize>(pub heapless::String<N>);

impl<const N: usize> MaxSize for Text<N> {
    const POSTCARD_MAX_SIZE: usize = varint_len(N) + N;
}

impl<const N: usize> Text<N> {
    /// Copies `s`, cutting it at a character boundary to fit `N` bytes.
    pub fn truncated(s: &str) -> Self {
        let mut end = s.len().min(N);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        let mut out = heapless::String::new();
        // Cannot fail: `end <= N` bytes.
        let _ = out.push_str(&s[..end]);
        Self(out)
    }

    /// Copies `s` if it fits, else `None`.
    pub fn new(s: &str) -> Option<Self> {
        let mut out = heapless::String::new();
        out.push_str(s).ok()?;
        Some(Self(out))
    }

    /// The text.
    pub fn as_str(&self) -> &str {
        self.0.as_str()
    }
}

/// A list of at most `N` items.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct List<T, const N: usize>(pub heapless::Vec<T, N>);

/// The empty list, for any item type.
impl<T, const N: usize> Default for List<T, N> {
    fn default() -> Self {
        Self(heapless::Vec::new())
    }
}

impl<T: MaxSize, const N: usize> MaxSize for List<T, N> {
    const POSTCARD_MAX_SIZE: usize = varint_len(N) + N * T::POSTCARD_MAX_SIZE;
}

impl<T: Clone, const N: usize> List<T, N> {
    /// Copies `items` if they fit, else `None`.
    pub fn from_slice(items: &[T]) -> Option<Self> {
        heapless::Vec::from_slice(items).ok().map(Self)
    }

    /// The items.
    pub fn as_slice(&self) -> &[T] {
        self.0.as_slice()
    }
}
