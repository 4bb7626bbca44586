//! Step 7a, the local feature map for scan-to-map refinement (paper 3.5, after LOAM's mapping) and
//! the accumulator that fuses all frames into one cloud.
//!
//! The feature map is a voxel hash map (as in KISS-ICP) of corner and plane points in the world
//! frame with at most `points_per_voxel` per voxel, none nearer than `min_spacing_m` to another
//! of its voxel (KISS-ICP's rule too: the voxel's room goes to the whole of what it holds, not
//! to the first few centimetres seen), so its size grows with the area covered, not with the
//! number of frames. Each frame's features are registered to it
//! ([`super::laser_odometry::register_joint`]) before they are added.
//!
//! The output accumulator keeps one centroid per `output_voxel_m` voxel: repeated views of a
//! surface average down the lidar's range noise instead of thickening the surface, and the cloud's
//! size is bounded by the surface area seen.

use super::geom::{Pose, V3, VoxelIndex, VoxelMap, voxel_of};
use super::laser_odometry::FeatureTarget;

/// Corner and plane points in the world frame.
#[derive(Debug, Clone)]
pub struct FeatureMap {
    target: FeatureTarget,
    points_per_voxel: usize,
    min_spacing_m: f64,
}

impl FeatureMap {
    /// An empty map with voxels of `voxel_m` (also the largest correspondence distance), adding
    /// a point only where its voxel holds fewer than `points_per_voxel` and none nearer than
    /// `min_spacing_m` (0: any distance).
    pub fn new(voxel_m: f64, points_per_voxel: usize, min_spacing_m: f64) -> Self {
        Self {
            target: FeatureTarget {
                corners: VoxelIndex::new(Vec::new(), voxel_m),
                planes: VoxelIndex::new(Vec::new(), voxel_m),
            },
            points_per_voxel,
            min_spacing_m,
        }
    }

    /// The map as a registration target.
    pub fn target(&self) -> &FeatureTarget {
        &self.target
    }

    /// Number of plane and corner points held.
    pub fn len(&self) -> usize {
        self.target.corners.points().len() + self.target.planes.points().len()
    }

    /// True when nothing was added yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Add a frame's features (robot frame) at `world_from_robot`, each with its scan-line tag.
    pub fn add(&mut self, world_from_robot: &Pose, planes: &[(V3, u32)], corners: &[(V3, u32)]) {
        let (cap, spacing) = (self.points_per_voxel, self.min_spacing_m);
        for &(p, tag) in planes {
            let p = world_from_robot.apply(p);
            self.target.planes.insert_capped(p, tag, cap, spacing);
        }
        for &(p, tag) in corners {
            let p = world_from_robot.apply(p);
            self.target.corners.insert_capped(p, tag, cap, spacing);
        }
    }
}

/// Voxels per block edge, as a power of two: blocks of 8 x 8 x 8 voxels (4 cm at the default
/// 5 mm output voxel).
const BLOCK_BITS: u32 = 3;

/// Voxels per block.
const BLOCK_VOXELS: usize = 1 << (3 * BLOCK_BITS);

/// Points buffered before they are sorted into the blocks: several frames' worth (a 10 Hz VLP-16
/// frame adds about 16 000), since consecutive frames see the same surfaces and a batch touches
/// each block's slots and cells once; larger batches gain nothing more (decision record 020).
/// Cost (computed, not measured): 6.3 MB
/// of pending points per accumulator and about 7 MB more while a batch is sorted in; the last
/// batch is sorted in when the cloud is read ([`CloudAccumulator::points`]).
const BATCH: usize = 262_144;

/// How an accumulator groups its voxels into blocks of [`BLOCK_VOXELS`]: it maps a voxel to
/// "block space", whose coordinates are grouped `1 << BLOCK_BITS` to a block edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Blocking {
    /// Block space is voxel space: blocks of 8 x 8 x 8 voxels, for surfaces in any direction.
    Cubes,
    /// Blocks of 16 x 32 x 1 voxels, for a height field one voxel thick (the floor's columns),
    /// which fills them, so they can be dense ([`Block::new`]); as cubes it would fill one layer
    /// in eight of each block (the layout alone, with sparse blocks, measured no faster: the
    /// gain is the dense cells'). Block space takes the lowest bit of x and
    /// the lowest two of y into z: `(x >> 1, y >> 2, z * 8 + (x & 1) + 2 * (y & 3))`. A one-to-one
    /// map for `|z| < 2^28` voxels (the floor's squashed heights are within a few voxels of 0).
    Sheets,
}

