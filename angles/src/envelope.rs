//! Robust lower envelope of the body in the side view.
//!
//! Body points inside the lateral band are binned along x (`bin_m`). In each bin the lowest *mode*
//! of the heights is found: the lowest window of height `2 w` that holds at least `min_support`
//! points, then re-centred on the mean of the points within `w` of it until it stops moving (a
//! flat-kernel mean shift that climbs from the noise tail to the surface; a peak with more than
//! twice its points in the next `2 w` above it, counted at its own lateral positions, is a tail
//! fluctuation, and the climb goes on; a narrow part under a wide surface is not a tail of it).
//! `w` is 2.5 x the noise sigma (at least 1 mm), so on a noisy flat surface the mode is the
//! surface itself, not its low noise tail; a lone low outlier (fewer than `min_support` points
//! within `2 w`) never forms a mode and is counted in `outliers_below`. A bin without any mode
//! is merged with its neighbours into a bin twice as wide, up to [`MAX_BIN_M`], and tried again
//! there: the envelope has the finest resolution the points support, bin by bin.
//!
//! The mode's points get a least-squares line `z = a + b (x - x_mean)`; the bin contributes two
//! envelope samples, the line's values at the mode's lowest and highest x, each pulled 2 noise sigma
//! toward the mean x (noise spreads points outward; with no noise the extremes are exact), heights
//! clamped to the mode's height range. On noiseless piecewise-flat surfaces both samples lie exactly on the surface, so
//! corners are kept to the point spacing; on noisy ones each sample averages the whole mode.
//! Across the path the mode's height is its points' mean, which on a round part (an exhaust pipe)
//! lies above the part's lowest line; where the scan path is known and the part's returns, taken
//! by their ray angle, show a stretch clearly below that mean, the line is lowered to it
//! ([`cross_section_floor`]).
//! Known bias (measured in the tests and docs/method/calculator.md): at a convex corner the mode mixes both
//! faces within `w`, which lifts the envelope there by up to about `w / 2`; a round part seen
//! from below and mostly along the path (nearly above the path), or in a strip between the
//! axles, keeps the mean, up to `w` above its lowest line.

use std::collections::BTreeMap;

use super::geom::V3;

/// One envelope sample in the side view (vehicle frame x forward, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvelopeSample {
    /// Position along the vehicle (metres).
    pub x_m: f64,
    /// Height above the ground (metres).
    pub z_m: f64,
    /// Mean lateral position of the supporting points (metres).
    pub y_m: f64,
    /// Points in the bin's lowest mode (the support of this sample).
    pub support: usize,
}

/// Envelope parameters.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EnvelopeParams<'a> {
    pub bin_m: f64,
    pub half_window_m: f64,
    pub min_support: usize,
    /// Noise sigma: the mode's extreme x are pulled in by 2 sigma (noise spreads them outward).
    pub noise_m: f64,
    /// Where the scanner was (see [`cross_section_floor`]); `None`: not known.
    pub scan_line: Option<ScanLine<'a>>,
}

/// Result of the envelope pass.
#[derive(Debug, Clone, Default)]
pub(crate) struct Envelope {
    pub samples: Vec<EnvelopeSample>,
    /// Points that lay below their bin's mode (rejected as outliers).
    pub outliers_below: usize,
    /// Bins with points but no mode of sufficient support.
    pub unsupported_bins: usize,
    /// Sparse bins at the noise fringe of a dense surface, not used (see [`fringe_bins`]).
    pub fringe_bins: usize,
}

/// Noise sigma normal to the underside, from the points themselves: the points are split into
/// 3 cm x 3 cm columns (x, y); each column with at least 12 points gets a least-squares plane
/// `z = a x + b y + c`; columns steeper than 45 degrees are skipped; the estimate is the median of
/// the columns' residual standard deviations (robust to the few columns that straddle an edge).
/// Range noise projects unevenly (rays near the sensor's path see it vertically, grazing rays
/// little), so this is a typical, not a worst-case, figure.
/// `None` if fewer than 10 columns qualify.
pub(crate) fn surface_noise(points: &[V3]) -> Option<f64> {
    const CELL_M: f64 = 0.03;
    let mut keyed: Vec<((i64, i64), V3)> = points
        .iter()
        .map(|p| {
            (
                (
                    (p[0] / CELL_M).floor() as i64,
                    (p[1] / CELL_M).floor() as i64,
                ),
                *p,
            )
        })
        .collect();
    keyed.sort_unstable_by_key(|a| a.0);
    let mut sigmas = Vec::new();
    for group in keyed.chunk_by(|a, b| a.0 == b.0) {
        if group.len() < 12 {
            continue;
        }
        let pts = group.iter().map(|(_, p)| *p);
        let Some((normal, centre)) = super::geom::fit_plane(pts.clone()) else {
            continue;
        };
        if normal[2] < std::f64::consts::FRAC_1_SQRT_2 {
            continue;
        }
        let ssr: f64 = pts
            .map(|p| {
                let d = p - centre;
                d.dot(&normal).powi(2)
            })
            .sum();
        sigmas.push((ssr / (group.len() - 3) as f64).sqrt());
    }
    if sigmas.len() < 10 {
        return None;
    }
    super::geom::median(&mut sigmas)
}

/// Cell edge of the local-surface estimate in [`across_path`] (metres): a point's surface is
/// fitted over the 3 x 3 x 3 cells around its own, a 3 cm cube.
const ACROSS_CELL_M: f64 = 0.01;
/// Fewest points in that cube for a surface estimate.
const ACROSS_MIN_POINTS: usize = 12;
/// A surface whose normal's x component exceeds this faces along the path (about 25 degrees from
/// a plane across it).
const ACROSS_MIN_NORMAL_X: f64 = 0.9;
/// Points this far above the lowest band point of their 1 cm column along x are never in a
/// lowest mode that a face across the path could lift; they are left unmarked and uncounted.
const ACROSS_REACH_M: f64 = 0.08;

/// Which of `points` (the band's body points, vehicle frame) lie on a face across the path, for
/// the envelope's modes to leave out: points outside `inner_x_m` (the axles' x: the overhangs,
/// where the approach and departure witnesses lie), at most [`ACROSS_REACH_M`] above the lowest
/// point of their column, whose local surface has a normal more than [`ACROSS_MIN_NORMAL_X`]
/// along x.
///
/// Why: the end cap of a part along the path (the sedan's exhaust silencer) is such a face. The
/// lidar smears its points along the rays, over the last few centimetres of the part, and there
/// they lift the bins' lowest modes by 1-2.5 cm, in some bins and not in others, so the
/// departure witness moves by centimetres along x between seeds (decision record 026).
///
/// The local surface is the smallest principal axis of the points in the 3 x 3 x 3 cells of
/// [`ACROSS_CELL_M`] around a point's cell: each cell's moments are summed once (one hash lookup
/// per point), then added up over the nine columns of cells around each column (nine lookups per
/// column). A neighbour search per point, the first version, cost the calculator a second on a
/// 2.8 M-point cloud, 27 lookups per cell 0.35-0.5 s for one grid; this, both grids, 45-60 ms
/// on the pipeline's million-point clouds. The cube is tied to a grid, so a cube straddling
/// the corner of a part mixes the faces and whether a point is marked depended on where the grid
/// fell (the sedan's departure sd moved between 0.13 and 0.23 with the cell size on the
/// pipeline's clouds); a point is marked if either of two grids, offset by half a cell, marks it.
pub(crate) fn across_path(points: &[V3], inner_x_m: (f64, f64)) -> Vec<bool> {
    use passangle_geom::{VoxelMap, voxel_of};
    let candidate = |p: &V3| p[0] < inner_x_m.0 || p[0] > inner_x_m.1;
    // The lowest candidate point per column of one cell along x.
    let column = |p: &V3| [voxel_of(*p, ACROSS_CELL_M)[0], 0, 0];
    let mut lowest: VoxelMap<f64> = VoxelMap::default();
    for p in points.iter().filter(|p| candidate(p)) {
        let z = lowest.entry(column(p)).or_insert(f64::MAX);
        *z = z.min(p[2]);
    }
    let near: Vec<usize> = points
        .iter()
        .enumerate()
        .filter(|(_, p)| candidate(p) && p[2] <= lowest[&column(p)] + ACROSS_REACH_M)
        .map(|(i, _)| i)
        .collect();
    let near_points: Vec<V3> = near.iter().map(|&i| points[i]).collect();
    let mut marked = vec![false; points.len()];
    for offset_m in [0.0, 0.5 * ACROSS_CELL_M] {
        for (&i, across) in near.iter().zip(faces_across(&near_points, offset_m)) {
            marked[i] |= across;
        }
    }
    marked
}

