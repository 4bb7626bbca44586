//! How far a limiting part may go on beyond its witness, from what the scanner saw from its path.
//!
//! An approach or departure witness is the envelope's outermost sample of a part's lower surface,
//! and the part may go on beyond it: among returns the envelope's end estimate took for the range
//! noise's smear, or unseen, where the lidar's flat rings only graze it or another part hides it.
//! The calculator does not guess: it walks outward from the witness at the witness's height and
//! stops at the first place the scanner looked at and found empty ([`end_reach`]). The part's end
//! lies between the witness and that place; the angle stays the witness's, and the stretch goes
//! into its uncertainty (`uncertainty::Uncertainty::with_end_reach`).
//!
//! "Looked at and found empty":
//! - no return lies there at or below the witness's height (within the noise), within the
//!   spacing of the returns along x;
//! - the place is within the scanner's vertical field of view and beyond its minimum range from
//!   some position of the scan's path;
//! - no seen surface blocks the ray: the cloud's body points, as a height map of each column's
//!   lowest point (the underside hangs from above; a ray rising beneath it is blocked where it
//!   climbs above a column's lowest point, by more than the noise). The march stops a column
//!   short of the place, whose own returns the first test judges.
//!
//! Approximation: the height map cannot tell a ray passing through a gap between two parts of
//! one column from a ray blocked by the upper one, so it calls such rays blocked (the reach comes
//! out longer, the uncertainty larger: the safe side). Ring spacing is not modelled: along the
//! path every elevation in the field of view is swept, so a place in view is taken as seen.

use crate::V3;

/// What the scanner can see from each position of the scan's path
/// ([`crate::AnglesConfig::scanner_view`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScannerView {
    /// Lowest elevation of its beams above the path's horizontal (radians; the VLP-16: -15 deg).
    pub elevation_min_rad: f64,
    /// Highest elevation (radians; the VLP-16: +15 deg).
    pub elevation_max_rad: f64,
    /// Nearest range it reports (metres).
    pub min_range_m: f64,
}

impl ScannerView {
    /// The Velodyne VLP-16: beams from -15 to +15 degrees (its manual's Table 9-1, `vlp16`'s
    /// `ELEVATION_DEG`), no returns nearer than about 0.5 m.
    pub const VLP16: Self = Self {
        elevation_min_rad: -15.0 * std::f64::consts::PI / 180.0,
        elevation_max_rad: 15.0 * std::f64::consts::PI / 180.0,
        min_range_m: 0.5,
    };

    pub(crate) fn is_valid(&self) -> bool {
        self.elevation_min_rad.is_finite()
            && self.elevation_max_rad.is_finite()
            && self.elevation_min_rad < self.elevation_max_rad
            && self.min_range_m.is_finite()
            && self.min_range_m >= 0.0
    }
}

/// Side of a height-map column (metres).
const CELL_M: f64 = 0.01;

/// Step of a ray's march (metres).
const STEP_M: f64 = 0.01;

/// Step of the walk outward from a witness (metres).
const WALK_M: f64 = 0.002;

/// How far along x (metres) from a place a return still counts as the surface going on there:
/// about the spacing of the lidar's returns on an underside near the robot, so that the gaps
/// between a surface's returns do not read as space seen empty.
const ALONG_M: f64 = 0.01;

/// How far beside the witness's y (metres) a return still counts as its part going on: the
/// witness's y is the mean of its supporting points.
const LATERAL_M: f64 = 0.02;

/// Path positions farther than this (metres, horizontally) from a place are not tried: at that
/// range the VLP-16's rings are 0.35 m apart and a part's end falls between them.
const MAX_SIGHT_M: f64 = 10.0;

/// Longest walk beyond a witness (metres). A part that goes on further than this without a place
/// seen empty at its height has no end in the scan: over a metre the angle can change by tens
/// of degrees, and the calculator reports it as not measured rather than as a number with such
/// an uncertainty.
pub(crate) const MAX_REACH_M: f64 = 1.0;

