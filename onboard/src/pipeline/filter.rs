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
use super::geom::{
    V3, VoxelMap, add, centroid_covariance, dist2, dot, scale, sub, symmetric_eigen, voxel_of,
};

/// Filter `points`; returns the filtered cloud (same order and length).
pub fn bilateral(points: &[V3], config: &FilterConfig) -> Vec<V3> {
    if !config.enabled || points.is_empty() {
        return points.to_vec();
    }
    let r = config.radius_m;
    let mut cells: VoxelMap<Vec<u32>> = VoxelMap::default();
    for (i, &p) in points.iter().enumerate() {
        cells.entry(voxel_of(p, r)).or_default().push(i as u32);
    }
    let mut neighbours = Vec::new();
    points
        .iter()
        .map(|&p| {
            neighbours.clear();
            let c = voxel_of(p, r);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(cell) = cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                            neighbours.extend(
                                cell.iter()
                                    .map(|&j| points[j as usize])
                                    .filter(|&q| dist2(p, q) <= r * r),
                            );
                        }
                    }
                }
            }
            filter_one(p, &neighbours, config)
        })
        .collect()
}

fn filter_one(p: V3, neighbours: &[V3], config: &FilterConfig) -> V3 {
    if neighbours.len() < 5 {
        return p;
    }
    let Some((_, cov)) = centroid_covariance(neighbours.iter().copied()) else {
        return p;
    };
    let (_, vectors) = symmetric_eigen(&cov);
    let n = [vectors[0][0], vectors[1][0], vectors[2][0]];
    let (two_ss, two_sn) = (
        2.0 * config.sigma_spatial_m.powi(2),
        2.0 * config.sigma_normal_m.powi(2),
    );
    let mut num = 0.0;
    let mut den = 0.0;
    for &q in neighbours {
        let d = sub(q, p);
        let h = dot(n, d);
        let w = (-dot(d, d) / two_ss - h * h / two_sn).exp();
        num += w * h;
        den += w;
    }
    if den > 0.0 {
        add(p, scale(n, num / den))
    } else {
        p
    }
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
                pts.push([x, f64::from(j) * 0.01, z + noise]);
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
