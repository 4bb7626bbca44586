//! A run's record files (`result.json`, `result.json.sig`) over the radio, byte-exact: cut into
//! [`RecordChunk`]s on the robot, reassembled and checked on the handheld, so the handheld's copy
//! is the very file the robot signed and `passangle verify` can check it.
//!
//! A file longer than [`MAX_RECORD_LEN`] is named with its length and not sent; the handheld
//! reports it ([`RecordError::TooLarge`]) instead of allocating for it.

use protocol::bounded::List;
use protocol::radio::{
    MAX_RECORD_LEN, RECORD_CHUNK_LEN, RecordChunk, RecordFile, RecordInfo, record_chunk_count,
};

use crate::chunks::ChunkSet;

/// A record file the robot offers with a result.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutgoingRecord {
    /// Which file.
    pub file: RecordFile,
    /// Its length on the robot, bytes (saturating at `u32::MAX`).
    pub len: u32,
    /// Its bytes; empty when `len` exceeds [`MAX_RECORD_LEN`] (then it is not sent).
    pub bytes: Vec<u8>,
}

impl OutgoingRecord {
    /// A file read whole.
    pub fn new(file: RecordFile, bytes: Vec<u8>) -> Self {
        let len = u32::try_from(bytes.len()).unwrap_or(u32::MAX);
        if len > MAX_RECORD_LEN {
            return Self::too_large(file, u64::from(len));
        }
        Self { file, len, bytes }
    }

    /// A file too long to send, by its length.
    pub fn too_large(file: RecordFile, len: u64) -> Self {
        Self {
            file,
            len: u32::try_from(len).unwrap_or(u32::MAX),
            bytes: Vec::new(),
        }
    }

    /// Whether it goes over the radio.
    pub fn is_sendable(&self) -> bool {
        self.len <= MAX_RECORD_LEN && self.bytes.len() == self.len as usize
    }

    /// What the result announces about it.
    pub fn info(&self) -> RecordInfo {
        RecordInfo {
            file: self.file,
            len: self.len,
        }
    }
}

/// Why a record file did not reach the handheld.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecordError {
    /// The file is longer than the radio carries; it stays on the robot.
    #[error(
        "{} is {len} bytes on the robot, more than the {MAX_RECORD_LEN} the radio carries: copy it from the run directory",
        .file.file_name()
    )]
    TooLarge {
        /// Which file.
        file: RecordFile,
        /// Its length, bytes.
        len: u32,
    },
}

/// Cuts a file into chunks (at least one, so an empty file is sent too). A file longer than
/// [`MAX_RECORD_LEN`] gives none.
pub fn chunks(run_id: u32, record: &OutgoingRecord) -> Vec<RecordChunk> {
    if !record.is_sendable() {
        return Vec::new();
    }
    let count = record_chunk_count(record.len);
    let Ok(count16) = u16::try_from(count) else {
        return Vec::new();
    };
    (0..count16)
        .map(|index| {
            let start = usize::from(index) * RECORD_CHUNK_LEN;
            let end = (start + RECORD_CHUNK_LEN).min(record.bytes.len());
            RecordChunk {
                run_id,
                file: record.file,
                index,
                count: count16,
                total_len: record.len,
                // At most RECORD_CHUNK_LEN bytes: always fits.
                bytes: List::from_slice(&record.bytes[start.min(end)..end]).unwrap_or_default(),
            }
        })
        .collect()
}

/// Reassembles one record file from chunks in any order, with duplicates; a chunk that does not
/// fit the announced length (wrong count, wrong size for its place) is ignored.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Assembler {
    run_id: u32,
    info: RecordInfo,
    chunks: ChunkSet<u8>,
}

impl Assembler {
    /// Expects the file `info` announces for `run_id`; a file longer than [`MAX_RECORD_LEN`] is
    /// refused.
    pub fn new(run_id: u32, info: RecordInfo) -> Result<Self, RecordError> {
        let too_large = RecordError::TooLarge {
            file: info.file,
            len: info.len,
        };
        if info.len > MAX_RECORD_LEN {
            return Err(too_large);
        }
        let count = u16::try_from(record_chunk_count(info.len)).map_err(|_| too_large)?;
        Ok(Self {
            run_id,
            info,
            chunks: ChunkSet::new(count),
        })
    }

