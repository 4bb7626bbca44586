//! The pipeline's configuration: one struct per stage, each with documented defaults, grouped in
//! [`PipelineConfig`]. Deserialised from TOML (the onboard service embeds it as `[pipeline]`) with
//! kebab-case keys; unknown keys are rejected so a typo never silently falls back to a default.
//!
//! ```toml
//! [pipeline.ground]
//! distance-threshold-m = 0.03
//! [pipeline.features]
//! window-half-width = 5
//! ```

use serde::Deserialize;

/// Every stage's settings. `PipelineConfig::default()` is the tuned configuration (every stage's
/// own default, except that the bilateral filter is off: see its `Default` impl).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct PipelineConfig {
    /// Sensor mounts on the robot.
    pub mounts: MountConfig,
    /// Step 2: ground removal (paper 3.1).
    pub ground: GroundConfig,
    /// Step 3: motion compensation (paper 3.2, eq. 1).
    pub deskew: DeskewConfig,
    /// Step 4: feature extraction and outlier rejection (paper 3.3, eqs. 2-5).
    pub features: FeatureConfig,
    /// Step 5: scan-to-scan laser odometry (two-step Levenberg-Marquardt).
    pub laser: LaserOdometryConfig,
    /// Step 6a: visual odometry from D435 depth frames.
    pub visual: VisualOdometryConfig,
    /// Step 6b: fusion of laser, visual and wheel odometry (paper Algorithm 1, eqs. 6-7).
    pub fusion: FusionConfig,
    /// Step 7a: scan-to-map refinement and the output cloud.
    pub map: MapConfig,
    /// Step 7b: bilateral filter of the output cloud.
    pub filter: FilterConfig,
}

impl Default for PipelineConfig {
    /// Each stage's default, but the bilateral filter off. On lidar-only simulator clouds (wheel
    /// odometry, 1.5 cm range noise) it pulls small parts that hang a few centimetres below the
    /// underside into it: the sedan's exhaust silencer and the van's spare wheel limit their
    /// departure angles, which read +1.4 and +0.5 degrees off with the filter at 1 cm voxels (+3.7
    /// and +4.4 at 2 cm) against +0.7 and +0.2 without it (wheel-odometry clouds). A `[filter]` section turns it on (its
    /// keys default to [`FilterConfig::default`], which is enabled).
    fn default() -> Self {
        Self {
            mounts: MountConfig::default(),
            ground: GroundConfig::default(),
            deskew: DeskewConfig::default(),
            features: FeatureConfig::default(),
            laser: LaserOdometryConfig::default(),
            visual: VisualOdometryConfig::default(),
            fusion: FusionConfig::default(),
            map: MapConfig::default(),
            filter: FilterConfig {
                enabled: false,
                ..FilterConfig::default()
            },
        }
    }
}

/// Where the sensors sit on the robot (robot frame: x forward, y left, z up, origin on the ground
/// below the robot's centre).
#[derive(Debug, Clone, PartialEq, Deserialize)]
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
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct GroundConfig {
    /// Remove ground points from the features used for registration (the ablation switch).
    pub enabled: bool,
    /// Inlier distance to the plane, metres (paper: 0.03).
    pub distance_threshold_m: f64,
    /// Stop once the inliers exceed this fraction of the frame (paper: 50 %).
    pub early_stop_fraction: f64,
    /// Hypotheses tried at most.
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
            early_stop_fraction: 0.5,
            max_iterations: 60,
            max_tilt_rad: 0.35,
            min_depth_below_lidar_m: 0.05,
            seed: 7,
        }
    }
}

/// Motion compensation.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct DeskewConfig {
    /// Compensate motion at all.
    pub enabled: bool,
    /// Below this yaw rate (rad/s) the straight-line model of eq. 1 is used; above it the general
    /// constant-twist model.
    pub straight_max_yaw_rate_radps: f64,
    /// The paper's empirical scale factor alpha of eq. 1 (1.0: trust the odometry's speed).
    pub alpha: f64,
}

impl Default for DeskewConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            straight_max_yaw_rate_radps: 0.02,
            alpha: 1.0,
        }
    }
}

