//! Tyres: find them from their contact with the ground, fit each as a circle in the side view.
//!
//! 1. Seeds: points a few centimetres above the ground (between `seed_low_m` and `seed_high_m`) are
//!    almost only tyre: cluster them on a 5 cm grid; keep compact clusters (a vehicle body part that
//!    low is wide, a tyre's footprint is not). The eight largest are fitted, and the tyres are the
//!    four (or three) of them at a rectangle's corners ([`vehicle_set`]).
//! 2. Side-view circle per tyre: points in the tyre's lateral slab, projected onto the x-z plane,
//!    cut into 1 cm horizontal slices; each slice splits into runs at gaps wider than `tyre_gap_m`
//!    (or 4 x the slice's median step in sparse clouds), and the ends of every run are silhouette
//!    candidates ([`slice_edges`]): with the scanner's range accuracy stated, where the run's
//!    density falls to half ([`band_edge`]), else its outermost point. A seeded RANSAC keeps
//!    the circle through three candidates that stands on the ground (lowest point within 2 cm
//!    above to 15 % of the radius below it), lies over the footprint and is no wider than it at
//!    the footprint's top, and explains the most slices on both sides at once
//!    ([`ground_constrained_ransac`]: tall walls beside the tyre, which the depth camera sees,
//!    and the wheel arch above a tyre seen only below the sills must not win); then geometric
//!    least squares on its inliers, trimmed at 3 sigma. Candidates lower than 30 % of the centre
//!    height are not used: a loaded tyre is flattened and bulges near the road. Rim edges, body faces, sills and mud
//!    flaps beside the tyre are candidates too, but no ground-standing circle explains them.
//!    Why the half density: the tread's front and back are seen nearly head-on, so the range
//!    noise runs along x there and a slice's outermost point is the largest of many noisy
//!    samples, 2-3 cm outside the outline with the simulated VLP-16 (decision records 014, 041).
//! 3. The static loaded radius is the centre's height above the ground; the fitted radius is the
//!    free tread radius. The lateral faces are the 1 % / 99 % quantiles of y of the points in the disc.

use std::collections::HashMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::geom::{Circle, V3, circle_covariance, fit_circle, median};

/// Grid cell for seed clustering (metres).
const SEED_CELL_M: f64 = 0.05;

/// A cluster of low points that may be a tyre footprint.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Seed {
    pub x: f64,
    pub y: f64,
    pub x_min: f64,
    pub x_max: f64,
    pub y_min: f64,
    pub y_max: f64,
    pub count: usize,
    /// Half chord at the top of the seed slice, for the first radius guess.
    pub half_chord_m: f64,
    /// The x extent of the points within [`SEED_TOP_M`] of the seed slice's top (`None`: fewer
    /// than two there): where the tyre's side view crosses that height
    /// ([`ground_constrained_ransac`]).
    pub top_x: Option<(f64, f64)>,
}

/// The seed slice's top layer, metres below `h_hi` ([`Seed::top_x`]).
const SEED_TOP_M: f64 = 0.015;

/// Find footprint clusters among points (x, y, h) with `h_lo < h < h_hi`; largest first.
pub(crate) fn find_seeds(points: &[V3], h_lo: f64, h_hi: f64) -> (Vec<Seed>, usize) {
    let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        if p[2] > h_lo && p[2] < h_hi {
            let key = (
                (p[0] / SEED_CELL_M).floor() as i64,
                (p[1] / SEED_CELL_M).floor() as i64,
            );
            cells.entry(key).or_default().push(i);
        }
    }
    let mut keys: Vec<(i64, i64)> = cells.keys().copied().collect();
    keys.sort_unstable();
    let mut seeds = Vec::new();
    for cluster in connected_cells(&cells, keys) {
        let members: Vec<usize> = cluster.iter().flat_map(|k| cells[k].clone()).collect();
        match seed_from(points, &members, h_hi) {
            Some(seed) => seeds.push(seed),
            None => seeds.extend(trimmed_seeds(points, &cells, &cluster, h_hi)),
        }
    }
    let compact = seeds.len();
    seeds.sort_by(|a, b| b.count.cmp(&a.count).then(a.x.total_cmp(&b.x)));
    (seeds, compact)
}

/// The 8-connected groups of `keys` (cells of `cells`), each in discovery order.
fn connected_cells(
    cells: &HashMap<(i64, i64), Vec<usize>>,
    keys: Vec<(i64, i64)>,
) -> Vec<Vec<(i64, i64)>> {
    let mut seen: HashMap<(i64, i64), bool> = HashMap::new();
    let mut groups = Vec::new();
    for start in keys {
        if seen.contains_key(&start) {
            continue;
        }
        seen.insert(start, true);
        let mut stack = vec![start];
        let mut group = Vec::new();
        while let Some((cx, cy)) = stack.pop() {
            group.push((cx, cy));
            for dx in -1..=1 {
                for dy in -1..=1 {
                    let k = (cx + dx, cy + dy);
                    if cells.contains_key(&k) && !seen.contains_key(&k) {
                        seen.insert(k, true);
                        stack.push(k);
                    }
                }
            }
        }
        groups.push(group);
    }
    groups
}