    /// The file.
    pub fn file(&self) -> RecordFile {
        self.info.file
    }

    /// Chunks expected.
    pub fn count(&self) -> u16 {
        self.chunks.count()
    }

    /// Takes a chunk; returns whether it was new and fits.
    pub fn add(&mut self, chunk: &RecordChunk) -> bool {
        if chunk.run_id != self.run_id
            || chunk.file != self.info.file
            || chunk.total_len != self.info.len
            || chunk.count != self.chunks.count()
        {
            return false;
        }
        let start = usize::from(chunk.index) * RECORD_CHUNK_LEN;
        let want = (self.info.len as usize)
            .saturating_sub(start)
            .min(RECORD_CHUNK_LEN);
        chunk.bytes.as_slice().len() == want
            && self.chunks.insert(chunk.index, chunk.bytes.as_slice())
    }

    /// Chunk indices still missing, ascending.
    pub fn missing(&self) -> Vec<u16> {
        self.chunks.missing()
    }

    /// Chunks received.
    pub fn received(&self) -> usize {
        self.chunks.received()
    }

    /// Whether every chunk arrived.
    pub fn is_complete(&self) -> bool {
        self.chunks.is_complete()
    }

    /// The whole file once complete (its length is the announced one).
    pub fn bytes(&self) -> Option<Vec<u8>> {
        if !self.is_complete() {
            return None;
        }
        let bytes = self.chunks.joined();
        (bytes.len() == self.info.len as usize).then_some(bytes)
    }
}

/// A record file as the handheld received it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReceivedRecord {
    /// Which file.
    pub file: RecordFile,
    /// Its bytes, exactly the robot's, or why they did not come.
    pub bytes: Result<Vec<u8>, RecordError>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_reassemble_byte_exact_in_any_order_with_duplicates() {
        for len in [0usize, 1, RECORD_CHUNK_LEN - 1, RECORD_CHUNK_LEN, 1000] {
            let bytes: Vec<u8> = (0..len).map(|i| (i * 7 % 251) as u8).collect();
            let out = OutgoingRecord::new(RecordFile::ResultJson, bytes.clone());
            let cs = chunks(4, &out);
            assert_eq!(cs.len(), len.div_ceil(RECORD_CHUNK_LEN).max(1));
            let mut a = Assembler::new(4, out.info()).unwrap();
            assert_eq!(usize::from(a.count()), cs.len());
            for c in cs.iter().rev().chain(cs.iter()) {
                a.add(c);
            }
            assert_eq!(a.bytes(), Some(bytes), "{len} bytes");
        }
    }

    #[test]
    fn chunks_that_do_not_fit_the_announcement_are_ignored() {
        let out = OutgoingRecord::new(RecordFile::ResultSig, vec![1; 500]);
        let cs = chunks(9, &out);
        let mut a = Assembler::new(9, out.info()).unwrap();
        let mut short = cs[0].clone();
        short.bytes = List::from_slice(&[1; 10]).unwrap();
        let mut other_file = cs[0].clone();
        other_file.file = RecordFile::ResultJson;
        let mut other_len = cs[0].clone();
        other_len.total_len = 501;
        let mut beyond = cs[2].clone();
        beyond.index = 3;
        for c in [short, other_file, other_len, beyond] {
            assert!(!a.add(&c), "{c:?}");
        }
        assert!(a.add(&cs[1]));
        assert_eq!(a.missing(), vec![0, 2]);
        assert_eq!(a.bytes(), None);
    }

    #[test]
    fn a_file_beyond_the_bound_is_named_not_sent() {
        let len = MAX_RECORD_LEN as usize + 1;
        let out = OutgoingRecord::new(RecordFile::ResultSig, vec![0; len]);
        assert!(out.bytes.is_empty() && !out.is_sendable());
        assert!(chunks(1, &out).is_empty());
        let e = Assembler::new(1, out.info()).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "result.json.sig is {len} bytes on the robot, more than the {MAX_RECORD_LEN} the radio carries: copy it from the run directory"
            )
        );
    }
}