/// Feature extraction per ring.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct FeatureConfig {
    /// N: neighbours on each side of the window's centre (|W| = 2N).
    pub window_half_width: usize,
    /// Largest azimuth span of a window, radians (paper eq. 2: pi / 16).
    pub max_window_angle_rad: f64,
    /// Reject outliers (mean-distance test, eqs. 3-4, plus statistical outlier removal).
    pub outlier_removal: bool,
    /// Statistical outlier removal: reject points whose mean neighbour distance over range
    /// exceeds the frame's mean by this many standard deviations.
    pub outlier_std_ratio: f64,
    /// Corner threshold lambda_c1 on the smoothness c of eq. 5.
    pub corner_threshold: f64,
    /// Plane threshold lambda_c2 on c.
    pub plane_threshold: f64,
    /// Sectors per ring for balancing.
    pub sectors: usize,
    /// Corners kept per sector at most.
    pub corners_per_sector: usize,
    /// Planar points kept per sector at most.
    pub planes_per_sector: usize,
    /// Points closer than this to the lidar are ignored, metres.
    pub min_range_m: f64,
    /// Points farther than this are ignored, metres (far returns only add drift under a car).
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
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
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
            // 0.2 until 2026-11-26 (docs/pipeline-history.md, "The refinement levelled by the
            // floor"): at 0.4 the pickup's 5 Hz frames carry 397 ground samples instead of 812
            // (seed 1, mean per frame; at 0.2 half of them came from the one ring that reaches
            // the floor 6-8 m away, at 0.4 still 222). Since the floor levels every pose
            // (`map.level-with-ground`), step 1 only starts step 2; with the levelled
            // refinement, 10 seeds per pass: angle sds and ATE equal within their noise.
            ground_sample_voxel_m: 0.4,
            huber_m: 0.05,
            // 0.03 m and 0.1 rad (docs/pipeline-history.md, "The map's pull cut off"): 10 seeds
            // per pass against Huber alone, mean ATE lower on all five with exact wheels; with
            // the assumed wheel errors lower on three, the off-roader the same, the sedan 21.9 ->
            // 23.7 mm.
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
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct VisualOdometryConfig {
    /// Use depth frames at all.
    pub enabled: bool,
    /// Take every this-many-th pixel in each direction.
    pub pixel_stride: usize,
    /// Depths outside this band are ignored, metres (D435: 0.17 m minimum at 848x480).
    pub min_depth_m: f64,
    /// Depths outside this band are ignored, metres.
    pub max_depth_m: f64,
    /// Gauss-Newton iterations.
    pub iterations: u32,
    /// Largest point-to-plane residual accepted, metres.
    pub max_residual_m: f64,
    /// Add depth points to the output cloud. Off by default: on the simulated passes the
    /// camera's points moved the angles away from the truth more often than towards it (seeds
    /// 1-3 per pass, 2026-11-25: the pickup's approach +0.16 -> +0.41 mean, the off-roader's
    /// departure sd 0.05 -> 0.35; the SUV's and the van's tyres were misfitted until cb8b3c5), and
    /// the figures in the README are all without them (README, next step 5).
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
            add_to_cloud: false,
        }
    }
}