/// [`across_path`]'s test on one grid, shifted by `offset_m` along every axis.
fn faces_across(points: &[V3], offset_m: f64) -> Vec<bool> {
    use passangle_geom::{VoxelMap, voxel_of};
    // Each cell's moments, about its first point (so the sums stay small).
    let mut index: VoxelMap<u32> = VoxelMap::default();
    let mut cells: Vec<([i32; 3], Moments)> = Vec::new();
    let cell_of_point: Vec<u32> = points
        .iter()
        .map(|&p| {
            let key = voxel_of(p.map(|c| c + offset_m), ACROSS_CELL_M);
            let id = *index.entry(key).or_insert_with(|| {
                cells.push((key, Moments::at(p.into())));
                (cells.len() - 1) as u32
            });
            cells[id as usize].1.add_point(p);
            id
        })
        .collect();
    // The cells sorted by (x, y, z): a column of cells (one x, y) is a run, and the 27 cells
    // around a cell lie in the 9 columns around its own, within one cell of its z.
    let mut order: Vec<u32> = (0..cells.len() as u32).collect();
    order.sort_unstable_by_key(|&id| cells[id as usize].0);
    let mut columns: VoxelMap<(usize, usize)> = VoxelMap::default();
    let mut start = 0;
    for run in order.chunk_by(|&a, &b| cells[a as usize].0[..2] == cells[b as usize].0[..2]) {
        let key = cells[run[0] as usize].0;
        columns.insert([key[0], key[1], 0], (start, start + run.len()));
        start += run.len();
    }
    let mut across = vec![false; cells.len()];
    let mut around: Vec<&[u32]> = Vec::with_capacity(9);
    for (&[x, y, _], &(lo, hi)) in &columns {
        around.clear();
        for dx in -1..=1 {
            for dy in -1..=1 {
                // Wrapping: keys saturate at the ends of i32 for absurd coordinates.
                let neighbour = [x.wrapping_add(dx), y.wrapping_add(dy), 0];
                if let Some(&(a, b)) = columns.get(&neighbour) {
                    around.push(&order[a..b]);
                }
            }
        }
        for &id in &order[lo..hi] {
            let (key, centre) = cells[id as usize];
            let mut sum = Moments::at(centre.origin);
            for column in &around {
                for &other in *column {
                    let (k, m) = &cells[other as usize];
                    if k[2].abs_diff(key[2]) <= 1 {
                        sum.add_moved(m);
                    }
                }
            }
            across[id as usize] = sum.faces_x();
        }
    }
    cell_of_point
        .iter()
        .map(|&id| across[id as usize])
        .collect()
}

/// Count, sum and second moments (xx, xy, xz, yy, yz, zz) of points about `origin`: the
/// mergeable form of `pipeline::geom::centroid_covariance`, so 27 cells' points are summed from
/// their cells' moments instead of being gathered again.
#[derive(Clone, Copy)]
struct Moments {
    origin: [f64; 3],
    n: f64,
    s: [f64; 3],
    ss: [f64; 6],
}

impl Moments {
    const PAIRS: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

    fn at(origin: [f64; 3]) -> Self {
        Self {
            origin,
            n: 0.0,
            s: [0.0; 3],
            ss: [0.0; 6],
        }
    }

    fn add_point(&mut self, p: V3) {
        let d: [f64; 3] = std::array::from_fn(|k| p[k] - self.origin[k]);
        self.n += 1.0;
        for (s, d) in self.s.iter_mut().zip(d) {
            *s += d;
        }
        for (ss, &(a, b)) in self.ss.iter_mut().zip(&Self::PAIRS) {
            *ss += d[a] * d[b];
        }
    }

    /// Add `m`'s points, moving its sums to this origin: with `t` its origin less this one,
    /// sum d' = sum d + n t and sum d'_a d'_b = sum d_a d_b + t_a sum d_b + t_b sum d_a + n t_a t_b.
    fn add_moved(&mut self, m: &Moments) {
        let t: [f64; 3] = std::array::from_fn(|k| m.origin[k] - self.origin[k]);
        for (k, &(a, b)) in Self::PAIRS.iter().enumerate() {
            self.ss[k] += m.ss[k] + t[a] * m.s[b] + t[b] * m.s[a] + m.n * t[a] * t[b];
        }
        for ((s, ms), t) in self.s.iter_mut().zip(m.s).zip(t) {
            *s += ms + m.n * t;
        }
        self.n += m.n;
    }

    /// True when there are at least [`ACROSS_MIN_POINTS`] points and their plane's normal (the
    /// smallest principal axis) is more than [`ACROSS_MIN_NORMAL_X`] along x.
    fn faces_x(&self) -> bool {
        if self.n < ACROSS_MIN_POINTS as f64 {
            return false;
        }
        let n = self.n;
        let c: [f64; 6] = std::array::from_fn(|k| {
            let (a, b) = Self::PAIRS[k];
            self.ss[k] / n - self.s[a] * self.s[b] / (n * n)
        });
        let cov = passangle_geom::M3::new(c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5]);
        // Eigenvalues ascending, eigenvectors as columns: the normal is column 0.
        passangle_geom::symmetric_eigen3(&cov)
            .is_some_and(|(_, vectors)| vectors[(0, 0)].abs() > ACROSS_MIN_NORMAL_X)
    }
}

/// Lower envelope of `points` (x, y, z), already restricted to the band.
pub(crate) fn lower_envelope(points: &[V3], params: EnvelopeParams) -> Envelope {
    let mut env = Envelope::default();
    let mut modes: Vec<BinMode> = Vec::new();
    let mut level = params;
    let mut pending = points.to_vec();
    loop {
        let (sparse, bins) = bin_modes(&pending, level, &mut modes, &mut env);
        // Bins without a mode at this width are tried again at twice the width (up to
        // `MAX_BIN_M`): a small part seen by few returns (a tow-hitch receiver, 30 points over
        // 14 cm) holds `min_support` points over a few centimetres, not in each 5 mm bin. Bins
        // that have a mode keep it at the finest width; their points never move up a level.
        let coarser = level.bin_m * 2.0;
        if sparse.is_empty() || coarser > MAX_BIN_M * (1.0 + 1e-9) {
            env.unsupported_bins += bins;
            break;
        }
        pending = sparse;
        level = EnvelopeParams {
            bin_m: coarser,
            half_window_m: params.half_window_m.max(0.4 * coarser),
            ..params
        };
    }
    modes.sort_by(|a, b| a.start_m.total_cmp(&b.start_m));
    let fringe = fringe_bins(&modes, params);
    env.fringe_bins = fringe.iter().filter(|f| **f).count();
    let extent_y_m = y_range(points);
    let floors: Vec<Option<f64>> = match params.scan_line {
        Some(line) => {
            let rays = line.rays(&modes);
            (0..modes.len())
                .map(|i| cross_section_floor(&modes, &rays, i, params, extent_y_m))
                .collect()
        }
        None => vec![None; modes.len()],
    };
    for ((mode, is_fringe), floor) in modes.iter().zip(fringe).zip(floors) {
        if !is_fringe {
            env.samples
                .extend(mode.line.samples(mode.support, floor, params.noise_m));
        }
    }
    env
}

/// The widest bin the envelope uses (metres), in [`lower_envelope`] and the automatic bin width.
pub(crate) const MAX_BIN_M: f64 = 0.04;

