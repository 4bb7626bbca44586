//! The pipeline's configuration: one struct per stage, each with documented defaults, grouped in
//! [`PipelineConfig`].
//!
//! **What an operator sets** (TOML, kebab-case keys; the onboard service embeds it as
//! `[processing.pipeline]`; unknown keys are rejected so a typo never silently falls back to a
//! default) is what differs from one robot to the next: where its sensors are mounted, the
//! lidar's near limit on this robot, the depth camera's band, which sensors it has and uses, and
//! its wheels' stated errors. Fourteen keys:
//!
//! ```toml
//! [pipeline.mounts]
//! lidar-xyz-m = [0.0, 0.0, 0.12]
//! [pipeline.fusion]
//! wheel-speed-sigma-mps = 0.003
//! ```
//!
//! **The method's parameters** (thresholds, iteration counts, voxels, tolerances, the ablation
//! switches of the paper's Figure 14) are fields too, so that tests and the ablation bench can
//! vary them in code, but `#[serde(skip)]`: no file sets them, a run's software version fixes
//! them, and each is documented where it is defined. None has a reason to differ between robots
//! (decision record 036).

use serde::{Deserialize, Serialize};

use crate::PipelineError;

/// Every stage's settings; `PipelineConfig::default()` is every stage's own default.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct PipelineConfig {
    /// Sensor mounts on the robot.
    pub mounts: MountConfig,
    /// Step 2: ground removal (paper 3.1).
    #[serde(skip)]
    pub ground: GroundConfig,
    /// Step 3: motion compensation (paper 3.2, eq. 1).
    #[serde(skip)]
    pub deskew: DeskewConfig,
    /// Step 4: feature extraction and outlier rejection (paper 3.3, eqs. 2-5).
    pub features: FeatureConfig,
    /// Step 5: scan-to-scan laser odometry (two-step Levenberg-Marquardt).
    #[serde(skip)]
    pub laser: LaserOdometryConfig,
    /// Step 6a: visual odometry from D435 depth frames.
    pub visual: VisualOdometryConfig,
    /// Step 6b: fusion of laser, visual and wheel odometry (paper Algorithm 1, eqs. 6-7).
    pub fusion: FusionConfig,
    /// Step 7: scan-to-map refinement and the output cloud.
    #[serde(skip)]
    pub map: MapConfig,
}

/// How many keys [`PipelineConfig::positive_values`] checks.
const POSITIVE_KEYS: usize = 15;

