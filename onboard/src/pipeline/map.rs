//! Step 7a, the local feature map for scan-to-map refinement (paper 3.5, after LOAM's mapping) and
//! the accumulator that fuses all frames into one cloud.
//!
//! The feature map is a voxel hash map (as in KISS-ICP) of corner and plane points in the world
//! frame with at most `points_per_voxel` per voxel, so its size grows with the area covered, not
//! with the number of frames. Each frame's features are registered to it
//! ([`super::laser_odometry::register_joint`]) before they are added.
//!
//! The output accumulator keeps one centroid per `output_voxel_m` voxel: repeated views of a
//! surface average down the lidar's range noise instead of thickening the surface, and the cloud's
//! size is bounded by the surface area seen.

use super::geom::{Pose, V3, VoxelIndex, VoxelMap, add, scale, voxel_of};
use super::laser_odometry::FeatureTarget;

/// Corner and plane points in the world frame.
#[derive(Debug, Clone)]
pub struct FeatureMap {
    target: FeatureTarget,
    points_per_voxel: usize,
}

impl FeatureMap {
    /// An empty map with voxels of `voxel_m` (also the largest correspondence distance).
    pub fn new(voxel_m: f64, points_per_voxel: usize) -> Self {
        Self {
            target: FeatureTarget {
                corners: VoxelIndex::new(Vec::new(), voxel_m),
                planes: VoxelIndex::new(Vec::new(), voxel_m),
            },
            points_per_voxel,
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
        for &(p, tag) in planes {
            self.target
                .planes
                .insert_capped(world_from_robot.apply(p), tag, self.points_per_voxel);
        }
        for &(p, tag) in corners {
            self.target.corners.insert_capped(
                world_from_robot.apply(p),
                tag,
                self.points_per_voxel,
            );
        }
    }
}

/// One centroid per voxel of everything added.
#[derive(Debug, Clone)]
pub struct CloudAccumulator {
    voxel_m: f64,
    cells: VoxelMap<(V3, u32)>,
}

impl CloudAccumulator {
    /// An empty accumulator with voxels of `voxel_m`.
    pub fn new(voxel_m: f64) -> Self {
        Self {
            voxel_m,
            cells: VoxelMap::default(),
        }
    }

    /// Add a world-frame point.
    pub fn add(&mut self, p: V3) {
        let cell = self
            .cells
            .entry(voxel_of(p, self.voxel_m))
            .or_insert(([0.0; 3], 0));
        cell.0 = add(cell.0, p);
        cell.1 += 1;
    }

    /// Number of occupied voxels.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The centroids, sorted by voxel so the output does not depend on hash order.
    pub fn points(&self) -> Vec<V3> {
        let mut cells: Vec<(&[i32; 3], &(V3, u32))> = self.cells.iter().collect();
        cells.sort_unstable_by_key(|(k, _)| **k);
        cells
            .into_iter()
            .map(|(_, (sum, n))| scale(*sum, 1.0 / f64::from(*n)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accumulator_averages_within_a_voxel() {
        let mut acc = CloudAccumulator::new(0.1);
        acc.add([0.01, 0.01, 0.01]);
        acc.add([0.03, 0.05, 0.07]);
        acc.add([0.25, 0.0, 0.0]);
        let pts = acc.points();
        assert_eq!(pts.len(), 2);
        assert!((pts[0][0] - 0.02).abs() < 1e-12 && (pts[0][2] - 0.04).abs() < 1e-12);
    }

    #[test]
    fn accumulator_returns_to_earlier_voxels_and_sorts_by_voxel() {
        let mut acc = CloudAccumulator::new(0.1);
        // Back and forth between voxels, then a voxel below the others.
        for p in [
            [0.31, 0.0, 0.0],
            [0.01, 0.0, 0.0],
            [0.33, 0.0, 0.0],
            [0.03, 0.0, 0.0],
            [0.05, 0.0, 0.0],
            [-0.05, 0.0, 0.0],
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
    fn feature_map_caps_points_per_voxel() {
        let mut map = FeatureMap::new(0.5, 3);
        let planes: Vec<(V3, u32)> = (0..10)
            .map(|i| ([f64::from(i) * 0.01, 0.0, 0.0], 0))
            .collect();
        map.add(&Pose::IDENTITY, &planes, &[]);
        assert_eq!(map.len(), 3);
        map.add(
            &Pose::from_xyz_rpy([5.0, 0.0, 0.0], [0.0; 3]),
            &planes,
            &[([0.0; 3], 1)],
        );
        assert_eq!(map.len(), 7);
    }
}