/// A cluster too wide to be a footprint may be one joined to stray points: a chain of cells that
/// hold one to six points each (seen on a pipeline cloud, suv-offset seed 6: an arc of floor hits
/// across 0.65 m tied the rear right footprint, up to 680 points per cell, to the centreline, so
/// that tyre was lost and the frame's heading went 11 degrees wrong). Cells with less than a tenth
/// of the 90th percentile of the cluster's cell counts are dropped and the rest regrouped; each
/// group that is compact becomes a seed. Clusters that are compact as they are never get here.
fn trimmed_seeds(
    points: &[V3],
    cells: &HashMap<(i64, i64), Vec<usize>>,
    cluster: &[(i64, i64)],
    h_hi: f64,
) -> Vec<Seed> {
    // The 90th percentile: a long chain of sparse cells can be half the cluster's cells.
    let mut counts: Vec<usize> = cluster.iter().map(|k| cells[k].len()).collect();
    counts.sort_unstable();
    let Some(&dense_count) = counts.get(counts.len() * 9 / 10) else {
        return Vec::new();
    };
    let mut dense: Vec<(i64, i64)> = cluster
        .iter()
        .copied()
        .filter(|k| cells[k].len() * 10 >= dense_count)
        .collect();
    if dense.len() == cluster.len() {
        return Vec::new();
    }
    dense.sort_unstable();
    let kept: HashMap<(i64, i64), Vec<usize>> =
        dense.iter().map(|k| (*k, cells[k].clone())).collect();
    connected_cells(&kept, dense)
        .iter()
        .filter_map(|group| {
            let members: Vec<usize> = group.iter().flat_map(|k| kept[k].clone()).collect();
            seed_from(points, &members, h_hi)
        })
        .collect()
}

fn seed_from(points: &[V3], members: &[usize], h_hi: f64) -> Option<Seed> {
    if members.len() < 8 {
        return None;
    }
    let (mut x_min, mut x_max, mut y_min, mut y_max) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let (mut sx, mut sy) = (0.0, 0.0);
    let (mut top_min, mut top_max) = (f64::MAX, f64::MIN);
    for &i in members {
        let p = points[i];
        x_min = x_min.min(p[0]);
        x_max = x_max.max(p[0]);
        y_min = y_min.min(p[1]);
        y_max = y_max.max(p[1]);
        sx += p[0];
        sy += p[1];
        if p[2] > h_hi - SEED_TOP_M {
            top_min = top_min.min(p[0]);
            top_max = top_max.max(p[0]);
        }
    }
    let n = members.len() as f64;
    let compact = (x_max - x_min) < 1.3 && (y_max - y_min) < 0.7 && (x_max - x_min) > 0.02;
    compact.then(|| Seed {
        x: sx / n,
        y: sy / n,
        x_min,
        x_max,
        y_min,
        y_max,
        count: members.len(),
        half_chord_m: if top_max > top_min {
            0.5 * (top_max - top_min)
        } else {
            0.5 * (x_max - x_min)
        },
        top_x: (top_max > top_min).then_some((top_min, top_max)),
    })
}

/// A tyre fitted in some ground-aligned frame (x, y, h).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TyreFit {
    pub centre_x: f64,
    pub centre_y: f64,
    /// Centre height above the ground = static loaded radius.
    pub loaded_radius_m: f64,
    /// Fitted tread (free) radius.
    pub free_radius_m: f64,
    pub inner_y: f64,
    pub outer_y: f64,
    pub residual_rms_m: f64,
    pub silhouette_points: usize,
    /// Covariance of the fit's `(centre x, centre height, free radius)`, m^2
    /// ([`super::geom::circle_covariance`] with the larger of the fit's RMS residual and the
    /// noise sigma).
    pub covariance: [[f64; 3]; 3],
}

/// Parameters for [`fit_tyre`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct TyreParams {
    pub h_lo: f64,
    pub h_hi: f64,
    pub gap_m: f64,
    pub noise_m: f64,
    /// Which side the vehicle centreline lies on: +1 if the centreline has larger y than this tyre.
    pub inward_sign: f64,
    /// Whether the scanner's range accuracy is stated: the run ends are then where the runs'
    /// density falls to half ([`band_edge`]), not their outermost returns.
    pub band_edges: bool,
    /// RANSAC seed.
    pub seed: u64,
}

/// Fit one tyre around its seed; `None` if no consistent circle is found.
pub(crate) fn fit_tyre(points: &[V3], seed: &Seed, params: TyreParams) -> Option<TyreFit> {
    // The slab reaches 1 cm inboard of the footprint (body parts hug the inner face) and 3 cm outboard.
    let (slab_lo, slab_hi) = if params.inward_sign > 0.0 {
        (seed.y_min - 0.03, seed.y_max + 0.01)
    } else {
        (seed.y_min - 0.01, seed.y_max + 0.03)
    };
    let cand: Vec<[f64; 2]> = points
        .iter()
        .filter(|p| {
            p[1] > slab_lo
                && p[1] < slab_hi
                && (p[0] - seed.x).abs() < 1.2
                && p[2] > params.h_lo
                && p[2] < 2.0
        })
        .map(|p| [p[0], p[2]])
        .collect();
    let h = params.h_hi;
    let r0 = ((seed.half_chord_m.powi(2) + h * h) / (2.0 * h)).clamp(0.15, 1.0);
    let centre_x = 0.5 * (seed.x_min + seed.x_max);
    let edges = slice_edges(&cand, 2.0 * r0 + 0.3, params.gap_m, params.band_edges);
    let footprint = Footprint {
        centre_x,
        top: seed
            .top_x
            .map(|(lo, hi)| (params.h_hi - 0.5 * SEED_TOP_M, lo, hi)),
    };
    let mut circle = ground_constrained_ransac(&edges, &footprint, params)?;
    // Least squares on the RANSAC inliers above the bulge zone of the fitted centre height (a
    // loaded tyre is flattened and bulges near the road), trimmed; repeated as the circle moves.
    let mut used = Vec::new();
    let mut rms = f64::NAN;
    for _ in 0..3 {
        let low = 0.3 * circle.v.max(0.1);
        let tol = inlier_tolerance(params.noise_m);
        let inliers: Vec<[f64; 2]> = edges
            .iter()
            .copied()
            .filter(|p| p[1] > low && circle_residual(*p, circle).abs() < tol)
            .collect();
        let (c, n, e) = trimmed_circle(&inliers, params.noise_m)?;
        let moved = (c.u - circle.u).abs() + (c.v - circle.v).abs() + (c.r - circle.r).abs();
        circle = c;
        used = n;
        rms = e;
        if moved < 1e-9 {
            break;
        }
    }
    if !(0.1..=1.2).contains(&circle.r) || circle.v <= 0.05 || used.len() < 10 {
        return None;
    }
    let covariance = circle_covariance(&used, circle, rms.max(params.noise_m))?;
    let (inner_y, outer_y) = lateral_faces(points, seed, circle, params);
    Some(TyreFit {
        centre_x: circle.u,
        centre_y: 0.5 * (inner_y + outer_y),
        loaded_radius_m: circle.v,
        free_radius_m: circle.r,
        inner_y,
        outer_y,
        residual_rms_m: rms,
        silhouette_points: used.len(),
        covariance,
    })
}