impl PipelineConfig {
    /// The values that must be positive numbers, by key.
    fn positive_values(&self) -> [(&'static str, f64); POSITIVE_KEYS] {
        [
            (
                "ground.distance-threshold-m",
                self.ground.distance_threshold_m,
            ),
            (
                "features.max-window-angle-rad",
                self.features.max_window_angle_rad,
            ),
            ("features.max-range-m", self.features.max_range_m),
            (
                "laser.max-correspondence-m",
                self.laser.max_correspondence_m,
            ),
            (
                "laser.ground-sample-voxel-m",
                self.laser.ground_sample_voxel_m,
            ),
            ("laser.huber-m", self.laser.huber_m),
            ("laser.max-residual-m", self.laser.max_residual_m),
            ("visual.max-depth-m", self.visual.max_depth_m),
            ("visual.max-residual-m", self.visual.max_residual_m),
            ("map.feature-voxel-m", self.map.feature_voxel_m),
            ("map.output-voxel-m", self.map.output_voxel_m),
            ("map.output-max-range-m", self.map.output_max_range_m),
            ("map.residual-sigma-m", self.map.residual_sigma_m),
            (
                "fusion.wheel-speed-sigma-mps",
                self.fusion.wheel_speed_sigma_mps,
            ),
            (
                "fusion.wheel-yaw-rate-sigma-radps",
                self.fusion.wheel_yaw_rate_sigma_radps,
            ),
        ]
    }

    /// A config from the text of a `[pipeline]`-like TOML table (kebab-case keys, unknown keys
    /// rejected, missing keys at their defaults), checked by [`Self::validate`].
    pub fn from_toml(text: &str) -> Result<Self, PipelineError> {
        let config: Self =
            toml::from_str(text).map_err(|e| PipelineError::InvalidConfig(e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// The near limit of the lidar's and the camera's range bands lies below the far one.
    fn check_bands(&self) -> Result<(), PipelineError> {
        for (key, near, far) in [
            (
                "features.min-range-m",
                self.features.min_range_m,
                self.features.max_range_m,
            ),
            (
                "visual.min-depth-m",
                self.visual.min_depth_m,
                self.visual.max_depth_m,
            ),
        ] {
            if !(near >= 0.0 && near < far) {
                return Err(PipelineError::InvalidConfig(format!(
                    "{key} = {near}: must be 0 or positive and under the far limit ({far} m)"
                )));
            }
        }
        Ok(())
    }

    /// Check every value the stages divide by or loop on; the error names the key.
    pub fn validate(&self) -> Result<(), PipelineError> {
        let positive = self.positive_values();
        for (key, v) in positive {
            if !(v > 0.0 && v.is_finite()) {
                return Err(PipelineError::InvalidConfig(format!(
                    "{key} = {v}: must be a positive number"
                )));
            }
        }
        if !(self.map.ground_voxel_m >= 0.0 && self.map.ground_voxel_m.is_finite()) {
            return Err(PipelineError::InvalidConfig(format!(
                "map.ground-voxel-m = {}: must be 0 (the output voxel) or a positive number",
                self.map.ground_voxel_m
            )));
        }
        for (key, v) in [
            ("laser.max-residual-rad", self.laser.max_residual_rad),
            ("fusion.slip-replay-s", self.fusion.slip_replay_s),
            (
                "laser.degeneracy-eigen-min",
                self.laser.degeneracy_eigen_min,
            ),
            (
                "laser.degeneracy-rotation-eigen-min-m2",
                self.laser.degeneracy_rotation_eigen_min_m2,
            ),
            (
                "laser.unaided-degeneracy-eigen-min",
                self.laser.unaided_degeneracy_eigen_min,
            ),
            (
                "laser.unaided-degeneracy-rotation-eigen-min-m2",
                self.laser.unaided_degeneracy_rotation_eigen_min_m2,
            ),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(PipelineError::InvalidConfig(format!(
                    "{key} = {v}: must be 0 or a positive number"
                )));
            }
        }
        if !(self.fusion.wheel_scale_baseline_m >= 0.0
            && self.fusion.wheel_scale_baseline_m.is_finite())
        {
            return Err(PipelineError::InvalidConfig(format!(
                "fusion.wheel-scale-baseline-m = {}: must be 0 (off) or a positive number",
                self.fusion.wheel_scale_baseline_m
            )));
        }
        if !(0.0..0.2).contains(&self.fusion.wheel_scale_min_slip) {
            return Err(PipelineError::InvalidConfig(format!(
                "fusion.wheel-scale-min-slip = {}: must lie in 0..0.2 (a fraction of the distance)",
                self.fusion.wheel_scale_min_slip
            )));
        }
        self.check_bands()?;
        if !(self.ground.confidence > 0.0 && self.ground.confidence < 1.0) {
            return Err(PipelineError::InvalidConfig(
                "ground.confidence must lie strictly between 0 and 1".into(),
            ));
        }
        if self.ground.max_iterations == 0 {
            return Err(PipelineError::InvalidConfig(
                "ground.max-iterations must be at least 1".into(),
            ));
        }
        if self.features.window_half_width == 0 || self.visual.pixel_stride == 0 {
            return Err(PipelineError::InvalidConfig(
                "features.window-half-width and visual.pixel-stride must be >= 1".into(),
            ));
        }
        let spacing = self.map.min_point_spacing_m;
        if !(spacing >= 0.0 && spacing < self.map.feature_voxel_m) {
            return Err(PipelineError::InvalidConfig(format!(
                "map.min-point-spacing-m = {spacing}: must be 0 (off) or positive and under \
                 map.feature-voxel-m ({})",
                self.map.feature_voxel_m
            )));
        }
        if self.laser.max_correspondence_m > self.map.feature_voxel_m {
            return Err(PipelineError::InvalidConfig(
                "laser.max-correspondence-m must not exceed map.feature-voxel-m".into(),
            ));
        }
        Ok(())
    }
}

/// Where the sensors sit on the robot (robot frame: x forward, y left, z up, origin on the ground
/// below the robot's centre).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct MountConfig {
    /// VLP-16 optical centre in the robot frame, metres.
    pub lidar_xyz_m: [f64; 3],
    /// Roll, pitch, yaw of the lidar's manual frame (x right, y forward at azimuth 0, z up) in the
    /// robot frame, radians. The default yaw of -pi/2 puts azimuth 0 along the robot's +x.
    pub lidar_rpy_rad: [f64; 3],
    /// D435 depth optical centre in the robot frame, metres.
    pub camera_xyz_m: [f64; 3],
    /// Roll, pitch, yaw of the camera's optical frame (x right, y down, z forward) in the robot
    /// frame, radians. The default looks straight up with the image's top towards the robot's
    /// front.
    pub camera_rpy_rad: [f64; 3],
}

impl Default for MountConfig {
    fn default() -> Self {
        Self {
            lidar_xyz_m: [0.0, 0.0, 0.12],
            lidar_rpy_rad: [0.0, 0.0, -std::f64::consts::FRAC_PI_2],
            camera_xyz_m: [0.12, 0.0, 0.09],
            // Optical z up, optical y (image down) backwards, optical x (image right) to the left:
            // a yaw of +pi/2 about the shared z axis.
            camera_rpy_rad: [0.0, 0.0, std::f64::consts::FRAC_PI_2],
        }
    }
}

/// RANSAC ground plane per frame.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundConfig {
    /// Remove ground points from the features used for registration (the ablation switch).
    pub enabled: bool,
    /// Inlier distance to the plane, metres (paper: 0.03).
    pub distance_threshold_m: f64,
    /// Probability that the search draws three ground points at least once: the hypotheses
    /// tried follow from it and the best plane's inlier fraction ([`super::ground`]). Replaces
    /// the paper's fixed stop at 50 % inliers, which under a car in a hall is never reached.
    pub confidence: f64,
    /// Hypotheses tried at most (bounds the CPU per frame).
    pub max_iterations: u32,
    /// Largest angle between the plane normal and the robot's z axis, radians.
    pub max_tilt_rad: f64,
    /// The plane must lie at least this far below the lidar, metres (rejects the underbody).
    pub min_depth_below_lidar_m: f64,
    /// Seed of the hypothesis sampler (mixed with the frame index).
    pub seed: u64,
}

impl Default for GroundConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            distance_threshold_m: 0.03,
            confidence: 0.9999,
            max_iterations: 1000,
            max_tilt_rad: 0.35,
            min_depth_below_lidar_m: 0.05,
            seed: 7,
        }
    }
}

