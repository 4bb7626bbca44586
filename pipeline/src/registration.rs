//! Registration: the laser's LM solves (`laser_odometry::solve`) put together as the
//! scan-to-scan two-step and the scan-to-map joint registration, and the degeneracy test with
//! solution remapping that decides which directions the scan determines.
//!
//! **Degeneracy** (Zhang, Kaess and Singh 2016, "solution remapping"): after the solve, the normal
//! matrix of each step (per residual) is eigen-decomposed; directions whose eigenvalue is below a
//! threshold are not determined by the scan (under a car: travel along two parallel planes). In
//! those directions the estimate is replaced by the prior (the fused prediction from visual and
//! wheel odometry), and the directions are reported so fusion knows which of the laser's components
//! to distrust.
//!
//! **Two thresholds.** The normal matrix mixes units: its translational block is dimensionless (a
//! mean of products of unit normal components, at most 1), its rotational block is in m^2 (the
//! squared lever arm `|q - c|` of each residual about the rotation centre). One threshold for both
//! (`degeneracy-eigen-min`, 0.3, the only one before) let a weak yaw through: a few tyre or bumper
//! residuals 2-5 m away give a yaw eigenvalue of 0.3-1 m^2 while the rotation is set by a handful
//! of points, and the laser-only trajectories diverged in yaw on three of five simulated passes.
//! So an eigen-direction that is mostly rotation (squared weight of its rotational components
//! above one half) is tested against `degeneracy-rotation-eigen-min-m2`, the others against
//! `degeneracy-eigen-min`. Approximation: an eigenvector that mixes rotation and translation (a
//! yaw about a point away from the centre) is classified by its larger part only.
//!
//! **Aided and unaided.** The threshold decides between the scan and the prior, so it depends on
//! the prior: with wheel or visual odometry over the interval (measured x, y, yaw, and Algorithm
//! 1's wheel gate behind it) the laser keeps a direction only above `degeneracy-eigen-min` /
//! `degeneracy-rotation-eigen-min-m2` (0.3 / 0.3 m^2); without them (laser only) the prior is the
//! constant-velocity guess, and [`unaided`] swaps in `unaided-degeneracy-eigen-min` (0.1: a weak
//! laser x still beats a guessed speed; at 0.3 the simulated van's laser-only run stood still for
//! its first 3 s and lost 0.8 m) and `unaided-degeneracy-rotation-eigen-min-m2` (1.0 m^2: a weak
//! laser yaw is worse than the straight-driving prior, which fusion then fills with zero rate).
//! The thresholds and their measurements: decision record 005.
//!
//! **Step 2 from step 1's correspondences.** Both steps register the same plane features (step 1
//! with the ground sample after them) against the same target, and step 1 moves them by
//! millimetres (z, roll, pitch). Step 2 keeps a plane feature's step-1 correspondence while the
//! feature is within the re-search distance of where it was searched, as either step does between
//! its own iterations. This saves searches without changing the result beyond its seed-to-seed
//! spread (decision record 017).
//!
//! **Gating a registration by another source** ([`keep_components`]): the pipeline may reject
//! some components of a registration after the fact (the scan-to-map refinement against wheel
//! odometry, as Algorithm 1 gates the scan-to-scan laser); the rejected components fall back to
//! the prior exactly as degenerate ones do.

use super::config::LaserOdometryConfig;
use super::geom::{Pose, V3, symmetric_eigen};
use super::laser_odometry::{FeatureTarget, Problem, SolveGuides, about, increment_about, solve};

/// How a registration went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    /// `target_from_source`.
    pub pose: Pose,
    /// Per parameter `[rx, ry, rz, tx, ty, tz]`: true where the scan did not determine it and the
    /// prior was used.
    pub degenerate: [bool; 6],
    /// Residuals used in the last iteration.
    pub residuals: usize,
    /// RMS of the last iteration's residuals, metres.
    pub rms_m: f64,
}

/// The degeneracy thresholds of one registration: eigenvalues of the per-residual normal matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DegeneracyThresholds {
    /// For eigen-directions that are mostly translation (dimensionless).
    pub translation: f64,
    /// For eigen-directions that are mostly rotation, m^2.
    pub rotation_m2: f64,
}