/// How many footprint clusters, largest first, are fitted as tyre candidates ([`vehicle_set`]
/// picks the tyres among them): a hall's floor, another vehicle's tyres and low underside parts
/// on the centreline leave clusters of their own, sometimes larger than a tyre's.
pub(crate) const CANDIDATE_SEEDS: usize = 8;

/// Narrowest and widest distance between the left and right footprints of one axle (metres): from
/// a city car's 1.2 m track less a tyre's width to a wide truck's 2.1 m plus its width.
const AXLE_WIDTH_M: (f64, f64) = (0.9, 2.5);

/// How far (metres) the two axles of a chosen set may depart from a rectangle: the difference of
/// their left-to-right vectors, and the wheelbase's component along the axles. A vehicle's tyres
/// stand at the corners of a rectangle up to the front and rear tracks' difference (a few
/// centimetres) and each footprint centre's error (up to half a tyre's width when half the
/// footprint is hidden).
const RECTANGLE_TOL_M: f64 = 0.25;

/// Front and rear axles at least this far apart along x (metres).
pub(crate) const MIN_WHEELBASE_M: f64 = 0.8;

/// Which of the fitted candidates (`(x, y, seed points)` each) are the vehicle's tyres, by the
/// vehicle's model: four, or three, at the corners of a rectangle whose sides run along and across
/// the frame's x, with the most footprint points among such sets; `None` without one (the caller
/// then takes the largest, as the seeds came). The most points, not the most corners: the robot
/// drives under the vehicle it measures, so its footprints are the nearest and the densest; a
/// parked neighbour's four (simulated hall A, 1.3 m beside the city car) are a rectangle too.
///
/// Why a model and not the four largest clusters: in a hall the largest low clusters include the
/// floor's and other objects' (simulated city car, tuning cloud hall-a/1, `passangle angles` with
/// defaults: a cluster 1.37 m to the side displaced a front tyre), and a low underside part on the
/// centreline is compact and can be larger than a footprint a low body half hides.
pub(crate) fn vehicle_set(
    candidates: &[(f64, f64, usize)],
    path: &[[f64; 2]],
) -> Option<Vec<usize>> {
    let n = candidates.len();
    let pos = |i: usize| [candidates[i].0, candidates[i].1];
    // An axle's (right, left) corners, if two candidates can be one.
    let axle = |a: usize, b: usize| {
        let (pa, pb) = (pos(a), pos(b));
        let (dx, dy) = (pb[0] - pa[0], pb[1] - pa[1]);
        // Across the frame's x, at most 20 degrees off: the frame follows the robot's path (then
        // the previous round's axles), and the robot drives under the vehicle along it.
        let across = (AXLE_WIDTH_M.0..=AXLE_WIDTH_M.1).contains(&dy.abs())
            && dx.abs() <= (20f64).to_radians().tan() * dy.abs();
        across.then_some(if dy > 0.0 { (pa, pb) } else { (pb, pa) })
    };
    let count = |set: &[usize]| set.iter().map(|&i| candidates[i].2).sum::<usize>();
    let mut best: Option<Vec<usize>> = None;
    let mut consider = |set: Vec<usize>| {
        if best.as_ref().is_none_or(|b| count(&set) > count(b)) {
            best = Some(set);
        }
    };
    for a in 0..n {
        for b in a + 1..n {
            let Some((right, left)) = axle(a, b).filter(|&p| straddled(path, p)) else {
                continue;
            };
            let across = [left[0] - right[0], left[1] - right[1]];
            for c in (0..n).filter(|&c| c != a && c != b) {
                // Three corners: `c` as the other axle's right or left, the fourth where the
                // rectangle puts it.
                let p = pos(c);
                let as_right = [p[0] + across[0], p[1] + across[1]];
                let as_left = [p[0] - across[0], p[1] - across[1]];
                let corners = |q| rectangle((right, left), q) && straddled(path, q);
                if corners((p, as_right)) || corners((as_left, p)) {
                    consider(vec![a, b, c]);
                }
                for d in (c + 1..n).filter(|&d| d != a && d != b) {
                    if axle(c, d).is_some_and(corners) {
                        consider(vec![a, b, c, d]);
                    }
                }
            }
        }
    }
    best.map(|mut set| {
        set.sort_unstable();
        set
    })
}

/// How far along x (metres) the scan path must come to an axle for [`straddled`] to check it.
const PATH_NEAR_AXLE_M: f64 = 0.5;

/// Whether the scan path (the sensor's positions, `(x, y)` in the frame) passes between an
/// axle's `(right, left)` corners where it comes nearest to the axle along x: the robot drives
/// under the vehicle it measures, so that vehicle's every axle straddles its path. True without a
/// path, or where the path does not come within [`PATH_NEAR_AXLE_M`] of the axle.
///
/// Why: beside the measured vehicle a parked neighbour's tyres (simulated halls, 3.2 m to the
/// side) pair with its own into axles 0.9-2.5 m wide, and such mixed sets are rectangles too.
fn straddled(path: &[[f64; 2]], (right, left): ([f64; 2], [f64; 2])) -> bool {
    let x = 0.5 * (right[0] + left[0]);
    path.iter()
        .min_by(|a, b| (a[0] - x).abs().total_cmp(&(b[0] - x).abs()))
        .filter(|p| (p[0] - x).abs() <= PATH_NEAR_AXLE_M)
        .is_none_or(|p| p[1] > right[1].min(left[1]) && p[1] < right[1].max(left[1]))
}