/// Motion compensation.
#[derive(Debug, Clone, PartialEq)]
pub struct DeskewConfig {
    /// Compensate motion at all.
    pub enabled: bool,
    /// Below this yaw rate (rad/s) the straight-line model of eq. 1 is used; above it the general
    /// constant-twist model.
    pub straight_max_yaw_rate_radps: f64,
}

impl Default for DeskewConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            straight_max_yaw_rate_radps: 0.02,
        }
    }
}

/// Feature extraction per ring.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct FeatureConfig {
    /// N: neighbours on each side of the window's centre (|W| = 2N).
    #[serde(skip)]
    pub window_half_width: usize,
    /// Largest azimuth span of a window, radians (paper eq. 2: pi / 16).
    #[serde(skip)]
    pub max_window_angle_rad: f64,
    /// Reject outliers (mean-distance test, eqs. 3-4, plus statistical outlier removal).
    #[serde(skip)]
    pub outlier_removal: bool,
    /// Statistical outlier removal: reject points whose mean neighbour distance over range
    /// exceeds the frame's mean by this many standard deviations.
    #[serde(skip)]
    pub outlier_std_ratio: f64,
    /// Corner threshold lambda_c1 on the smoothness c of eq. 5.
    #[serde(skip)]
    pub corner_threshold: f64,
    /// Plane threshold lambda_c2 on c.
    #[serde(skip)]
    pub plane_threshold: f64,
    /// Sectors per ring for balancing.
    #[serde(skip)]
    pub sectors: usize,
    /// Corners kept per sector at most.
    #[serde(skip)]
    pub corners_per_sector: usize,
    /// Planar points kept per sector at most.
    #[serde(skip)]
    pub planes_per_sector: usize,
    /// Points closer than this to the lidar are ignored, metres.
    pub min_range_m: f64,
    /// Points farther than this are ignored, metres (far returns only add drift under a car).
    #[serde(skip)]
    pub max_range_m: f64,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        Self {
            window_half_width: 5,
            max_window_angle_rad: std::f64::consts::PI / 16.0,
            outlier_removal: true,
            outlier_std_ratio: 2.0,
            corner_threshold: 0.005,
            plane_threshold: 0.002,
            sectors: 6,
            corners_per_sector: 4,
            planes_per_sector: 12,
            min_range_m: 0.4,
            max_range_m: 12.0,
        }
    }
}

