//! Speed of `pipeline::geom::VoxelIndex` queries on one core, printed as figures (no timed
//! assertions), against two peers measured in the same run on the same points and queries:
//! - `brute`: a linear scan over every point (the reference answer; every result of the index is
//!   checked against it and mismatches are counted and printed);
//! - `old27`: a plain voxel hash (voxel -> point indices with the byte-at-a-time FxHash, all 27
//!   voxels around the query scanned, ties by visiting order), the straightforward design.
//!
//! ```text
//! cargo run --release -p onboard --example bench_voxel_index [-- QUERIES]
//! ```
//!
//! The scene imitates what the pipeline indexes under a car (seeded, so every run is the same):
//! ground within 8 m, an underbody plane 0.35 m up, four tyre cylinders, 3 mm noise; queries are
//! points of the same surfaces moved by up to 3 cm (a registration's moved features). Cases:
//! - `scan k=5 r=0.2 voxel=0.2`: the scan-to-scan target (`max_correspondence_m` voxels);
//! - `scan ... voxel=0.1` and `voxel=0.05`: the same with voxels smaller than the radius, to show
//!   the trade-off (more voxels to visit; `old27` is faster there only because it scans 27 voxels
//!   whatever the radius and so misses neighbours: its mismatches);
//! - `map k=5 r=0.2 voxel=0.5`: the scan-to-map feature map (`feature_voxel_m` voxels);
//! - `filter within r=0.05 voxel=0.05`: the bilateral filter's neighbourhoods (all points within
//!   the radius; `old27` is the filter's former loop).
//!
//! Output lines: `case impl ns_per_query=N ratio_vs_old27=R mismatches=M`.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::hint::black_box;
use std::time::Instant;

use pipeline::geom::{V3, VoxelIndex, voxel_of};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The former hasher: one multiply round per byte of the key.
#[derive(Default, Clone, Copy)]
struct OldFx(u64);

impl Hasher for OldFx {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// The former index: indices per voxel, the 27 voxels around the query, ties by visiting order.
struct Old27 {
    voxel_m: f64,
    cells: HashMap<[i32; 3], Vec<u32>, BuildHasherDefault<OldFx>>,
    points: Vec<V3>,
}

impl Old27 {
    fn new(points: Vec<V3>, voxel_m: f64) -> Self {
        let mut cells: HashMap<[i32; 3], Vec<u32>, BuildHasherDefault<OldFx>> = HashMap::default();
        for (i, &p) in points.iter().enumerate() {
            cells
                .entry(voxel_of(p, voxel_m))
                .or_default()
                .push(i as u32);
        }
        Self {
            voxel_m,
            cells,
            points,
        }
    }

    fn cells_around(&self, q: V3) -> impl Iterator<Item = &Vec<u32>> {
        let c = voxel_of(q, self.voxel_m);
        (-1..=1).flat_map(move |dx| {
            (-1..=1).flat_map(move |dy| {
                (-1..=1).filter_map(move |dz| self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]))
            })
        })
    }

    fn nearest<const K: usize>(&self, q: V3, radius_m: f64, out: &mut [(f64, u32); K]) -> usize {
        let r2 = radius_m * radius_m;
        let mut n = 0;
        for cell in self.cells_around(q) {
            for &i in cell {
                let d2 = (self.points[i as usize] - q).norm_squared();
                if d2 > r2 || (n == K && d2 >= out[K - 1].0) {
                    continue;
                }
                let mut j = if n < K {
                    n += 1;
                    n - 1
                } else {
                    K - 1
                };
                while j > 0 && out[j - 1].0 > d2 {
                    out[j] = out[j - 1];
                    j -= 1;
                }
                out[j] = (d2, i);
            }
        }
        n
    }

    fn within(&self, q: V3, radius_m: f64, out: &mut Vec<u32>) {
        out.clear();
        for cell in self.cells_around(q) {
            out.extend(
                cell.iter().copied().filter(|&i| {
                    (self.points[i as usize] - q).norm_squared() <= radius_m * radius_m
                }),
            );
        }
    }
}

/// A point on the scene's surfaces (ground, underbody, tyres), with 3 mm noise.
fn surface_point(rng: &mut ChaCha8Rng) -> V3 {
    let noise = |rng: &mut ChaCha8Rng| rng.random_range(-0.003..0.003);
    let p = match rng.random_range(0..10) {
        0..=3 => {
            let r: f64 = rng.random_range(0.3_f64..8.0);
            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            [r * a.cos(), r * a.sin(), 0.0]
        }
        4..=7 => [
            rng.random_range(-2.5..2.5),
            rng.random_range(-0.8..0.8),
            0.35,
        ],
        _ => {
            let (cx, cy) =
                [(1.4, 0.8), (1.4, -0.8), (-1.4, 0.8), (-1.4, -0.8)][rng.random_range(0..4)];
            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            [
                cx + 0.3 * a.cos(),
                cy + rng.random_range(-0.1..0.1),
                0.3 + 0.3 * a.sin(),
            ]
        }
    };
    V3::new(p[0] + noise(rng), p[1] + noise(rng), p[2] + noise(rng))
}