impl Blocking {
    fn block_space_of(self, v: [i32; 3]) -> [i32; 3] {
        match self {
            Self::Cubes => v,
            Self::Sheets => [
                v[0] >> 1,
                v[1] >> 2,
                v[2].wrapping_shl(3) | (v[0] & 1) | ((v[1] & 3) << 1),
            ],
        }
    }

    fn voxel_of_block_space(self, b: [i32; 3]) -> [i32; 3] {
        match self {
            Self::Cubes => b,
            Self::Sheets => [
                b[0].wrapping_shl(1) | (b[2] & 1),
                b[1].wrapping_shl(2) | ((b[2] >> 1) & 3),
                b[2] >> 3,
            ],
        }
    }
}

/// The voxels of one block that hold points: the sum of each one's points and their count.
#[derive(Debug, Clone)]
struct Block {
    /// Sparse blocks (surfaces through 3D space fill a few of a block's voxels): a voxel's index
    /// within the block to 1 + its cell's index in `cells` (0: empty), so a block's occupied
    /// cells sit together in memory. `None`: a dense block, `cells[local]` is the voxel at
    /// `local` (the floor's sheets, which fill most of theirs), one dependent load less per
    /// point.
    slots: Option<Box<[u16; BLOCK_VOXELS]>>,
    cells: Vec<(V3, u32)>,
}

impl Block {
    fn new(blocking: Blocking) -> Self {
        match blocking {
            Blocking::Cubes => Self {
                slots: Some(Box::new([0; BLOCK_VOXELS])),
                cells: Vec::new(),
            },
            Blocking::Sheets => Self {
                slots: None,
                cells: vec![(V3::zeros(), 0); BLOCK_VOXELS],
            },
        }
    }

    /// Add `p` to the voxel at `local`; true when that voxel was empty.
    fn add(&mut self, local: usize, p: V3) -> bool {
        let cell = match &mut self.slots {
            None => &mut self.cells[local],
            Some(slots) => {
                let slot = &mut slots[local];
                if *slot == 0 {
                    self.cells.push((V3::zeros(), 0));
                    // At most BLOCK_VOXELS (512) cells per block: fits u16.
                    *slot = self.cells.len() as u16;
                }
                &mut self.cells[usize::from(*slot) - 1]
            }
        };
        let new = cell.1 == 0;
        cell.0 += p;
        cell.1 += 1;
        new
    }

    /// The cell of the voxel at `local`, if it holds points.
    fn cell(&self, local: usize) -> Option<(V3, u32)> {
        let cell = match &self.slots {
            None => self.cells[local],
            Some(slots) => *self.cells.get(usize::from(slots[local]).checked_sub(1)?)?,
        };
        (cell.1 > 0).then_some(cell)
    }
}

/// The floor of the output cloud: one point per `cell_m` x `cell_m` column of the world's x-y
/// grid, the mean of the ground points (each frame's RANSAC plane inliers) that fell in it.
///
/// The floor is a height field, so its columns are averaged over every frame that saw them. In 3D
/// voxels a column keeps one centroid per voxel of height, and floor hits that a frame's small
/// pitch error lifted 2-3.5 cm keep their own layer, which the calculator can take for underside
/// (decision record 010). Averaged into their columns they sink toward the floor by the share of
/// the column's hits they are.
///
/// Implementation: a column is a voxel of a [`CloudAccumulator`] in coordinates where heights are
/// compressed into one voxel layer (`z' = cell / 2 + z * cell / (2 * FLOOR_HALF_RANGE_M)`), so
/// the floor keeps that accumulator's batched, cache-friendly layout (a hash map with one lookup
/// per point costs measurably more per frame). Its blocks are dense sheets (`Blocking::Sheets`),
/// slightly cheaper than sparse cubes for a floor, with the same output (decision record 006). Floor more than [`FLOOR_HALF_RANGE_M`] above or below the first frame's ground
/// splits a column in two points, as the 3D voxels did.
#[derive(Debug, Clone)]
pub struct FloorAccumulator {
    cell_m: f64,
    /// Compressed heights: `z' = cell / 2 + z * squash`.
    squash: f64,
    columns: CloudAccumulator,
}

/// Heights within this of the world's z = 0 (the first frame's ground) share a column's point.
pub const FLOOR_HALF_RANGE_M: f64 = 1.0;