/// Scan-to-scan registration.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserOdometryConfig {
    /// Levenberg-Marquardt iterations per step.
    pub iterations: u32,
    /// Largest correspondence distance, metres.
    pub max_correspondence_m: f64,
    /// The ground sample of step 1 (z, roll, pitch) and of nothing else: one ground point per
    /// voxel of this size, metres.
    pub ground_sample_voxel_m: f64,
    /// Huber kernel width, metres.
    pub huber_m: f64,
    /// Residuals beyond `max-residual-m` plus what an attitude error of `max-residual-rad` moves
    /// them (their lever arm across the residual's direction) have no weight: the Huber kernel
    /// truncated (`laser_odometry::Kernel`), metres.
    pub max_residual_m: f64,
    /// The attitude error the cutoff allows for, radians (see `max-residual-m`).
    pub max_residual_rad: f64,
    /// Initial LM damping (relative to the Hessian's diagonal).
    pub lm_lambda: f64,
    /// An eigenvalue of a step's normal matrix below this (per correspondence) marks that
    /// direction degenerate; the prior fills it. For eigen-directions that are mostly translation
    /// (the translational block is dimensionless, at most 1); see `registration`.
    pub degeneracy_eigen_min: f64,
    /// The same for eigen-directions that are mostly rotation, m^2 (the rotational block holds
    /// squared lever arms, so it needs its own scale; see `registration`).
    pub degeneracy_rotation_eigen_min_m2: f64,
    /// `degeneracy-eigen-min` for intervals that neither wheel nor visual odometry covers (laser
    /// only): the prior is then only the constant-velocity guess, so a weaker laser translation
    /// is still the better estimate (see `registration`).
    pub unaided_degeneracy_eigen_min: f64,
    /// `degeneracy-rotation-eigen-min-m2` for intervals without wheel or visual odometry: there a
    /// weak laser rotation is worse than the straight-driving prior (see `registration`), m^2.
    pub unaided_degeneracy_rotation_eigen_min_m2: f64,
}

impl Default for LaserOdometryConfig {
    fn default() -> Self {
        Self {
            iterations: 8,
            max_correspondence_m: 0.2,
            // The floor levels every pose (`map.level-with-ground`), so step 1 only starts step
            // 2; a coarse ground sample keeps the one ring that reaches the far floor from
            // dominating it (decision record 022).
            ground_sample_voxel_m: 0.4,
            huber_m: 0.05,
            // A residual beyond what a 3 cm offset plus a 0.1 rad attitude error explain is
            // another surface, not this one (decision record 003).
            max_residual_m: 0.03,
            max_residual_rad: 0.1,
            lm_lambda: 1e-3,
            degeneracy_eigen_min: 0.3,
            degeneracy_rotation_eigen_min_m2: 0.3,
            unaided_degeneracy_eigen_min: 0.1,
            unaided_degeneracy_rotation_eigen_min_m2: 1.0,
        }
    }
}

