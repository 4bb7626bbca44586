//! Ground plane: RANSAC over a seeded random subsample, then least-squares refinement on the inliers.
//!
//! Hypotheses whose normal leans more than `max_ground_tilt_rad` from the cloud's z are rejected.
//! Score = inliers - 10 x points far (more than `BELOW_M`) below the plane, so a large flat
//! underbody never wins over the ground it sits above, even when it holds more points.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::geom::{V3, fit_plane, median, unit};

/// Points further than this below a candidate plane count against it.
const BELOW_M: f64 = 0.10;
/// Each such point costs this many inliers: the ground is the lowest large plane.
const BELOW_WEIGHT: i64 = 10;
/// RANSAC subsample size.
const SUBSAMPLE: usize = 40_000;
/// RANSAC hypotheses.
const ITERATIONS: usize = 400;

/// A plane `{p : normal . p = offset}` with `normal` the upward unit normal, in cloud coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Plane {
    pub normal: V3,
    pub offset: f64,
}

impl Plane {
    pub fn height(&self, p: V3) -> f64 {
        self.normal.dot(&p) - self.offset
    }

    fn through(normal: V3, point: V3) -> Self {
        Self {
            normal,
            offset: normal.dot(&point),
        }
    }
}

/// RANSAC ground hypothesis (before refinement).
pub(crate) fn ransac(
    points: &[V3],
    threshold_m: f64,
    max_tilt_rad: f64,
    seed: u64,
) -> Option<Plane> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sample: Vec<V3> = if points.len() <= SUBSAMPLE {
        points.to_vec()
    } else {
        (0..SUBSAMPLE)
            .map(|_| points[rng.random_range(0..points.len())])
            .collect()
    };
    if sample.len() < 3 {
        return None;
    }
    // Half of the hypotheses draw from the lowest quarter (by cloud z) of the sample: the ground
    // is low, and may hold a minority of the points when the vehicle is densely scanned.
    let mut low: Vec<V3> = sample.clone();
    low.sort_unstable_by(|a, b| a[2].total_cmp(&b[2]));
    low.truncate((sample.len() / 4).max(3));
    let min_cos = max_tilt_rad.cos();
    let mut best: Option<(i64, Plane)> = None;
    for i in 0..ITERATIONS {
        let pool = if i % 2 == 0 { &low } else { &sample };
        let [a, b, c] = [0, 1, 2].map(|_| pool[rng.random_range(0..pool.len())]);
        let Some(mut n) = unit((b - a).cross(&(c - a))) else {
            continue;
        };
        if n[2] < 0.0 {
            n = n.map(|v| -v);
        }
        if n[2] < min_cos {
            continue;
        }
        let plane = Plane::through(n, a);
        let mut score = 0i64;
        for &p in &sample {
            let h = plane.height(p);
            if h.abs() < threshold_m {
                score += 1;
            } else if h < -BELOW_M {
                score -= BELOW_WEIGHT;
            }
        }
        if best.is_none_or(|(s, _)| score > s) {
            best = Some((score, plane));
        }
    }
    best.filter(|(s, _)| *s >= 3).map(|(_, p)| p)
}

/// Least-squares refit on the points within `threshold_m` of `plane` that `keep` accepts.
pub(crate) fn refine(
    points: &[V3],
    plane: Plane,
    threshold_m: f64,
    keep: impl Fn(V3) -> bool,
) -> Option<Plane> {
    let inliers = points
        .iter()
        .copied()
        .filter(|&p| plane.height(p).abs() < threshold_m && keep(p));
    let (normal, point) = fit_plane(inliers)?;
    Some(Plane::through(normal, point))
}

/// Side of the floor cells over which [`local_noise_sigma`] takes the floor as flat, metres.
const LOCAL_CELL_M: f64 = 0.25;

/// Fewer floor points than this in a cell: the cell says nothing about the noise.
const LOCAL_CELL_MIN_POINTS: usize = 5;

/// The returns' own scatter on the floor: 1.4826 x the median absolute deviation of the points
/// within `threshold_m` of the plane from their [`LOCAL_CELL_M`] cell's median height. A hall's
/// floor undulates by centimetres over metres; over a quarter metre it is flat to a millimetre, so
/// the plane's residuals ([`noise_sigma`]) hold the floor's shape and these hold the sensor's
/// noise. `None` when no cell holds enough points.
pub(crate) fn local_noise_sigma(
    points: &[V3],
    plane: Plane,
    threshold_m: f64,
    keep: impl Fn(V3) -> bool,
) -> Option<f64> {
    let mut cells: passangle_geom::VoxelMap<Vec<f64>> = passangle_geom::VoxelMap::default();
    for &p in points.iter().filter(|&&p| keep(p)) {
        let h = plane.height(p);
        if h.abs() < threshold_m {
            let [x, y, _] = passangle_geom::voxel_of(p, LOCAL_CELL_M);
            cells.entry([x, y, 0]).or_default().push(h);
        }
    }
    let mut deviations = Vec::new();
    for heights in cells.values_mut() {
        if heights.len() >= LOCAL_CELL_MIN_POINTS
            && let Some(m) = median(heights)
        {
            deviations.extend(heights.iter().map(|h| (h - m).abs()));
        }
    }
    median(&mut deviations).map(|m| 1.4826 * m)
}

/// Robust noise estimate (1.4826 x median absolute height) of the points within `threshold_m`:
/// the sensor's noise and the floor's departure from the plane together.
pub(crate) fn noise_sigma(
    points: &[V3],
    plane: Plane,
    threshold_m: f64,
    keep: impl Fn(V3) -> bool,
) -> (f64, usize) {
    let mut h: Vec<f64> = points
        .iter()
        .filter(|&&p| keep(p))
        .map(|&p| plane.height(p).abs())
        .filter(|h| *h < threshold_m)
        .collect();
    let n = h.len();
    (1.4826 * median(&mut h).unwrap_or(0.0), n)
}
