//! Step 4, features (paper section 3.3, eqs. 2-5).
//!
//! Each ring (laser line) is walked in azimuth order with a sliding window W of N neighbours on
//! each side of a centre point:
//!
//! 1. **Window width** (eq. 2): the azimuth between the window's first and last points must stay
//!    below `max_window_angle_rad` (pi / 16); wider windows straddle a gap in the scan and are
//!    skipped, so no feature is taken across a structural break.
//! 2. **Mean distance** (eqs. 3-4): `l_a = 1/(2N) sum_j |p_0 - p_j|`. Divided by the centre's range
//!    (the spacing of a ring grows linearly with range), it is the outlier statistic.
//! 3. **Statistical outlier removal**: points whose normalised `l_a` exceeds the frame's mean by
//!    more than `outlier_std_ratio` standard deviations are outliers (sparse points off the main
//!    structure, mixed pixels at edges). They become neither features nor cloud points.
//! 4. **Smoothness** (eq. 5): `c = |sum_j (p_j - p_0)| / (|W| |p_0|)`, computed in the same pass.
//!    `c > corner_threshold` marks a corner candidate, `c < plane_threshold` a plane candidate.
//! 5. **Selection**: each ring is split into `sectors`; per sector the sharpest corners and the
//!    flattest plane points are kept up to a cap, and a chosen point suppresses its window
//!    neighbours, so features spread over the whole scene instead of clustering on one edge.
//!
//! Ground points (step 2) take part in windows but are never selected as features.

use super::config::FeatureConfig;
use super::geom::V3;

/// One point as feature extraction sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RingPoint {
    /// Position, robot frame after deskewing, metres.
    pub p: V3,
    /// Range from the lidar, metres.
    pub range_m: f64,
    /// Azimuth of the firing, radians.
    pub azimuth_rad: f64,
    /// Ring 0..16.
    pub ring: u8,
    /// Ground point: may be a neighbour, never a feature.
    pub is_ground: bool,
}

/// The features of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Features {
    /// Corner points (sharp: edges, tyre silhouettes), robot frame.
    pub corners: Vec<V3>,
    /// Plane points (flat: underbody panels, ground when not removed), robot frame.
    pub planes: Vec<V3>,
    /// Every non-ground, non-outlier point with `c > corner_threshold` (uncapped): the
    /// registration target for the next frame and the map ("less sharp" in LOAM), with its ring.
    pub corner_candidates: Vec<(V3, u8)>,
    /// Every non-ground, non-outlier point with `c < plane_threshold` ("less flat"), with its ring.
    pub plane_candidates: Vec<(V3, u8)>,
    /// Ground points with `c < plane_threshold`, with their ring: plane features for the z, roll
    /// and pitch step only (as in LeGO-LOAM), never for x, y and yaw.
    pub ground_candidates: Vec<(V3, u8)>,
    /// `true` for each input point rejected as an outlier.
    pub is_outlier: Vec<bool>,
    /// Windows that passed the width test.
    pub windows: usize,
}

#[derive(Clone, Copy)]
struct Scored {
    index: usize,
    smoothness: f64,
    spread: f64,
}

/// Extract corner and plane features from one frame's points (any order; grouped by ring here,
/// keeping their order within a ring, which must be azimuth order as the lidar fires).
pub fn extract(points: &[RingPoint], config: &FeatureConfig) -> Features {
    let n_half = config.window_half_width.max(1);
    let mut rings: Vec<Vec<usize>> = vec![Vec::new(); 16];
    for (i, p) in points.iter().enumerate() {
        if (config.min_range_m..=config.max_range_m).contains(&p.range_m)
            && let Some(ring) = rings.get_mut(usize::from(p.ring))
        {
            ring.push(i);
        }
    }
    let mut scored: Vec<Vec<Scored>> = Vec::with_capacity(rings.len());
    let mut windows = 0;
    let mut scratch = RingScratch::default();
    for ring in &rings {
        let out = score_ring(
            points,
            ring,
            n_half,
            config.max_window_angle_rad,
            &mut scratch,
        );
        windows += out.len();
        scored.push(out);
    }
    let mut is_outlier = vec![false; points.len()];
    if config.outlier_removal {
        mark_outliers(&scored, config.outlier_std_ratio, &mut is_outlier);
    }
    let mut features = Features {
        windows,
        ..Features::default()
    };
    for ring in &scored {
        select(points, ring, &is_outlier, config, &mut features);
    }
    features.is_outlier = is_outlier;
    features
}

