//! Step 5, laser odometry: feature registration by Levenberg-Marquardt (paper 3.3, after LOAM and
//! LeGO-LOAM), shared by scan-to-scan odometry and the scan-to-map refinement of step 7.
//!
//! Residuals, for a source point `q = T p` moved by the current estimate `T = target_from_source`:
//! - **point-to-plane** (plane features): the five nearest target plane points within
//!   `max_correspondence_m` are fitted by PCA; if they are flat (smallest eigenvalue well below the
//!   middle one) the residual is `n . (q - c)`.
//! - **point-to-line** (corner features): the five nearest target corners; if they are linear
//!   (largest eigenvalue dominates) the residual is the distance from `q` to the line.
//!
//! Both are weighted by a Huber kernel (`huber_m`) truncated beyond a cutoff that grows with the
//! residual's lever arm (`max_residual_m`, `max_residual_rad`; see `Kernel`). The increment is
//! left-multiplied with its rotation about the prior's position `c`, `T <- about(c, delta) T`, with
//! `delta = [rx, ry, rz, tx, ty, tz]`, so the Jacobian of a residual with unit direction `e` (the
//! plane normal, or the perpendicular to the line) is `[(q - c) x e, e]`: the same numbers wherever
//! the robot is in the target frame (see `about`).
//!
//! **Two steps** (scan-to-scan): step 1 solves z, roll and pitch from the plane features (the
//! underbody and any remaining ground fix them well); step 2 solves x, y and yaw with the
//! others held, from the corners plus the plane features (tyre sidewalls and body panels with
//! horizontal normals constrain x, y and yaw too; LeGO-LOAM uses corners only, which under a car are
//! too few for a well-posed step).
//!
//! **Degeneracy** and the two registrations built from these solves: [`super::registration`].

use super::config::LaserOdometryConfig;
pub use super::registration::{Registration, Scan, register_joint, register_two_step};

use super::geom::{
    Neighbour, Pose, Twist6, V3, VoxelIndex, centroid_covariance, solve_spd, symmetric_eigen_m3,
};
use super::registration::{DegeneracyThresholds, determined_projection};

/// The target of a registration: feature points indexed for nearest-neighbour search.
#[derive(Debug, Clone)]
pub struct FeatureTarget {
    /// Corner points.
    pub corners: VoxelIndex,
    /// Plane points.
    pub planes: VoxelIndex,
}

/// One linearised residual: unit direction `e` and a point `c` on the target feature, so that the
/// residual of a moved point `q` is `e . (q - c)`.
#[derive(Clone, Copy)]
struct Correspondence {
    source: V3,
    direction: V3,
    anchor: V3,
    /// Beyond this the residual has no weight ([`Kernel`]): set by the solve's search
    /// (`refresh`), which knows the solve's centre; unbounded for the diagnostics' residuals.
    cutoff_m: f64,
}

/// True when the neighbours come from at least two scan lines (tags). Neighbours on one ring lie
/// along that ring, so they can define neither a plane nor the edge line across the rings (LOAM
/// takes its neighbours from adjacent rings for the same reason).
fn spans_lines(nn: &[Neighbour]) -> bool {
    nn.iter().any(|n| n.tag != nn[0].tag)
}

/// Tag bit of ground points in a [`FeatureTarget`]'s plane index (the rest of a tag is the scan
/// line). Plane fits never mix ground and non-ground points: under a car the underbody is only
/// 5-20 cm above the ground, within one correspondence radius, and five neighbours taken from both
/// surfaces fit a fake vertical "plane" (the two ring arcs stacked above each other) whose normal
/// points along the ray. That plane moves with the sensor's ring pattern, not with the world, and
/// pulled every scan-to-scan x estimate towards zero motion: the laser-only drift of about 10 %
/// per metre on the simulated sedan came from these residuals.
pub const GROUND_TAG_BIT: u32 = 1 << 31;

/// Up to `K` nearest target points within `radius_m`, nearest first, keeping only those of the
/// nearest one's class (ground or not, [`GROUND_TAG_BIT`]); returns how many of the first five
/// slots are filled.
fn nearest_same_class<const K: usize>(
    index: &VoxelIndex,
    q: V3,
    radius_m: f64,
    out: &mut [Neighbour; 5],
) -> usize {
    let mut nn = [Neighbour::default(); K];
    let found = index.neighbours(q, radius_m, &mut nn);
    if found == 0 {
        return 0;
    }
    let class = nn[0].tag & GROUND_TAG_BIT;
    let mut n = 0;
    for &candidate in &nn[..found] {
        if candidate.tag & GROUND_TAG_BIT == class {
            out[n] = candidate;
            n += 1;
            if n == out.len() {
                break;
            }
        }
    }
    n
}