/// The brute-force answer: the K nearest within the radius, by distance then index.
fn brute_nearest<const K: usize>(points: &[V3], q: V3, radius_m: f64) -> Vec<(f64, u32)> {
    let mut all: Vec<(f64, u32)> = points
        .iter()
        .enumerate()
        .map(|(i, &p)| ((p - q).norm_squared(), i as u32))
        .filter(|&(d2, _)| d2 <= radius_m * radius_m)
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    all.truncate(K);
    all
}

/// Nanoseconds per call of `f` over `queries`, best of three passes.
fn time_per_query(queries: &[V3], mut f: impl FnMut(V3) -> usize) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        let mut sink = 0;
        for &q in queries {
            sink += f(black_box(q));
        }
        black_box(sink);
        best = best.min(start.elapsed().as_secs_f64() * 1e9 / queries.len() as f64);
    }
    best
}

fn nearest_case(name: &str, points: &[V3], queries: &[V3], voxel_m: f64, radius_m: f64) {
    let index = VoxelIndex::new(points.to_vec(), voxel_m);
    let old = Old27::new(points.to_vec(), voxel_m);
    let checked = &queries[..queries.len().min(2000)];
    let mut mismatches = 0;
    let mut old_mismatches = 0;
    for &q in checked {
        let want = brute_nearest::<5>(points, q, radius_m);
        let mut out = [(0.0, 0); 5];
        let n = index.nearest(q, radius_m, &mut out);
        mismatches += usize::from(out[..n] != want[..]);
        let n = old.nearest(q, radius_m, &mut out);
        // The old index broke distance ties by visiting order: compare distances only.
        old_mismatches += usize::from(out[..n].iter().map(|p| p.0).ne(want.iter().map(|p| p.0)));
    }
    let mut out = [(0.0, 0); 5];
    let t_new = time_per_query(queries, |q| index.nearest(q, radius_m, &mut out));
    let t_old = time_per_query(queries, |q| old.nearest(q, radius_m, &mut out));
    let t_brute = time_per_query(checked, |q| brute_nearest::<5>(points, q, radius_m).len());
    println!(
        "{name} brute ns_per_query={t_brute:.0} ratio_vs_old27={:.2} mismatches=0",
        t_brute / t_old
    );
    println!(
        "{name} old27 ns_per_query={t_old:.0} ratio_vs_old27=1.00 mismatches={old_mismatches}"
    );
    println!(
        "{name} voxel_index ns_per_query={t_new:.0} ratio_vs_old27={:.2} mismatches={mismatches}",
        t_new / t_old
    );
}

fn within_case(name: &str, points: &[V3], voxel_m: f64, radius_m: f64) {
    let index = VoxelIndex::new(points.to_vec(), voxel_m);
    let old = Old27::new(points.to_vec(), voxel_m);
    let mut mismatches = 0;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for &q in points.iter().step_by(10) {
        old.within(q, radius_m, &mut a);
        b.clear();
        index.for_each_within(q, radius_m, |i, _| b.push(i));
        // Same points in the same order (the filter's sums depend on the order).
        mismatches += usize::from(a != b);
    }
    let t_new = time_per_query(points, |q| {
        let mut n = 0;
        index.for_each_within(q, radius_m, |_, _| n += 1);
        n
    });
    let t_old = time_per_query(points, |q| {
        old.within(q, radius_m, &mut a);
        a.len()
    });
    println!("{name} old27 ns_per_query={t_old:.0} ratio_vs_old27=1.00 mismatches=0");
    println!(
        "{name} voxel_index ns_per_query={t_new:.0} ratio_vs_old27={:.2} mismatches={mismatches}",
        t_new / t_old
    );
}

fn main() {
    /// Voxel-index query speed against two peers.
    #[derive(clap::Parser)]
    struct Args {
        /// Queries per measurement.
        #[arg(default_value_t = 50_000)]
        queries: usize,
    }
    let n_queries = <Args as clap::Parser>::parse().queries;
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let target: Vec<V3> = (0..8000).map(|_| surface_point(&mut rng)).collect();
    let queries: Vec<V3> = (0..n_queries)
        .map(|_| {
            let p = surface_point(&mut rng);
            let mut jitter = || rng.random_range(-0.03..0.03);
            V3::new(p[0] + jitter(), p[1] + jitter(), p[2] + jitter())
        })
        .collect();
    println!("points={} queries={}", target.len(), queries.len());
    nearest_case("scan_k5_r0.2_voxel0.2", &target, &queries, 0.2, 0.2);
    nearest_case("scan_k5_r0.2_voxel0.1", &target, &queries, 0.1, 0.2);
    nearest_case("scan_k5_r0.2_voxel0.05", &target, &queries, 0.05, 0.2);
    nearest_case("map_k5_r0.2_voxel0.5", &target, &queries, 0.5, 0.2);
    // The fused cloud is dense: 2 cm centroids.
    let dense: Vec<V3> = (0..60_000).map(|_| surface_point(&mut rng)).collect();
    within_case("filter_within_r0.05_voxel0.05", &dense, 0.05, 0.05);
}