/// One bin's lowest mode.
struct BinMode {
    /// Where the bin starts along x and its width (metres).
    start_m: f64,
    width_m: f64,
    /// Points in the mode.
    support: usize,
    /// The mode's points and their line along x (through their mean height).
    points: Vec<V3>,
    line: ModeLine,
}

impl BinMode {
    /// Points per metre along x.
    fn density(&self) -> f64 {
        self.support as f64 / self.width_m
    }
}

/// The lowest mode of every bin of `params.bin_m` into `modes`; returns the points of the bins
/// without one and how many such bins there were.
fn bin_modes(
    points: &[V3],
    params: EnvelopeParams,
    modes: &mut Vec<BinMode>,
    env: &mut Envelope,
) -> (Vec<V3>, usize) {
    let mut keyed: Vec<(i64, V3)> = points
        .iter()
        .map(|p| ((p[0] / params.bin_m).floor() as i64, *p))
        .collect();
    keyed.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1[2].total_cmp(&b.1[2])));
    let mut sparse = Vec::new();
    let mut sparse_bins = 0;
    for group in keyed.chunk_by(|a, b| a.0 == b.0) {
        let key = group[0].0;
        let bin: Vec<V3> = group.iter().map(|(_, p)| *p).collect();
        if let Some((lo, hi)) = bin_mode(&bin, params) {
            env.outliers_below += lo;
            let mode = &bin[lo..hi];
            modes.push(BinMode {
                start_m: key as f64 * params.bin_m,
                width_m: params.bin_m,
                support: mode.len(),
                line: ModeLine::of(mode),
                points: mode.to_vec(),
            });
        } else {
            sparse_bins += 1;
            sparse.extend(bin);
        }
    }
    (sparse, sparse_bins)
}

/// Width of the lateral strips of [`lower_envelope_strips`] (metres): narrower than a sill or a
/// fuel tank, wide enough to hold a bin's support.
pub(crate) const BETWEEN_AXLES_STRIP_M: f64 = 0.1;

/// [`lower_envelope`] of each lateral strip `strip_m` wide, the samples of all strips together:
/// the side view's lower envelope is the lowest surface across the width, and one mode over the
/// whole width mixes surfaces less than a window apart in height (the module's known bias).
/// The strips keep their modes' means ([`cross_section_floor`] is not used): the rays that
/// describe a cross-section run nearly across the path and cross a strip within its width, so
/// the strip's edges cut away the returns that range noise carries across them, and the few
/// groups left between the edges are biased (on the simulated SUV's flat underside they read
/// 3-4 mm low). The whole band's envelope, which spans the same stretch, uses it.
pub(crate) fn lower_envelope_strips(
    points: &[V3],
    params: EnvelopeParams,
    strip_m: f64,
) -> Envelope {
    let params = EnvelopeParams {
        scan_line: None,
        ..params
    };
    let mut strips: BTreeMap<i64, Vec<V3>> = BTreeMap::new();
    for p in points {
        strips
            .entry((p[1] / strip_m).floor() as i64)
            .or_default()
            .push(*p);
    }
    strips
        .values()
        .map(|pts| lower_envelope(pts, params))
        .fold(Envelope::default(), Envelope::merged)
}

impl Envelope {
    /// This envelope with `other`'s samples added; the counts stay this envelope's.
    pub(crate) fn with_samples_of(mut self, other: Envelope) -> Envelope {
        self.samples.extend(other.samples);
        self
    }

    /// Both envelopes' samples and counts.
    fn merged(mut self, other: Envelope) -> Envelope {
        self.samples.extend(other.samples);
        self.outliers_below += other.outliers_below;
        self.unsupported_bins += other.unsupported_bins;
        self.fringe_bins += other.fringe_bins;
        self
    }
}

/// Noise fringe: range noise smears a surface's edge beyond it (mostly along x, since a low
/// sensor sees the underside and the bumpers' lower edges along the vehicle), into bins that hold
/// fewer points than the surface. A bin is fringe if a bin within 4 noise sigma (at most
/// `FRINGE_REACH_M`; none without noise) along x has at least `FRINGE_RATIO` x its density
/// (points per metre along x, so that bins of different widths compare) and a mode no higher
/// than its own plus `max(3 sigma, 2 mm)`:
/// a sparser bin beside a denser surface at about the same height or lower. Ratio 2 is the
/// half-density point where a blurred edge truly ends: on lidar-only simulator clouds (VLP-16,
/// 1.5 cm range noise) the off-roader's bumper edge was smeared 2 cm forward and its approach
/// angle read 0.9 degree low with the ratio 4 used before, 0.3 degree high with 2. A sparse part
/// clearly lower than its dense neighbours (a tow ball below a bumper) is kept. Known cost, also
/// without noise: a part with less than half the support of a surface within 2 cm of it along x
/// and not lower than it is ignored (its effect is then bounded by those 2 cm); in sparse clouds,
/// where supports fluctuate, the outermost bins of an edge go first (an inward bias of a bin).
fn fringe_bins(modes: &[BinMode], params: EnvelopeParams) -> Vec<bool> {
    // The fringe is as wide as the noise blur: about 4 sigma, capped at `FRINGE_REACH_M`; a
    // noiseless cloud has none (its sparse bins are real corners, e.g. steep bumper faces).
    let reach_m = (4.0 * params.noise_m).min(FRINGE_REACH_M);
    if reach_m < 1e-4 {
        return vec![false; modes.len()];
    }
    // Bins up to `ceil(reach / bin)` finest bins apart along x are neighbours: at most that many
    // minus one finest bins between their intervals.
    let gap_m = ((reach_m / params.bin_m).ceil() - 1.0) * params.bin_m + 1e-9;
    let tol = (3.0 * params.noise_m).max(0.002);
    // Modes are sorted by start; a neighbour starts at most `gap_m + MAX_BIN_M` from this one.
    let window = gap_m + MAX_BIN_M;
    modes
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let lo = modes[..i].partition_point(|o| o.start_m < m.start_m - window);
            modes[lo..]
                .iter()
                .enumerate()
                .take_while(|(_, o)| o.start_m <= m.start_m + window)
                .any(|(j, o)| {
                    let between = (o.start_m - (m.start_m + m.width_m))
                        .max(m.start_m - (o.start_m + o.width_m));
                    lo + j != i
                        && between <= gap_m
                        && o.density() >= FRINGE_RATIO as f64 * m.density()
                        && o.line.z_m <= m.line.z_m + tol
                })
        })
        .collect()
}

/// How far along x a dense bin marks sparse neighbours as fringe.
const FRINGE_REACH_M: f64 = 0.02;
/// Support ratio that marks a bin as fringe.
const FRINGE_RATIO: usize = 2;

/// Index range (into the height-sorted bin) of the lowest mode.
fn bin_mode(bin: &[V3], params: EnvelopeParams) -> Option<(usize, usize)> {
    let (w, m) = (params.half_window_m, params.min_support.max(1));
    let n = bin.len();
    let mut j = 0;
    let mut first = None;
    for i in 0..n {
        j = j.max(i);
        while j < n && bin[j][2] < bin[i][2] + 2.0 * w {
            j += 1;
        }
        if j - i >= m {
            first = Some((i, j));
            break;
        }
    }
    let (mut lo, mut hi) = first?;
    let window = |centre: f64| {
        (
            bin.partition_point(|p| p[2] < centre - w),
            bin.partition_point(|p| p[2] <= centre + w),
        )
    };
    for _ in 0..32 {
        // Mean shift to a local density peak.
        for _ in 0..64 {
            let (nlo, nhi) = window(mean_z(&bin[lo..hi]));
            if nhi - nlo < m || (nlo, nhi) == (lo, hi) {
                break;
            }
            (lo, hi) = (nlo, nhi);
        }
        // A peak in the noise tail of a denser surface just above it is not a surface of its
        // own: if the next 2 w above hold more than twice its points at its own lateral
        // positions, keep climbing. (Counted across the whole band, a floor 1.3 m wide outnumbered
        // the sedan's 12 cm wide silencer 2-3 cm below it, and every other bin of the silencer's
        // last 2 cm took the floor.)
        let mean = mean_z(&bin[lo..hi]);
        let (y_lo, y_hi) = y_range(&bin[lo..hi]);
        let above = bin[hi..bin.partition_point(|p| p[2] <= mean + 3.0 * w)]
            .iter()
            .filter(|p| p[1] >= y_lo && p[1] <= y_hi)
            .count();
        if above <= 2 * (hi - lo) {
            break;
        }
        let (nlo, nhi) = window(mean + w);
        if nhi - nlo < m {
            break;
        }
        (lo, hi) = (nlo, nhi);
    }
    Some((lo, hi))
}

