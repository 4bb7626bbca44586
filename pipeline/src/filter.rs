//! Step 7b, the bilateral filter (paper 3.5, refs. 31 and 33): edge-preserving smoothing of the
//! fused cloud.
//!
//! For each point `p` with neighbours `q` within `radius_m`, the local normal `n` comes from the
//! neighbourhood's covariance (smallest eigenvector), and `p` moves along it by
//! `sum w_s w_r (n . (q - p)) / sum w_s w_r`, with the spatial weight
//! `w_s = exp(-|q - p|^2 / 2 sigma_s^2)` and the range weight `w_r = exp(-(n . (q - p))^2 / 2 sigma_n^2)`.
//! On a noisy flat surface the offsets are small and the point moves to the local mean surface; across
//! an edge the offsets are large, the range weight vanishes, and the edge stays sharp.
//! The filter reads only the input cloud (a Jacobi step), so the result does not depend on order.

use super::config::FilterConfig;
use super::geom::{V3, centroid_covariance, symmetric_eigen_m3, voxel_of};

/// Filter `points`; returns the filtered cloud (same order and length).
///
/// The cloud is large (hundreds of thousands of points), so the neighbour search is built for
/// memory locality rather than hash lookups: points are sorted by their voxel (of the radius)
/// into one array, and the voxels are swept in ascending `(x, y, z)` order. The neighbours of a
/// voxel lie in the 9 columns `(x + dx, y + dy)` at heights `z - 1 ..= z + 1`, which are runs of
/// consecutive voxels in that order; one cursor per column only ever moves forward, so the sweep
/// reads memory nearly sequentially. Each voxel's candidates are gathered once and shared by its
/// points. Neighbours come in ascending voxel order and input order within a voxel, so every
/// point's sums run in a fixed order.
pub fn bilateral(points: &[V3], config: &FilterConfig) -> Vec<V3> {
    if !config.enabled || points.is_empty() {
        return points.to_vec();
    }
    let r = config.radius_m;
    let grid = SortedGrid::new(points, r);
    let mut out = points.to_vec();
    let mut cursors = [0usize; 9];
    let mut candidates: Vec<V3> = Vec::new();
    let mut neighbours: Vec<V3> = Vec::new();
    for cell in &grid.cells {
        candidates.clear();
        for (column, cursor) in COLUMNS.iter().zip(&mut cursors) {
            let lo = [
                cell.key[0] + column[0],
                cell.key[1] + column[1],
                cell.key[2] - 1,
            ];
            let hi = [lo[0], lo[1], cell.key[2] + 1];
            while grid.cells.get(*cursor).is_some_and(|c| c.key < lo) {
                *cursor += 1;
            }
            for c in grid.cells[*cursor..].iter().take_while(|c| c.key <= hi) {
                candidates.extend_from_slice(&grid.points[c.start..c.end]);
            }
        }
        for k in cell.start..cell.end {
            let p = grid.points[k];
            neighbours.clear();
            neighbours.extend(
                candidates
                    .iter()
                    .copied()
                    .filter(|&q| (p - q).norm_squared() <= r * r),
            );
            out[grid.input_index[k]] = filter_one(p, &neighbours, config);
        }
    }
    out
}

/// The `(dx, dy)` offsets of the 9 neighbouring columns, in ascending order.
const COLUMNS: [[i64; 2]; 9] = [
    [-1, -1],
    [-1, 0],
    [-1, 1],
    [0, -1],
    [0, 0],
    [0, 1],
    [1, -1],
    [1, 0],
    [1, 1],
];

/// One occupied voxel: its key and its points' range in [`SortedGrid::points`].
struct GridCell {
    key: [i64; 3],
    start: usize,
    end: usize,
}

/// Points sorted by voxel (keys ascending, input order within a voxel).
struct SortedGrid {
    points: Vec<V3>,
    /// Input index of each sorted point.
    input_index: Vec<usize>,
    cells: Vec<GridCell>,
}