/// Whether two axles' `(right, left)` corners stand at a rectangle's corners within
/// [`RECTANGLE_TOL_M`], at least [`MIN_WHEELBASE_M`] apart along x.
fn rectangle(p: ([f64; 2], [f64; 2]), q: ([f64; 2], [f64; 2])) -> bool {
    let vector = |(r, l): ([f64; 2], [f64; 2])| [l[0] - r[0], l[1] - r[1]];
    let mid = |(r, l): ([f64; 2], [f64; 2])| [0.5 * (l[0] + r[0]), 0.5 * (l[1] + r[1])];
    let (u, v) = (vector(p), vector(q));
    let (m, k) = (mid(p), mid(q));
    let base = [m[0] - k[0], m[1] - k[1]];
    let width = u[0].hypot(u[1]);
    base[0].abs() >= MIN_WHEELBASE_M
        && (u[0] - v[0]).hypot(u[1] - v[1]) <= RECTANGLE_TOL_M
        && (base[0] * u[0] + base[1] * u[1]).abs() / width <= RECTANGLE_TOL_M
}

fn circle_residual(p: [f64; 2], c: Circle) -> f64 {
    (p[0] - c.u).hypot(p[1] - c.v) - c.r
}

/// Height of the horizontal slices whose ends are the tyre's side-view silhouette (metres).
const SLICE_M: f64 = 0.01;

/// The tyre's side-view silhouette candidates: the ends of the connected runs of each horizontal
/// slice.
///
/// Per slice of [`SLICE_M`] below `z_max`, the points are sorted along x and split into runs at
/// every gap wider than `gap_m` (or 4 x the slice's median step, in sparse clouds). Both ends of
/// every run are candidates: the tyre's outline, but also the rim's edge, the body faces, sills or
/// mud flaps beside the tyre; [`ground_constrained_ransac`] keeps the circle that stands on the
/// ground and explains the most of them.
///
/// Why slices, not the outermost point per angular sector around a guessed centre: a low sensor
/// sees only the tyre's lower part (a VLP-16 0.12 m up sees about the lower two thirds), and the
/// upper boundary of what it sees lies well inside the circle. Every angular sector above the
/// centre then returns a point of that boundary, which pulls the fit down (on the sedan demo's
/// cloud the fitted centre heights were 2 cm low and one rear tyre failed outright). A slice's
/// run ends lie on the circle wherever the slice reaches the tyre's sides.
pub(crate) fn slice_edges(
    cand: &[[f64; 2]],
    z_max: f64,
    gap_m: f64,
    band_edges: bool,
) -> Vec<[f64; 2]> {
    let mut keyed: Vec<(i64, [f64; 2])> = cand
        .iter()
        .filter(|p| p[1] < z_max)
        .map(|p| (slice_of(p[1]), *p))
        .collect();
    keyed.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1[0].total_cmp(&b.1[0])));
    let mut out = Vec::new();
    for slice in keyed.chunk_by(|a, b| a.0 == b.0) {
        let xs: Vec<[f64; 2]> = slice.iter().map(|(_, p)| *p).collect();
        let mut steps: Vec<f64> = xs.windows(2).map(|w| w[1][0] - w[0][0]).collect();
        let gap = gap_m.max(4.0 * median(&mut steps).unwrap_or(0.0));
        for run in xs.chunk_by(|a, b| b[0] - a[0] <= gap) {
            if let [first, .., last] = run {
                if band_edges {
                    let xs = || run.iter().map(|p| p[0]);
                    out.push([band_edge(xs(), first[0], 1.0), first[1]]);
                    out.push([band_edge(xs().rev(), last[0], -1.0), last[1]]);
                } else {
                    out.push(*first);
                    out.push(*last);
                }
            }
        }
    }
    out
}

/// Bin width (metres) of [`band_edge`]'s density profile: the pipeline's output voxel.
const BAND_BIN_M: f64 = 0.005;
/// Bins of [`band_edge`]'s profile inward from a run's extreme: 4 cm, past the VLP-16's 3 cm
/// stated accuracy, so the profile reaches the tread band's inner side.
const BAND_BINS: usize = 8;
/// Fewest points [`band_edge`] needs within its bins; sparser runs keep their extreme.
const BAND_MIN_POINTS: usize = 20;

/// Where a run's end lies, from its points `xs` ordered from the extreme `extreme` inward
/// (`inward` = +1: toward larger x): the position at which the run's density, in
/// [`BAND_BIN_M`] bins, first reaches half its largest value within [`BAND_BINS`] bins of the
/// extreme (linearly interpolated between bin centres); never beyond the extreme.
///
/// Why: the tread's front and back are seen nearly head-on, so the range noise runs along x
/// there, and the outermost of the hundreds of returns a slice holds near the outline lies 2-3 cm
/// outside it (record 014). Fitted to the extremes, the tyres came out up to 8 cm large (tuning set,
/// true-pose clouds), which moved near witnesses' angles by up to a degree. The run's density is
/// that of a step (returns inside the outline, none outside) blurred by the noise, whose half
/// height is the step's edge whatever the noise. This is approximate: where the tread's own band
/// (its returns seen head-on, centred on the outline) outweighs the sidewall's even spread, the
/// half height of that band's peak lies about 1.2 noise sigma outside the outline; still nearer
/// than the extreme, at 2-3 sigma.
fn band_edge(xs: impl Iterator<Item = f64>, extreme: f64, inward: f64) -> f64 {
    let mut counts = [0usize; BAND_BINS];
    for x in xs {
        let k = ((x - extreme) * inward / BAND_BIN_M).floor();
        if k >= BAND_BINS as f64 {
            break;
        }
        counts[k.max(0.0) as usize] += 1;
    }
    let peak = counts.iter().copied().max().unwrap_or(0);
    if counts.iter().sum::<usize>() < BAND_MIN_POINTS {
        return extreme;
    }
    let k = counts.iter().position(|&c| 2 * c >= peak).unwrap_or(0);
    // Between the centres of bin k and of its outer neighbour (none beyond the extreme).
    let outer = if k == 0 { 0 } else { counts[k - 1] };
    let frac = (0.5 * peak as f64 - outer as f64) / ((counts[k] - outer) as f64).max(1.0);
    extreme + inward * BAND_BIN_M * (k as f64 - 0.5 + frac.clamp(0.0, 1.0)).max(0.0)
}