/// Buffers reused across the rings of a frame.
#[derive(Default)]
struct RingScratch {
    /// The ring's positions in one contiguous run.
    pos: Vec<V3>,
    /// `ahead[i * n_half + d - 1] = |pos[i + d] - pos[i]|`.
    ahead: Vec<f64>,
}

/// Eqs. 2-5 for every window of one ring (`ring`: indices into `points`, azimuth order) that
/// passes the width test.
///
/// Each distance between two points at most `n_half` apart is computed once and serves the
/// windows of both (the direct double loop computed every one twice); the sums add the same
/// values in the same order as the direct loop, so the scores are identical to it
/// (`shared_distances_score_like_the_direct_loop`).
fn score_ring(
    points: &[RingPoint],
    ring: &[usize],
    n_half: usize,
    max_window_angle_rad: f64,
    scratch: &mut RingScratch,
) -> Vec<Scored> {
    let RingScratch { pos, ahead } = scratch;
    pos.clear();
    pos.extend(ring.iter().map(|&i| points[i].p));
    ahead.clear();
    ahead.resize(pos.len() * n_half, 0.0);
    for (i, (row, &p)) in ahead.chunks_exact_mut(n_half).zip(pos.iter()).enumerate() {
        for (slot, &q) in row.iter_mut().zip(&pos[i + 1..]) {
            *slot = (q - p).norm();
        }
    }
    let mut out = Vec::new();
    for k in n_half..ring.len().saturating_sub(n_half) {
        let first = &points[ring[k - n_half]];
        let last = &points[ring[k + n_half]];
        if azimuth_span(first.azimuth_rad, last.azimuth_rad) >= max_window_angle_rad {
            continue;
        }
        let centre = pos[k];
        let mut sum = V3::zeros();
        for &q in &pos[k - n_half..=k + n_half] {
            let d = q - centre;
            sum = V3::new(sum[0] + d[0], sum[1] + d[1], sum[2] + d[2]);
        }
        // |p_j - p_k| for j = k - n_half .. k - 1 (stored ahead of p_j, `n_half - 1` apart),
        // then for j = k + 1 ..= k + n_half (ahead of p_k): the direct loop's order, without
        // the centre's own zero (adding +0.0 changes nothing). |a - b| = |b - a| exactly.
        let behind = (k - n_half) * n_half + n_half - 1;
        let mut total_distance = 0.0;
        for o in 0..n_half {
            total_distance += ahead[behind + o * (n_half - 1)];
        }
        for &d in &ahead[k * n_half..(k + 1) * n_half] {
            total_distance += d;
        }
        let w = (2 * n_half) as f64;
        let range_m = points[ring[k]].range_m;
        out.push(Scored {
            index: ring[k],
            smoothness: sum.norm() / (w * range_m),
            spread: total_distance / w / range_m,
        });
    }
    out
}