impl FloorAccumulator {
    /// An empty floor with columns of `cell_m` (> 0).
    pub fn new(cell_m: f64) -> Self {
        Self {
            cell_m,
            squash: cell_m / (2.0 * FLOOR_HALF_RANGE_M),
            columns: CloudAccumulator::with_blocking(cell_m, Blocking::Sheets),
        }
    }

    /// Add a world-frame ground point.
    pub fn add(&mut self, p: V3) {
        self.columns
            .add(V3::new(p[0], p[1], 0.5 * self.cell_m + p[2] * self.squash));
    }

    /// Number of occupied columns.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }

    /// The columns' means, sorted by column so the output does not depend on hash order.
    pub fn points(&self) -> Vec<V3> {
        self.columns
            .points()
            .into_iter()
            .map(|p| V3::new(p.x, p.y, (p.z - 0.5 * self.cell_m) / self.squash))
            .collect()
    }
}

/// One centroid per voxel of everything added.
///
/// Layout: voxels are grouped into blocks of 8 x 8 x 8; a hash map finds the block, an array in
/// the block finds the voxel, and a block's cells are contiguous. Points are buffered and added
/// a batch at a time, grouped by block, so each block is looked up once per batch and its memory
/// is touched in one go. The former layout (one hash map entry per voxel, points added in
/// firing order) spent about an eighth of the pipeline's time on a cache and TLB miss per point in
/// a table of a million voxels.
///
/// The grouping is stable and batches are added in order, so every voxel's sum is formed in the
/// order its points were added: the centroids are bit-for-bit those of one hash map entry per
/// voxel (test `blocks_give_the_centroids_and_order_of_one_map_entry_per_voxel`).
#[derive(Debug, Clone)]
pub struct CloudAccumulator {
    voxel_m: f64,
    blocking: Blocking,
    /// Keyed by block in block space ([`Blocking`]).
    blocks: VoxelMap<Block>,
    /// Occupied voxels in `blocks`.
    len: usize,
    /// Points added since the last batch went into `blocks`, in order.
    pending: Vec<V3>,
}

impl CloudAccumulator {
    /// An empty accumulator with voxels of `voxel_m`.
    pub fn new(voxel_m: f64) -> Self {
        Self::with_blocking(voxel_m, Blocking::Cubes)
    }

    fn with_blocking(voxel_m: f64, blocking: Blocking) -> Self {
        Self {
            voxel_m,
            blocking,
            blocks: VoxelMap::default(),
            len: 0,
            pending: Vec::new(),
        }
    }

    /// Add a world-frame point.
    pub fn add(&mut self, p: V3) {
        self.pending.push(p);
        if self.pending.len() >= BATCH {
            self.len += add_grouped(
                &mut self.blocks,
                None,
                &self.pending,
                self.voxel_m,
                self.blocking,
            );
            self.pending.clear();
        }
    }

    /// The blocks the pending points fall in, copied from `blocks` (or new) with the pending
    /// points added, and how many voxels they add.
    fn pending_overlay(&self) -> (VoxelMap<Block>, usize) {
        let mut overlay = VoxelMap::default();
        let added = add_grouped(
            &mut overlay,
            Some(&self.blocks),
            &self.pending,
            self.voxel_m,
            self.blocking,
        );
        (overlay, added)
    }

    /// Number of occupied voxels.
    pub fn len(&self) -> usize {
        if self.pending.is_empty() {
            self.len
        } else {
            self.len + self.pending_overlay().1
        }
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0 && self.pending.is_empty()
    }

    /// The centroids, sorted by voxel so the output does not depend on hash order.
    ///
    /// A voxel's coordinate along each axis is `block * 8 + local`, so the voxels' lexicographic
    /// order is that of (block x, local x, block y, local y, block z, local z): with the blocks
    /// sorted, the nested walk below emits the voxels in order without sorting them (sorting a
    /// million voxels was about 8 % of a run's pipeline time).
    pub fn points(&self) -> Vec<V3> {
        const SIDE: usize = 1 << BLOCK_BITS;
        let (overlay, added) = self.pending_overlay();
        let flushed = self
            .blocks
            .iter()
            .filter(|(k, _)| !overlay.contains_key(*k));
        let mut blocks: Vec<([i32; 3], &Block)> =
            flushed.chain(&overlay).map(|(k, b)| (*k, b)).collect();
        if self.blocking == Blocking::Sheets {
            let mut keyed: Vec<([i32; 3], V3)> = Vec::with_capacity(self.len + added);
            for (key, block) in blocks {
                for local in 0..BLOCK_VOXELS {
                    if let Some(cell) = block.cell(local) {
                        let voxel = self
                            .blocking
                            .voxel_of_block_space(voxel_of_local(key, local));
                        keyed.push((voxel, centroid(cell)));
                    }
                }
            }
            keyed.sort_unstable_by_key(|&(voxel, _)| voxel);
            return keyed.into_iter().map(|(_, p)| p).collect();
        }
        blocks.sort_unstable_by_key(|(key, _)| *key);
        let mut out = Vec::with_capacity(self.len + added);
        for slab in blocks.chunk_by(|a, b| a.0[0] == b.0[0]) {
            for local_x in 0..SIDE {
                for row in slab.chunk_by(|a, b| a.0[1] == b.0[1]) {
                    for local_y in 0..SIDE {
                        let first = (local_x * SIDE + local_y) * SIDE;
                        for (_, block) in row {
                            out.extend(
                                (first..first + SIDE)
                                    .filter_map(|local| block.cell(local).map(centroid)),
                            );
                        }
                    }
                }
            }
        }
        out
    }
}