/// Distance within which a silhouette point supports a circle (metres).
fn inlier_tolerance(noise_m: f64) -> f64 {
    (3.0 * noise_m).max(0.008)
}

/// How far above the footprint's top two of the three points of every RANSAC sample lie at most
/// ([`ground_constrained_ransac`]), metres.
const LOW_FLANK_M: f64 = 0.15;

/// What the footprint says about the tyre's circle ([`ground_constrained_ransac`]).
struct Footprint {
    /// The footprint's centre along x.
    centre_x: f64,
    /// `(h, x_lo, x_hi)`: at height `h` the tyre spans at least `x_lo..x_hi` (the seed slice's
    /// top layer, [`Seed::top_x`]).
    top: Option<(f64, f64, f64)>,
}

/// How far a hypothesis's chord at the footprint's top may reach beyond the points there (metres):
/// the tread's bulge and the noise keep those points on or outside the tyre's circle, so a circle
/// wider than them by more than this is not the tyre.
const FOOTPRINT_CHORD_MARGIN_M: f64 = 0.05;

/// RANSAC over silhouette points (seeded): circles through three of them whose centre lies
/// within 0.3 m of the footprint's centre along x, that stand on the ground (the lowest point
/// at most 2 cm below it, a deflection of at most 15 % of the radius) and whose chord at the
/// footprint's top reaches at most [`FOOTPRINT_CHORD_MARGIN_M`] beyond the footprint's points
/// there. The hypothesis with the most [`support`] (slices with an edge within
/// [`inlier_tolerance`] on both sides) wins (ties: the smaller sum of residuals). Two of the
/// three points of every sample are edges of the tyre's lower flanks, at most [`LOW_FLANK_M`]
/// above the footprint's top: every sensor under the car sees them, and walls and arches rarely
/// reach that low.
///
/// Why the chord, the support per slice and the sampling: a sensor that sees higher than the
/// lidar (the D435 pitched up, its points in the cloud) sees the wheel arch's vertical walls fore
/// and aft of the tyre and the body's end faces. A large circle standing on the ground runs
/// nearly vertical at its sides over 20-30 cm of height, within the inlier tolerance of two such
/// walls, and a thin wall gives two run ends per slice. On the simulated `suv-offset` pass (seed
/// 1, the camera's points in the cloud) 136 wall edges lay on a 0.72 m circle centred 21 cm off
/// the footprint, against 59 on the tyre's circle: the front tyres were fitted at 0.72 m and the
/// approach was not found. Near the ground that circle is 40 cm wider than the footprint, which
/// the lidar sees from close by under every tyre. Smaller circles through one wall pass the chord
/// test; counting each slice once, and only where both sides lie on the circle, keeps them below
/// the tyre, and with most edges on walls, samples of three edges from anywhere rarely fell on
/// the tyre alone (one of the three
/// from the flanks still lost the tyre on one RANSAC seed in 20;
/// `tall_walls_beside_the_tyre_do_not_make_a_larger_circle`, 200 seeds, fails without any one of
/// the three).
fn ground_constrained_ransac(
    edges: &[[f64; 2]],
    footprint: &Footprint,
    params: TyreParams,
) -> Option<Circle> {
    const HYPOTHESES: usize = 400;
    if edges.len() < 6 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let tol = inlier_tolerance(params.noise_m);
    let plausible = |c: &Circle| {
        let stands = c.v - c.r <= 0.02 && c.r - c.v <= 0.15 * c.r;
        stands
            && (c.u - footprint.centre_x).abs() <= 0.3
            && (0.1..=1.2).contains(&c.r)
            && within_footprint(*c, footprint)
    };
    // `edges` run up by slice, so the lower flanks (whole slices) are a prefix.
    let flank_top = slice_of(footprint.top.map_or(params.h_hi, |t| t.0) + LOW_FLANK_M);
    let low = edges.partition_point(|p| slice_of(p[1]) <= flank_top);
    let flanks = if low >= 3 { &edges[..low] } else { edges };
    let mut best: Option<(usize, f64, Circle)> = None;
    for _ in 0..HYPOTHESES {
        let [a, b] = [0, 1].map(|_| flanks[rng.random_range(0..flanks.len())]);
        let c = edges[rng.random_range(0..edges.len())];
        let Some(circle) = circle_through(a, b, c).filter(plausible) else {
            continue;
        };
        let (count, sum) = support(edges, circle, tol);
        if best.is_none_or(|(n, s, _)| count > n || (count == n && sum < s)) {
            best = Some((count, sum, circle));
        }
    }
    best.filter(|(n, _, _)| *n >= MIN_SUPPORT_SLICES)
        .map(|(_, _, c)| c)
}

