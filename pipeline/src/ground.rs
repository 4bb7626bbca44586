//! Step 2, ground removal (paper section 3.1): a RANSAC plane per frame.
//!
//! Ground dominates every frame under a car and its rings pull scan matching into local minima, so
//! the ground's points are kept out of feature extraction. Hypotheses are planes through three
//! random points; a hypothesis must be nearly horizontal (normal within `max_tilt_rad` of the robot's
//! z axis) and lie below the lidar (so the underbody, the other big plane, is never taken for the
//! ground). The search stops as soon as a plane holds more than `early_stop_fraction` of the points
//! (the paper's 50 % rule) and otherwise keeps the best of `max_iterations`. The sampler is seeded
//! from the config's seed and the frame index: the same frame always gives the same answer.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::GroundConfig;
use super::geom::{V3, cross, dot, norm, scale, sub};

/// A plane `normal . p + offset = 0` with a unit normal pointing up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal (z component positive).
    pub normal: V3,
    /// Offset, metres.
    pub offset_m: f64,
}

impl Plane {
    /// Signed distance of `p` (positive above).
    pub fn distance(&self, p: V3) -> f64 {
        dot(self.normal, p) + self.offset_m
    }
}

/// The ground found in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundSplit {
    /// The plane, robot frame.
    pub plane: Plane,
    /// `true` for each ground point (same order as the input).
    pub is_ground: Vec<bool>,
    /// Number of ground points.
    pub inliers: usize,
    /// Hypotheses tried.
    pub iterations: u32,
}

/// Find the ground plane of `points_in_robot` (robot frame, lidar at `lidar_z_m`). `None` when no
/// acceptable plane was found (fewer than three points, or nothing horizontal below the lidar).
pub fn segment_ground(
    points_in_robot: &[V3],
    lidar_z_m: f64,
    config: &GroundConfig,
    frame_index: u64,
) -> Option<GroundSplit> {
    let n = points_in_robot.len();
    if n < 3 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ frame_index.wrapping_mul(0x9e37_79b9));
    let min_cos = config.max_tilt_rad.cos();
    let stop = (config.early_stop_fraction * n as f64).ceil() as usize;
    let mut best: Option<(Plane, usize)> = None;
    let mut iterations = 0;
    while iterations < config.max_iterations {
        iterations += 1;
        let a = points_in_robot[rng.random_range(0..n)];
        let b = points_in_robot[rng.random_range(0..n)];
        let c = points_in_robot[rng.random_range(0..n)];
        let Some(plane) = plane_through(a, b, c) else {
            continue;
        };
        // The plane's height below the lidar (at the robot's x, y = 0).
        let depth_below_lidar = lidar_z_m + plane.offset_m / plane.normal[2];
        if plane.normal[2] < min_cos || depth_below_lidar < config.min_depth_below_lidar_m {
            continue;
        }
        let count = count_inliers(points_in_robot, plane, config.distance_threshold_m);
        if best.is_none_or(|(_, b)| count > b) {
            best = Some((plane, count));
        }
        if count > stop {
            break;
        }
    }
    let (plane, _) = best?;
    // Least-squares refit on the inliers: three points give the normal to about a degree, the
    // thousands of inliers to a few hundredths.
    let plane = refit(points_in_robot, plane, config.distance_threshold_m).unwrap_or(plane);
    let is_ground: Vec<bool> = points_in_robot
        .iter()
        .map(|&p| plane.distance(p).abs() <= config.distance_threshold_m)
        .collect();
    let inliers = is_ground.iter().filter(|&&g| g).count();
    Some(GroundSplit {
        plane,
        is_ground,
        inliers,
        iterations,
    })
}

fn refit(points: &[V3], plane: Plane, threshold_m: f64) -> Option<Plane> {
    let inliers = points
        .iter()
        .copied()
        .filter(move |&p| plane.distance(p).abs() <= threshold_m);
    let (c, cov) = super::geom::centroid_covariance(inliers)?;
    let (_, vectors) = super::geom::symmetric_eigen(&cov);
    let mut normal = [vectors[0][0], vectors[1][0], vectors[2][0]];
    if normal[2] < 0.0 {
        normal = scale(normal, -1.0);
    }
    Some(Plane {
        normal,
        offset_m: -dot(normal, c),
    })
}

fn count_inliers(points: &[V3], plane: Plane, threshold_m: f64) -> usize {
    points
        .iter()
        .filter(|&&p| plane.distance(p).abs() <= threshold_m)
        .count()
}

/// The plane through three points with an upward normal; `None` if they are (nearly) collinear.
pub fn plane_through(a: V3, b: V3, c: V3) -> Option<Plane> {
    let n = cross(sub(b, a), sub(c, a));
    let len = norm(n);
    if !(len > 1e-9) {
        return None;
    }
    let mut normal = scale(n, 1.0 / len);
    if normal[2] < 0.0 {
        normal = scale(normal, -1.0);
    }
    Some(Plane {
        normal,
        offset_m: -dot(normal, a),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ground rings at z = 0 plus a flat underbody at z = 0.3 with more points than the ground.
    fn scene() -> Vec<V3> {
        let mut points = Vec::new();
        for ring in 1..6 {
            let r = 0.5 * f64::from(ring);
            for k in 0..300 {
                let a = f64::from(k) * std::f64::consts::TAU / 300.0;
                points.push([r * a.cos(), r * a.sin(), 0.004 * (f64::from(k) * 0.7).sin()]);
            }
        }
        for i in 0..40 {
            for j in 0..50 {
                points.push([f64::from(i) * 0.1 - 2.0, f64::from(j) * 0.05 - 1.2, 0.3]);
            }
        }
        points
    }

    #[test]
    fn finds_the_ground_not_the_larger_underbody() {
        let points = scene();
        let split = segment_ground(&points, 0.12, &GroundConfig::default(), 0).unwrap();
        assert!(split.plane.normal[2] > 0.999);
        assert!(split.plane.offset_m.abs() < 0.01, "{:?}", split.plane);
        assert_eq!(split.inliers, 1500);
        assert!(split.is_ground[..1500].iter().all(|&g| g));
        assert!(split.is_ground[1500..].iter().all(|&g| !g));
    }

    #[test]
    fn same_frame_same_answer_and_none_for_walls_only() {
        let points = scene();
        let c = GroundConfig::default();
        assert_eq!(
            segment_ground(&points, 0.12, &c, 3),
            segment_ground(&points, 0.12, &c, 3)
        );
        let wall: Vec<V3> = (0..200)
            .map(|i| [1.0, f64::from(i % 20) * 0.1, f64::from(i / 20) * 0.1])
            .collect();
        assert!(segment_ground(&wall, 0.12, &c, 0).is_none());
        assert!(segment_ground(&[[0.0; 3]; 2], 0.12, &c, 0).is_none());
    }
}
