//! The cloud preview sent over the radio: decimated, quantised to millimetres as i16, cut into
//! [`CloudChunk`]s of [`CHUNK_POINTS`], and reassembled on the handheld with selective resend.
//!
//! At 57600 baud a full cloud (hundreds of thousands of points) would take minutes; the preview is
//! a voxel-decimated subset (one point per occupied voxel, lowest z kept, so the underside envelope
//! survives) capped at a configurable count. Quantisation: round to 1 mm, clamp to +-32.767 m.

use std::collections::BTreeMap;

use protocol::bounded::List;
use protocol::radio::{CHUNK_POINTS, CloudChunk};

use crate::chunks::ChunkSet;

/// Decimates `points_m` to at most `max_points` points, quantised to millimetres.
///
/// Points fall into cubic voxels of `voxel_m`; each voxel keeps its lowest point (the underside
/// matters). The voxel is doubled until the count fits `max_points`. The output is sorted
/// (x, y, z) so it is deterministic whatever the input order.
pub fn decimate(points_m: &[[f64; 3]], voxel_m: f64, max_points: usize) -> Vec<[i16; 3]> {
    let mut voxel = voxel_m.max(1e-3);
    loop {
        let mut cells: BTreeMap<[i64; 3], [f64; 3]> = BTreeMap::new();
        for p in points_m.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
            let key = [0, 1, 2].map(|k| (p[k] / voxel).floor() as i64);
            cells
                .entry(key)
                .and_modify(|q| {
                    if p[2] < q[2] {
                        *q = *p;
                    }
                })
                .or_insert(*p);
        }
        if cells.len() <= max_points || voxel > 100.0 {
            let mut out: Vec<[i16; 3]> = cells.values().map(|p| quantise(*p)).collect();
            out.sort_unstable();
            out.truncate(max_points);
            return out;
        }
        voxel *= 2.0;
    }
}

/// Metres to clamped i16 millimetres.
pub fn quantise(p_m: [f64; 3]) -> [i16; 3] {
    p_m.map(|v| (v * 1000.0).round().clamp(-32_767.0, 32_767.0) as i16)
}

/// i16 millimetres back to metres.
pub fn dequantise(p_mm: [i16; 3]) -> [f64; 3] {
    p_mm.map(|v| f64::from(v) * 1e-3)
}

/// Cuts the preview into chunks (at least one, possibly empty, so the handheld knows the count).
pub fn chunks(run_id: u32, points_mm: &[[i16; 3]]) -> Vec<CloudChunk> {
    let pieces: Vec<&[[i16; 3]]> = if points_mm.is_empty() {
        vec![&[]]
    } else {
        points_mm.chunks(CHUNK_POINTS).collect()
    };
    let count = pieces.len().min(usize::from(u16::MAX)) as u16;
    pieces
        .into_iter()
        .take(usize::from(count))
        .enumerate()
        .map(|(i, piece)| CloudChunk {
            run_id,
            index: i as u16,
            count,
            // `chunks(CHUNK_POINTS)` never yields more than the list holds.
            points_mm: List::from_slice(piece).unwrap_or_default(),
        })
        .collect()
}

/// Reassembles one run's preview from chunks in any order, with duplicates.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Assembler {
    run_id: u32,
    chunks: ChunkSet<[i16; 3]>,
}

impl Assembler {
    /// Expects `count` chunks of `run_id`.
    pub fn new(run_id: u32, count: u16) -> Self {
        Self {
            run_id,
            chunks: ChunkSet::new(count),
        }
    }

    /// The run.
    pub fn run_id(&self) -> u32 {
        self.run_id
    }

    /// Takes a chunk; returns whether it was new. Chunks of other runs or out of range are ignored.
    pub fn add(&mut self, chunk: &CloudChunk) -> bool {
        chunk.run_id == self.run_id
            && chunk.count == self.chunks.count()
            && self.chunks.insert(chunk.index, chunk.points_mm.as_slice())
    }

    /// Chunk indices still missing, ascending.
    pub fn missing(&self) -> Vec<u16> {
        self.chunks.missing()
    }

    /// Whether every chunk arrived.
    pub fn is_complete(&self) -> bool {
        self.chunks.is_complete()
    }

    /// The points received so far, in chunk order.
    pub fn points_mm(&self) -> Vec<[i16; 3]> {
        self.chunks.joined()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_caps_count_and_keeps_lowest_point_per_voxel() {
        let mut pts = Vec::new();
        for i in 0..100 {
            for j in 0..100 {
                let (x, y) = (f64::from(i) * 0.01, f64::from(j) * 0.01);
                pts.push([x, y, 0.22]);
                pts.push([x, y, 0.21]);
            }
        }
        let out = decimate(&pts, 0.05, 1_000);
        assert!(out.len() <= 1_000);
        assert_eq!(out.len(), 400, "20 x 20 voxels of 5 cm");
        assert!(out.iter().all(|p| p[2] == 210), "lowest z kept");
        let small = decimate(&pts, 0.05, 50);
        assert!(small.len() <= 50 && !small.is_empty());
    }

    #[test]
    fn quantisation_rounds_and_clamps() {
        assert_eq!(quantise([0.0014, -0.0016, 40.0]), [1, -2, 32_767]);
        let back = dequantise([1, -2, 3]);
        assert!((0..3).all(|k| (back[k] - [0.001, -0.002, 0.003][k]).abs() < 1e-12));
        assert_eq!(quantise([f64::NAN, 0.0, 0.0])[0], 0, "NaN saturates to 0");
    }

    #[test]
    fn chunks_reassemble_in_any_order_with_duplicates() {
        let pts: Vec<[i16; 3]> = (0..100).map(|i| [i, -i, 2 * i]).collect();
        let cs = chunks(5, &pts);
        assert_eq!(cs.len(), 5);
        let mut a = Assembler::new(5, 5);
        for c in cs.iter().rev().chain(cs.iter()) {
            a.add(c);
        }
        assert!(a.is_complete());
        assert_eq!(a.points_mm(), pts);
        let mut b = Assembler::new(5, 5);
        b.add(&cs[1]);
        b.add(&cs[3]);
        assert_eq!(b.missing(), vec![0, 2, 4]);
        assert!(!b.add(&chunks(6, &pts)[0]), "other run ignored");
        assert_eq!(
            chunks(1, &[]).len(),
            1,
            "an empty preview still has one chunk"
        );
    }
}