/// How many slices of `edges` (in [`slice_edges`]'s order: by slice, then x) have an edge within
/// `tol` of `circle` on both sides of its centre, and the sum of those edges' residuals (the
/// closest on each side).
///
/// Why both sides: every slice a sensor sees a tyre in crosses its outline twice, once ahead of
/// the centre and once behind it, at the same height. A body edge beside the tyre crosses a
/// circle on one side only: a wheel arch's sloping front, a sill's end, a mud flap. On the
/// simulated city car (tyres seen only below the sills, tuning clouds) circles of 0.4-0.5 m
/// through the lower flanks and the arch's slope above them out-counted the 0.29 m tyre when each
/// side counted alone: rear tyres fitted at 0.38-0.43 m, departures 10-11 degrees too large. A thin
/// vertical wall, whose two run ends lie on the same circle on one side, counts at most once.
fn support(edges: &[[f64; 2]], circle: Circle, tol: f64) -> (usize, f64) {
    let (mut count, mut sum) = (0, 0.0);
    for slice in edges.chunk_by(|a, b| slice_of(a[1]) == slice_of(b[1])) {
        let closest = |behind: bool| {
            slice
                .iter()
                .filter(|p| (p[0] < circle.u) == behind)
                .map(|p| circle_residual(*p, circle).abs())
                .filter(|d| *d < tol)
                .min_by(f64::total_cmp)
        };
        if let (Some(a), Some(b)) = (closest(true), closest(false)) {
            count += 1;
            sum += a + b;
        }
    }
    (count, sum)
}

/// The fewest slices that must [`support`] a tyre's circle: three points fix a circle, and three
/// slices crossed on both sides give six.
const MIN_SUPPORT_SLICES: usize = 3;

/// The [`SLICE_M`] slice a height falls in.
fn slice_of(z: f64) -> i64 {
    (z / SLICE_M).floor() as i64
}

/// Whether `circle`'s chord at the footprint's top reaches at most [`FOOTPRINT_CHORD_MARGIN_M`]
/// beyond the footprint's points there (true when the footprint has no top layer).
fn within_footprint(circle: Circle, footprint: &Footprint) -> bool {
    footprint.top.is_none_or(|(h, lo, hi)| {
        let half = (circle.r.powi(2) - (circle.v - h).powi(2)).max(0.0).sqrt();
        circle.u - half >= lo - FOOTPRINT_CHORD_MARGIN_M
            && circle.u + half <= hi + FOOTPRINT_CHORD_MARGIN_M
    })
}