/// Plane through the five nearest target points of one class (ground or not), if they are flat
/// (and not a line).
fn plane_at(index: &VoxelIndex, q: V3, radius_m: f64) -> Option<(V3, V3)> {
    let mut nn = [Neighbour::default(); 5];
    if nearest_same_class::<8>(index, q, radius_m, &mut nn) < 5 || !spans_lines(&nn) {
        return None;
    }
    let (c, cov) = centroid_covariance(nn.iter().map(|n| n.p))?;
    let (values, vectors) = symmetric_eigen_m3(&cov);
    if values[0] > 0.1 * values[1] || values[1] < 0.01 * values[2] {
        return None;
    }
    Some((vectors.column(0).into_owned(), c))
}

/// Line through the five nearest target corners, if they are linear: `(direction, point)`.
fn line_at(index: &VoxelIndex, q: V3, radius_m: f64) -> Option<(V3, V3)> {
    let mut nn = [Neighbour::default(); 5];
    if index.neighbours(q, radius_m, &mut nn) < 5 || !spans_lines(&nn) {
        return None;
    }
    let (c, cov) = centroid_covariance(nn.iter().map(|n| n.p))?;
    let (values, vectors) = symmetric_eigen_m3(&cov);
    if values[2] < 3.0 * values[1] {
        return None;
    }
    Some((vectors.column(2).into_owned(), c))
}

fn correspondences(
    target: &FeatureTarget,
    planes: &[V3],
    corners: &[V3],
    pose: &Pose,
    radius_m: f64,
) -> Vec<Correspondence> {
    let plane_matches = planes
        .iter()
        .filter_map(|&p| match_plane(target, p, pose.apply(p), radius_m));
    let corner_matches = corners
        .iter()
        .filter_map(|&p| match_corner(target, p, pose.apply(p), radius_m));
    plane_matches.chain(corner_matches).collect()
}

/// The point-to-plane correspondence of plane feature `p`, at `q` in the target frame.
fn match_plane(target: &FeatureTarget, p: V3, q: V3, radius_m: f64) -> Option<Correspondence> {
    let (n, c) = plane_at(&target.planes, q, radius_m)?;
    Some(Correspondence {
        source: p,
        direction: n,
        anchor: c,
        cutoff_m: f64::INFINITY,
    })
}

/// The point-to-line correspondence of corner feature `p`, at `q` in the target frame: the
/// residual runs along the perpendicular from the line to `q` (none if `q` is on the line).
fn match_corner(target: &FeatureTarget, p: V3, q: V3, radius_m: f64) -> Option<Correspondence> {
    let (u, c) = line_at(&target.corners, q, radius_m)?;
    let d = q - c;
    let perp = d - u * d.dot(&u);
    let len = perp.norm();
    (len > 1e-9).then(|| Correspondence {
        source: p,
        direction: perp * (1.0 / len),
        anchor: c,
        cutoff_m: f64::INFINITY,
    })
}

/// One source feature's correspondence and where it was searched.
#[derive(Clone, Copy)]
pub(crate) struct Match {
    /// The source point as moved by the pose of its last search (target frame); `None` before
    /// the first.
    searched_at: Option<V3>,
    found: Option<Correspondence>,
}

/// The correspondence search of one solve: the scan's features (`planes`, then `corners`, in the
/// order of its `matches`) against `target`, within `radius_m`, with the kernel's cutoffs taken
/// about the solve's `centre`.
struct Search<'a> {
    target: &'a FeatureTarget,
    planes: &'a [V3],
    corners: &'a [V3],
    centre: V3,
    radius_m: f64,
    /// A feature is searched again once it moved this far from where it was last searched.
    research_m: f64,
    kernel: Kernel,
}

impl Search<'_> {
    /// Search again the features that `pose` moves more than `research_m` from where they were
    /// last searched; returns how many.
    fn refresh(&self, pose: &Pose, matches: &mut [Match]) -> usize {
        let mut searched = 0;
        for (i, (&p, m)) in self
            .planes
            .iter()
            .chain(self.corners)
            .zip(matches)
            .enumerate()
        {
            let q = pose.apply(p);
            if is_fresh(m, q, self.research_m) {
                continue;
            }
            m.searched_at = Some(q);
            m.found = if i < self.planes.len() {
                match_plane(self.target, p, q, self.radius_m)
            } else {
                match_corner(self.target, p, q, self.radius_m)
            }
            .map(|c| Correspondence {
                cutoff_m: self.kernel.cutoff(q, self.centre, c.direction),
                ..c
            });
            searched += 1;
        }
        searched
    }

    /// True when some feature is more than `research_m` from where it was last searched.
    fn any_stale(&self, pose: &Pose, matches: &[Match]) -> bool {
        self.planes
            .iter()
            .chain(self.corners)
            .zip(matches)
            .any(|(&p, m)| !is_fresh(m, pose.apply(p), self.research_m))
    }
}

