//! Speed of the geometry's hot operations on one core, printed as figures (no timed assertions):
//! - `eigen3`: eigen-decomposition of 3x3 covariances (planes, lines, blobs, as the pipeline's
//!   feature fits see them) by the closed form (`symmetric_eigen3`), by cyclic Jacobi
//!   (`symmetric_eigen_jacobi`) and by nalgebra's general `SymmetricEigen`;
//! - `voxel`: building a `VoxelIndex` and its K = 5 nearest-neighbour queries within 0.2 m in
//!   0.2 m voxels (the scan-to-scan target), on a seeded scene of ground, underbody and tyres;
//! - `pose`: `Pose::apply` and `centroid_covariance` of five points (the per-correspondence work).
//!
//! ```text
//! cargo run --release -p passangle-geom --example bench_geom [-- REPEATS]
//! ```
//!
//! Output lines: `case impl ns_per_op=N`, the best of REPEATS (default 5) timed runs.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;
use std::time::Instant;

use passangle_geom::{
    M3, Neighbour, Pose, V3, VoxelIndex, centroid_covariance, symmetric_eigen_jacobi,
    symmetric_eigen3,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn v3(x: f64, y: f64, z: f64) -> V3 {
    V3::new(x, y, z)
}

fn m3(m: &M3) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

/// The best of `repeats` runs of `f` over `n` items, nanoseconds per item.
fn best_ns(repeats: usize, n: usize, mut f: impl FnMut() -> f64) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let start = Instant::now();
        black_box(f());
        best = best.min(start.elapsed().as_secs_f64() * 1e9 / n as f64);
    }
    best
}

/// Covariances of five to forty points on planes, lines and blobs in random orientations.
fn covariances(rng: &mut ChaCha8Rng, n: usize) -> Vec<M3> {
    (0..n)
        .map(|case| {
            let pose = Pose::from_xyz_rpy(
                v3(0.0, 0.0, 0.0),
                v3(
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                ),
            );
            let spread = match case % 3 {
                0 => v3(0.2, 0.2, 0.002),
                1 => v3(0.3, 0.01, 0.01),
                _ => v3(0.1, 0.08, 0.05),
            };
            let count = rng.random_range(5..40);
            let points: Vec<V3> = (0..count)
                .map(|_| {
                    pose.apply(v3(
                        spread[0] * rng.random_range(-1.0..1.0),
                        spread[1] * rng.random_range(-1.0..1.0),
                        spread[2] * rng.random_range(-1.0..1.0),
                    ))
                })
                .collect();
            centroid_covariance(points.into_iter()).unwrap().1
        })
        .collect()
}

/// Ground within 8 m, an underbody 0.35 m up, four tyre cylinders, 3 mm noise.
fn scene(rng: &mut ChaCha8Rng, n: usize) -> Vec<V3> {
    (0..n)
        .map(|i| {
            let noise = v3(
                rng.random_range(-0.003..0.003),
                rng.random_range(-0.003..0.003),
                rng.random_range(-0.003..0.003),
            );
            let p = match i % 4 {
                0 | 1 => v3(
                    rng.random_range(-8.0..8.0),
                    rng.random_range(-8.0..8.0),
                    0.0,
                ),
                2 => v3(
                    rng.random_range(-2.0..2.0),
                    rng.random_range(-0.9..0.9),
                    0.35,
                ),
                _ => {
                    let t: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                    let wheel = [(-1.4, -0.8), (-1.4, 0.8), (1.4, -0.8), (1.4, 0.8)][i % 16 / 4];
                    v3(
                        wheel.0 + 0.33 * t.cos(),
                        wheel.1 + rng.random_range(-0.1..0.1),
                        0.33 + 0.33 * t.sin(),
                    )
                }
            };
            p + noise
        })
        .collect()
}

fn main() {
    let repeats: usize = std::env::args()
        .nth(1)
        .map_or(5, |s| s.parse().expect("REPEATS"));
    let mut rng = ChaCha8Rng::seed_from_u64(7);

    let covs = covariances(&mut rng, 100_000);
    let arrays: Vec<[[f64; 3]; 3]> = covs.iter().map(m3).collect();
    let n = covs.len();
    let closed = best_ns(repeats, n, || {
        covs.iter()
            .map(|m| symmetric_eigen3(black_box(m)).unwrap().0[0])
            .sum()
    });
    let jacobi = best_ns(repeats, n, || {
        arrays
            .iter()
            .map(|m| symmetric_eigen_jacobi(black_box(m)).0[0])
            .sum()
    });
    let general = best_ns(repeats, n, || {
        covs.iter()
            .map(|m| {
                nalgebra::SymmetricEigen::new(*black_box(m))
                    .eigenvalues
                    .min()
            })
            .sum()
    });
    println!("eigen3 closed-form ns_per_op={closed:.1}");
    println!("eigen3 jacobi ns_per_op={jacobi:.1}");
    println!("eigen3 nalgebra-SymmetricEigen ns_per_op={general:.1}");

    let points = scene(&mut rng, 200_000);
    let queries: Vec<V3> = (0..200_000)
        .map(|i| {
            points[(i * 7919) % points.len()]
                + v3(
                    rng.random_range(-0.03..0.03),
                    rng.random_range(-0.03..0.03),
                    rng.random_range(-0.03..0.03),
                )
        })
        .collect();
    let build = best_ns(repeats, points.len(), || {
        VoxelIndex::new(points.clone(), 0.2).points().len() as f64
    });
    let index = VoxelIndex::new(points.clone(), 0.2);
    let query = best_ns(repeats, queries.len(), || {
        let mut out = [Neighbour::default(); 5];
        queries
            .iter()
            .map(|&q| {
                let k = index.neighbours(black_box(q), 0.2, &mut out);
                out[..k].iter().map(|n| n.d2).sum::<f64>()
            })
            .sum()
    });
    println!("voxel build ns_per_op={build:.1}");
    println!("voxel nearest-k5-r0.2 ns_per_op={query:.1}");

    let pose = Pose::from_xyz_rpy(v3(1.0, -2.0, 0.3), v3(0.02, -0.05, 1.2));
    let apply = best_ns(repeats, points.len(), || {
        points.iter().map(|&p| black_box(pose).apply(p)[2]).sum()
    });
    let five = best_ns(repeats, points.len() / 5, || {
        points
            .chunks_exact(5)
            .map(|c| centroid_covariance(black_box(c).iter().copied()).unwrap().1[(0, 0)])
            .sum()
    });
    println!("pose apply ns_per_op={apply:.1}");
    println!("pose centroid-covariance-5 ns_per_op={five:.1}");
}