/// The mean of a cell's points.
fn centroid((sum, n): (V3, u32)) -> V3 {
    sum * (1.0 / f64::from(n))
}

/// Add `points` (in order within each voxel) to `blocks`, block by block; a block not yet in
/// `blocks` starts as a copy of the one in `base`, if any, else empty. Returns the number of
/// voxels that were empty before.
fn add_grouped(
    blocks: &mut VoxelMap<Block>,
    base: Option<&VoxelMap<Block>>,
    points: &[V3],
    voxel_m: f64,
    blocking: Blocking,
) -> usize {
    // Counting sort of the points by block, stable (first-seen block order).
    let mut group_of_block: VoxelMap<u32> = VoxelMap::default();
    let mut block_keys: Vec<[i32; 3]> = Vec::new();
    let mut starts: Vec<usize> = Vec::new();
    let mut voxels = Vec::with_capacity(points.len());
    let mut groups = Vec::with_capacity(points.len());
    // Consecutive points (one firing's column, neighbours on a ring) often share a block.
    let mut last: Option<([i32; 3], usize)> = None;
    for &p in points {
        let voxel = blocking.block_space_of(voxel_of(p, voxel_m));
        let key = voxel.map(|c| c >> BLOCK_BITS);
        let group = match last {
            Some((last_key, group)) if last_key == key => group,
            _ => *group_of_block.entry(key).or_insert_with(|| {
                block_keys.push(key);
                starts.push(0);
                (block_keys.len() - 1) as u32
            }) as usize,
        };
        last = Some((key, group));
        starts[group] += 1;
        voxels.push(voxel);
        groups.push(group);
    }
    let mut next = 0;
    for start in &mut starts {
        let count = *start;
        *start = next;
        next += count;
    }
    let mut order = vec![0; points.len()];
    let mut fill = starts.clone();
    for (i, &group) in groups.iter().enumerate() {
        order[fill[group]] = i;
        fill[group] += 1;
    }
    starts.push(points.len());
    let mut added = 0;
    for (group, key) in block_keys.iter().enumerate() {
        let block = blocks.entry(*key).or_insert_with(|| {
            base.and_then(|b| b.get(key))
                .cloned()
                .unwrap_or_else(|| Block::new(blocking))
        });
        for &i in &order[starts[group]..starts[group + 1]] {
            added += usize::from(block.add(local_index(voxels[i]), points[i]));
        }
    }
    added
}

/// Index of `voxel` within its block, x-major.
fn local_index(voxel: [i32; 3]) -> usize {
    let mask = (1 << BLOCK_BITS) - 1;
    voxel
        .iter()
        .fold(0, |acc, &c| (acc << BLOCK_BITS) | (c & mask) as usize)
}