/// True when `m` was searched within `limit_m` of `q`.
fn is_fresh(m: &Match, q: V3, limit_m: f64) -> bool {
    m.searched_at
        .is_some_and(|s| (s - q).norm_squared() <= limit_m * limit_m)
}

/// One residual of a registration, for diagnostics: the source point (source frame), the unit
/// direction the residual is measured along (target frame), the signed residual in metres, and
/// whether it came from a corner (point-to-line) or a plane (point-to-plane) feature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResidualInfo {
    /// Source point, source frame.
    pub source: V3,
    /// Unit direction of the residual, target frame.
    pub direction: V3,
    /// Signed residual, metres.
    pub residual_m: f64,
    /// Point-to-line (corner) rather than point-to-plane.
    pub corner: bool,
    /// The target's line or plane: the centroid of the neighbours it was fitted through,
    /// target frame.
    pub anchor: V3,
}

/// The residuals of `planes` and `corners` against `target` at `pose` (`target_from_source`),
/// exactly as one registration iteration forms them. For diagnostics (which surfaces pull the
/// estimate where) and tests.
pub fn residuals_at(
    target: &FeatureTarget,
    planes: &[V3],
    corners: &[V3],
    pose: &Pose,
    radius_m: f64,
) -> Vec<ResidualInfo> {
    let plane_corr = correspondences(target, planes, &[], pose, radius_m);
    let n_planes = plane_corr.len();
    let mut all = plane_corr;
    all.extend(correspondences(target, &[], corners, pose, radius_m));
    all.iter()
        .enumerate()
        .map(|(i, c)| ResidualInfo {
            source: c.source,
            direction: c.direction,
            residual_m: c.direction.dot(&(pose.apply(c.source) - c.anchor)),
            corner: i >= n_planes,
            anchor: c.anchor,
        })
        .collect()
}

/// The residuals' robust kernel: Huber of width `huber_m`, truncated at a cutoff of `cutoff_m`
/// plus what an attitude error of `cutoff_rad` would add to the residual, `cutoff_rad * |(q - c) x
/// e|` (its rotational Jacobian: the lever arm about the solve's centre `c`, across the
/// residual's direction `e`). A residual beyond the cutoff has zero weight and a constant cost:
/// it no longer pulls.
///
/// Why: under a car the wrong correspondences are silhouettes. The map's corner line runs round
/// the far side of a cylinder lying across the path (a differential), seen from elsewhere, 5-15
/// cm from where this scan grazes it, and such residuals point along the travel; with Huber alone
/// each still pulls by the kernel's width, all the same way (decision record 003). The lever-arm
/// term keeps the residuals a drifted yaw moves (the far tyres' sides), which hold the map's yaw
/// against the wheels' (a plain cutoff loses them), while residuals along the travel near the
/// centre line get the tight cutoff.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Kernel {
    huber_m: f64,
    cutoff_m: f64,
    cutoff_rad: f64,
}

impl Kernel {
    fn of(config: &LaserOdometryConfig) -> Self {
        Self {
            huber_m: config.huber_m,
            cutoff_m: config.max_residual_m,
            cutoff_rad: config.max_residual_rad,
        }
    }

    /// The cutoff of a residual along `e` at `q` (target frame), solved about `centre`.
    fn cutoff(&self, q: V3, centre: V3, e: V3) -> f64 {
        self.cutoff_m + self.cutoff_rad * (q - centre).cross(&e).norm()
    }

    /// IRLS weight of residual `r` with cutoff `cutoff_m`.
    fn weight(&self, r: f64, cutoff_m: f64) -> f64 {
        let (k, r) = (self.huber_m, r.abs());
        if r > cutoff_m {
            0.0
        } else if r <= k {
            1.0
        } else {
            k / r
        }
    }

    /// Cost of residual `r` with cutoff `cutoff_m`.
    fn cost(&self, r: f64, cutoff_m: f64) -> f64 {
        let k = self.huber_m;
        let r = r.abs().min(cutoff_m);
        if r <= k {
            0.5 * r * r
        } else {
            k * (r - 0.5 * k)
        }
    }
}

fn cost(corr: &[Correspondence], pose: &Pose, k: Kernel) -> f64 {
    corr.iter()
        .map(|c| {
            k.cost(
                c.direction.dot(&(pose.apply(c.source) - c.anchor)),
                c.cutoff_m,
            )
        })
        .sum()
}