impl DegeneracyThresholds {
    /// The thresholds of a laser config.
    pub fn of(config: &LaserOdometryConfig) -> Self {
        Self {
            translation: config.degeneracy_eigen_min,
            rotation_m2: config.degeneracy_rotation_eigen_min_m2,
        }
    }

    /// The threshold for eigenvector `v` (`[rx, ry, rz, tx, ty, tz]`, unit length).
    fn for_direction(&self, v: &[f64; 6]) -> f64 {
        let rotational: f64 = v[..3].iter().map(|c| c * c).sum();
        if rotational > 0.5 {
            self.rotation_m2
        } else {
            self.translation
        }
    }
}

/// `config` with the unaided degeneracy thresholds in place of the aided ones: for intervals
/// where the prior comes from no measuring source (see the module docs).
pub fn unaided(config: &LaserOdometryConfig) -> LaserOdometryConfig {
    LaserOdometryConfig {
        degeneracy_eigen_min: config.unaided_degeneracy_eigen_min,
        degeneracy_rotation_eigen_min_m2: config.unaided_degeneracy_rotation_eigen_min_m2,
        ..config.clone()
    }
}

/// The projection onto the determined eigen-directions of `h` (per residual, restricted to
/// `active`), and which parameters lie mostly in the undetermined ones.
pub(crate) fn determined_projection(
    h: &[[f64; 6]; 6],
    active: &[usize],
    thresholds: DegeneracyThresholds,
) -> ([[f64; 6]; 6], [bool; 6]) {
    let mut m = *h;
    for i in 0..6 {
        if !active.contains(&i) {
            m[i] = [0.0; 6];
            m[i][i] = 1e12;
        }
    }
    let (values, vectors) = symmetric_eigen(&m);
    let mut projection = [[0.0; 6]; 6];
    let mut bad_weight = [0.0; 6];
    for (e, &value) in values.iter().enumerate() {
        let v: [f64; 6] = std::array::from_fn(|k| vectors[k][e]);
        if value >= thresholds.for_direction(&v) {
            for a in 0..6 {
                for b in 0..6 {
                    projection[a][b] += v[a] * v[b];
                }
            }
        } else {
            for k in 0..6 {
                bad_weight[k] += v[k] * v[k];
            }
        }
    }
    let degenerate = std::array::from_fn(|k| active.contains(&k) && bad_weight[k] > 0.5);
    (projection, degenerate)
}

/// Replace the estimate by the prior along the degenerate eigen-directions of `h` (restricted to
/// `active`); returns the remapped pose and which parameters were mostly taken from the prior.
fn remap(
    estimate: &Pose,
    prior: &Pose,
    h: &[[f64; 6]; 6],
    active: &[usize],
    thresholds: DegeneracyThresholds,
) -> (Pose, [bool; 6]) {
    let (projection, degenerate) = determined_projection(h, active, thresholds);
    let centre = prior.translation;
    let delta = increment_about(centre, &estimate.compose(&prior.inverse()));
    let kept: [f64; 6] = std::array::from_fn(|a| (0..6).map(|b| projection[a][b] * delta[b]).sum());
    (about(centre, &kept).compose(prior), degenerate)
}

/// `estimate` with the components not in `keep` (`[rx, ry, rz, tx, ty, tz]` of the increment
/// from `prior`, rotating about the prior's position as the solves do) replaced by the prior's.
pub fn keep_components(estimate: &Pose, prior: &Pose, keep: [bool; 6]) -> Pose {
    let centre = prior.translation;
    let mut delta = increment_about(centre, &estimate.compose(&prior.inverse()));
    for (d, k) in delta.iter_mut().zip(keep) {
        if !k {
            *d = 0.0;
        }
    }
    about(centre, &delta).compose(prior)
}

/// Every parameter of a registration, in increment order: roll, pitch, yaw, x, y, z.
pub const ALL_SIX: [usize; 6] = [0, 1, 2, 3, 4, 5];

/// The parameters the floor leaves: yaw, x and y (the two-step registration's step 2, the
/// levelled refinement).
pub const YAW_X_Y: [usize; 3] = [2, 3, 4];