/// Odometry fusion (Algorithm 1).
// Independent on/off switches of a config file, not a state machine.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct FusionConfig {
    /// Use laser odometry as a source (off only for baselines).
    pub use_laser: bool,
    /// Use wheel odometry as a source.
    pub use_wheel: bool,
    /// Use visual odometry as a source. Off by default: fused on the simulated passes (seeds 1-3
    /// per pass, its points not in the cloud, 2026-11-25) it lowered the mean ATE on two passes
    /// (sedan 7.1 -> 6.1 mm, suv-offset 23.5 -> 22.1), raised it on the off-roader (9.0 -> 11.8)
    /// and read the pickup's approach higher (+0.17 -> +0.45 mean); the README's figures and the
    /// demo are laser + wheel. Visual odometry still runs when `visual.enabled` is set (its
    /// figures are in the run's statistics).
    pub use_visual: bool,
    /// The laser must also agree with the wheel odometry (within the tolerances) to win a group.
    pub gate_laser_by_wheel: bool,
    /// Frames averaged for the constant-velocity reference (eq. 6: ten).
    pub reference_frames: usize,
    /// Per-axis rotation deviation (rx, ry, rz) from the reference below which the laser is
    /// trusted, radians per second of motion. The paper's [0.1, 0.1, 0.1] quaternion components
    /// are per frame of its own rate; rates make the threshold independent of the frame rate.
    pub rotation_tolerance_radps: [f64; 3],
    /// Per-axis translation deviation (x, y, z) below which the laser is trusted, m/s (the paper's
    /// [0.1, 0.5, 0.1] allows more along the direction of travel).
    pub translation_tolerance_mps: [f64; 3],
    /// Laser-wheel pairs (per translation component and interval) the wheel scale (slip) factor
    /// is estimated over; 0 takes the wheels' distances as they are (see `fusion`).
    pub wheel_scale_frames: usize,
    /// Wheel travel between the two scans of one long-baseline slip measurement, metres (see
    /// `slip`); 0 turns the long-baseline wheel-scale estimator off.
    pub wheel_scale_baseline_m: f64,
    /// The long-baseline wheel scale is applied only when it differs from 1 by more than this
    /// fraction (and by more than three standard errors); see `fusion`. 0.025: approaching a car
    /// the measurements read up to 2 % short on slip-free simulated passes (the off-roader).
    pub wheel_scale_min_slip: f64,
    /// Seconds of lidar frames kept from the start of the run so that, once the long-baseline
    /// wheel scale is first significant, steps 2-7 run again over them with that scale from the
    /// first frame (0: off). The slip of the travel before the scale is significant (about a
    /// metre) otherwise stays in the trajectory and the cloud. Frames are kept until then or
    /// until this window has passed, whichever is first (a VLP-16 second is about 7 MB by count: 300,000 points of 24 bytes).
    pub slip_replay_s: f64,
    /// Rotation rates (rx, ry, rz) that no source determines come from the constant-velocity
    /// reference multiplied by this factor per frame: 1 holds the reference's rate (translation
    /// always does), 0 takes zero (the robot drives straight by design). See `fusion`.
    pub rotation_gap_decay: f64,
    /// Gate the scan-to-map refinement by wheel odometry as `gate-laser-by-wheel` gates the
    /// scan-to-scan laser: a group (rotation, translation) of the refined increment that differs
    /// from the wheels by a tolerance or more keeps the fused prediction's values.
    pub gate_refinement_by_wheel: bool,
    /// The same gate for the refinement's rotation group only: a refined increment whose rotation
    /// rates differ from the wheels' (yaw; the wheels know no roll or pitch) by a tolerance or more
    /// keeps the fused prediction's rotation, and its x, y stay the map's.
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
            // Off: on the slip-free simulated passes the per-frame estimate drifted off 1 (the
            // scan-to-scan x is too noisy for a few per cent); the long-baseline estimator below
            // replaces it. See `slip` and docs/pipeline-history.md, "Slip".
            wheel_scale_frames: 0,
            wheel_scale_baseline_m: 0.25,
            wheel_scale_min_slip: 0.025,
            slip_replay_s: 8.0,
            // Zero: held laser yaw rates integrated to 50 degrees on the simulated offroader
            // (laser only); see `fusion` and docs/pipeline-history.md, "Yaw under a car".
            rotation_gap_decay: 0.0,
            // Off: on the simulated passes (laser + wheel, seed 1, 9e49f69) it cut the largest yaw
            // error (suv-offset 2.8 -> 0.35 degrees) but rejected some of the map's drift
            // corrections: ATE offroader 2.48 -> 2.56 cm, pickup 0.45 -> 1.00 cm, van 1.68 -> 1.09.
            gate_refinement_by_wheel: false,
            // On: the refinement's yaw jumped by up to 1-2 degrees a frame where the map
            // determined it weakly (suv-offset leaving the car); seeds 1-3 of all five passes,
            // ATE equal or lower, largest yaw error suv-offset 1.2-2.3 -> 0.3-0.7 degrees.
            gate_refinement_rotation_by_wheel: true,
            wheel_speed_sigma_mps: 0.003,
            wheel_yaw_rate_sigma_radps: 0.004,
            // On: with the assumed mecanum wheel errors (`bench_pipeline 10 --wheel-noise`, map
            // wheel prior on) mean ATE 33/27/27/39/32 -> 30/27/22/35/28 mm (offroader, pickup,
            // sedan, suv-offset, van); on the exact simulated wheels it found a false bias of
            // 0.03-0.08 deg/s in 3 of 50 runs, angles within 0.03 degree, ATE within 0.8 mm.
            wheel_yaw_bias: true,
        }
    }
}