/// The voxel at index `local` (see [`local_index`]) of block `block_key`.
fn voxel_of_local(block_key: [i32; 3], local: usize) -> [i32; 3] {
    let mask = (1 << BLOCK_BITS) - 1;
    std::array::from_fn(|k| {
        let shift = BLOCK_BITS * (2 - k as u32);
        (block_key[k] << BLOCK_BITS) | ((local >> shift) & mask) as i32
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_floor_is_one_mean_per_column_whatever_the_height() {
        let mut floor = FloorAccumulator::new(0.02);
        assert!(floor.is_empty());
        // Four hits on the floor and one lifted 3 cm by a tilted frame, in one 2 cm column: one
        // point at the mean (as 3D voxels they were two, the lifted one kept at 3 cm).
        for z in [0.0, 0.001, -0.001, 0.0, 0.03] {
            floor.add(V3::new(0.011, 0.013, z));
        }
        // A second column, behind the first in x.
        floor.add(V3::new(-0.005, 0.013, 0.002));
        assert_eq!(floor.len(), 2);
        let points = floor.points();
        assert_eq!(points.len(), 2);
        assert!(
            (points[0][0] + 0.005).abs() < 1e-12,
            "sorted by column: {points:?}"
        );
        assert!((points[1][2] - 0.006).abs() < 1e-12, "{points:?}");
        assert!((points[1][0] - 0.011).abs() < 1e-12 && (points[1][1] - 0.013).abs() < 1e-12);
    }

    #[test]
    fn accumulator_averages_within_a_voxel() {
        let mut acc = CloudAccumulator::new(0.1);
        acc.add(V3::new(0.01, 0.01, 0.01));
        acc.add(V3::new(0.03, 0.05, 0.07));
        acc.add(V3::new(0.25, 0.0, 0.0));
        let pts = acc.points();
        assert_eq!(pts.len(), 2);
        assert!((pts[0][0] - 0.02).abs() < 1e-12 && (pts[0][2] - 0.04).abs() < 1e-12);
    }

    #[test]
    fn accumulator_returns_to_earlier_voxels_and_sorts_by_voxel() {
        let mut acc = CloudAccumulator::new(0.1);
        // Back and forth between voxels, then a voxel below the others.
        for p in [
            V3::new(0.31, 0.0, 0.0),
            V3::new(0.01, 0.0, 0.0),
            V3::new(0.33, 0.0, 0.0),
            V3::new(0.03, 0.0, 0.0),
            V3::new(0.05, 0.0, 0.0),
            V3::new(-0.05, 0.0, 0.0),
        ] {
            acc.add(p);
        }
        assert_eq!(acc.len(), 3);
        let pts = acc.points();
        assert!((pts[0][0] + 0.05).abs() < 1e-12, "{pts:?}");
        assert!((pts[1][0] - 0.03).abs() < 1e-12, "{pts:?}");
        assert!((pts[2][0] - 0.32).abs() < 1e-12, "{pts:?}");
        assert!(CloudAccumulator::new(0.1).is_empty());
    }

    #[test]
    fn blocks_give_the_centroids_and_order_of_one_map_entry_per_voxel() {
        use rand::{Rng, SeedableRng};
        // The reference: one hash map entry per voxel (the former layout), points added in
        // order. Dense voxels (tens of points each) make any change of the summation order show
        // in the last bits; 20 000 points cross a batch boundary.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let voxel_m = 0.005;
        let mut acc = CloudAccumulator::new(voxel_m);
        let mut reference: VoxelMap<(V3, u32)> = VoxelMap::default();
        let expected = |reference: &VoxelMap<(V3, u32)>| -> Vec<V3> {
            let mut cells: Vec<_> = reference.iter().collect();
            cells.sort_unstable_by_key(|(k, _)| **k);
            cells
                .into_iter()
                .map(|(_, (sum, n))| *sum * (1.0 / f64::from(*n)))
                .collect()
        };
        for i in 0..BATCH + 4000 {
            // Around the origin (negative voxels, block edges) and a few far out.
            let spread = match i % 100 {
                0 => 50.0,
                k if k % 2 == 0 => 0.03,
                _ => 0.1,
            };
            let p = V3::from_fn(|_, _| rng.random_range(-spread..spread));
            acc.add(p);
            let cell = reference
                .entry(voxel_of(p, voxel_m))
                .or_insert((V3::zeros(), 0));
            cell.0 += p;
            cell.1 += 1;
            if i == 1000 || i == BATCH - 1 || i == BATCH {
                // Before the first batch, at it and just after: pending points count.
                assert_eq!(acc.len(), reference.len(), "after {i} points");
                assert_eq!(acc.points(), expected(&reference), "after {i} points");
            }
        }
        let expected = expected(&reference);
        // Most points share voxels with earlier ones: the blocks are revisited across batches.
        assert!(
            expected.len() > 5000 && expected.len() < BATCH / 2,
            "{}",
            expected.len()
        );
        assert_eq!(acc.len(), expected.len());
        assert_eq!(acc.points(), expected);
    }

    #[test]
    fn local_index_round_trips_for_negative_and_extreme_voxels() {
        for voxel in [
            [0, 0, 0],
            [-1, -8, 7],
            [9, -9, 1000],
            [i32::MIN, i32::MAX, -1],
        ] {
            let block = voxel.map(|c| c >> BLOCK_BITS);
            let local = local_index(voxel);
            assert!(local < BLOCK_VOXELS);
            assert_eq!(voxel_of_local(block, local), voxel);
        }
    }

    #[test]
    fn sheet_block_space_round_trips() {
        for voxel in [
            [0, 0, 0],
            [-1, -1, -1],
            [1, 2, 3],
            [-7, 5, -2],
            [i32::MIN, i32::MAX, 1 << 27],
        ] {
            let b = Blocking::Sheets.block_space_of(voxel);
            assert_eq!(Blocking::Sheets.voxel_of_block_space(b), voxel);
        }
        // A block holds 16 x 32 columns of one layer.
        let block = |v: [i32; 3]| Blocking::Sheets.block_space_of(v).map(|c| c >> BLOCK_BITS);
        assert_eq!(block([0, 0, 0]), block([15, 31, 0]));
        assert_ne!(block([0, 0, 0]), block([16, 0, 0]));
        assert_ne!(block([0, 0, 0]), block([0, 32, 0]));
        assert_ne!(block([0, 0, 0]), block([0, 0, 1]));
        assert_ne!(block([0, 0, 0]), block([-1, 0, 0]));
    }

    #[test]
    fn sheet_blocks_give_the_centroids_and_order_of_cube_blocks() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut cubes = CloudAccumulator::new(0.02);
        let mut sheets = CloudAccumulator::with_blocking(0.02, Blocking::Sheets);
        for i in 0..2 * BATCH + 100 {
            // A layer one voxel thick around the origin, a few points above and below it.
            let z = match i % 50 {
                0 => rng.random_range(-0.1..0.1),
                _ => rng.random_range(0.0..0.02),
            };
            let p = V3::new(rng.random_range(-3.0..3.0), rng.random_range(-2.0..2.0), z);
            cubes.add(p);
            sheets.add(p);
            if i == 1000 || i == BATCH + 7 {
                assert_eq!(sheets.len(), cubes.len(), "after {i} points");
                assert_eq!(sheets.points(), cubes.points(), "after {i} points");
            }
        }
        let points = cubes.points();
        assert!(points.len() > 20_000, "{}", points.len());
        assert_eq!(sheets.len(), cubes.len());
        assert_eq!(sheets.points(), points);
    }

    #[test]
    fn feature_map_caps_points_per_voxel() {
        let mut map = FeatureMap::new(0.5, 3, 0.0);
        let planes: Vec<(V3, u32)> = (0..10)
            .map(|i| (V3::new(f64::from(i) * 0.01, 0.0, 0.0), 0))
            .collect();
        map.add(&Pose::IDENTITY, &planes, &[]);
        assert_eq!(map.len(), 3);
        map.add(
            &Pose::from_xyz_rpy([5.0, 0.0, 0.0], [0.0; 3]),
            &planes,
            &[(V3::zeros(), 1)],
        );
        assert_eq!(map.len(), 7);
    }

    #[test]
    fn a_spaced_map_leaves_room_for_surfaces_seen_later() {
        // The far side of a part, seen first and often: 30 frames of the same 19 points, 1 cm
        // apart. Then its near side, 10 cm away in the same 0.2 m voxel.
        let line = |z: f64, tag: u32| -> Vec<(V3, u32)> {
            (1..20)
                .map(|i| (V3::new(f64::from(i) * 0.01, 0.05, z), tag))
                .collect()
        };
        let (far, near) = (line(0.05, 0), line(0.15, 1));
        let near_held = |map: &FeatureMap| {
            let planes = &map.target().planes;
            planes.points().iter().filter(|p| p[2] > 0.1).count()
        };
        let mut first = FeatureMap::new(0.2, 20, 0.0);
        let mut spaced = FeatureMap::new(0.2, 20, 0.045);
        for map in [&mut first, &mut spaced] {
            for _ in 0..30 {
                map.add(&Pose::IDENTITY, &far, &[]);
            }
            map.add(&Pose::IDENTITY, &near, &[]);
        }
        // Without spacing the voxel is full of the far side; with it each side holds a point
        // every 5 cm (x 0.01, 0.06, 0.11, 0.16).
        assert_eq!(first.len(), 20);
        assert_eq!(near_held(&first), 0);
        assert_eq!(spaced.len(), 8);
        assert_eq!(near_held(&spaced), 4);
    }
}