/// Angle between two azimuths, radians in [0, pi].
fn azimuth_span(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

/// Statistical outlier removal over the normalised mean distances of all windows of the frame.
fn mark_outliers(scored: &[Vec<Scored>], std_ratio: f64, is_outlier: &mut [bool]) {
    let all = scored.iter().flatten();
    let n = all.clone().count() as f64;
    if n < 2.0 {
        return;
    }
    let mean = all.clone().map(|s| s.spread).sum::<f64>() / n;
    let var = all.clone().map(|s| (s.spread - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let limit = mean + std_ratio * var.sqrt();
    for s in all {
        if s.spread > limit {
            is_outlier[s.index] = true;
        }
    }
}

fn select(
    points: &[RingPoint],
    ring: &[Scored],
    is_outlier: &[bool],
    config: &FeatureConfig,
    out: &mut Features,
) {
    let sectors = config.sectors.max(1);
    let suppress = config.window_half_width.max(1);
    let mut taken = vec![false; ring.len()];
    for s in 0..sectors {
        let lo = ring.len() * s / sectors;
        let hi = ring.len() * (s + 1) / sectors;
        for k in lo..hi {
            let p = &points[ring[k].index];
            if p.is_ground
                && !is_outlier[ring[k].index]
                && ring[k].smoothness < config.plane_threshold
            {
                out.ground_candidates.push((p.p, p.ring));
            }
        }
        let mut order: Vec<usize> = (lo..hi)
            .filter(|&k| !is_outlier[ring[k].index] && !points[ring[k].index].is_ground)
            .collect();
        order.sort_by(|&a, &b| ring[b].smoothness.total_cmp(&ring[a].smoothness));
        for &k in &order {
            let p = &points[ring[k].index];
            if ring[k].smoothness > config.corner_threshold {
                out.corner_candidates.push((p.p, p.ring));
            } else if ring[k].smoothness < config.plane_threshold {
                out.plane_candidates.push((p.p, p.ring));
            }
        }
        let mut picked = 0;
        for &k in &order {
            if picked == config.corners_per_sector || ring[k].smoothness <= config.corner_threshold
            {
                break;
            }
            if !taken[k] {
                out.corners.push(points[ring[k].index].p);
                picked += 1;
                mark(&mut taken, k, suppress);
            }
        }
        picked = 0;
        for &k in order.iter().rev() {
            if picked == config.planes_per_sector || ring[k].smoothness >= config.plane_threshold {
                break;
            }
            if !taken[k] {
                out.planes.push(points[ring[k].index].p);
                picked += 1;
                mark(&mut taken, k, suppress);
            }
        }
    }
}

fn mark(taken: &mut [bool], k: usize, radius: usize) {
    let lo = k.saturating_sub(radius);
    let hi = (k + radius + 1).min(taken.len());
    for t in &mut taken[lo..hi] {
        *t = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One ring sweeping a square room (walls at +-2 m) from its centre: corners at the four room
    /// corners, planes along the walls.
    fn square_room(spike_at: Option<usize>) -> Vec<RingPoint> {
        let n = 1800;
        (0..n)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / n as f64;
                let (s, c) = a.sin_cos();
                let mut r = 2.0 / c.abs().max(s.abs());
                if spike_at == Some(i) {
                    r *= 0.6;
                }
                RingPoint {
                    p: V3::new(r * c, r * s, 0.0),
                    range_m: r,
                    azimuth_rad: a,
                    ring: 3,
                    is_ground: false,
                }
            })
            .collect()
    }

    #[test]
    fn corners_at_room_corners_planes_on_walls() {
        let f = extract(&square_room(None), &FeatureConfig::default());
        assert!(!f.corners.is_empty() && !f.planes.is_empty());
        for c in &f.corners {
            let (x, y) = (c[0].abs(), c[1].abs());
            assert!(
                (x - 2.0).abs() < 0.1 && (y - 2.0).abs() < 0.1,
                "corner {c:?}"
            );
        }
        for p in &f.planes {
            let on_wall = (p[0].abs() - 2.0).abs() < 1e-9 || (p[1].abs() - 2.0).abs() < 1e-9;
            let near_corner = (p[0].abs() - 2.0).abs() < 0.2 && (p[1].abs() - 2.0).abs() < 0.2;
            assert!(on_wall && !near_corner, "plane {p:?}");
        }
        // SOR flags the tail of the spread distribution: in a clean room, only points next to its
        // corners (where the window bends and the spacing grows).
        let points = square_room(None);
        for (p, _) in points.iter().zip(&f.is_outlier).filter(|(_, o)| **o) {
            let near_corner = (p.p[0].abs() - 2.0).abs() < 0.4 && (p.p[1].abs() - 2.0).abs() < 0.4;
            assert!(near_corner, "{p:?}");
        }
    }

    /// The direct double loop of eqs. 3-5, every distance computed for each window it is in.
    fn score_ring_direct(points: &[RingPoint], ring: &[usize], n_half: usize) -> Vec<Scored> {
        let mut out = Vec::new();
        for k in n_half..ring.len().saturating_sub(n_half) {
            let (first, last) = (&points[ring[k - n_half]], &points[ring[k + n_half]]);
            if azimuth_span(first.azimuth_rad, last.azimuth_rad) >= std::f64::consts::PI / 16.0 {
                continue;
            }
            let centre = points[ring[k]];
            let mut sum = V3::zeros();
            let mut total_distance = 0.0;
            for &j in &ring[k - n_half..=k + n_half] {
                let d = points[j].p - centre.p;
                sum = V3::new(sum[0] + d[0], sum[1] + d[1], sum[2] + d[2]);
                total_distance += d.norm();
            }
            let w = (2 * n_half) as f64;
            out.push(Scored {
                index: ring[k],
                smoothness: sum.norm() / (w * centre.range_m),
                spread: total_distance / w / centre.range_m,
            });
        }
        out
    }

    #[test]
    fn shared_distances_score_like_the_direct_loop() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // A noisy ring with gaps (some windows fail the width test), every other point taken.
        let mut points = Vec::new();
        let mut azimuth_rad: f64 = 0.0;
        for _ in 0..2000 {
            azimuth_rad += if rng.random_bool(0.02) { 0.4 } else { 0.003 };
            let range_m = rng.random_range(0.3..6.0);
            let p = V3::new(
                range_m * azimuth_rad.cos(),
                range_m * azimuth_rad.sin(),
                rng.random_range(-0.5..0.5),
            );
            points.push(RingPoint {
                p,
                range_m,
                azimuth_rad: azimuth_rad.rem_euclid(std::f64::consts::TAU),
                ring: 3,
                is_ground: false,
            });
        }
        let ring: Vec<usize> = (0..points.len()).step_by(2).collect();
        for n_half in [1, 3, 5, 8] {
            let direct = score_ring_direct(&points, &ring, n_half);
            let mut scratch = RingScratch::default();
            let shared = score_ring(
                &points,
                &ring,
                n_half,
                std::f64::consts::PI / 16.0,
                &mut scratch,
            );
            assert!(
                direct.len() > 500 && direct.len() < ring.len() - 2 * n_half,
                "{}",
                direct.len()
            );
            assert_eq!(direct.len(), shared.len());
            for (a, b) in direct.iter().zip(&shared) {
                assert_eq!(a.index, b.index);
                assert_eq!(
                    a.smoothness.to_bits(),
                    b.smoothness.to_bits(),
                    "n_half {n_half}"
                );
                assert_eq!(a.spread.to_bits(), b.spread.to_bits(), "n_half {n_half}");
            }
        }
    }

    #[test]
    fn an_isolated_spike_is_an_outlier_and_never_a_feature() {
        let spike = 300;
        let points = square_room(Some(spike));
        let f = extract(&points, &FeatureConfig::default());
        assert!(f.is_outlier[spike]);
        assert!(!f.corners.contains(&points[spike].p));
        let without = FeatureConfig {
            outlier_removal: false,
            ..FeatureConfig::default()
        };
        let f = extract(&points, &without);
        assert!(f.corners.contains(&points[spike].p), "the test can fail");
    }

    #[test]
    fn windows_across_a_gap_are_skipped_and_ground_is_never_a_feature() {
        let mut points = square_room(None);
        points.retain(|p| !(1.0..1.6).contains(&p.azimuth_rad));
        for p in &mut points {
            p.is_ground = p.p[0] > 0.0;
        }
        let f = extract(&points, &FeatureConfig::default());
        assert!(f.corners.iter().chain(&f.planes).all(|p| p[0] <= 0.0));
        let full = extract(&square_room(None), &FeatureConfig::default());
        assert!(f.windows < full.windows);
    }
}