/// Path positions nearer than this (metres) to the last one kept are not tried again: a path
/// that lingers (a stopped robot) costs no more than one that moves.
const PATH_STEP_M: f64 = 0.02;

/// Longest side of the height map's box (metres): 3,000 x 3,000 columns at most.
const MAX_EXTENT_M: f64 = 30.0;

/// The lowest body point of each column of the vehicle frame's x-y grid.
struct HeightMap {
    x0: f64,
    y0: f64,
    nx: usize,
    ny: usize,
    lowest: Vec<f32>,
}

impl HeightMap {
    /// Columns over `x_range` x `y_range` (vehicle frame, metres; each at most
    /// [`MAX_EXTENT_M`] long, the rest is left out); points at or below `floor_m` (ground) and
    /// outside the box are left out.
    fn new(points: &[V3], floor_m: f64, x_range: [f64; 2], y_range: [f64; 2]) -> Self {
        let cells = |[lo, hi]: [f64; 2]| {
            let n = ((hi - lo).min(MAX_EXTENT_M) / CELL_M).floor() + 1.0;
            if n.is_finite() && n >= 1.0 {
                n as usize
            } else {
                0
            }
        };
        let (nx, ny) = (cells(x_range), cells(y_range));
        let mut map = Self {
            x0: x_range[0],
            y0: y_range[0],
            nx,
            ny,
            lowest: vec![f32::INFINITY; nx * ny],
        };
        for p in points.iter().filter(|p| p[2] > floor_m) {
            if let Some(i) = map.index(p[0], p[1]) {
                map.lowest[i] = map.lowest[i].min(p[2] as f32);
            }
        }
        map
    }

    fn index(&self, x: f64, y: f64) -> Option<usize> {
        let i = ((x - self.x0) / CELL_M).floor();
        let j = ((y - self.y0) / CELL_M).floor();
        if i < 0.0 || j < 0.0 || i >= self.nx as f64 || j >= self.ny as f64 {
            return None;
        }
        Some(i as usize * self.ny + j as usize)
    }

    /// The lowest body point of the column holding `(x, y)`; infinity where there is none.
    fn lowest(&self, x: f64, y: f64) -> f64 {
        self.index(x, y)
            .map_or(f64::INFINITY, |i| f64::from(self.lowest[i]))
    }
}

/// The path's finite positions at least [`PATH_STEP_M`] apart, in order. (A non-finite
/// position would pass every test of a ray from it and make every place seen.)
fn thin_path(path: &[V3]) -> Vec<V3> {
    let mut kept: Vec<V3> = Vec::with_capacity(path.len());
    for &p in path.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
        if kept.last().is_none_or(|q| (p - q).norm() >= PATH_STEP_M) {
            kept.push(p);
        }
    }
    kept
}

/// What the scanner saw and from where, vehicle frame: the rays' blockers, the returns, the
/// path.
pub(crate) struct Sight {
    /// Blocks the rays.
    map: HeightMap,
    /// The body's points (above the floor), sorted by x.
    body_by_x: Vec<V3>,
    /// Where the scanner was ([`thin_path`]).
    path: Vec<V3>,
    /// What it sees from there.
    view: ScannerView,
    /// How far a ray may climb above a column's lowest point before it counts as blocked, and how
    /// far above a place a return still counts as the part going on there (metres; noise).
    tolerance_m: f64,
}

impl Sight {
    /// The sight of a scan: `points` every usable point (those at or below `floor_m` are floor),
    /// `path` the scanner's positions; `None` without a path.
    pub(crate) fn new(
        points: &[V3],
        floor_m: f64,
        path: &[V3],
        view: ScannerView,
        tolerance_m: f64,
    ) -> Option<Self> {
        let path = thin_path(path);
        let (lo, hi) = path
            .iter()
            .map(|p| p[0])
            .fold(None, |r: Option<(f64, f64)>, x| {
                Some(r.map_or((x, x), |(a, b)| (a.min(x), b.max(x))))
            })?;
        // The rays of interest run from the path to the vehicle's underside: the map covers the
        // path and the vehicle's width beside it.
        let half_width_m = path.iter().map(|p| p[1].abs()).fold(0.0, f64::max) + 2.0;
        let map = HeightMap::new(
            points,
            floor_m,
            [lo - 1.0, hi + 1.0],
            [-half_width_m, half_width_m],
        );
        let mut body_by_x: Vec<V3> = points.iter().filter(|p| p[2] > floor_m).copied().collect();
        body_by_x.sort_by(|a, b| a[0].total_cmp(&b[0]));
        Some(Self {
            map,
            body_by_x,
            path,
            view,
            tolerance_m,
        })
    }