impl SortedGrid {
    fn new(points: &[V3], voxel_m: f64) -> Self {
        // i64 keys: the neighbour offsets cannot overflow even at the ends of voxel_of's range.
        let mut keyed: Vec<([i64; 3], usize)> = points
            .iter()
            .enumerate()
            .map(|(i, &p)| (voxel_of(p, voxel_m).map(i64::from), i))
            .collect();
        keyed.sort_unstable();
        let mut cells: Vec<GridCell> = Vec::new();
        for (k, &(key, _)) in keyed.iter().enumerate() {
            match cells.last_mut() {
                Some(last) if last.key == key => last.end = k + 1,
                _ => cells.push(GridCell {
                    key,
                    start: k,
                    end: k + 1,
                }),
            }
        }
        Self {
            points: keyed.iter().map(|&(_, i)| points[i]).collect(),
            input_index: keyed.iter().map(|&(_, i)| i).collect(),
            cells,
        }
    }
}

fn filter_one(p: V3, neighbours: &[V3], config: &FilterConfig) -> V3 {
    if neighbours.len() < 5 {
        return p;
    }
    let Some((_, cov)) = centroid_covariance(neighbours.iter().copied()) else {
        return p;
    };
    let (_, vectors) = symmetric_eigen_m3(&cov);
    let n = vectors.column(0).into_owned();
    let (two_ss, two_sn) = (
        2.0 * config.sigma_spatial_m.powi(2),
        2.0 * config.sigma_normal_m.powi(2),
    );
    let mut num = 0.0;
    let mut den = 0.0;
    for &q in neighbours {
        let d = q - p;
        let h = n.dot(&d);
        let w = (-d.dot(&d) / two_ss - h * h / two_sn).exp();
        num += w * h;
        den += w;
    }
    if den > 0.0 { p + n * (num / den) } else { p }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A noisy step: z = 0 for x < 0 and z = 0.1 for x >= 0, noise sigma 5 mm.
    fn step(seed: u64) -> (Vec<V3>, Vec<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut pts = Vec::new();
        let mut truth = Vec::new();
        for i in -30..30 {
            for j in 0..30 {
                let x = f64::from(i) * 0.01;
                let z = if x < 0.0 { 0.0 } else { 0.1 };
                let noise: f64 = (0..6).map(|_| rng.random_range(-0.005..0.005)).sum::<f64>();
                pts.push(V3::new(x, f64::from(j) * 0.01, z + noise));
                truth.push(z);
            }
        }
        (pts, truth)
    }

    fn rms(pts: &[V3], truth: &[f64]) -> f64 {
        (pts.iter()
            .zip(truth)
            .map(|(p, z)| (p[2] - z).powi(2))
            .sum::<f64>()
            / pts.len() as f64)
            .sqrt()
    }

    /// The filter with neighbours found by a linear scan, in the order the sweep promises
    /// (ascending voxel, then input order).
    fn bilateral_brute(points: &[V3], config: &FilterConfig) -> Vec<V3> {
        let r = config.radius_m;
        points
            .iter()
            .map(|&p| {
                let mut near: Vec<([i32; 3], usize)> = points
                    .iter()
                    .enumerate()
                    .filter(|&(_, &q)| (p - q).norm_squared() <= r * r)
                    .map(|(i, &q)| (voxel_of(q, r), i))
                    .collect();
                near.sort_unstable();
                let neighbours: Vec<V3> = near.iter().map(|&(_, i)| points[i]).collect();
                filter_one(p, &neighbours, config)
            })
            .collect()
    }

    #[test]
    fn sweep_finds_the_same_neighbours_as_a_linear_scan() {
        let (mut pts, _) = step(2);
        // Negative coordinates and a second, tilted surface crossing voxel rows.
        pts.extend((0..400).map(|i| {
            let (x, y) = (
                f64::from(i % 20) * 0.013 - 0.2,
                f64::from(i / 20) * 0.017 - 0.3,
            );
            V3::new(x, y, 0.5 * x + 0.05)
        }));
        assert_eq!(
            bilateral(&pts, &FilterConfig::default()),
            bilateral_brute(&pts, &FilterConfig::default())
        );
    }

    #[test]
    fn smooths_noise_and_keeps_the_step() {
        let (pts, truth) = step(1);
        let out = bilateral(&pts, &FilterConfig::default());
        assert!(
            rms(&out, &truth) < 0.6 * rms(&pts, &truth),
            "{} {}",
            rms(&out, &truth),
            rms(&pts, &truth)
        );
        // Points next to the edge stay on their own side.
        for (p, z) in out.iter().zip(&truth) {
            assert!((p[2] - z).abs() < 0.03, "{p:?} vs {z}");
        }
        let off = FilterConfig {
            enabled: false,
            ..FilterConfig::default()
        };
        assert_eq!(bilateral(&pts, &off), pts);
    }
}