/// Normal equations `(H, g)` over all six parameters, and how many residuals have weight (are
/// within the kernel's cutoff).
fn normal_equations(
    corr: &[Correspondence],
    pose: &Pose,
    centre: V3,
    k: Kernel,
) -> ([[f64; 6]; 6], [f64; 6], usize) {
    let mut h = [[0.0; 6]; 6];
    let mut g = [0.0; 6];
    let mut weighted = 0;
    for c in corr {
        let q = pose.apply(c.source);
        let r = c.direction.dot(&(q - c.anchor));
        let w = k.weight(r, c.cutoff_m);
        if w == 0.0 {
            continue;
        }
        weighted += 1;
        let jw = (q - centre).cross(&c.direction);
        let j = [
            jw[0],
            jw[1],
            jw[2],
            c.direction[0],
            c.direction[1],
            c.direction[2],
        ];
        for a in 0..6 {
            g[a] += w * j[a] * r;
            for b in 0..6 {
                h[a][b] += w * j[a] * j[b];
            }
        }
    }
    (h, g, weighted)
}

/// `exp(d) * pose` (left increment).
fn apply_increment(pose: &Pose, d: &Twist6, centre: V3) -> Pose {
    about(centre, d).compose(pose)
}

/// The increment `d` with its rotation about `centre` instead of the origin:
/// `p -> R (p - centre) + centre + t`. Registration rotates about the prior's position, so that
/// the rotational Jacobian `(q - centre) x e` and the degeneracy test do not depend on how far the
/// robot is from the target frame's origin. (With rotations about the origin, the scan-to-map
/// refinement's yaw eigenvalue grew with the squared distance travelled, yaw was never found
/// degenerate late in a run, and its noise went into the trajectory.)
pub(crate) fn about(centre: V3, d: &Twist6) -> Pose {
    let e = Pose::from_increment(*d);
    let translation = e.translation - e.rotation * centre + centre;
    Pose {
        rotation: e.rotation,
        translation,
    }
}

/// Inverse of [`about`]: the increment `d` with `about(centre, d) == m`.
pub(crate) fn increment_about(centre: V3, m: &Pose) -> Twist6 {
    let translation = m.translation + m.rotation * centre - centre;
    Pose {
        rotation: m.rotation,
        translation,
    }
    .to_increment()
}

/// A solve searches a source feature's correspondence again once the feature has moved more
/// than this fraction of the correspondence radius (5 mm with the default 0.2 m) from where it was
/// last searched. In between, the LM iterates on the fixed correspondences: the point-to-plane and
/// point-to-line residuals are linearised around target features that barely change when the
/// query moves by a few per cent of the radius, and the search is most of a solve's time. Per
/// feature rather than for the whole set: a small rotation moves the features 10 m away by
/// millimetres and the near ones (most of them under a car) by far less.
///
/// 2.5 % of the search radius keeps the trajectory of a search in every iteration on the
/// simulated passes; twice that loses accuracy (decision record 006).
pub(crate) const RESEARCH_FRACTION: f64 = 0.025;

/// An LM step whose rotation (rad) and translation (m) are both shorter than this has converged.
pub(crate) const CONVERGED_STEP: f64 = 1e-6;

/// What [`solve`] returns.
#[derive(Clone)]
pub(crate) struct Solution {
    /// The solved pose.
    pub pose: Pose,
    /// The last iteration's normal matrix per residual, zero outside the problem's `active`.
    pub information: [[f64; 6]; 6],
    /// Residuals the kernel weighted in the last iteration.
    pub residuals: usize,
    /// RMS of the last iteration's residuals, metres.
    pub rms_m: f64,
    /// What the solve did.
    #[cfg_attr(
        not(test),
        expect(dead_code, reason = "read by the tests and diagnostics")
    )]
    pub stats: SolveStats,
    /// The final correspondences, for a later solve's `warm` start.
    pub matches: Vec<Match>,
}

/// What one solve did, for tests and diagnostics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct SolveStats {
    /// Search rounds: iterations that searched at least one feature's correspondence.
    pub searches: u32,
    /// Correspondence searches (nearest-neighbour queries and fits), over all rounds.
    pub queries: usize,
    /// LM iterations (normal equations formed).
    pub iterations: u32,
}

/// One registration problem for [`solve`]: a scan's features against a target, from `init`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Problem<'a> {
    /// What the scan is registered against.
    pub target: &'a FeatureTarget,
    /// The scan's plane features (robot frame).
    pub planes: &'a [V3],
    /// The scan's corner features (robot frame).
    pub corners: &'a [V3],
    /// The starting pose.
    pub init: Pose,
    /// The solved parameters: indices into `[rx, ry, rz, tx, ty, tz]`.
    pub active: &'a [usize],
    /// LM iterations at most.
    pub iterations: u32,
    /// Correspondence radius, kernel and damping.
    pub config: &'a LaserOdometryConfig,
    /// What the solve is held to besides the scan.
    pub guides: SolveGuides,
}

