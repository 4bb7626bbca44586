//! The bookkeeping both chunked transfers share, the preview's cloud ([`super::preview`]) and a
//! run's files ([`super::record_files`]): which of `count` chunks arrived, each kept once, and
//! their items joined in index order.

use std::collections::BTreeMap;

/// Up to `count` chunks of items of type `T`, keyed by their index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChunkSet<T> {
    count: u16,
    got: BTreeMap<u16, Vec<T>>,
}

impl<T: Copy> ChunkSet<T> {
    /// Expects chunks `0..count`.
    pub fn new(count: u16) -> Self {
        Self {
            count,
            got: BTreeMap::new(),
        }
    }

    /// Chunks expected.
    pub fn count(&self) -> u16 {
        self.count
    }

    /// Keeps chunk `index`; false when it is out of range or already here.
    pub fn insert(&mut self, index: u16, items: &[T]) -> bool {
        if index >= self.count || self.got.contains_key(&index) {
            return false;
        }
        self.got.insert(index, items.to_vec());
        true
    }

    /// Chunk indices still missing, ascending.
    pub fn missing(&self) -> Vec<u16> {
        (0..self.count)
            .filter(|i| !self.got.contains_key(i))
            .collect()
    }

    /// Chunks received.
    pub fn received(&self) -> usize {
        self.got.len()
    }

    /// Whether every chunk arrived.
    pub fn is_complete(&self) -> bool {
        self.got.len() == usize::from(self.count)
    }

    /// The items received so far, in chunk order.
    pub fn joined(&self) -> Vec<T> {
        self.got.values().flatten().copied().collect()
    }
}