/// D435 depth odometry (projective point-to-plane ICP between consecutive depth frames).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct VisualOdometryConfig {
    /// Use depth frames at all.
    pub enabled: bool,
    /// Take every this-many-th pixel in each direction.
    #[serde(skip)]
    pub pixel_stride: usize,
    /// Depths outside this band are ignored, metres (D435: 0.17 m minimum at 848x480).
    pub min_depth_m: f64,
    /// Depths outside this band are ignored, metres.
    pub max_depth_m: f64,
    /// Gauss-Newton iterations.
    #[serde(skip)]
    pub iterations: u32,
    /// Largest point-to-plane residual accepted, metres.
    #[serde(skip)]
    pub max_residual_m: f64,
    /// Add the depth camera's points to the output cloud where the lidar does not see them:
    /// nearer than `features.min-range-m` or outside its +-15 degree view (above its top beam: a
    /// high bumper ahead, the underside right above the robot). On by default: the lidar alone
    /// cannot see a bumper edge higher than about 0.39 m from a 1 m start (decision record 037).
    pub add_to_cloud: bool,
}

impl Default for VisualOdometryConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            pixel_stride: 8,
            min_depth_m: 0.17,
            max_depth_m: 3.0,
            iterations: 10,
            max_residual_m: 0.02,
            add_to_cloud: true,
        }
    }
}

/// Odometry fusion (Algorithm 1).
// Independent on/off switches of a config file, not a state machine.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct FusionConfig {
    /// Use laser odometry as a source (off only for baselines).
    pub use_laser: bool,
    /// Use wheel odometry as a source.
    pub use_wheel: bool,
    /// Use visual odometry as a source. Off by default: fused on the simulated passes it lowered
    /// the trajectory error on some and raised it on others (decision record 011). Visual
    /// odometry still runs when `visual.enabled` is set (its figures are in the run's statistics).
    pub use_visual: bool,
    /// The laser must also agree with the wheel odometry (within the tolerances) to win a group.
    #[serde(skip)]
    pub gate_laser_by_wheel: bool,
    /// Frames averaged for the constant-velocity reference (eq. 6: ten).
    #[serde(skip)]
    pub reference_frames: usize,
    /// Per-axis rotation deviation (rx, ry, rz) from the reference below which the laser is
    /// trusted, radians per second of motion. The paper's [0.1, 0.1, 0.1] quaternion components
    /// are per frame of its own rate; rates make the threshold independent of the frame rate.
    #[serde(skip)]
    pub rotation_tolerance_radps: [f64; 3],
    /// Per-axis translation deviation (x, y, z) below which the laser is trusted, m/s (the paper's
    /// [0.1, 0.5, 0.1] allows more along the direction of travel).
    #[serde(skip)]
    pub translation_tolerance_mps: [f64; 3],
    /// Wheel travel between the two scans of one long-baseline slip measurement, metres (see
    /// `slip`); 0 turns the long-baseline wheel-scale estimator off.
    #[serde(skip)]
    pub wheel_scale_baseline_m: f64,
    /// The long-baseline wheel scale is applied only when it differs from 1 by more than this
    /// fraction (and by more than three standard errors); see `fusion`. 0.025: approaching a car
    /// the measurements read up to 2 % short on slip-free simulated passes (the off-roader).
    #[serde(skip)]
    pub wheel_scale_min_slip: f64,
    /// Seconds of lidar frames kept from the start of the run so that, once the long-baseline
    /// wheel scale is first significant, steps 2-7 run again over them with that scale from the
    /// first frame (0: off). The slip of the travel before the scale is significant (about a
    /// metre) otherwise stays in the trajectory and the cloud. Frames are kept until then or
    /// until this window has passed, whichever is first (a VLP-16 second is about 7 MB by count: 300,000 points of 24 bytes).
    #[serde(skip)]
    pub slip_replay_s: f64,
    /// Gate the scan-to-map refinement's rotation by wheel odometry as `gate-laser-by-wheel`
    /// gates the scan-to-scan laser: a refined increment whose rotation
    /// rates differ from the wheels' (yaw; the wheels know no roll or pitch) by a tolerance or more
    /// keeps the fused prediction's rotation, and its x, y stay the map's.
    #[serde(skip)]
    pub gate_refinement_rotation_by_wheel: bool,
    /// The wheel odometry's velocity error (along and across, each), m/s: the standard deviation
    /// the scan-to-map refinement's wheel prior (`map.wheel-prior`) gives a frame's wheel
    /// translation, times the frame's duration. Default 0.003: the simulator's assumed mecanum
    /// model (`hil_sim::wheel_odometry::WheelNoise::TYPICAL_MECANUM`: 1 % of 0.3 m/s along,
    /// 3 mm/s across), not measured on the robot; set it from a real run.
    pub wheel_speed_sigma_mps: f64,
    /// The wheel odometry's yaw-rate error, rad/s, for the same prior. Default 0.004 (0.22
    /// deg/s: the assumed model's 0.1 deg/s bias and 0.2 deg/s wander together).
    pub wheel_yaw_rate_sigma_radps: f64,
    /// Measure the wheels' yaw-rate bias with the slip meter's long-baseline registrations (the
    /// wheels' turn against the laser's where the laser determines the yaw) and take it off the
    /// wheels' yaw rate once it is significant (three standard errors, at least four
    /// measurements), as the slip scale is taken off their distance. Needs
    /// `wheel-scale-baseline-m` > 0.
    #[serde(skip)]
    pub wheel_yaw_bias: bool,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            use_laser: true,
            use_wheel: true,
            use_visual: false,
            gate_laser_by_wheel: true,
            reference_frames: 10,
            rotation_tolerance_radps: [0.01, 0.01, 0.01],
            translation_tolerance_mps: [0.02, 0.02, 0.02],
            wheel_scale_baseline_m: 0.25,
            wheel_scale_min_slip: 0.025,
            slip_replay_s: 8.0,
            // On: where the map determines the yaw weakly (leaving the car) the refinement's
            // yaw can jump by degrees in a frame; the wheels bound it (decision record 005).
            gate_refinement_rotation_by_wheel: true,
            wheel_speed_sigma_mps: 0.003,
            wheel_yaw_rate_sigma_radps: 0.004,
            // On: mecanum wheels have a yaw-rate bias; the slip meter's long-baseline
            // registrations measure it (decision record 001).
            wheel_yaw_bias: true,
        }
    }
}