/// What a solve is held to besides the scan ([`Problem::guides`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct SolveGuides {
    /// Project every step onto the eigen-directions that the first iteration's normal matrix
    /// determines under these thresholds (the others stay at `init` during the solve, LOAM's
    /// in-solve solution remapping).
    pub hold: Option<DegeneracyThresholds>,
    /// A Gaussian prior on the pose: the information matrix `L` of the increment from `init`
    /// (`[rx, ry, rz, tx, ty, tz]`, rotations about `init`'s position, as the solve's steps), in
    /// the residuals' units (squared residual noise over the prior's covariance). The solve then
    /// minimises the residuals' cost plus `0.5 d^T L d`, and the normal matrix it returns
    /// includes `L`.
    pub prior_information: Option<[[f64; 6]; 6]>,
}

/// The prior's cost `0.5 d^T L d` and gradient `L d` at `pose`, `d` its increment from `init`.
fn prior_terms(information: &[[f64; 6]; 6], init: &Pose, pose: &Pose) -> (f64, Twist6) {
    let d = increment_about(init.translation, &pose.compose(&init.inverse()));
    let g: Twist6 = std::array::from_fn(|a| (0..6).map(|b| information[a][b] * d[b]).sum());
    let cost = 0.5 * (0..6).map(|a| d[a] * g[a]).sum::<f64>();
    (cost, g)
}

/// A prior's information matrix and the pose it is centred on.
type PriorRef<'a> = (&'a [[f64; 6]; 6], &'a Pose);

/// One LM solve of `problem` over its `active` parameters, held by its guides (to the
/// directions the first iteration determines, by a prior).
///
/// At most `iterations` LM iterations. Each feature's correspondence is searched at the start and
/// again only once the feature has moved more than [`RESEARCH_FRACTION`] of the correspondence
/// radius since its last search; the solve ends when a step is shorter than [`CONVERGED_STEP`]
/// (or the LM finds no better pose) with every feature searched within that distance of where the
/// final pose puts it. The normal matrix, residual count and RMS are those of the last iteration:
/// at the final pose up to the converged step, with correspondences searched within that small
/// move of it.
///
/// `warm`: the correspondences of an earlier solve against the same target (the first
/// `warm.len()` features, in the same order; empty for a cold start). A feature whose
/// correspondence was searched within [`RESEARCH_FRACTION`] of the radius of where `init` puts it
/// keeps it, as it would between two iterations of one solve.
pub(crate) fn solve(problem: &Problem<'_>, warm: Vec<Match>) -> Solution {
    let Problem {
        target,
        planes,
        corners,
        init,
        active,
        iterations,
        config,
        guides,
    } = *problem;
    let k = Kernel::of(config);
    let mut projection: Option<[[f64; 6]; 6]> = None;
    let centre = init.translation;
    let search = Search {
        target,
        planes,
        corners,
        centre,
        radius_m: config.max_correspondence_m,
        research_m: RESEARCH_FRACTION * config.max_correspondence_m,
        kernel: k,
    };
    let mut pose = init;
    let mut lambda = config.lm_lambda;
    let mut last_h = [[0.0; 6]; 6];
    let mut last_n = 0;
    let mut rms = f64::NAN;
    let mut stats = SolveStats::default();
    let mut matches = warm_start(warm, planes.len() + corners.len(), k, centre);
    let mut corr: Vec<Correspondence> = matches.iter().filter_map(|m| m.found).collect();
    for _ in 0..iterations {
        let searched = search.refresh(&pose, &mut matches);
        if searched > 0 {
            corr = matches.iter().filter_map(|m| m.found).collect();
            stats.searches += 1;
            stats.queries += searched;
        }
        let (mut h, mut g, weighted) = normal_equations(&corr, &pose, centre, k);
        if weighted < active.len() {
            break;
        }
        let data_cost = cost(&corr, &pose, k);
        let mut before = data_cost;
        if let Some(l) = &guides.prior_information {
            let (prior_cost, prior_g) = prior_terms(l, &init, &pose);
            before += prior_cost;
            for a in 0..6 {
                g[a] += prior_g[a];
                for b in 0..6 {
                    h[a][b] += l[a][b];
                }
            }
        }
        // Per residual: the ones the kernel's cutoff leaves out do not count.
        last_h = h;
        last_n = weighted;
        if let (Some(thresholds), None) = (guides.hold, projection) {
            let per_residual = h.map(|row| row.map(|v| v / last_n as f64));
            projection = Some(determined_projection(&per_residual, active, thresholds).0);
        }
        rms = (2.0 * data_cost / corr.len() as f64).sqrt();
        stats.iterations += 1;
        let system = LmSystem {
            corr: &corr,
            h: &h,
            g: &g,
            active,
            projection: projection.as_ref(),
            prior: guides.prior_information.as_ref().map(|l| (l, &init)),
            centre,
            kernel: k,
        };
        let step = lm_step(&system, &pose, &mut lambda, before);
        let converged = match step {
            Some((candidate, d)) => {
                pose = candidate;
                is_converged(&d)
            }
            None => true,
        };
        // Done when converged with every feature searched close enough to the final pose; a
        // converged step with stale features goes on with their new search.
        if converged && !search.any_stale(&pose, &matches) {
            break;
        }
    }
    let mut h = [[0.0; 6]; 6];
    if last_n > 0 {
        for &a in active {
            for &b in active {
                h[a][b] = last_h[a][b] / last_n as f64;
            }
        }
    }
    Solution {
        pose,
        information: h,
        residuals: last_n,
        rms_m: rms,
        stats,
        matches,
    }
}