/// Scan-to-map refinement and the output cloud.
// Independent on/off switches of a config file, not a state machine.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct MapConfig {
    /// Refine each fused pose against the local feature map.
    pub refine: bool,
    /// Voxel of the feature map, metres; at least `laser.max-correspondence-m` (a search looks
    /// into the query's voxel and its 26 neighbours). The map keeps the first `points-per-voxel`
    /// points of each voxel (at least `min-point-spacing-m` apart since 2026-11-26). 0.2 (0.5
    /// until 2026-11-26): in 0.5 m voxels those were the points seen first, from far, 10-20 cm
    /// apart, and the refinement's plane and line fits through
    /// them missed curved and occluding surfaces seen from nearer later. Registered from the
    /// true pose against a map built at the true poses (`diag_laser_odometry NAME --map
    /// --free`), the map pulled each frame back along x by 12-48 mm on the five simulated passes
    /// and its yaw scattered by 4-15 mrad RMS; at 0.2 m by 5-12 mm and 1.3-5.5 mrad. In the
    /// pipeline (10 seeds per pass, exact wheels) mean ATE 9.6 / 26.0 / 10.0 / 23.0 / 14.7 ->
    /// 7.1 / 11.4 / 6.2 / 25.8 / 13.5 mm (off-roader, pickup, sedan, suv-offset, van) and sd <
    /// 0.15 on 14 of 15 angles instead of 12; with the assumed wheel errors 8 of 15 either way.
    /// The cost: 10-16 % more CPU per frame on four of the five passes (ten seeds side by side;
    /// the pickup 1.09-1.11 in interleaved runs), in the plane searches and fits against the
    /// denser map; a search index in 0.4 m voxels over the same 0.2 m caps gave the same output
    /// and no gain (1.004).
    /// A smaller map voxel also anchors the map less: more voxels are filled from later, drifted
    /// poses (`pipeline::tests`, 5 % slipping wheels: 62 % of their error left after 0.87 m
    /// against 32 %, of which part was the coarse map's backward pull). Measurements in
    /// docs/pipeline-history.md, "The feature map's voxel".
    pub feature_voxel_m: f64,
    /// Feature points kept per map voxel at most. 20; at 0.2 m voxels 10 and 40 gave the same
    /// angle counts within their noise and the same CPU (docs/pipeline-history.md).
    pub points_per_voxel: usize,
    /// A feature point is added to the map only where no point of its voxel lies nearer than
    /// this, metres (0: off; KISS-ICP's rule, the voxel over the square root of the points per
    /// voxel). 0.045 (off until 2026-11-26): the first points of a voxel are those seen first,
    /// often the same few centimetres of a surface from many frames, and the voxel was full
    /// before the robot saw the near side of the same part (a differential, a tyre, a face
    /// behind a depth step); a frame's fits then went through the far side and pulled x back.
    /// Registered from the true pose against a map built at the true poses (`diag_laser_odometry
    /// NAME --map --free`), the mean x pull per frame (off-roader, pickup, sedan, suv-offset,
    /// van) -9.8 / -3.5 / -3.6 / -10.9 / -10.8 mm -> -4.6 / -1.0 / -1.7 / -3.3 / -2.7; with the
    /// map that much less biased it is also weighted more against the wheels
    /// (`residual-sigma-m`). Measurements in docs/pipeline-history.md, "The map's points spaced".
    pub min_point_spacing_m: f64,
    /// Levenberg-Marquardt iterations of the refinement.
    pub iterations: u32,
    /// Voxel of the output cloud (centroid per voxel), metres. 5 mm: on lidar-only clouds the
    /// angles need the density for small parts. The sedan's exhaust silencer limits its departure
    /// angle and hangs only 1.7-6.5 cm below the underside; at 1 cm voxels it keeps too few points
    /// per envelope bin and the departure read +0.6 and +1.7 degrees off in two demo runs, at 5 mm
    /// +0.6 (wheel-odometry clouds of four vehicles: within 0.6 degree at 5 mm, 0.7 at 1 cm). The
    /// cost: about 2.9 M points instead of 1.2 M for a 7 m pass (the calculator needs about 1.2 s
    /// per million points).
    pub output_voxel_m: f64,
    /// Lidar points farther than this from the sensor are not added to the output, metres.
    ///
    /// 4 m: a frame's pose is its attitude averaged over the 100 ms sweep, so a 3-15 Hz
    /// vibration of the robot (0.2 degree RMS in the simulated suv-offset pass) tilts each
    /// firing by up to half a degree against it, which is 3-4 cm of height on the floor 4-8 m
    /// away. At the former 8 m those floor points rose 4-5 cm above the fitted ground, past the
    /// calculator's body threshold, and became the approach and departure witnesses: suv-offset
    /// seeds 1-5 read -22.6 / +0.3 / +0.5 / -0.2 / -23.6 (approach) and -23.1 / +1.0 / +0.8 /
    /// -23.1 / -24.4 (departure); at 4 m -0.2 / 0.16 and +0.7 / 0.5 (mean / sd). The robot passes
    /// under the whole vehicle, so every part of it comes within 4 m; seeds 1-3 of the other four
    /// passes moved within their seed-to-seed spread (README, "The point-cloud pipeline").
    pub output_max_range_m: f64,
    /// Keep ground points in the output cloud (the angle calculator fits the ground plane).
    pub keep_ground: bool,
    /// Side of the floor's columns in the output cloud, metres: the ground points (each frame's
    /// plane inliers) become one point per column of this side, their mean
    /// ([`super::map::FloorAccumulator`]); 0: they go into the output voxels like every other
    /// point. The calculator needs the ground only for its plane, and the floor is most of a run's
    /// points (about 70 % at 1 cm), so coarser floor cells make the cloud, the filter and the
    /// calculator several times smaller. 2 cm (as 3D voxels, before the columns): the sedan's demo
    /// cloud 2.7 M -> 1.3 M points, the calculator 3.4 s -> 0.7 s, the same angles within 0.02
    /// degree (sedan, van; offline clouds, 2026-11-22).
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
    /// tuning value rather than the lidar's range noise. 0.01 (0.02 until 2026-11-26). With the
    /// map's points unspaced, 0.01 let the map's backward pull through (the off-roader's approach
    /// -0.39 degree on exact wheels, 10 seeds); with them spaced (`min-point-spacing-m`) it holds
    /// wandering wheels better: against the unspaced 0.02, over 20 seeds per pass with the
    /// assumed errors, sd < 0.15 on 10 of 15 angles instead of 8 and mean ATE lower on all five
    /// passes. The cost is on exact wheels: against the spaced map at 0.02 (10 seeds) mean ATE
    /// higher on four of five passes (the van 5.4 -> 10.6 mm), and 6.1 mm instead of 1.3 over
    /// `pipeline::tests`' garage run. 0.005 let the pull through again (the off-roader's
    /// departure -0.40).
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
            keep_ground: true,
            ground_voxel_m: 0.02,
            level_with_ground: true,
            // On: the robot's mecanum wheels are not exact. With the assumed wheel errors
            // (`bench_pipeline 10 --wheel-noise`, 10 seeds) mean ATE 36/25/49/51/55 -> 33/27/27/
            // 39/32 mm (offroader, pickup, sedan, suv-offset, van), angle sd below 0.15 on 6 of 15
            // instead of 5; on the simulator's exact wheels (with `fusion.wheel-yaw-bias`) 10 ->
            // 12 of 15, but the pickup's ATE 7.7 -> 23 mm and suv-offset's departure +0.17 ->
            // +0.69 (docs/pipeline-history.md, "Wheel errors and the wheel prior").
            wheel_prior: true,
            residual_sigma_m: 0.01,
        }
    }
}

/// Edge-preserving bilateral filter of the output cloud.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case", default)]
pub struct FilterConfig {
    /// Filter at all.
    pub enabled: bool,
    /// Neighbourhood radius, metres.
    pub radius_m: f64,
    /// Spatial Gaussian sigma, metres.
    pub sigma_spatial_m: f64,
    /// Range (along-normal offset) Gaussian sigma, metres: offsets much larger than this (edges)
    /// barely move a point.
    pub sigma_normal_m: f64,
}

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            radius_m: 0.05,
            sigma_spatial_m: 0.025,
            sigma_normal_m: 0.02,
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
        let c: PipelineConfig = toml::from_str("[ground]\ndistance-threshold-m = 0.05\n").unwrap();
        assert!((c.ground.distance_threshold_m - 0.05).abs() < 1e-12);
        let e = toml::from_str::<PipelineConfig>("[ground]\ndistance-threshold = 0.05\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("distance-threshold"), "{e}");
    }
}