/// A scan-to-map registration problem for [`register_joint`].
#[derive(Debug, Clone, Copy)]
pub struct JointProblem<'a> {
    /// What the scan is registered against (the feature map).
    pub target: &'a FeatureTarget,
    /// The scan's plane features (robot frame).
    pub planes: &'a [V3],
    /// The scan's corner features (robot frame).
    pub corners: &'a [V3],
    /// `target_from_source` to start from and fall back to.
    pub prior: Pose,
    /// The prior as a Gaussian too, when there is one (see [`register_joint`]).
    pub prior_information: Option<[[f64; 6]; 6]>,
    /// The solved parameters: indices into `[rx, ry, rz, tx, ty, tz]`.
    pub active: &'a [usize],
    /// LM iterations at most.
    pub iterations: u32,
    /// Correspondence radius, kernel, damping and degeneracy thresholds.
    pub config: &'a LaserOdometryConfig,
}

/// Register a scan's features to the problem's `target` with the `active` parameters (increment order: roll,
/// pitch, yaw, x, y, z; the others stay at `prior`'s) in one LM problem (the scan-to-map
/// refinement: all six, or x, y and yaw once the floor has levelled `prior`), starting from and
/// falling back to `prior` = `target_from_source`.
///
/// `prior_information`: the prior as a Gaussian too (its information matrix on the increment,
/// in the residuals' units): the solve weighs the scan against it, and a direction counts as
/// determined when the scan and the prior together determine it, so the hard split below (scan
/// or prior) applies only to the directions the prior leaves free.
pub fn register_joint(problem: &JointProblem<'_>) -> Registration {
    let JointProblem {
        target,
        planes,
        corners,
        prior,
        prior_information,
        active,
        iterations,
        config,
    } = *problem;
    let thresholds = DegeneracyThresholds::of(config);
    // The steps are held to the directions the first linearisation determines (LOAM's in-solve
    // remapping): the joint solve against the map otherwise wanders along the undetermined ones,
    // which the remapping below would throw away anyway, and its far features then go stale and
    // are searched again (it ran all its iterations; the scan-to-map solve was 37 % of the CPU).
    let solution = solve(
        &Problem {
            target,
            planes,
            corners,
            init: prior,
            active,
            iterations,
            config,
            guides: SolveGuides {
                hold: Some(thresholds),
                prior_information,
            },
        },
        Vec::new(),
    );
    let (pose, degenerate) = remap(
        &solution.pose,
        &prior,
        &solution.information,
        active,
        thresholds,
    );
    Registration {
        pose,
        degenerate,
        residuals: solution.residuals,
        rms_m: solution.rms_m,
    }
}

/// One scan's features in its robot frame, as the two-step registration takes them.
#[derive(Debug, Clone, Copy)]
pub struct Scan<'a> {
    /// Step 1's planes (z, roll, pitch): the plane features, then the ground sample.
    pub step1_planes: &'a [V3],
    /// How many of `step1_planes`, from the first, step 2 registers (x, y, yaw): the plane
    /// features' count.
    pub step2_planes: usize,
    /// Corner features (step 2).
    pub corners: &'a [V3],
}

impl<'a> Scan<'a> {
    /// Step 2's planes: the first [`Self::step2_planes`] of step 1's.
    pub fn planes(&self) -> &'a [V3] {
        &self.step1_planes[..self.step2_planes.min(self.step1_planes.len())]
    }

    /// What the scan-to-map refinement registers, `(planes, corners)`, and the parameters it
    /// solves ([`register_joint`]). `levelled`: the frame's floor has set the prior's roll, pitch
    /// and height, which it also sets on the result, so only yaw, x and y are solved, from step
    /// 2's planes and the corners; the ground sample, which constrains only the other three, is
    /// not registered (about half the refinement's queries, for the same accuracy; decision record
    /// 022).
    /// Else all six, from step 1's planes (with the ground sample) and the corners.
    pub fn for_refinement(&self, levelled: bool) -> ((&'a [V3], &'a [V3]), &'static [usize]) {
        if levelled {
            ((self.planes(), self.corners), &YAW_X_Y)
        } else {
            ((self.step1_planes, self.corners), &ALL_SIX)
        }
    }
}