    /// Whether `c` was in view, unblocked, from some position of the path.
    fn seen(&self, c: V3) -> bool {
        self.path.iter().any(|&o| self.seen_from(o, c))
    }

    /// Whether a return lies within [`ALONG_M`] of `c` along x, [`LATERAL_M`] across, and at or
    /// below its height (within the tolerance): the surface may go on there.
    fn returns_at(&self, c: V3) -> bool {
        let from = self.body_by_x.partition_point(|p| p[0] < c[0] - ALONG_M);
        self.body_by_x[from..]
            .iter()
            .take_while(|p| p[0] <= c[0] + ALONG_M)
            .any(|p| (p[1] - c[1]).abs() <= LATERAL_M && p[2] <= c[2] + self.tolerance_m)
    }

    fn seen_from(&self, o: V3, c: V3) -> bool {
        let d = c - o;
        let horizontal = d[0].hypot(d[1]);
        let range = d.norm();
        if range < self.view.min_range_m || horizontal > MAX_SIGHT_M || range == 0.0 {
            return false;
        }
        let elevation = d[2].atan2(horizontal);
        if elevation < self.view.elevation_min_rad || elevation > self.view.elevation_max_rad {
            return false;
        }
        // March to within a column of the place (its own column is judged by the caller).
        let steps = ((range - CELL_M) / STEP_M).floor().max(0.0) as usize;
        (1..=steps).all(|k| {
            let p = o + d * (k as f64 * STEP_M / range);
            p[2] <= self.map.lowest(p[0], p[1]) + self.tolerance_m
        })
    }
}