/// Scan-to-map refinement and the output cloud.
// Independent on/off switches of a config file, not a state machine.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, PartialEq)]
pub struct MapConfig {
    /// Refine each fused pose against the local feature map.
    pub refine: bool,
    /// Voxel of the feature map, metres; at least `laser.max-correspondence-m` (a search looks
    /// into the query's voxel and its 26 neighbours). The map keeps the first `points-per-voxel`
    /// points of each voxel, at least `min-point-spacing-m` apart. Small voxels keep the plane
    /// and line fits on the surfaces seen from near rather than on the points seen first from
    /// far; too small a voxel anchors the map less, as more voxels fill from later, drifted
    /// poses (decision record 021).
    pub feature_voxel_m: f64,
    /// Feature points kept per map voxel at most (decision record 021).
    pub points_per_voxel: usize,
    /// A feature point is added to the map only where no point of its voxel lies nearer than
    /// this, metres (0: off; KISS-ICP's rule, the voxel over the square root of the points per
    /// voxel). Without spacing, a voxel fills with the same few centimetres of a surface seen
    /// from many frames before the robot sees the near side of the same part, and the fits go
    /// through the far side and pull x back (decision record 025).
    pub min_point_spacing_m: f64,
    /// Levenberg-Marquardt iterations of the refinement.
    pub iterations: u32,
    /// Voxel of the output cloud (centroid per voxel), metres. The calculator's envelope needs
    /// the density for small low parts (an exhaust silencer a few centimetres below the
    /// underside keeps too few points per envelope bin at 1 cm).
    pub output_voxel_m: f64,
    /// Lidar points farther than this from the sensor are not added to the output, metres.
    ///
    /// A frame's pose is its attitude averaged over the 100 ms sweep, so a vibration of the
    /// robot tilts each firing by up to half a degree against it: 3-4 cm of height on the floor
    /// 4-8 m away, enough to lift far floor points past the calculator's body threshold. The
    /// robot passes under the whole vehicle, so every part of it comes within 4 m
    /// (decision record 010).
    pub output_max_range_m: f64,
    /// Side of the floor's columns in the output cloud, metres: the ground points (each frame's
    /// plane inliers) become one point per column of this side, their mean
    /// ([`super::map::FloorAccumulator`]); 0: they go into the output voxels like every other
    /// point. The calculator needs the ground only for its plane, and the floor is most of a
    /// run's points, so coarser floor cells make the cloud, the filter and the calculator
    /// several times smaller without moving the angles.
    pub ground_voxel_m: f64,
    /// Set each frame's roll, pitch and height from its RANSAC ground plane against the first
    /// frame's (a flat floor is an absolute reference; removes z, roll and pitch drift).
    pub level_with_ground: bool,
    /// Weigh the refinement's x, y and yaw against the wheels instead of taking them from the map
    /// wherever the map determines them: the fused prediction enters the solve as a Gaussian
    /// prior on x, y and yaw with the wheels' errors (`fusion.wheel-speed-sigma-mps`,
    /// `fusion.wheel-yaw-rate-sigma-radps`, times the frame's duration) against map residuals
    /// of `residual-sigma-m`. Only over intervals the wheels cover.
    pub wheel_prior: bool,
    /// The map residuals' noise for the wheel prior's weighting, metres. The solve counts its
    /// residuals as independent, which they are not (many points on few surfaces), so this is a
    /// tuning value rather than the lidar's range noise, chosen on the simulated passes with
    /// the assumed wheel errors (decision records 001 and 025).
    pub residual_sigma_m: f64,
}

