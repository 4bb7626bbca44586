//! Fixtures shared by the pipeline's unit tests: a synthetic scene under a car, its feature
//! target, and scans of it.

use crate::geom::{Pose, V3, VoxelIndex};
use crate::laser_odometry::FeatureTarget;
use crate::registration::Scan;

/// A synthetic "under a car" scene: ground, underbody at 0.35 m, four tyre cylinders (corner
/// lines along their silhouettes) and optionally a box that pins the travel direction.
pub(crate) fn scene(with_tyres: bool) -> (Vec<V3>, Vec<V3>) {
    let mut planes = Vec::new();
    let mut corners = Vec::new();
    for i in -40..40 {
        for j in -10..10 {
            let (x, y) = (f64::from(i) * 0.1, f64::from(j) * 0.1);
            planes.push(V3::new(x, y, 0.0));
            planes.push(V3::new(x + 0.05, y + 0.05, 0.35));
        }
    }
    if with_tyres {
        for (cx, cy) in [(1.4_f64, 0.8_f64), (1.4, -0.8), (-1.4, 0.8), (-1.4, -0.8)] {
            for k in 0..60 {
                let a = f64::from(k) * std::f64::consts::TAU / 60.0;
                let (x, z) = (cx + 0.3 * a.cos(), 0.3 + 0.3 * a.sin());
                // Tyre sidewall (a vertical disc facing the robot) and its edges.
                for w in 0..4 {
                    let r = 0.3 - 0.06 * f64::from(w);
                    planes.push(V3::new(cx + r * a.cos(), cy, 0.3 + r * a.sin()));
                }
                corners.push(V3::new(x, cy, z));
                corners.push(V3::new(x, cy - 0.2 * cy.signum(), z));
            }
            // Vertical edge lines at the tyre fronts and backs.
            for k in 0..20 {
                let z = f64::from(k) * 0.02;
                corners.push(V3::new(cx + 0.3, cy, z));
                corners.push(V3::new(cx - 0.3, cy, z));
            }
        }
    }
    (planes, corners)
}

pub(crate) fn target_of(planes: &[V3], corners: &[V3]) -> FeatureTarget {
    // Every synthetic point is its own scan line.
    let tags = |n: usize| (0..n as u32).collect();
    FeatureTarget {
        corners: VoxelIndex::new_tagged(corners.to_vec(), tags(corners.len()), 0.5),
        planes: VoxelIndex::new_tagged(planes.to_vec(), tags(planes.len()), 0.5),
    }
}

pub(crate) fn moved(points: &[V3], pose: &Pose) -> Vec<V3> {
    let inv = pose.inverse();
    points.iter().map(|&p| inv.apply(p)).collect()
}

/// A scan without a ground sample: step 1 and step 2 register the same planes.
pub(crate) fn scan_of<'a>(planes: &'a [V3], corners: &'a [V3]) -> Scan<'a> {
    Scan {
        step1_planes: planes,
        step2_planes: planes.len(),
        corners,
    }
}
