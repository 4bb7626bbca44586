//! Registration: the laser's LM solves ([`super::laser_odometry::solve`]) put together as the
//! scan-to-scan two-step and the scan-to-map joint registration, and the degeneracy test with
//! solution remapping that decides which directions the scan determines.
//!
//! **Degeneracy** (Zhang, Kaess and Singh 2016, "solution remapping"): after the solve, the normal
//! matrix of each step (per residual) is eigen-decomposed; directions whose eigenvalue is below
//! `degeneracy_eigen_min` are not determined by the scan (under a car: travel along two parallel
//! planes). In those directions the estimate is replaced by the prior (the fused prediction from
//! visual and wheel odometry), and the directions are reported so fusion knows which of the laser's
//! components to distrust.

use super::config::LaserOdometryConfig;
use super::geom::{Pose, V3, symmetric_eigen};
use super::laser_odometry::{FeatureTarget, about, increment_about, solve};

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

/// Replace the estimate by the prior along the degenerate eigen-directions of `h` (restricted to
/// `active`); returns the remapped pose and which parameters were mostly taken from the prior.
fn remap(
    estimate: &Pose,
    prior: &Pose,
    h: &[[f64; 6]; 6],
    active: &[usize],
    eigen_min: f64,
) -> (Pose, [bool; 6]) {
    let mut m = *h;
    for i in 0..6 {
        if !active.contains(&i) {
            m[i] = [0.0; 6];
            m[i][i] = 1e12;
        }
    }
    let (values, vectors) = symmetric_eigen(&m);
    let centre = prior.translation;
    let delta = increment_about(centre, &estimate.compose(&prior.inverse()));
    let mut kept = [0.0; 6];
    let mut bad_weight = [0.0; 6];
    for (e, &value) in values.iter().enumerate() {
        let v: [f64; 6] = std::array::from_fn(|k| vectors[k][e]);
        if value >= eigen_min {
            let proj: f64 = (0..6).map(|k| v[k] * delta[k]).sum();
            for k in 0..6 {
                kept[k] += proj * v[k];
            }
        } else {
            for k in 0..6 {
                bad_weight[k] += v[k] * v[k];
            }
        }
    }
    let degenerate = std::array::from_fn(|k| active.contains(&k) && bad_weight[k] > 0.5);
    (about(centre, &kept).compose(prior), degenerate)
}

/// Register source features to `target` with all six parameters in one LM problem (the scan-to-map
/// refinement), starting from and falling back to `prior` = `target_from_source`.
pub fn register_joint(
    target: &FeatureTarget,
    planes: &[V3],
    corners: &[V3],
    prior: Pose,
    iterations: u32,
    config: &LaserOdometryConfig,
) -> Registration {
    let active = [0, 1, 2, 3, 4, 5];
    let (pose, h, residuals, rms_m) =
        solve(target, planes, corners, prior, &active, iterations, config);
    let (pose, degenerate) = remap(&pose, &prior, &h, &active, config.degeneracy_eigen_min);
    Registration {
        pose,
        degenerate,
        residuals,
        rms_m,
    }
}

/// Scan-to-scan two-step registration: `prev_from_cur`, starting from and falling back to `prior`.
/// `step1_planes` (the plane features plus the ground's) fix z, roll and pitch; `planes` and
/// `corners` then fix x, y and yaw.
pub fn register_two_step(
    target: &FeatureTarget,
    step1_planes: &[V3],
    planes: &[V3],
    corners: &[V3],
    prior: Pose,
    config: &LaserOdometryConfig,
) -> Registration {
    let step1 = [0, 1, 5];
    let (pose1, h1, n1, _) = solve(
        target,
        step1_planes,
        &[],
        prior,
        &step1,
        config.iterations,
        config,
    );
    let (pose1, deg1) = remap(&pose1, &prior, &h1, &step1, config.degeneracy_eigen_min);
    let step2 = [2, 3, 4];
    let (pose2, h2, n2, rms_m) = solve(
        target,
        planes,
        corners,
        pose1,
        &step2,
        config.iterations,
        config,
    );
    let (pose, deg2) = remap(&pose2, &pose1, &h2, &step2, config.degeneracy_eigen_min);
    Registration {
        pose,
        degenerate: std::array::from_fn(|k| deg1[k] || deg2[k]),
        residuals: n1.max(n2),
        rms_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::laser_odometry::tests::{moved, scene, target_of};

    #[test]
    fn recovers_a_known_motion_in_both_modes() {
        let (planes, corners) = scene(true);
        let target = target_of(&planes, &corners);
        let truth = Pose::from_xyz_rpy([0.04, 0.01, 0.005], [0.003, -0.004, 0.01]);
        let (sp, sc) = (moved(&planes, &truth), moved(&corners, &truth));
        // The synthetic tyres are a small share of the residuals: accept weaker directions than
        // the default (which is tuned to hand x, y and yaw to wheel odometry under real cars).
        let config = LaserOdometryConfig {
            degeneracy_eigen_min: 0.01,
            ..LaserOdometryConfig::default()
        };
        for reg in [
            register_two_step(&target, &sp, &sp, &sc, Pose::IDENTITY, &config),
            register_joint(&target, &sp, &sc, Pose::IDENTITY, 10, &config),
        ] {
            let err = reg.pose.compose(&truth.inverse()).to_increment();
            assert!(err.iter().all(|e| e.abs() < 3e-3), "{err:?} {reg:?}");
            assert!(reg.degenerate.iter().all(|&d| !d), "{reg:?}");
        }
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
            let reg = register_joint(&target, &sp, &sc, world_from_target, 10, &config);
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

    #[test]
    fn two_parallel_planes_leave_x_y_yaw_to_the_prior() {
        let (planes, corners) = scene(false);
        let target = target_of(&planes, &corners);
        let truth = Pose::from_xyz_rpy([0.05, 0.0, 0.01], [0.0, 0.0, 0.0]);
        let sp = moved(&planes, &truth);
        let prior = Pose::from_xyz_rpy([0.03, 0.0, 0.0], [0.0, 0.0, 0.0]);
        let reg = register_two_step(
            &target,
            &sp,
            &sp,
            &[],
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