/// Scan-to-scan two-step registration of `scan`: `prev_from_cur`, starting from and falling
/// back to `prior`. Step 1's planes fix z, roll and pitch; step 2's planes and the corners then
/// fix x, y and yaw.
pub fn register_two_step(
    target: &FeatureTarget,
    scan: Scan<'_>,
    prior: Pose,
    config: &LaserOdometryConfig,
) -> Registration {
    let (planes, corners) = (scan.planes(), scan.corners);
    let thresholds = DegeneracyThresholds::of(config);
    let guides = SolveGuides::default();
    let step1 = [0, 1, 5];
    let first = solve(
        &Problem {
            target,
            planes: scan.step1_planes,
            corners: &[],
            init: prior,
            active: &step1,
            iterations: config.iterations,
            config,
            guides,
        },
        Vec::new(),
    );
    let (pose1, deg1) = remap(&first.pose, &prior, &first.information, &step1, thresholds);
    let mut matches = first.matches;
    // Step 2 starts from step 1's plane correspondences (its planes lead step 1's, same target):
    // only those step 1 moved by more than the re-search distance are searched again.
    matches.truncate(planes.len());
    let step2 = YAW_X_Y;
    let second = solve(
        &Problem {
            target,
            planes,
            corners,
            init: pose1,
            active: &step2,
            iterations: config.iterations,
            config,
            guides,
        },
        matches,
    );
    let (pose, deg2) = remap(
        &second.pose,
        &pose1,
        &second.information,
        &step2,
        thresholds,
    );
    Registration {
        pose,
        degenerate: std::array::from_fn(|k| deg1[k] || deg2[k]),
        residuals: first.residuals.max(second.residuals),
        rms_m: second.rms_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laser_odometry::Solution;
    use crate::test_support::{moved, scan_of, scene, target_of};

    #[test]
    fn recovers_a_known_motion_in_both_modes() {
        let (target, truth, (sp, sc), config) = known_motion();
        for reg in [
            register_two_step(&target, scan_of(&sp, &sc), Pose::IDENTITY, &config),
            register_joint(&JointProblem {
                target: &target,
                planes: &sp,
                corners: &sc,
                prior: Pose::IDENTITY,
                prior_information: None,
                active: &ALL_SIX,
                iterations: 10,
                config: &config,
            }),
        ] {
            let err = reg.pose.compose(&truth.inverse()).to_increment();
            assert!(err.iter().all(|e| e.abs() < 3e-3), "{err:?} {reg:?}");
            assert!(reg.degenerate.iter().all(|&d| !d), "{reg:?}");
        }
    }

    /// The test scene as target, the truth, the scene's planes and corners moved by it, and a
    /// configuration for it: the synthetic tyres are a small share of the residuals, so it
    /// accepts weaker directions than the default (which is tuned to hand x, y and yaw to wheel
    /// odometry under real cars).
    fn known_motion() -> (FeatureTarget, Pose, (Vec<V3>, Vec<V3>), LaserOdometryConfig) {
        let (planes, corners) = scene(true);
        let truth = Pose::from_xyz_rpy([0.04, 0.01, 0.005], [0.003, -0.004, 0.01]);
        let moved_scan = (moved(&planes, &truth), moved(&corners, &truth));
        let config = LaserOdometryConfig {
            degeneracy_eigen_min: 0.01,
            degeneracy_rotation_eigen_min_m2: 0.01,
            ..LaserOdometryConfig::default()
        };
        (target_of(&planes, &corners), truth, moved_scan, config)
    }

    #[test]
    fn a_levelled_refinement_moves_x_y_yaw_only() {
        // The pipeline's refinement once the floor has levelled the prior: only x, y and yaw
        // move; roll, pitch and height stay exactly the prior's, even where the features would
        // move them (here the prior's are off the truth's by 3, 4 mrad and 5 mm).
        let (target, _, (sp, sc), config) = known_motion();
        let prior = Pose::IDENTITY;
        let ((planes, corners), active) = scan_of(&sp, &sc).for_refinement(true);
        let reg = register_joint(&JointProblem {
            target: &target,
            planes,
            corners,
            prior,
            prior_information: None,
            active,
            iterations: 10,
            config: &config,
        });
        let moved_by = increment_about(prior.translation, &reg.pose.compose(&prior.inverse()));
        for k in [0, 1, 5] {
            assert!(moved_by[k].abs() < 1e-12, "{moved_by:?}");
        }
        // x, y and yaw towards the truth's 0.04 m, 0.01 m and 0.01 rad.
        assert!((moved_by[3] - 0.04).abs() < 0.01, "{moved_by:?}");
        assert!((moved_by[4] - 0.01).abs() < 0.01, "{moved_by:?}");
        assert!((moved_by[2] - 0.01).abs() < 0.005, "{moved_by:?}");
    }

    #[test]
    fn degeneracy_does_not_depend_on_the_distance_from_the_target_origin() {
        // The scan-to-map target is the world frame: late in a run the robot is metres from its
        // origin. The same registration there must find the same degenerate directions.
        let (planes, corners) = scene(true);
        let truth = Pose::from_xyz_rpy([0.04, 0.01, 0.005], [0.003, -0.004, 0.01]);
        let (sp, sc) = (moved(&planes, &truth), moved(&corners, &truth));
        let config = LaserOdometryConfig::default();
        let run = |shift_m: f64| {
            let world_from_target = Pose::from_xyz_rpy([shift_m, 0.0, 0.0], [0.0; 3]);
            let shifted =
                |v: &[V3]| -> Vec<V3> { v.iter().map(|&p| world_from_target.apply(p)).collect() };
            let target = target_of(&shifted(&planes), &shifted(&corners));
            let reg = register_joint(&JointProblem {
                target: &target,
                planes: &sp,
                corners: &sc,
                prior: world_from_target,
                prior_information: None,
                active: &ALL_SIX,
                iterations: 10,
                config: &config,
            });
            let in_target = world_from_target.inverse().compose(&reg.pose);
            (
                reg.degenerate,
                in_target.compose(&truth.inverse()).to_increment(),
            )
        };
        let (near, near_err) = run(0.0);
        let (far, far_err) = run(20.0);
        assert_eq!(near, far, "errors near {near_err:?} far {far_err:?}");
        for k in 0..6 {
            assert!(
                (near_err[k] - far_err[k]).abs() < 1e-6,
                "{near_err:?} {far_err:?}"
            );
        }
    }

    /// Step 2's normal matrix of a scan between two parallel planes with a few tyre residuals:
    /// x and y well determined, yaw weakly (0.6 m^2 per residual, from a handful of points 2 m
    /// away).
    fn weak_yaw_normal_matrix() -> [[f64; 6]; 6] {
        let mut h = [[0.0; 6]; 6];
        h[2][2] = 0.6;
        h[3][3] = 0.5;
        h[4][4] = 0.2;
        h
    }

    #[test]
    fn a_weak_yaw_is_degenerate_without_a_measured_prior() {
        let h = weak_yaw_normal_matrix();
        let prior = Pose::from_xyz_rpy([0.03, 0.0, 0.0], [0.0; 3]);
        let estimate = Pose::from_xyz_rpy([0.032, 0.001, 0.0], [0.0, 0.0, 0.004]);
        let step2 = [2, 3, 4];
        // The former single threshold (0.3 for rotations in m^2 and translations alike) keeps
        // the weak yaw and drops the y that the tyres do determine.
        let single = DegeneracyThresholds {
            translation: 0.3,
            rotation_m2: 0.3,
        };
        let (_, degenerate) = remap(&estimate, &prior, &h, &step2, single);
        assert_eq!(degenerate, [false, false, false, false, true, false]);
        // Unaided (laser only) thresholds: yaw to the prior, x and y from the scan.
        let config = unaided(&LaserOdometryConfig::default());
        let (pose, degenerate) = remap(
            &estimate,
            &prior,
            &h,
            &step2,
            DegeneracyThresholds::of(&config),
        );
        assert_eq!(degenerate, [false, false, true, false, false, false]);
        let rpy = pose.rpy();
        assert!(rpy[2].abs() < 1e-12, "{rpy:?}");
        assert!((pose.translation[0] - 0.032).abs() < 1e-6, "{pose:?}");
        assert!((pose.translation[1] - 0.001).abs() < 1e-6, "{pose:?}");
        // With wheel or visual odometry behind the prior the aided thresholds apply (0.3 / 0.3).
        let aided = DegeneracyThresholds::of(&LaserOdometryConfig::default());
        assert_eq!(aided, single);
    }

    #[test]
    fn rotation_and_translation_eigen_directions_get_their_own_threshold() {
        let h = weak_yaw_normal_matrix();
        let (prior, estimate) = (Pose::IDENTITY, Pose::IDENTITY);
        let only = |translation, rotation_m2| {
            remap(
                &estimate,
                &prior,
                &h,
                &[2, 3, 4],
                DegeneracyThresholds {
                    translation,
                    rotation_m2,
                },
            )
            .1
        };
        // Raising the rotation threshold never touches x and y, and the other way round.
        assert_eq!(only(0.0, 0.7), [false, false, true, false, false, false]);
        assert_eq!(only(0.6, 0.0), [false, false, false, true, true, false]);
        assert_eq!(only(0.3, 0.0), [false, false, false, false, true, false]);
    }

    #[test]
    fn keep_components_takes_the_rejected_ones_from_the_prior() {
        let prior = Pose::from_xyz_rpy([5.0, 1.0, 0.0], [0.0, 0.0, 0.3]);
        let correction = Pose::from_xyz_rpy([0.01, -0.02, 0.003], [0.001, 0.002, 0.02]);
        let estimate = about(prior.translation, &correction.to_increment()).compose(&prior);
        let yaw_rejected = [true, true, false, true, true, true];
        let kept = keep_components(&estimate, &prior, yaw_rejected);
        let delta = increment_about(prior.translation, &kept.compose(&prior.inverse()));
        let want = correction.to_increment();
        for k in 0..6 {
            let expected = if k == 2 { 0.0 } else { want[k] };
            assert!((delta[k] - expected).abs() < 1e-9, "{delta:?} vs {want:?}");
        }
        let all = keep_components(&estimate, &prior, [true; 6]);
        let diff = all.compose(&estimate.inverse()).to_increment();
        assert!(diff.iter().all(|d| d.abs() < 1e-12), "{diff:?}");
    }

    #[test]
    fn a_held_solve_does_not_move_along_undetermined_directions() {
        // Two parallel planes determine z, roll and pitch; a small patch facing along x (a few
        // dozen of 3 200 residuals) pulls x weakly, below the degeneracy threshold. The prior is
        // 2 cm off in x. A free solve follows the patch (and the remapping afterwards puts x
        // back to the prior); a held one never moves x.
        let (mut planes, corners) = scene(false);
        for i in 0..6 {
            for j in 0..6 {
                planes.push(V3::new(2.0, f64::from(i) * 0.05, 0.1 + f64::from(j) * 0.04));
            }
        }
        let target = target_of(&planes, &corners);
        let truth = Pose::from_xyz_rpy([0.05, 0.0, 0.01], [0.0, 0.0, 0.0]);
        let sp = moved(&planes, &truth);
        let prior = Pose::from_xyz_rpy([0.03, 0.0, 0.0], [0.0, 0.0, 0.004]);
        let config = LaserOdometryConfig::default();
        let active = [0, 1, 2, 3, 4, 5];
        let thresholds = DegeneracyThresholds::of(&config);
        let run = |hold| {
            let Solution { pose, stats, .. } = solve(
                &Problem {
                    target: &target,
                    planes: &sp,
                    corners: &[],
                    init: prior,
                    active: &active,
                    iterations: 6,
                    config: &config,
                    guides: SolveGuides {
                        hold,
                        prior_information: None,
                    },
                },
                Vec::new(),
            );
            let d = increment_about(prior.translation, &pose.compose(&prior.inverse()));
            (d, stats)
        };
        let (free, free_stats) = run(None);
        let (held, held_stats) = run(Some(thresholds));
        // Held: x, y and yaw stay at the prior (to the eigenvectors' small mixing); z is solved.
        for k in [2, 3, 4] {
            assert!(held[k].abs() < 1e-4, "held {held:?} free {free:?}");
        }
        assert!((held[5] - 0.01).abs() < 1e-3, "held {held:?}");
        // Free: x moved towards the patch's 5 cm (what the remapping then discards).
        assert!(free[3] > 0.01, "free {free:?}");
        assert!(
            held_stats.iterations <= free_stats.iterations,
            "{held_stats:?} {free_stats:?}"
        );
    }

    #[test]
    fn a_gaussian_prior_is_weighed_against_the_scan_by_information() {
        // The scan determines x fully (tyres); the truth is 5 cm, the prior 3 cm. No prior: the
        // scan's 5 cm. A prior carrying as much information on x as the scan: halfway, 4 cm (the
        // product of two Gaussians). An overwhelming prior: 3 cm. The prior holds only x.
        let (planes, corners) = scene(true);
        let target = target_of(&planes, &corners);
        let truth = Pose::from_xyz_rpy([0.05, 0.0, 0.0], [0.0; 3]);
        let (sp, sc) = (moved(&planes, &truth), moved(&corners, &truth));
        let prior = Pose::from_xyz_rpy([0.03, 0.0, 0.0], [0.0; 3]);
        let config = LaserOdometryConfig {
            degeneracy_eigen_min: 0.01,
            degeneracy_rotation_eigen_min_m2: 0.01,
            ..LaserOdometryConfig::default()
        };
        let x_with = |information_x: Option<f64>| {
            let l = information_x.map(|v| {
                let mut l = [[0.0; 6]; 6];
                l[3][3] = v;
                l
            });
            register_joint(&JointProblem {
                target: &target,
                planes: &sp,
                corners: &sc,
                prior,
                prior_information: l,
                active: &ALL_SIX,
                iterations: 20,
                config: &config,
            })
            .pose
            .translation[0]
        };
        let free = x_with(None);
        assert!((free - 0.05).abs() < 1e-3, "{free}");
        // The scan's information on x: its normal matrix per residual times the residuals, at
        // the truth.
        let at_truth = solve(
            &Problem {
                target: &target,
                planes: &sp,
                corners: &sc,
                init: truth,
                active: &[0, 1, 2, 3, 4, 5],
                iterations: 1,
                config: &config,
                guides: SolveGuides::default(),
            },
            Vec::new(),
        );
        let scan_information = at_truth.information[3][3] * at_truth.residuals as f64;
        let equal = x_with(Some(scan_information));
        assert!((equal - 0.04).abs() < 1.5e-3, "{equal}");
        let strong = x_with(Some(scan_information * 1e6));
        assert!((strong - 0.03).abs() < 1e-4, "{strong}");
        // A zero prior is no prior.
        let zero = x_with(Some(0.0));
        assert!((zero - free).abs() < 1e-9, "{zero} {free}");
    }

    #[test]
    fn two_parallel_planes_leave_x_y_yaw_to_the_prior() {
        let (planes, corners) = scene(false);
        let target = target_of(&planes, &corners);
        let truth = Pose::from_xyz_rpy([0.05, 0.0, 0.01], [0.0, 0.0, 0.0]);
        let sp = moved(&planes, &truth);
        let prior = Pose::from_xyz_rpy([0.03, 0.0, 0.0], [0.0, 0.0, 0.0]);
        let reg = register_two_step(
            &target,
            scan_of(&sp, &[]),
            prior,
            &LaserOdometryConfig::default(),
        );
        assert!(
            reg.degenerate[3] && reg.degenerate[4] && reg.degenerate[2],
            "{reg:?}"
        );
        assert!(!reg.degenerate[5] && !reg.degenerate[0] && !reg.degenerate[1]);
        // x comes from the prior, z from the scan.
        assert!(
            (reg.pose.translation[0] - 0.03).abs() < 1e-6,
            "{:?}",
            reg.pose
        );
        assert!(
            (reg.pose.translation[2] - 0.01).abs() < 1e-3,
            "{:?}",
            reg.pose
        );
    }
}