/// How far (metres, along x in the direction `outward`, +1 or -1) the part under `witness` may
/// go on beyond it: walking outward at the witness's height in steps of [`WALK_M`] to the first
/// place in the scanner's view with no return at or below that height, the length of the walk
/// less the [`ALONG_M`] of the last returns' neighbourhood, at least 0. `None` when no such
/// place lies within [`MAX_REACH_M`]: the scan does not show where the part ends.
///
/// Two things lengthen it: returns beyond the witness at its height (the envelope's end
/// estimate weighed them as the range noise's smear, but the surface may go on among them), and
/// places out of view (the part may go on unseen).
pub(crate) fn end_reach(sight: &Sight, witness: V3, outward: f64) -> Option<f64> {
    let steps = (MAX_REACH_M / WALK_M).round() as usize;
    (1..=steps).find_map(|k| {
        let walked = k as f64 * WALK_M;
        let c = V3::new(witness[0] + outward * walked, witness[1], witness[2]);
        (!sight.returns_at(c) && sight.seen(c)).then(|| (walked - ALONG_M).max(0.0))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block from x `x0` to `x1` and z `z0` to `z1`, 0.3 m wide, sampled every centimetre.
    fn block(x: [f64; 2], z: [f64; 2]) -> Vec<V3> {
        let n = |[a, b]: [f64; 2]| ((b - a) / 0.01).round() as i32;
        let mut out = Vec::new();
        for i in 0..=n(x) {
            for k in 0..=n(z) {
                for j in -15..=15 {
                    out.push(V3::new(
                        x[0] + f64::from(i) * 0.01,
                        f64::from(j) * 0.01,
                        z[0] + f64::from(k) * 0.01,
                    ));
                }
            }
        }
        out
    }

    fn path(from_x: f64, to_x: f64) -> Vec<V3> {
        let n = ((to_x - from_x) / 0.05).round() as usize;
        (0..=n)
            .map(|k| V3::new(from_x + k as f64 * 0.05, 0.0, 0.25))
            .collect()
    }

    fn reach(points: &[V3], path: &[V3], witness: V3) -> Option<f64> {
        let sight = Sight::new(points, 0.03, path, ScannerView::VLP16, 0.01)?;
        end_reach(&sight, witness, 1.0)
    }

    /// Within a walk step of the end.
    const RESOLUTION_M: f64 = WALK_M + 1e-9;

    #[test]
    fn an_end_seen_from_below_reaches_no_further_than_the_resolution() {
        // A plate's end at 0.7 m is grazed from behind, through the free space below the plate.
        let plate = block([0.0, 1.0], [0.7, 0.71]);
        let r = reach(&plate, &path(-3.0, 2.0), V3::new(1.0, 0.0, 0.7));
        assert!(r.is_some_and(|r| r <= RESOLUTION_M), "{r:?}");
    }

    #[test]
    fn an_end_hidden_from_behind_and_above_the_view_from_ahead_has_no_reach() {
        // A lower part under the plate (down to 0.26 m, just above the scanner) blocks every ray
        // from behind it; from the path's positions beyond it the top beam (15 deg from 0.25 m)
        // climbs to the plate's 0.65 m only 1.49 m further on, more than a metre beyond the
        // plate's end; from ahead, a path ending 0.5 m beyond the plate sees nothing that high
        // there: the scan does not show where the plate ends. A path ending 3 m beyond it does.
        let mut points = block([0.0, 1.0], [0.65, 0.66]);
        points.extend(block([0.0, 1.0], [0.26, 0.66]));
        let witness = V3::new(1.0, 0.0, 0.65);
        let r = reach(&points, &path(-3.0, 1.5), witness);
        assert!(r.is_none(), "{r:?}");
        let r = reach(&points, &path(-3.0, 4.0), witness);
        assert!(r.is_some_and(|r| r <= RESOLUTION_M), "{r:?}");
    }

    #[test]
    fn a_part_ahead_that_blocks_the_view_lengthens_the_reach() {
        // As above, with a tall block from 0.3 to 0.4 m beyond the plate's end: the stretch up to
        // it is hidden from ahead, and beyond it the view from ahead reaches the plate's height.
        let mut points = block([0.0, 1.0], [0.55, 0.56]);
        points.extend(block([0.3, 0.6], [0.3, 0.56]));
        points.extend(block([1.3, 1.4], [0.1, 0.7]));
        let r = reach(&points, &path(-3.0, 4.0), V3::new(1.0, 0.0, 0.55));
        assert!(
            r.is_some_and(|r| (0.3..=0.4 + RESOLUTION_M).contains(&r)),
            "{r:?}"
        );
    }

    #[test]
    fn a_non_finite_path_position_sees_nothing() {
        // As in the test above, hidden from the path; a NaN position among the path's must not
        // make the place seen.
        let mut points = block([0.0, 1.0], [0.65, 0.66]);
        points.extend(block([0.0, 1.0], [0.26, 0.66]));
        let mut with_nan = path(-3.0, 1.5);
        with_nan.insert(10, V3::new(f64::NAN, 0.0, 0.25));
        with_nan.push(V3::new(2.0, f64::INFINITY, 0.25));
        let r = reach(&points, &with_nan, V3::new(1.0, 0.0, 0.65));
        assert!(r.is_none(), "{r:?}");
    }

    #[test]
    fn a_hostile_extent_does_not_size_the_map() {
        let far = [V3::new(-1e12, 0.0, 1.0), V3::new(1e12, 1e12, 1.0)];
        let map = HeightMap::new(&far, 0.03, [-1e12, 1e12], [f64::NEG_INFINITY, f64::NAN]);
        assert!(map.lowest.len() <= 3_001 * 3_001);
        assert!(map.lowest(0.0, 0.0).is_infinite());
    }
}