/// The circle through three points, `None` if they are (nearly) collinear.
fn circle_through(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Option<Circle> {
    let (bx, by) = (b[0] - a[0], b[1] - a[1]);
    let (cx, cy) = (c[0] - a[0], c[1] - a[1]);
    let d = 2.0 * (bx * cy - by * cx);
    if d.abs() < 1e-9 {
        return None;
    }
    let (b2, c2) = (bx * bx + by * by, cx * cx + cy * cy);
    let u = (cy * b2 - by * c2) / d;
    let v = (bx * c2 - cx * b2) / d;
    Some(Circle {
        u: a[0] + u,
        v: a[1] + v,
        r: u.hypot(v),
    })
}

/// Circle fit, then refit without residuals beyond 3 sigma (robust MAD), twice.
/// Returns the circle, the points used and their RMS residual.
fn trimmed_circle(points: &[[f64; 2]], noise_m: f64) -> Option<(Circle, Vec<[f64; 2]>, f64)> {
    let mut pts = points.to_vec();
    let mut c = fit_circle(&pts)?;
    for _ in 0..3 {
        let res = |p: &[f64; 2]| (p[0] - c.u).hypot(p[1] - c.v) - c.r;
        let mut abs: Vec<f64> = pts.iter().map(|p| res(p).abs()).collect();
        let sigma = 1.4826 * median(&mut abs)?;
        let limit = (3.0 * sigma).max(3.0 * noise_m).max(0.002);
        let kept: Vec<[f64; 2]> = pts
            .iter()
            .copied()
            .filter(|p| res(p).abs() <= limit)
            .collect();
        if kept.len() == pts.len() || kept.len() < 8 {
            break;
        }
        pts = kept;
        c = fit_circle(&pts)?;
    }
    let rms = (pts
        .iter()
        .map(|p| ((p[0] - c.u).hypot(p[1] - c.v) - c.r).powi(2))
        .sum::<f64>()
        / pts.len() as f64)
        .sqrt();
    Some((c, pts, rms))
}

/// Inner and outer face (y) of the tyre: 1 % / 99 % quantiles of y of points inside the disc.
fn lateral_faces(points: &[V3], seed: &Seed, c: Circle, params: TyreParams) -> (f64, f64) {
    let tol = (3.0 * params.noise_m).max(0.01);
    // As for the slab: 1 cm inboard of the footprint, 5 cm outboard.
    let (lo, hi) = if params.inward_sign > 0.0 {
        (seed.y_min - 0.05, seed.y_max + 0.01)
    } else {
        (seed.y_min - 0.01, seed.y_max + 0.05)
    };
    let mut ys: Vec<f64> = points
        .iter()
        .filter(|p| {
            p[1] > lo
                && p[1] < hi
                && p[2] > params.h_hi
                && (p[0] - c.u).hypot(p[2] - c.v) < c.r + tol
        })
        .map(|p| p[1])
        .collect();
    if ys.len() < 10 {
        return if params.inward_sign > 0.0 {
            (seed.y_max, seed.y_min)
        } else {
            (seed.y_min, seed.y_max)
        };
    }
    ys.sort_unstable_by(f64::total_cmp);
    let q = |f: f64| ys[((ys.len() - 1) as f64 * f).round() as usize];
    let (lo, hi) = (q(0.01), q(0.99));
    if params.inward_sign > 0.0 {
        (hi, lo)
    } else {
        (lo, hi)
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Gaussian sample by Box-Muller (no extra dependency); the angle tests' one.
    pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f64 {
        let u1: f64 = rng.random_range(f64::EPSILON..1.0);
        let u2: f64 = rng.random_range(0.0..1.0);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// A tyre as a VLP-16 0.12 m up sees it from under the car: the inner sidewall annulus
    /// (rim to tread) and the tread's front and back, only below `seen_top_m` (the sensor does not
    /// see the upper third), sampled every `spacing_m`, with range noise `noise_m` along x (the
    /// rays that graze a tyre's front and back run along the vehicle). Beside it: the ground and
    /// the vertical body faces 0.46 m ahead of and behind the axle.
    pub(super) fn seen_tyre(
        centre_x: f64,
        loaded_m: f64,
        free_m: f64,
        spacing_m: f64,
        noise_m: f64,
    ) -> Vec<V3> {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (inner_y, width, rim) = (0.70, 0.245, 0.24);
        let seen_top_m = 0.48;
        let mut pts = Vec::new();
        let steps = |lo: f64, hi: f64| {
            let n = ((hi - lo) / spacing_m).ceil() as usize;
            (0..=n).map(move |i| lo + (hi - lo) * i as f64 / n as f64)
        };
        for x in steps(centre_x - free_m, centre_x + free_m) {
            for z in steps(0.0, seen_top_m) {
                let rho = (x - centre_x).hypot(z - loaded_m);
                // Inside the free circle and above the flattened contact patch.
                if rho > rim && rho < free_m && z > 0.0 {
                    pts.push(V3::new(x + noise_m * gauss(&mut rng), inner_y, z));
                }
            }
        }
        // Tread front and back, across the width.
        for z in steps(0.0, seen_top_m) {
            let h = free_m * free_m - (z - loaded_m).powi(2);
            if h <= 0.0 {
                continue;
            }
            for y in steps(inner_y, inner_y + width) {
                for side in [-1.0, 1.0] {
                    pts.push(V3::new(
                        centre_x + side * h.sqrt() + noise_m * gauss(&mut rng),
                        y,
                        z,
                    ));
                }
            }
        }
        for x in steps(centre_x - 1.2, centre_x + 1.2) {
            for y in steps(0.3, 1.1) {
                pts.push(V3::new(x, y, 0.002 * gauss(&mut rng)));
            }
        }
        for side in [-1.0, 1.0] {
            for z in steps(0.17, 0.45) {
                for y in steps(0.70, 0.90) {
                    pts.push(V3::new(
                        centre_x + side * 0.46 + noise_m * gauss(&mut rng),
                        y,
                        z,
                    ));
                }
            }
        }
        pts
    }

    fn fit(points: &[V3], noise_m: f64) -> TyreFit {
        fit_seeded(points, noise_m, 1)
    }

    fn fit_seeded(points: &[V3], noise_m: f64, seed: u64) -> TyreFit {
        let (seeds, _) = find_seeds(points, 0.025, 0.08);
        let params = TyreParams {
            h_lo: 0.025,
            h_hi: 0.08,
            gap_m: 0.025,
            noise_m,
            inward_sign: -1.0,
            band_edges: false,
            seed,
        };
        fit_tyre(points, &seeds[0], params).expect("a tyre fit")
    }

    #[test]
    fn sparse_noisy_lower_two_thirds_give_the_centre() {
        // 2 cm spacing, 4 mm noise: the cloud a 1-2 cm output voxel leaves of a VLP-16 pass.
        // The angular-sector silhouette used before took the upper boundary of the seen part for
        // the tyre's outline and put the centre about 4 cm low here.
        let pts = seen_tyre(0.3, 0.335, 0.335, 0.02, 0.004);
        let f = fit(&pts, 0.004);
        assert!((f.centre_x - 0.3).abs() < 0.005, "{f:?}");
        assert!((f.loaded_radius_m - 0.335).abs() < 0.008, "{f:?}");
        assert!((f.free_radius_m - 0.335).abs() < 0.012, "{f:?}");
    }

    #[test]
    fn deflected_tyre_keeps_centre_height_and_free_radius_apart() {
        // Loaded radius 0.32 (centre height), free tread radius 0.335, dense and noiseless.
        let pts = seen_tyre(-0.2, 0.32, 0.335, 0.005, 0.0);
        let f = fit(&pts, 0.0);
        assert!((f.centre_x + 0.2).abs() < 0.002, "{f:?}");
        assert!((f.loaded_radius_m - 0.32).abs() < 0.003, "{f:?}");
        assert!((f.free_radius_m - 0.335).abs() < 0.003, "{f:?}");
    }

    #[test]
    fn tall_walls_beside_the_tyre_do_not_make_a_larger_circle() {
        // What the D435 pitched up adds to the lidar's view (simulated suv-offset, seed 1): the
        // wheel arch's back wall 0.5 m behind the axle up to 0.8 m, and the body's front face
        // 0.92 m ahead up to 1.05 m. A 0.72 m circle standing on the ground explained more of
        // their run ends than the tyre did.
        let mut pts = seen_tyre(0.0, 0.343, 0.37, 0.01, 0.004);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for (x, z_lo, z_hi) in [(-0.5, 0.26, 0.8), (0.92, 0.40, 1.05)] {
            for i in 0..=((z_hi - z_lo) / 0.005) as usize {
                for j in 0..=20 {
                    let (y, z) = (0.70 + 0.01 * f64::from(j), z_lo + 0.005 * i as f64);
                    pts.push(V3::new(x + 0.004 * gauss(&mut rng), y, z));
                }
            }
        }
        // Every RANSAC seed: the walls supply most of the edges, so the sampling must not find
        // the tyre by luck.
        for seed in 1..=200 {
            let f = fit_seeded(&pts, 0.004, seed);
            assert!(f.centre_x.abs() < 0.01, "seed {seed}: {f:?}");
            assert!(
                (f.loaded_radius_m - 0.343).abs() < 0.01,
                "seed {seed}: {f:?}"
            );
            assert!((f.free_radius_m - 0.37).abs() < 0.015, "seed {seed}: {f:?}");
        }
    }

    #[test]
    fn an_arch_slope_beside_a_tyre_seen_below_the_sills_does_not_make_a_larger_circle() {
        // A city car's 0.289 m tyre (0.276 m loaded) that a VLP-16 sees only below its sills at
        // 0.2 m, and the body's slope ahead of it, from 0.30 m ahead of the axle at 0.12 m up to
        // 0.52 m at 0.45 m (the simulated city car's front, tuning cloud hall-b/1). A circle of
        // about 0.5 m through the flanks' lowest edges and the slope out-counted the tyre when
        // each side of a slice counted alone (this test failed then).
        let mut pts: Vec<V3> = seen_tyre(0.0, 0.276, 0.289, 0.01, 0.004)
            .into_iter()
            .filter(|p| p[2] < 0.2)
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for i in 0..=50 {
            let t = f64::from(i) / 50.0;
            for j in 0..=20 {
                let y = 0.70 + 0.01 * f64::from(j);
                let x = 0.30 + 0.22 * t + 0.002 * gauss(&mut rng);
                pts.push(V3::new(x, y, 0.12 + 0.33 * t));
            }
        }
        for seed in 1..=50 {
            let f = fit_seeded(&pts, 0.004, seed);
            assert!(f.centre_x.abs() < 0.01, "seed {seed}: {f:?}");
            assert!(
                (f.loaded_radius_m - 0.276).abs() < 0.015,
                "seed {seed}: {f:?}"
            );
            assert!((f.free_radius_m - 0.289).abs() < 0.02, "seed {seed}: {f:?}");
        }
    }

    #[test]
    fn the_tyres_are_the_corners_of_a_rectangle_not_the_largest_clusters() {
        // A city car's footprints (2.4 m wheelbase, 1.43 m track, 2 degrees yawed), a low part on
        // the centreline larger than a rear footprint, and a cluster beside the car.
        let (s, c) = (2f64.to_radians().sin(), 2f64.to_radians().cos());
        let corner = |x: f64, y: f64, n: usize| (c * x - s * y, s * x + c * y, n);
        let mut candidates = vec![
            (0.1, 0.02, 900),
            corner(1.2, 0.715, 800),
            corner(1.2, -0.715, 760),
            (1.0, -1.95, 700),
            corner(-1.2, 0.715, 500),
            corner(-1.2, -0.715, 450),
        ];
        assert_eq!(vehicle_set(&candidates, &[]), Some(vec![1, 2, 4, 5]));
        // Three corners still make a vehicle; the fourth is where the rectangle puts it.
        candidates.remove(5);
        assert_eq!(vehicle_set(&candidates, &[]), Some(vec![1, 2, 4]));
        // Two corners on one side and junk: no rectangle.
        let no_axle = [(1.2, 0.7, 800), (-1.2, 0.7, 800), (0.0, 0.0, 900)];
        assert_eq!(vehicle_set(&no_axle, &[]), None);
        // An axle and a cluster on the centreline of the other: not a corner.
        let mid = [(1.2, 0.7, 800), (1.2, -0.7, 800), (-1.2, 0.0, 900)];
        assert_eq!(vehicle_set(&mid, &[]), None);
    }

    #[test]
    fn the_tyres_straddle_the_robots_path() {
        // The measured car's footprints, its left ones half hidden, and a neighbour parked 3.2 m
        // to the right with denser footprints: its four are a rectangle, and its left tyres
        // pair with the car's right ones into axles 1.7 m wide.
        let candidates = [
            (1.2, 0.715, 300),
            (1.2, -0.715, 800),
            (-1.2, 0.715, 300),
            (-1.2, -0.715, 800),
            (1.5, -2.4, 2000),
            (1.5, -4.0, 2000),
            (-1.1, -2.4, 2000),
            (-1.1, -4.0, 2000),
        ];
        assert_eq!(vehicle_set(&candidates, &[]), Some(vec![4, 5, 6, 7]));
        let path: Vec<[f64; 2]> = (0..=60)
            .map(|i| [-3.0 + 0.1 * f64::from(i), 0.05])
            .collect();
        assert_eq!(vehicle_set(&candidates, &path), Some(vec![0, 1, 2, 3]));
        // A path that stops short of an axle does not judge it.
        let short: Vec<[f64; 2]> = path.iter().copied().filter(|p| p[0] > 0.0).collect();
        assert_eq!(
            vehicle_set(&candidates[..4], &short),
            Some(vec![0, 1, 2, 3])
        );
    }

    #[test]
    fn a_runs_end_is_the_half_height_of_its_noisy_band_not_its_outermost_return() {
        // A slice's run with its end at x = 0: 1,500 returns spread evenly inside, each moved
        // along x by the VLP-16's simulated range noise (sigma 1.5 cm, clipped at 3 cm).
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut xs: Vec<f64> = (0..1500)
            .map(|i| -0.3 + 0.0002 * f64::from(i) + (0.015 * gauss(&mut rng)).clamp(-0.03, 0.03))
            .collect();
        xs.sort_by(f64::total_cmp);
        let extreme = *xs.last().expect("points");
        let edge = band_edge(xs.iter().rev().copied(), extreme, -1.0);
        assert!(extreme > 0.02, "{extreme}");
        assert!(edge.abs() < 0.005, "edge {edge}, extreme {extreme}");
        // The same from the other end, mirrored.
        let mirrored: Vec<f64> = xs.iter().rev().map(|x| -x).collect();
        let other = band_edge(mirrored.iter().copied(), mirrored[0], 1.0);
        assert!((other + edge).abs() < 1e-12, "{other} {edge}");
        // Noiseless and uniform: the extreme is the edge.
        let even: Vec<f64> = (0..100).map(|i| 0.001 * f64::from(i)).collect();
        assert!((band_edge(even.iter().rev().copied(), 0.099, -1.0) - 0.099).abs() < 1e-15);
        // Too few returns to profile: the extreme.
        let few = [0.05, 0.04, 0.0, -0.01];
        assert!((band_edge(few.iter().copied(), 0.05, -1.0) - 0.05).abs() < 1e-15);
    }

    #[test]
    fn circle_through_three_points() {
        let c = circle_through([1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]).expect("a circle");
        assert!(c.u.abs() < 1e-12 && c.v.abs() < 1e-12 && (c.r - 1.0).abs() < 1e-12);
        assert!(circle_through([0.0, 0.0], [1.0, 1.0], [2.0, 2.0]).is_none());
    }
}