/// Lowest and highest y of `points`.
fn y_range(points: &[V3]) -> (f64, f64) {
    points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p[1]), hi.max(p[1]))
    })
}

fn mean_z(points: &[V3]) -> f64 {
    points.iter().map(|p| p[2]).sum::<f64>() / points.len().max(1) as f64
}

/// A mode's least-squares line along x, `z = z_m + slope (x - x_m)`, and its points' extent.
#[derive(Debug, Clone, Copy)]
struct ModeLine {
    x_m: f64,
    y_m: f64,
    z_m: f64,
    slope: f64,
    x_range: (f64, f64),
    y_range: (f64, f64),
    z_range: (f64, f64),
    /// Points, and their sums of squares and products about the means (x x, x z): what pools
    /// lines ([`pooled_line`]).
    n: usize,
    sxx: f64,
    sxz: f64,
}

impl ModeLine {
    fn of(mode: &[V3]) -> ModeLine {
        let n = mode.len() as f64;
        let (mx, my, mz) = mode.iter().fold((0.0, 0.0, 0.0), |(a, b, c), p| {
            (a + p[0], b + p[1], c + p[2])
        });
        let (mx, my, mz) = (mx / n, my / n, mz / n);
        let (mut sxx, mut sxz) = (0.0, 0.0);
        let (mut x_range, mut z_range) = ((f64::MAX, f64::MIN), (f64::MAX, f64::MIN));
        for p in mode {
            sxx += (p[0] - mx).powi(2);
            sxz += (p[0] - mx) * (p[2] - mz);
            x_range = (x_range.0.min(p[0]), x_range.1.max(p[0]));
            z_range = (z_range.0.min(p[2]), z_range.1.max(p[2]));
        }
        ModeLine {
            x_m: mx,
            y_m: my,
            z_m: mz,
            slope: slope_of(mode.len(), sxx, sxz),
            x_range,
            y_range: y_range(mode),
            z_range,
            n: mode.len(),
            sxx,
            sxz,
        }
    }

    /// The two samples of a bin: the line at the mode's lowest and highest x, each pulled 2
    /// noise sigma toward the mean x, the line lowered to `floor` (at the mean x) where the
    /// surface's cross-section puts its lowest line below the mode's mean
    /// ([`cross_section_floor`]), heights clamped to the mode's range.
    fn samples(&self, support: usize, floor: Option<f64>, noise_m: f64) -> Vec<EnvelopeSample> {
        let level = floor.unwrap_or(self.z_m);
        let at =
            |x: f64| (level + self.slope * (x - self.x_m)).clamp(self.z_range.0, self.z_range.1);
        let sample = |x: f64| EnvelopeSample {
            x_m: x,
            z_m: at(x),
            y_m: self.y_m,
            support,
        };
        let mx = self.x_m;
        let (x_lo, x_hi) = (
            (self.x_range.0 + 2.0 * noise_m).min(mx),
            (self.x_range.1 - 2.0 * noise_m).max(mx),
        );
        if x_hi - x_lo < 1e-9 {
            vec![sample(mx)]
        } else {
            vec![sample(x_lo), sample(x_hi)]
        }
    }
}

/// A least-squares slope from `n` points' sums about their means; 0 for fewer than 3 points or
/// no spread along x.
fn slope_of(n: usize, sxx: f64, sxz: f64) -> f64 {
    if n >= 3 && sxx > 1e-12 {
        sxz / sxx
    } else {
        0.0
    }
}

/// The least-squares line `(x_mean, z_mean, slope)` through all the points of `lines`, from
/// their sums (no point is visited).
fn pooled_line<'a>(lines: impl Iterator<Item = &'a ModeLine> + Clone) -> (f64, f64, f64) {
    let (n, sx, sz) = lines.clone().fold((0, 0.0, 0.0), |(n, sx, sz), l| {
        (n + l.n, sx + l.n as f64 * l.x_m, sz + l.n as f64 * l.z_m)
    });
    let (mx, mz) = (sx / n.max(1) as f64, sz / n.max(1) as f64);
    let (sxx, sxz) = lines.fold((0.0, 0.0), |(sxx, sxz), l| {
        let (dx, dz) = (l.x_m - mx, l.z_m - mz);
        (
            sxx + l.sxx + l.n as f64 * dx * dx,
            sxz + l.sxz + l.n as f64 * dx * dz,
        )
    });
    (mx, mz, slope_of(n, sxx, sxz))
}

/// How far along x (metres) the modes of one part are pooled to see its cross-section.
const CROSS_SECTION_REACH_M: f64 = 0.02;

/// Fewest pooled points for a cross-section fit.
const MIN_CROSS_SECTION_POINTS: usize = 30;