/// `features` correspondences for a solve centred on `centre`: those of `warm` (an earlier
/// solve's, its first features in the same order) with their cutoffs made this solve's, the rest
/// unsearched.
fn warm_start(mut warm: Vec<Match>, features: usize, k: Kernel, centre: V3) -> Vec<Match> {
    let unsearched = Match {
        searched_at: None,
        found: None,
    };
    warm.truncate(features);
    // The cutoffs depend on the solve's centre: those of kept correspondences are this solve's.
    for m in &mut warm {
        if let (Some(q), Some(c)) = (m.searched_at, m.found.as_mut()) {
            c.cutoff_m = k.cutoff(q, centre, c.direction);
        }
    }
    warm.resize(features, unsearched);
    warm
}

/// One iteration's linear system: the normal equations `h`, `g` of the correspondences `corr`
/// at the current pose (with the prior's terms), over the `active` parameters, optionally
/// projected onto the determined directions.
struct LmSystem<'a> {
    corr: &'a [Correspondence],
    h: &'a [[f64; 6]; 6],
    g: &'a [f64; 6],
    active: &'a [usize],
    projection: Option<&'a [[f64; 6]; 6]>,
    /// The prior's information matrix and `init`, when there is a prior.
    prior: Option<PriorRef<'a>>,
    centre: V3,
    kernel: Kernel,
}

/// One Levenberg-Marquardt step of `system` from `pose`, whose cost (the prior's included) is
/// `before`: up to four dampings, the first whose pose lowers the cost wins (the damping then
/// shrinks). Returns the new pose and its increment, or `None` when no damping improved the cost.
fn lm_step(
    system: &LmSystem<'_>,
    pose: &Pose,
    lambda: &mut f64,
    before: f64,
) -> Option<(Pose, Twist6)> {
    let &LmSystem {
        corr,
        h,
        g,
        active,
        projection,
        prior,
        centre,
        kernel: k,
    } = system;
    for _ in 0..4 {
        let mut a = [[0.0; 6]; 6];
        let mut b = [0.0; 6];
        for (i, &pi) in active.iter().enumerate() {
            b[i] = -g[pi];
            for (j, &pj) in active.iter().enumerate() {
                a[i][j] = h[pi][pj];
            }
            a[i][i] += *lambda * h[pi][pi] + 1e-9;
        }
        for i in active.len()..6 {
            a[i][i] = 1.0;
        }
        let x = solve_spd(&a, &b)?;
        let mut d = [0.0; 6];
        for (i, &pi) in active.iter().enumerate() {
            d[pi] = x[i];
        }
        if let Some(p) = projection {
            d = std::array::from_fn(|a| (0..6).map(|b| p[a][b] * d[b]).sum());
        }
        let candidate = apply_increment(pose, &d, centre);
        let prior_cost = prior.map_or(0.0, |(l, init)| prior_terms(l, init, &candidate).0);
        if cost(corr, &candidate, k) + prior_cost < before {
            *lambda = (*lambda * 0.3).max(1e-7);
            return Some((candidate, d));
        }
        *lambda *= 10.0;
    }
    None
}