impl Default for MapConfig {
    fn default() -> Self {
        Self {
            refine: true,
            feature_voxel_m: 0.2,
            points_per_voxel: 20,
            min_point_spacing_m: 0.045,
            iterations: 6,
            output_voxel_m: 0.005,
            output_max_range_m: 4.0,
            ground_voxel_m: 0.02,
            level_with_ground: true,
            // On: the robot's mecanum wheels are not exact; weighing the map against them
            // bounds both (decision record 001).
            wheel_prior: true,
            residual_sigma_m: 0.01,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_toml_gives_defaults_and_unknown_keys_are_rejected() {
        let c: PipelineConfig = toml::from_str("").unwrap();
        assert_eq!(c, PipelineConfig::default());
        let c: PipelineConfig =
            toml::from_str("[fusion]\nwheel-speed-sigma-mps = 0.005\n").unwrap();
        assert!((c.fusion.wheel_speed_sigma_mps - 0.005).abs() < 1e-12);
        let e = toml::from_str::<PipelineConfig>("[fusion]\nwheel-speed-sigma = 0.005\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("wheel-speed-sigma"), "{e}");
    }

    #[test]
    fn the_methods_parameters_are_not_settable() {
        for text in [
            "[ground]\ndistance-threshold-m = 0.05\n",
            "[map]\noutput-voxel-m = 0.01\n",
            "[features]\ncorner-threshold = 0.01\n",
            "[fusion]\nreference-frames = 5\n",
            "[visual]\npixel-stride = 4\n",
        ] {
            let e = toml::from_str::<PipelineConfig>(text)
                .unwrap_err()
                .to_string();
            assert!(e.contains("unknown"), "{text}: {e}");
        }
    }

    #[test]
    fn the_operator_sets_fourteen_keys() {
        let table = toml::Value::try_from(PipelineConfig::default()).unwrap();
        let keys: usize = table
            .as_table()
            .unwrap()
            .values()
            .map(|t| t.as_table().map_or(1, toml::Table::len))
            .sum();
        assert_eq!(keys, 14, "{table}");
    }
}