/// The lowest height (at the mode's mean x) of the surface under mode `i` across the path, when
/// the points show that part of the surface lies clearly below the mode's mean; `None` when no
/// part of it does (a surface flat across the path, or too few points to tell). `rays` are the
/// modes' points whose rays from the scan line may run mostly across the path ([`ScanLine::ray`]).
///
/// Why: the mode holds the points within a window `2 w` of its lowest height, and its height is
/// their mean. On a surface flat across the path that mean is the surface. On a round part along
/// the path (an exhaust pipe) it is the mean over the arc the lidar sees, and a sensor beside and
/// below the part sees mostly the side facing it: on the simulated SUV's exhaust (3 cm radius,
/// 42 cm beside the path) the densest returns lie 1.5-2.5 cm beside the pipe's lowest line, and
/// the modes' means read 5-9 mm above it. The side view wants the lowest line.
///
/// Model: range noise moves a return along its ray only. So, in the cross-section across the
/// path, a return's *ray angle* seen from the scan path ([`ScanLine`]) carries no range noise,
/// and the mean height of the returns at one ray angle is the height where that ray meets the
/// surface. Its lateral position, on the other hand, carries most of the noise when the rays
/// are nearly level (a part seen from its side), and a curve fitted across the lateral
/// position flattens: the returns of the side facing the sensor smear over the lowest line.
/// The surface's lowest line is the lowest of the heights along the rays.
///
/// One bin holds too few points, so the modes of the same part within
/// [`CROSS_SECTION_REACH_M`] along x are pooled (those whose mean lies within mode `i`'s lateral
/// extent and within `w` of its height), each point taken as its offset from the pool's own
/// least-squares line along x (which removes the part's slope along x). Only the points whose
/// ray may run mostly across the path take part (`rays`). They are ordered by ray
/// angle and split into consecutive groups, as many as each group has points (the square root
/// of their number: resolution across the section against each group's standard error).
/// Groups near the points' lateral limits are left out (see `clear` below). The lowest group's
/// mean, pooled with the groups that do not differ from it by three standard errors (a flat
/// stretch is one level, not the lowest of its noisy pieces), is the lowest line when it lies
/// more than three of its standard errors below the pool's line, and below the mode's mean.
fn cross_section_floor(
    modes: &[BinMode],
    rays: &[Vec<Ray>],
    i: usize,
    params: EnvelopeParams,
    extent_y_m: (f64, f64),
) -> Option<f64> {
    let own = &modes[i].line;
    // Modes are sorted by start; a mode's mean x lies within its bin, at most `MAX_BIN_M` on.
    let first = modes.partition_point(|m| m.start_m < own.x_m - CROSS_SECTION_REACH_M - MAX_BIN_M);
    let pool: Vec<usize> = (first..modes.len())
        .take_while(|&k| modes[k].start_m <= own.x_m + CROSS_SECTION_REACH_M)
        .filter(|&k| {
            let m = &modes[k].line;
            (m.x_m - own.x_m).abs() <= CROSS_SECTION_REACH_M
                && (m.z_m - own.z_m).abs() <= params.half_window_m
                && (own.y_range.0..=own.y_range.1).contains(&m.y_m)
        })
        .collect();
    if pool.iter().map(|&k| rays[k].len()).sum::<usize>() < MIN_CROSS_SECTION_POINTS {
        return None;
    }
    // The pool's own line along x: one level for the part over the pool's length, so that a
    // mode whose mean one bin's mix of points lifted takes the part's lowest line, not its own
    // mean minus the pool's depth.
    let (mx, mz, slope) = pooled_line(pool.iter().map(|&k| &modes[k].line));
    let pool_at = |x: f64| mz + slope * (x - mx);
    let mut rows: Vec<Row> = pool
        .iter()
        .flat_map(|&k| &rays[k])
        .map(|ray| Row {
            ray,
            dz: ray.point[2] - pool_at(ray.point[0]),
        })
        .collect();
    rows.sort_by(|a, b| a.ray.across.total_cmp(&b.ray.across));
    let n_groups = (rows.len() as f64).sqrt() as usize;
    let groups: Vec<Group> = (0..n_groups)
        .map(|g| Group::of(&rows[g * rows.len() / n_groups..(g + 1) * rows.len() / n_groups]))
        .collect();
    // One scatter about the groups' means for all groups: a few points' own scatter is too
    // noisy a figure for a test.
    let sigma =
        (groups.iter().map(|g| g.dz_ss).sum::<f64>() / (rows.len() - n_groups) as f64).sqrt();
    let se = |n: usize| sigma / (n as f64).sqrt();
    // How far range noise spreads a group's points across the path: the groups' typical spread
    // in range (most groups are not cut), times the share of the ray across the path.
    let mut spreads: Vec<f64> = groups.iter().map(|g| g.range_sd).collect();
    let range_sd = super::geom::median(&mut spreads)?;
    // A group within three of those sigmas of the points' lateral limits (a strip's or the
    // band's edge) lost the returns that noise carried beyond the limit, and its mean is
    // biased: such groups are left out.
    let clear = |g: &Group| {
        let reach = 3.0 * range_sd * g.sin_across.abs();
        g.y_mean - reach >= extent_y_m.0 && g.y_mean + reach <= extent_y_m.1
    };
    let usable: Vec<&Group> = groups.iter().filter(|g| clear(g)).collect();
    let lowest = usable
        .iter()
        .min_by(|a, b| a.dz_mean.total_cmp(&b.dz_mean))?;
    let (n, sum) = usable
        .iter()
        .filter(|g| g.dz_mean - lowest.dz_mean <= 3.0 * se(g.n).hypot(se(lowest.n)))
        .fold((0usize, 0.0), |(n, s), g| {
            (n + g.n, s + g.dz_mean * g.n as f64)
        });
    let level = sum / n as f64;
    let floor = pool_at(own.x_m) + level;
    (n >= params.min_support.max(1) && level < -3.0 * se(n) && floor < own.z_m).then_some(floor)
}

/// A mode point whose ray may run mostly across the path ([`ScanLine::ray`]).
struct Ray {
    /// Ray angle in the cross-section, radians from up toward +y.
    across: f64,
    /// Distance from the scan line in the cross-section.
    range: f64,
    point: V3,
}

/// A pooled point in [`cross_section_floor`].
struct Row<'a> {
    ray: &'a Ray,
    /// Height above the pool's line.
    dz: f64,
}

/// Consecutive rows of [`cross_section_floor`].
struct Group {
    n: usize,
    dz_mean: f64,
    /// Sum of squares of `dz` about its mean.
    dz_ss: f64,
    y_mean: f64,
    /// Standard deviation of the range.
    range_sd: f64,
    /// Sine of the mean ray angle: the share of range noise across the path.
    sin_across: f64,
}

impl Group {
    fn of(rows: &[Row]) -> Group {
        let n = rows.len();
        let mean = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).sum::<f64>() / n as f64;
        let (dz_mean, range_mean) = (mean(&|r| r.dz), mean(&|r| r.ray.range));
        Group {
            n,
            dz_mean,
            dz_ss: rows.iter().map(|r| (r.dz - dz_mean).powi(2)).sum(),
            y_mean: mean(&|r| r.ray.point[1]),
            range_sd: (mean(&|r| (r.ray.range - range_mean).powi(2))).sqrt(),
            sin_across: mean(&|r| r.ray.across).sin(),
        }
    }
}

/// Where the scanner was, as the cross-section across the path sees it: its lateral position
/// and height along x (the scan path in the vehicle frame), and how steeply it can look.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ScanLine<'a> {
    /// Positions sorted by x, at least one.
    path: &'a [V3],
    /// Tangents of the lowest and highest beam elevations above the path's horizontal.
    tan_elevation: (f64, f64),
}

impl<'a> ScanLine<'a> {
    /// The line through `path`, sorted by x, for a scanner whose beams span
    /// `elevation_rad` (lowest, highest) above the horizontal; `None` if the path is empty or
    /// not sorted, or the span is not within the open quarter turns about the horizontal.
    pub(crate) fn new(path: &'a [V3], elevation_rad: (f64, f64)) -> Option<Self> {
        let quarter = std::f64::consts::FRAC_PI_2;
        let valid = !path.is_empty()
            && path.windows(2).all(|w| w[0][0] <= w[1][0])
            && -quarter < elevation_rad.0
            && elevation_rad.0 < elevation_rad.1
            && elevation_rad.1 < quarter;
        valid.then_some(Self {
            path,
            tan_elevation: (elevation_rad.0.tan(), elevation_rad.1.tan()),
        })
    }

    /// Each mode's points' [`Self::ray`]s.
    fn rays(&self, modes: &[BinMode]) -> Vec<Vec<Ray>> {
        modes
            .iter()
            .map(|m| m.points.iter().filter_map(|p| self.ray(p)).collect())
            .collect()
    }

    /// `p`'s ray in the cross-section through it, when the scanner's ray to it may lie mostly
    /// across the path. A beam that reaches at most `e` above (below) the horizontal sees a
    /// point `dz` above (below) it and `dy` beside the path from at least
    /// `sqrt((dz / tan e)^2 - dy^2)` along the path; when that exceeds the ray's run across the
    /// path, `hypot(dy, dz)`, most of the point's range noise lies along the path, where the
    /// bins and the parts' ends select the points, and the cross-section does not describe it
    /// (a bumper straight above the path is seen from a metre or more ahead or behind it).
    /// `None` for such a point.
    fn ray(&self, p: &V3) -> Option<Ray> {
        let (y, z) = self.at(p[0]);
        let (dy, dh) = (p[1] - y, p[2] - z);
        let along_sq = if dh == 0.0 {
            0.0
        } else {
            let tan_e = if dh > 0.0 {
                self.tan_elevation.1
            } else {
                self.tan_elevation.0
            };
            // No beam reaches that far up (down).
            if tan_e * dh <= 0.0 {
                return None;
            }
            (dh / tan_e).powi(2) - dy * dy
        };
        let across_sq = dy * dy + dh * dh;
        (along_sq <= across_sq).then(|| Ray {
            across: dy.atan2(dh),
            range: across_sq.sqrt(),
            point: *p,
        })
    }