/// True when increment `d` (`[rx, ry, rz, tx, ty, tz]`) is below [`CONVERGED_STEP`] in both
/// rotation and translation.
fn is_converged(d: &Twist6) -> bool {
    V3::new(d[0], d[1], d[2]).norm() < CONVERGED_STEP
        && V3::new(d[3], d[4], d[5]).norm() < CONVERGED_STEP
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{moved, scene, target_of};

    const ALL: [usize; 6] = [0, 1, 2, 3, 4, 5];

    /// A cold, unguided solve of every parameter.
    fn solve_plain(
        target: &FeatureTarget,
        planes: &[V3],
        corners: &[V3],
        init: Pose,
        iterations: u32,
        config: &LaserOdometryConfig,
    ) -> Solution {
        solve(
            &Problem {
                target,
                planes,
                corners,
                init,
                active: &ALL,
                iterations,
                config,
                guides: SolveGuides::default(),
            },
            Vec::new(),
        )
    }

    /// A joint solve of the tyre scene moved by `truth`, and the scene it solved.
    struct SceneSolve {
        pose: Pose,
        h: [[f64; 6]; 6],
        stats: SolveStats,
        target: FeatureTarget,
        planes: Vec<V3>,
        corners: Vec<V3>,
    }

    fn solve_scene(truth: &Pose, init: Pose, iterations: u32) -> SceneSolve {
        let (planes, corners) = scene(true);
        let target = target_of(&planes, &corners);
        let (planes, corners) = (moved(&planes, truth), moved(&corners, truth));
        let config = LaserOdometryConfig::default();
        let solution = solve_plain(&target, &planes, &corners, init, iterations, &config);
        SceneSolve {
            pose: solution.pose,
            h: solution.information,
            stats: solution.stats,
            target,
            planes,
            corners,
        }
    }

    fn error_of(pose: &Pose, truth: &Pose) -> Twist6 {
        pose.compose(&truth.inverse()).to_increment()
    }

    #[test]
    fn a_warm_solve_searches_only_the_features_that_moved() {
        // A cold solve's correspondences, handed to a second solve from where the first ended:
        // every feature is where it was searched, so nothing is searched again and the pose holds.
        let truth = Pose::from_xyz_rpy([0.03, -0.01, 0.004], [0.002, -0.001, 0.01]);
        let (planes, corners) = scene(true);
        let target = target_of(&planes, &corners);
        let (sp, sc) = (moved(&planes, &truth), moved(&corners, &truth));
        let config = LaserOdometryConfig::default();
        let run = |init: Pose, warm: Vec<Match>| {
            let s = solve(
                &Problem {
                    target: &target,
                    planes: &sp,
                    corners: &sc,
                    init,
                    active: &ALL,
                    iterations: 30,
                    config: &config,
                    guides: SolveGuides::default(),
                },
                warm,
            );
            (s.pose, s.stats, s.matches)
        };
        let (cold, cold_stats, matches) = run(Pose::IDENTITY, Vec::new());
        assert!(cold_stats.queries > sp.len() + sc.len(), "{cold_stats:?}");
        let (warm, warm_stats, _) = run(cold, matches.clone());
        assert_eq!(warm_stats.queries, 0, "{warm_stats:?}");
        let moved_by = error_of(&warm, &cold);
        assert!(moved_by.iter().all(|e| e.abs() < 1e-4), "{moved_by:?}");
        // The planes' correspondences alone, from 2 cm further on: the planes (all moved past the
        // re-search distance) and the corners (never searched) are searched once each.
        let shifted = Pose::from_xyz_rpy([0.02, 0.0, 0.0], [0.0; 3]).compose(&cold);
        let planes_only = matches[..sp.len()].to_vec();
        let (_, stats, _) = run(shifted, planes_only);
        assert!(stats.queries >= sp.len() + sc.len(), "{stats:?}");
    }

    #[test]
    fn a_small_motion_converges_on_one_search_and_stops_early() {
        // Every source point moves less than the re-search distance (5 mm): one search suffices.
        let truth = Pose::from_xyz_rpy([0.0015, -0.001, 0.0005], [0.0002, -0.0001, 0.0003]);
        let SceneSolve { pose, stats, .. } = solve_scene(&truth, Pose::IDENTITY, 30);
        let err = error_of(&pose, &truth);
        // The scene's tyres are sampled circles: point-to-line fits on them are good to about a
        // millimetre (a search in every iteration ends 1.1 mm off in y here).
        assert!(err.iter().all(|e| e.abs() < 2e-3), "{err:?} {stats:?}");
        assert_eq!(stats.searches, 1, "{stats:?}");
        let (planes, corners) = scene(true);
        assert_eq!(stats.queries, planes.len() + corners.len(), "{stats:?}");
        assert!(stats.iterations < 10, "{stats:?}");
    }

    #[test]
    fn only_the_features_that_moved_are_searched_again() {
        // A yaw of 0.3 degree about the solve's centre (the origin) moves the features within
        // about 1 m of it by less than the re-search distance, the far ones by up to 2 cm.
        let truth = Pose::from_xyz_rpy([0.0; 3], [0.0, 0.0, 0.005]);
        let SceneSolve { pose, stats, .. } = solve_scene(&truth, Pose::IDENTITY, 30);
        let err = error_of(&pose, &truth);
        assert!(err.iter().all(|e| e.abs() < 2e-3), "{err:?} {stats:?}");
        let (planes, corners) = scene(true);
        let n = planes.len() + corners.len();
        assert!(stats.searches >= 2, "{stats:?}");
        assert!(stats.queries > n, "{stats:?}");
        assert!(
            stats.queries < stats.searches as usize * n,
            "{stats:?} of {n}"
        );
    }

    #[test]
    fn a_large_motion_is_found_by_searching_again() {
        // 8 cm and 1.1 degrees: the first correspondences are the wrong ones for many points;
        // only new searches as the pose moves find the motion.
        let truth = Pose::from_xyz_rpy([0.08, -0.03, 0.01], [0.004, -0.003, 0.02]);
        let SceneSolve { pose, stats, .. } = solve_scene(&truth, Pose::IDENTITY, 30);
        let err = error_of(&pose, &truth);
        assert!(err.iter().all(|e| e.abs() < 3e-3), "{err:?} {stats:?}");
        assert!(stats.searches >= 2, "{stats:?}");
        assert!(stats.iterations < 30, "{stats:?}");
    }

    #[test]
    fn residuals_beyond_the_cutoff_do_not_pull() {
        // Corners whose nearest target line is the wrong one, 12 cm away along x (a silhouette
        // seen from elsewhere: the map's line runs round the far side of a cylinder), all on one
        // side: the Huber kernel still pulls by its width for each of them; the cutoff drops them.
        let truth = Pose::from_xyz_rpy([0.02, 0.0, 0.0], [0.0; 3]);
        let (planes, corners) = scene(true);
        let target = target_of(&planes, &corners);
        let mut source_corners = corners.clone();
        for &(cx, cy) in &[(1.4_f64, 0.8_f64), (1.4, -0.8), (-1.4, 0.8), (-1.4, -0.8)] {
            for k in 0..60 {
                let z = 0.01 + f64::from(k) * 0.006;
                source_corners.push(V3::new(cx + 0.3 + 0.12, cy, z));
            }
        }
        let (planes, source_corners) = (moved(&planes, &truth), moved(&source_corners, &truth));
        let x_error = |max_residual_m: f64| {
            let config = LaserOdometryConfig {
                max_residual_m,
                max_residual_rad: 0.0,
                ..LaserOdometryConfig::default()
            };
            let s = solve_plain(
                &target,
                &planes,
                &source_corners,
                Pose::from_xyz_rpy([0.015, 0.0, 0.0], [0.0; 3]),
                30,
                &config,
            );
            (error_of(&s.pose, &truth)[3], s.residuals)
        };
        let ((huber, n_huber), (cut, n_cut)) = (x_error(f64::INFINITY), x_error(0.05));
        assert!(huber.abs() > 5e-3, "Huber alone: x error {huber}");
        assert!(cut.abs() < 2e-3, "cut at 5 cm: x error {cut}");
        // The residuals cut off do not count as residuals (the degeneracy test divides by them).
        assert!(
            n_cut + 200 < n_huber,
            "{n_cut} residuals cut, {n_huber} Huber"
        );
    }

    #[test]
    fn the_normal_matrix_is_the_one_at_the_final_pose() {
        // Registration's degeneracy test reads the returned matrix: it must match one formed
        // from a fresh search at the final pose, not the first (stale) correspondence set.
        let truth = Pose::from_xyz_rpy([0.08, -0.03, 0.01], [0.004, -0.003, 0.02]);
        let s = solve_scene(&truth, Pose::IDENTITY, 30);
        let (pose, h) = (s.pose, s.h);
        let config = LaserOdometryConfig::default();
        let corr = correspondences(
            &s.target,
            &s.planes,
            &s.corners,
            &pose,
            config.max_correspondence_m,
        );
        let (fresh, _, weighted) = normal_equations(&corr, &pose, V3::zeros(), Kernel::of(&config));
        let n = weighted as f64;
        let largest = (0..6).map(|a| h[a][a]).fold(0.0, f64::max);
        for a in 0..6 {
            for b in 0..6 {
                let diff = (h[a][b] - fresh[a][b] / n).abs();
                assert!(
                    diff < 0.02 * largest,
                    "[{a}][{b}]: {} vs {}",
                    h[a][b],
                    fresh[a][b] / n
                );
            }
        }
    }

    #[test]
    fn plane_fits_do_not_mix_the_ground_with_a_low_underbody() {
        // Under a car, ring arcs on the underbody (z = 0.17 m) and on the ground run stacked
        // within one correspondence radius. Two underbody rings (tags 1, 2) and a ground ring
        // (tag 3) just outside and below them:
        let mut points = Vec::new();
        let mut tags = Vec::new();
        let mut add = |p: V3, tag: u32| {
            points.push(p);
            tags.push(tag);
        };
        for y in [-0.12, 0.0, 0.12] {
            add(V3::new(0.95, y, 0.17), 1);
        }
        for y in [-0.1, 0.0, 0.1] {
            add(V3::new(0.80, y, 0.17), 2);
        }
        for y in [-0.08, 0.0, 0.08] {
            add(V3::new(0.98, y, 0.0), 3 | GROUND_TAG_BIT);
        }
        let index = VoxelIndex::new_tagged(points, tags, 0.2);
        // The five nearest include the ground point below; a fit over them is not the underbody.
        let (normal, _) = plane_at(&index, V3::new(0.95, 0.0, 0.17), 0.2).expect("underbody plane");
        assert!(normal[2].abs() > 0.999, "normal {normal:?}");
        // From the ground side, the ground ring alone is one scan line: no plane.
        assert_eq!(plane_at(&index, V3::new(0.98, 0.0, 0.0), 0.2), None);
    }
}