    /// Lateral position and height at `x`: interpolated between the path's positions, the
    /// nearest end's beyond them (the scanner sees an overhang's end from the path's end).
    fn at(&self, x: f64) -> (f64, f64) {
        let k = self.path.partition_point(|p| p[0] < x);
        let (a, b) = match k {
            0 => (self.path[0], self.path[0]),
            k if k == self.path.len() => (self.path[k - 1], self.path[k - 1]),
            k => (self.path[k - 1], self.path[k]),
        };
        let t = if b[0] > a[0] {
            (x - a[0]) / (b[0] - a[0])
        } else {
            0.0
        };
        (a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: EnvelopeParams<'static> = EnvelopeParams {
        bin_m: 0.01,
        half_window_m: 0.002,
        min_support: 5,
        noise_m: 0.0,
        scan_line: None,
    };

    /// A part along the path in the rear overhang, seen as the sedan's silencer is: a sparse
    /// lower surface at 0.21 m (x -1.0 .. -0.6, 4 cm wide: the cylinder's bottom) ending in a
    /// dense disc-shaped end cap at x -1.0 (radius 6 cm, centre 0.27 m up), the cap's points
    /// smeared 3 mm along x, the surface's 2 mm in z; behind it a floor at 0.30 m to x -1.3.
    /// Returns the points and which are the cap's.
    fn part_with_end_cap(x_shift_m: f64) -> (Vec<V3>, Vec<bool>) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut gauss = move |sigma: f64| {
            let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
            sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let (mut points, mut is_cap) = (Vec::new(), Vec::new());
        for i in 0..=80 {
            for j in 0..=8 {
                let (x, y) = (-1.0 + f64::from(i) * 0.005, 0.43 + f64::from(j) * 0.005);
                points.push(V3::new(x + x_shift_m, y, 0.21 + gauss(0.002)));
                is_cap.push(false);
            }
        }
        // The body goes on behind the part, higher (the rear floor), so the cap is an interior
        // end, not the band's.
        for i in 1..=30 {
            for j in 0..=30 {
                let (x, y) = (-1.0 - f64::from(i) * 0.01, 0.30 + f64::from(j) * 0.01);
                points.push(V3::new(x + x_shift_m, y, 0.30 + gauss(0.002)));
                is_cap.push(false);
            }
        }
        for j in -24..=24 {
            for k in -24..=24 {
                let (dy, dz) = (f64::from(j) * 0.0025, f64::from(k) * 0.0025);
                if dy.hypot(dz) <= 0.06 {
                    points.push(V3::new(
                        -1.0 + x_shift_m + gauss(0.003),
                        0.45 + dy,
                        0.27 + dz,
                    ));
                    is_cap.push(true);
                }
            }
        }
        (points, is_cap)
    }

    #[test]
    fn an_end_cap_is_across_the_path_and_the_surface_before_it_is_not() {
        let (points, is_cap) = part_with_end_cap(0.0);
        let marked = across_path(&points, (-0.5, 2.5));
        let share = |cap: bool, far: bool| {
            let of: Vec<bool> = points
                .iter()
                .zip(&is_cap)
                .zip(&marked)
                // Within reach of the lowest point (8 cm), and "far": outside the 3 cm cube at the
                // corner, where the faces mix.
                .filter(|((p, c), _)| {
                    **c == cap && p[2] < 0.28 && (!far || p[0] > -0.96 || p[2] > 0.24)
                })
                .map(|(_, m)| *m)
                .collect();
            of.iter().filter(|m| **m).count() as f64 / of.len() as f64
        };
        assert!(share(true, true) > 0.95, "cap {}", share(true, true));
        assert!(share(false, true) < 1e-12, "surface {}", share(false, true));
        // The corner mixes the faces: some of the cap's lowest points stay.
        assert!(
            share(true, false) > 0.8,
            "cap with corner {}",
            share(true, false)
        );
        // Between the axles nothing is marked (the test applies to the overhangs only).
        let (inside, _) = part_with_end_cap(1.5);
        assert!(!across_path(&inside, (-0.5, 2.5)).iter().any(|m| *m));
    }

    #[test]
    fn absurd_coordinates_do_not_panic() {
        // Keys saturate at the ends of i32 (1e12 m / 1 cm); their neighbours must not overflow.
        let mut points = Vec::new();
        for k in 0..30 {
            let d = f64::from(k) * 1e-3;
            points.push(V3::new(1e12 + d, 1e12, 1e12 - d));
            points.push(V3::new(-1e12, -1e12 - d, -1e12 + d));
            points.push(V3::new(f64::MAX, f64::MIN, d));
        }
        let marked = across_path(&points, (-0.5, 0.5));
        assert_eq!(marked.len(), points.len());
    }

    #[test]
    fn an_end_cap_left_out_no_longer_lifts_the_parts_last_bins() {
        let (points, _) = part_with_end_cap(0.0);
        // The calculator's window: 2.5 noise sigma, the sigma (4 mm) from the tyres' fits.
        let params = EnvelopeParams {
            bin_m: 0.005,
            half_window_m: 0.01,
            min_support: 5,
            noise_m: 0.004,
            scan_line: None,
        };
        // The rearmost sample below 0.25 m (the departure witness's candidate): x and height.
        let rearmost = |pts: &[V3]| {
            lower_envelope(pts, params)
                .samples
                .iter()
                .filter(|s| s.z_m < 0.25)
                .map(|s| (s.x_m, s.z_m))
                .fold((f64::MAX, f64::NAN), |a, b| if b.0 < a.0 { b } else { a })
        };
        let (_, lifted) = rearmost(&points);
        assert!(lifted > 0.22, "the cap lifts the last bins: {lifted}");
        let marked = across_path(&points, (-0.5, 2.5));
        let kept: Vec<V3> = points
            .iter()
            .zip(&marked)
            .filter(|(_, m)| !**m)
            .map(|(p, _)| *p)
            .collect();
        let (end, height) = rearmost(&kept);
        assert!(
            (height - 0.21).abs() < 0.003,
            "the part's end at {height} m"
        );
        assert!((end + 1.0).abs() < 0.006, "the part ends at {end}");
    }

    #[test]
    fn single_low_outlier_is_ignored() {
        let mut pts: Vec<V3> = (0..40)
            .map(|i| V3::new(0.005, f64::from(i) * 0.01, 0.30))
            .collect();
        pts.push(V3::new(0.005, 0.1, 0.10));
        let env = lower_envelope(&pts, P);
        assert_eq!(env.outliers_below, 1);
        assert!(
            env.samples
                .iter()
                .all(|s| (s.z_m - 0.30).abs() < 1e-12 && s.support == 40)
        );
    }

    #[test]
    fn narrow_low_feature_with_support_wins() {
        let mut pts: Vec<V3> = (0..40)
            .map(|i| V3::new(0.005, f64::from(i) * 0.01, 0.30))
            .collect();
        pts.extend((0..6).map(|i| V3::new(0.005, 0.5 + f64::from(i) * 0.005, 0.20)));
        let env = lower_envelope(&pts, P);
        assert!(
            env.samples
                .iter()
                .all(|s| (s.z_m - 0.20).abs() < 1e-12 && s.support == 6)
        );
    }

    #[test]
    fn sloped_surface_samples_lie_on_it() {
        let pts: Vec<V3> = (0..200)
            .map(|i| {
                let x = f64::from(i % 20) * 0.0005;
                V3::new(x, f64::from(i / 20) * 0.01, 0.25 + 0.3 * x)
            })
            .collect();
        let env = lower_envelope(
            &pts,
            EnvelopeParams {
                half_window_m: 0.01,
                ..P
            },
        );
        assert_eq!(env.samples.len(), 2);
        for s in env.samples {
            assert!((s.z_m - (0.25 + 0.3 * s.x_m)).abs() < 1e-12, "{s:?}");
        }
    }

    /// A small part seen by few returns (4 per 1 cm bin, fewer than `min_support`) is found at
    /// twice the bin width; as thin a scatter over the widest bin is not.
    #[test]
    fn a_sparse_part_is_found_at_a_coarser_bin() {
        let part: Vec<V3> = (0..24)
            .map(|i| V3::new(1.0 + f64::from(i) * 0.0025, 0.0, 0.45))
            .collect();
        let env = lower_envelope(&part, P);
        assert_eq!(env.unsupported_bins, 0);
        assert!(!env.samples.is_empty());
        assert!(
            env.samples
                .iter()
                .all(|s| (s.z_m - 0.45).abs() < 1e-12 && s.support == 8),
            "{:?}",
            env.samples
        );
        let (lo, hi) = env.samples.iter().fold((f64::MAX, f64::MIN), |(a, b), s| {
            (a.min(s.x_m), b.max(s.x_m))
        });
        assert!(lo < 1.003 && hi > 1.055, "the part spans {lo}..{hi}");
        // Four points over 4 cm never make a mode.
        let thin: Vec<V3> = (0..4)
            .map(|i| V3::new(2.0 + f64::from(i) * 0.01, 0.0, 0.45))
            .collect();
        let env = lower_envelope(&thin, P);
        assert!(env.samples.is_empty());
        assert!(env.unsupported_bins > 0);
    }

    #[test]
    fn sparse_bins_are_reported_not_used() {
        let pts = [V3::new(0.0, 0.0, 0.3), V3::new(0.0, 0.1, 0.5)];
        let env = lower_envelope(&pts, P);
        assert!(env.samples.is_empty());
        assert_eq!(env.unsupported_bins, 1);
    }

    /// A narrow part (a pipe 10 cm wide) 2 w below a surface across the whole band: the surface
    /// outnumbers the part's points in the bin, but not at the part's lateral positions, so the
    /// part is the bin's lowest mode, not a noise tail of the surface (the old rule counted the
    /// surface's points across the whole band and climbed to it).
    #[test]
    fn a_sill_a_window_below_a_wide_floor_keeps_its_height_in_its_strip() {
        // Between the axles: the floor pan 0.19 m up across 1.2 m, the sills 1 cm lower outboard
        // of it (the fleet's city car). One mode over the whole width mixes the two within the
        // window; per lateral strip the sill's own mode is its height.
        use rand::{Rng, SeedableRng};
        let noise = 0.003;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut gauss = move || {
            let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
            noise * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let mut pts = Vec::new();
        for i in 0..20 {
            let x = f64::from(i) * 0.005;
            for j in 0..240 {
                pts.push(V3::new(x, -0.6 + f64::from(j) * 0.005, 0.19 + gauss()));
            }
            for j in 0..40 {
                pts.push(V3::new(x, 0.62 + f64::from(j) * 0.005, 0.18 + gauss()));
            }
        }
        let params = EnvelopeParams {
            half_window_m: 2.5 * noise,
            noise_m: noise,
            ..P
        };
        let lowest = |env: &Envelope| env.samples.iter().map(|s| s.z_m).fold(f64::MAX, f64::min);
        let strips = lower_envelope_strips(&pts, params, BETWEEN_AXLES_STRIP_M);
        assert!(
            (lowest(&strips) - 0.18).abs() < 0.002,
            "{:?}",
            lowest(&strips)
        );
        let whole = lower_envelope(&pts, params);
        assert!(lowest(&whole) > 0.183, "{:?}", lowest(&whole));
    }

    /// The envelope's parameters for a cloud with 3 mm noise: 5 mm bins, the window 2.5 sigma.
    const NOISE_3MM: EnvelopeParams<'static> = EnvelopeParams {
        bin_m: 0.005,
        half_window_m: 2.5 * 0.003,
        min_support: 5,
        noise_m: 0.003,
        scan_line: None,
    };

    /// Seeded normal deviates.
    fn gaussian(seed: u64) -> impl FnMut(f64) -> f64 {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        move |sigma: f64| {
            let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
            sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// A pipe along the path (radius 3 cm, lowest line 0.21 m up, `beside_m` beside the path)
    /// over `x` -0.3..0, scanned from a sensor on the path 0.10 m up as it drives by: each
    /// return comes from 0.2-1.5 m further along the path (the sensor looks ahead and behind),
    /// on a ray evenly spaced in angle across the pipe's silhouette, moved along its ray by
    /// range noise `range_m` (most of it along x, the rest across the pipe). The sensor sees the
    /// arc of the pipe facing it: both sides of the lowest line when the pipe is near the path,
    /// one side, from the lowest line up, when it is far beside it.
    fn pipe_seen_by_a_passing_sensor(beside_m: f64, range_m: f64, seed: u64) -> Vec<V3> {
        let (cy, cz, r): (f64, f64, f64) = (-beside_m, 0.24, 0.03);
        let sensor = (0.0, 0.10);
        let mut gauss = gaussian(seed);
        let mut spread = gaussian(seed + 1);
        let (dy, dz) = (cy - sensor.0, cz - sensor.1);
        let (to_centre, dist) = (dz.atan2(dy), dy.hypot(dz));
        let half = (r / dist).asin();
        let mut pts = Vec::new();
        for i in 0..300 {
            let x = -0.3 + f64::from(i) * 0.001;
            for k in 0..25 {
                let a = to_centre - half + 2.0 * half * (f64::from(k) + 0.5) / 25.0;
                let (uy, uz) = (a.cos(), a.sin());
                // Nearest intersection of the ray's projection with the circle.
                let b = uy * dy + uz * dz;
                let disc = b * b - (dist * dist - r * r);
                if disc < 0.0 {
                    continue;
                }
                let t = b - disc.sqrt();
                // The ray's run along x, 0.2-1.5 m (the tanh of a normal deviate), sets its
                // share across the path.
                let along = 0.85 + 0.65 * spread(1.0).tanh();
                let across = t / t.hypot(along);
                let noise = gauss(range_m);
                pts.push(V3::new(
                    x + noise * along / t.hypot(along),
                    sensor.0 + (t + noise * across) * uy,
                    sensor.1 + (t + noise * across) * uz,
                ));
            }
        }
        pts
    }

    /// The scan line of [`pipe_seen_by_a_passing_sensor`]'s sensor.
    const PIPE_SENSOR_PATH: [V3; 2] = [V3::new(-2.0, 0.0, 0.10), V3::new(2.0, 0.0, 0.10)];

    /// A scan line along `path` for a VLP-16 (beams +-15 degrees).
    fn vlp16_line(path: &[V3]) -> Option<ScanLine<'_>> {
        let e = 15f64.to_radians();
        ScanLine::new(path, (-e, e))
    }

    /// [`NOISE_3MM`] seen by a VLP-16 along `path`.
    fn seen_along(path: &[V3]) -> EnvelopeParams<'_> {
        EnvelopeParams {
            scan_line: vlp16_line(path),
            ..NOISE_3MM
        }
    }

    /// A sensor path 0.10 m up, `y_m` beside the vehicle's centreline.
    fn path_beside(y_m: f64) -> [V3; 2] {
        [V3::new(-2.0, y_m, 0.10), V3::new(2.0, y_m, 0.10)]
    }

    /// The pipe's envelope with the scanner's path known (or not): the mean height of its
    /// samples, and of its modes' own means.
    fn pipe_heights(pts: &[V3], path_known: bool) -> (f64, f64) {
        let params = EnvelopeParams {
            scan_line: vlp16_line(&PIPE_SENSOR_PATH).filter(|_| path_known),
            ..NOISE_3MM
        };
        let env = lower_envelope(pts, params);
        let floor = env.samples.iter().map(|s| s.z_m).sum::<f64>() / env.samples.len() as f64;
        let mut modes = Vec::new();
        bin_modes(pts, params, &mut modes, &mut Envelope::default());
        let mode_mean = modes.iter().map(|m| m.line.z_m).sum::<f64>() / modes.len() as f64;
        (floor, mode_mean)
    }

    #[test]
    fn a_pipe_seen_from_below_along_the_path_keeps_the_mean_of_its_modes() {
        // 15 cm beside the path and 11-14 cm above the sensor: a VLP-16 sees it from 0.4 m or
        // more along the path, most of the range noise lies along the path, and the
        // cross-section does not describe it (the known limit): the modes' mean stays, above
        // the lowest line.
        let pts = pipe_seen_by_a_passing_sensor(0.15, 0.01, 3);
        let (floor, mode_mean) = pipe_heights(&pts, true);
        assert!(mode_mean > 0.2125, "modes' mean {mode_mean}");
        assert!((floor - mode_mean).abs() < 5e-4, "{floor} {mode_mean}");
    }

    #[test]
    fn a_pipe_seen_from_its_side_has_its_lowest_line_along_the_rays() {
        // 42 cm beside the path: the points rise from the lowest line up one side only, and the
        // range noise runs nearly across the path.
        let pts = pipe_seen_by_a_passing_sensor(0.42, 0.01, 3);
        let (along_rays, mode_mean) = pipe_heights(&pts, true);
        assert!(mode_mean > 0.214, "modes' mean {mode_mean}");
        assert!(
            (along_rays - 0.21).abs() < 0.25 * (mode_mean - 0.21),
            "along the rays {along_rays}, modes' mean {mode_mean}"
        );
        // Without the path the rays are not known, and the modes' mean stays.
        let (unknown, _) = pipe_heights(&pts, false);
        assert!((unknown - mode_mean).abs() < 5e-4, "{unknown} {mode_mean}");
    }

    #[test]
    fn a_round_parts_bins_share_its_lowest_line() {
        // Along the pipe seen from its side, each bin's mode mean scatters with its own mix of
        // returns; the lowest line is the pool's, so the samples scatter less than the modes.
        let pts = pipe_seen_by_a_passing_sensor(0.42, 0.01, 5);
        let params = seen_along(&PIPE_SENSOR_PATH);
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|z| (z - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        // Away from the pipe's ends, where the pool is whole.
        let inner = |x: f64| (-0.27..-0.03).contains(&x);
        let mut modes = Vec::new();
        bin_modes(&pts, params, &mut modes, &mut Envelope::default());
        let mode_means: Vec<f64> = modes
            .iter()
            .filter(|m| inner(m.line.x_m))
            .map(|m| m.line.z_m)
            .collect();
        let samples: Vec<f64> = lower_envelope(&pts, params)
            .samples
            .iter()
            .filter(|s| inner(s.x_m))
            .map(|s| s.z_m)
            .collect();
        assert!(
            sd(&samples) < 0.7 * sd(&mode_means),
            "samples' sd {}, modes' sd {}",
            sd(&samples),
            sd(&mode_means)
        );
    }

    /// The modes of `pts`, sorted by x as [`lower_envelope`] sorts them.
    fn sorted_modes(pts: &[V3], params: EnvelopeParams) -> Vec<BinMode> {
        let mut modes = Vec::new();
        bin_modes(pts, params, &mut modes, &mut Envelope::default());
        modes.sort_by(|a, b| a.start_m.total_cmp(&b.start_m));
        modes
    }

    /// [`cross_section_floor`] of mode `i`, the rays taken from `params`' scan line.
    fn floor_of(
        modes: &[BinMode],
        i: usize,
        params: EnvelopeParams,
        extent_y_m: (f64, f64),
    ) -> Option<f64> {
        let rays = params.scan_line.unwrap().rays(modes);
        cross_section_floor(modes, &rays, i, params, extent_y_m)
    }

    /// `height(y)` over x 0..0.1 m and `y` in `ys`, points 1 mm x 5 mm apart, each moved along
    /// its ray from a sensor 0.10 m up at `sensor_y` by range noise `sigma_m`.
    fn scanned_beside(
        height: impl Fn(f64) -> f64,
        ys: std::ops::Range<i32>,
        sensor_y: f64,
        sigma_m: f64,
        seed: u64,
    ) -> Vec<V3> {
        let mut gauss = gaussian(seed);
        (0..100)
            .flat_map(|i| ys.clone().map(move |j| (i, j)))
            .map(|(i, j)| {
                let y = f64::from(j) * 0.005;
                let (dy, dz) = (y - sensor_y, height(y) - 0.10);
                let t = 1.0 + gauss(sigma_m) / dy.hypot(dz);
                V3::new(f64::from(i) * 0.001, sensor_y + t * dy, 0.10 + t * dz)
            })
            .collect()
    }

    #[test]
    fn a_flat_surface_keeps_the_mean_of_its_modes() {
        let path = path_beside(0.5);
        let params = seen_along(&path);
        for seed in 0..4 {
            let pts = scanned_beside(|_| 0.25, -60..0, 0.5, 0.01, seed);
            let modes = sorted_modes(&pts, params);
            for i in 0..modes.len() {
                assert_eq!(
                    floor_of(&modes, i, params, y_range(&pts)),
                    None,
                    "seed {seed} bin {i}"
                );
            }
        }
    }

    #[test]
    fn a_surface_tilted_across_the_path_reads_its_lower_edge() {
        // 30 cm wide, rising 6 mm from its lower edge (0.25 m, 0.8 m beside the path) to its
        // upper one: the side view's lowest line is the lower edge; the modes' means lie 3 mm
        // up. The band reaches 30 cm beyond the lower edge (`extent`).
        let path = path_beside(0.5);
        let params = seen_along(&path);
        let mut pts = scanned_beside(|y| 0.25 + 0.02 * (y + 0.3), -60..0, 0.5, 0.01, 8);
        let extent = (-0.6, 0.0);
        let mut modes = Vec::new();
        bin_modes(&pts, params, &mut modes, &mut Envelope::default());
        let mode_mean = modes.iter().map(|m| m.line.z_m).sum::<f64>() / modes.len() as f64;
        assert!((mode_mean - 0.253).abs() < 5e-4, "modes' mean {mode_mean}");
        modes.sort_by(|a, b| a.start_m.total_cmp(&b.start_m));
        // The groups within three standard errors of the lowest are pooled with it: on a tilt
        // they reach a little way up it.
        for i in 0..modes.len() {
            let floor = floor_of(&modes, i, params, extent);
            assert!(floor.is_some_and(|z| z > 0.2495 && z < 0.252), "{floor:?}");
        }
        // With the band's edge at the lower edge, the lowest groups lost the returns that noise
        // carried out of the band and are left out: the floor reads higher.
        pts.retain(|p| p[1] >= -0.3);
        let modes = sorted_modes(&pts, params);
        for i in 0..modes.len() {
            let floor = floor_of(&modes, i, params, y_range(&pts));
            assert!(floor.is_none_or(|z| z > 0.2505), "{floor:?}");
        }
    }

    #[test]
    fn a_flat_bottom_with_rounded_corners_keeps_its_flat_height() {
        // A bumper's lower face 1.2 m wide, flat at 0.30 m over its middle 0.8 m, its corners
        // curving up by 6 mm over their last 0.2 m (within the mode's window), seen from 0.9 m
        // beside it: the modes' means lie 0.5 mm up, the flat middle is the lowest line.
        let path = path_beside(1.5);
        let params = seen_along(&path);
        let height = |y: f64| 0.30 + 0.006 * ((y.abs() - 0.4).max(0.0) / 0.2).powi(2);
        let pts = scanned_beside(height, -120..121, 1.5, 0.01, 9);
        let env = lower_envelope(&pts, params);
        for s in &env.samples {
            assert!(s.z_m > 0.2995 && s.z_m < 0.3005, "{s:?}");
        }
    }

    #[test]
    fn narrow_part_under_wide_surface_is_not_a_tail() {
        let w = 0.004;
        let mut pts: Vec<V3> = (0..20)
            .map(|i| {
                let jitter = if i % 2 == 0 { 0.001 } else { -0.001 };
                V3::new(0.005, 0.40 + f64::from(i) * 0.005, 0.20 + jitter)
            })
            .collect();
        pts.extend((0..240).map(|i| V3::new(0.005, -0.6 + f64::from(i) * 0.005, 0.20 + 2.0 * w)));
        let env = lower_envelope(
            &pts,
            EnvelopeParams {
                half_window_m: w,
                ..P
            },
        );
        assert!(!env.samples.is_empty());
        for s in &env.samples {
            assert!((s.z_m - 0.20).abs() < 0.0015, "{s:?}");
        }
    }
}
