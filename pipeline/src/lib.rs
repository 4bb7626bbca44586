//! The point-cloud building pipeline (docs/architecture.md section 6, steps 2-7; paper sections 3.1-3.5).
//!
//! [`Pipeline`] takes sensor data one message at a time and returns the fused cloud at the end. It
//! is pure: no clocks, files or unseeded randomness; every stamp is an input (seconds on one common
//! clock that the caller maps the sensor and MCU clocks onto).
//!
//! Per lidar frame `k` (the paper's order):
//! 1. points move from the lidar's manual frame to the robot frame (`mounts`);
//! 2. [`deskew`]: motion compensation to the frame's start (eq. 1, velocity from wheel odometry;
//!    the general constant twist when turning, the last fused velocity without wheels);
//! 3. [`ground`]: RANSAC ground plane (3.1), kept out of the features;
//! 4. [`features`]: window test, outliers, smoothness, corners and planes (3.3, eqs. 2-5);
//! 5. [`laser_odometry`]: two-step LM against frame `k - 1`, starting from the fused prediction of
//!    the other sources; degenerate directions fall back to that prediction;
//! 6. [`fusion`]: Algorithm 1 over laser, [`visual_odometry`] (depth frames, tracked as they arrive)
//!    and wheel odometry, under the ten-frame constant-velocity reference (eqs. 6-7), with the
//!    wheels' slip scale measured by the laser over a long baseline ([`slip`]);
//! 7. [`map`]: scan-to-map refinement against the local feature map (3.5), then the frame's points
//!    (and the depth points in its interval) are fused into the output cloud. The paper's
//!    bilateral filter of the fused cloud is not applied: it pulls small parts that hang a few
//!    centimetres below the underside into it (decision record 036).
//!
//! **Streaming**: a lidar frame is processed as soon as every source in use (wheel, depth) has
//! reported past the frame's end, so the odometry of its interval is complete; [`Pipeline::finish`]
//! flushes what is left.
//!
//! **Slip replay** (`fusion.slip-replay-s`): the slip scale is significant only after about a
//! metre of travel, and the frames before it were placed with the unscaled wheels (3 % slip: 3 cm
//! by then). The frames of the run's start are kept, and once, when the scale first turns
//! significant, steps 2-7 run again over them from a fresh state whose fusion applies that
//! scale from the first frame; then the run goes on. On a slipping pass this removes the bias
//! the unscaled first metre leaves in the approach end; slip-free passes are unchanged
//! (decision record 009).

// `!(x > 0.0)` is deliberate throughout: it rejects NaN along with the out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Small fixed-size matrix code reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

pub mod config;
// The pipeline's geometry, re-exported so that `pipeline::geom::X` names it.
pub use passangle_geom as geom;
pub mod deskew;
pub mod features;
pub mod fusion;
pub mod ground;
pub mod laser_odometry;
pub mod map;
pub mod registration;
pub mod slip;
pub mod visual_odometry;

use std::collections::VecDeque;
use std::sync::Arc;

use thiserror::Error;

pub use config::PipelineConfig;
pub use visual_odometry::DepthImage;

use self::deskew::{DeskewModel, Velocity};
use self::features::RingPoint;
use self::fusion::{Fusion, Source, SourceRate};
use self::geom::{Pose, Twist6, V3, VoxelIndex, voxel_of};
use self::laser_odometry::{FeatureTarget, GROUND_TAG_BIT};
use self::map::{CloudAccumulator, FeatureMap, FloorAccumulator};
use self::registration::{
    JointProblem, Scan, keep_components, register_joint, register_two_step, unaided,
};
use self::slip::{ScanAt, SlipMeter};
use self::visual_odometry::{VisualOdometry, VisualStep};

/// One lidar return as the pipeline needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarPoint {
    /// Position in the lidar's manual frame (x right, y forward at azimuth 0, z up), metres.
    pub xyz_in_lidar_m: [f32; 3],
    /// Firing time after the frame's start, seconds.
    pub time_offset_s: f32,
    /// Azimuth of the firing, radians.
    pub azimuth_rad: f32,
    /// Ring 0..16 by elevation.
    pub ring: u8,
}

/// One revolution of the lidar.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarFrame {
    /// Frame start (first firing), seconds on the common clock.
    pub stamp_s: f64,
    /// Points in firing order.
    pub points: Vec<LidarPoint>,
}

/// Wheel odometry from the firmware (`protocol::mcu::Odometry`), stamped on the common clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelOdometry {
    /// Seconds on the common clock.
    pub stamp_s: f64,
    /// Integrated pose in the odometry frame, metres.
    pub x_m: f64,
    /// Integrated pose, metres.
    pub y_m: f64,
    /// Integrated heading, radians.
    pub yaw_rad: f64,
    /// Body velocity (robot frame), m/s.
    pub vx_mps: f64,
    /// Body velocity, m/s.
    pub vy_mps: f64,
    /// Yaw rate, rad/s.
    pub wz_radps: f64,
}

impl WheelOdometry {
    /// From the firmware's message, with its MCU stamp already mapped to `stamp_s`.
    pub fn from_mcu(msg: &protocol::mcu::Odometry, stamp_s: f64) -> Self {
        Self {
            stamp_s,
            x_m: f64::from(msg.x_m),
            y_m: f64::from(msg.y_m),
            yaw_rad: f64::from(msg.yaw_rad),
            vx_mps: f64::from(msg.vx_mps),
            vy_mps: f64::from(msg.vy_mps),
            wz_radps: f64::from(msg.wz_radps),
        }
    }

    /// This report with its position and speeds times `scale` (a calibrated distance scale:
    /// the increment between any two reports, all the pipeline takes from the wheels, is then
    /// `scale` times as long); heading and yaw rate unchanged.
    #[must_use]
    pub fn scaled(self, scale: f64) -> Self {
        Self {
            x_m: self.x_m * scale,
            y_m: self.y_m * scale,
            vx_mps: self.vx_mps * scale,
            vy_mps: self.vy_mps * scale,
            ..self
        }
    }
}

/// The pose estimated for one lidar frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryPoint {
    /// Frame start, seconds.
    pub stamp_s: f64,
    /// `world_from_robot` at the frame start (world = robot frame at the first frame).
    pub world_from_robot: Pose,
    /// Which source each fused increment component came from (`Zero` for the first frame).
    pub chosen: [Source; 6],
    /// Components the laser odometry could not determine.
    pub laser_degenerate: [bool; 6],
    /// Components the scan-to-map refinement could not determine or that its wheel gate rejected
    /// (both keep the fused prediction's value); all false when it did not run.
    pub refine_rejected: [bool; 6],
}

/// Counters for the report and the benchmarks.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PipelineStats {
    /// Lidar frames processed.
    pub frames: usize,
    /// Lidar points in.
    pub points_in: usize,
    /// Points marked ground.
    pub ground_points: usize,
    /// Frames where no ground plane was found.
    pub frames_without_ground: usize,
    /// Points rejected as outliers.
    pub outlier_points: usize,
    /// Corner features selected.
    pub corners: usize,
    /// Plane features selected.
    pub planes: usize,
    /// Frames where the laser was degenerate in at least one component.
    pub degenerate_frames: usize,
    /// Frames where the scan-to-scan laser was degenerate, per component `[rx, ry, rz, tx, ty, tz]`.
    pub laser_degenerate: [usize; 6],
    /// Frames where the scan-to-map refinement was degenerate, per component.
    pub refine_degenerate: [usize; 6],
    /// Frames where the refinement's rotation / translation group disagreed with the wheels and
    /// was rejected (`fusion.gate-refinement-rotation-by-wheel`; the translation is never
    /// rejected, so its count stays 0).
    pub refine_gated: [usize; 2],
    /// Frames deskewed with the general twist model.
    pub twist_deskews: usize,
    /// Depth frames received / tracked.
    pub depth_frames: usize,
    /// Depth frames with a visual odometry step.
    pub visual_steps: usize,
    /// Depth points added to the output cloud (`visual.add-to-cloud`).
    pub depth_points: usize,
    /// Wheel odometry messages received.
    pub wheel_messages: usize,
    /// Fused components taken from [laser, visual, wheel, reference, zero].
    pub chosen: [usize; 5],
    /// Long-baseline slip measurements (per translation component) fusion accepted.
    pub scale_measurements: usize,
    /// The wheel scale factor fusion applied in the last frame (1: no significant slip).
    pub wheel_scale: f64,
    /// The long-baseline wheel scale estimate in the last frame, applied or not, and its
    /// standard error (NaN and infinite without measurements).
    pub wheel_scale_estimate: (f64, f64),
    /// Long-baseline yaw measurements fusion kept (`fusion.wheel-yaw-bias`).
    pub yaw_measurements: usize,
    /// The wheel yaw-rate bias fusion took off in the last frame, rad/s (0: none significant).
    pub wheel_yaw_bias_radps: f64,
    /// Times steps 2-7 ran again from the first frame with a significant wheel scale
    /// (`fusion.slip-replay-s`): 0 or 1. The other counters are the last pass's.
    pub slip_replays: usize,
}

/// The run's result.
#[derive(Debug, Clone, PartialEq)]
pub struct BuiltCloud {
    /// The fused cloud in the world frame (robot frame at the first lidar frame: x
    /// forward, y left, z up, origin on the ground below the robot's centre), metres.
    pub points_in_world: Vec<V3>,
    /// One pose per lidar frame.
    pub trajectory: Vec<TrajectoryPoint>,
    /// Counters.
    pub stats: PipelineStats,
}

/// The scan-to-map refinement's error along the path per metre travelled, where it determines
/// x. An assumption of the order the tuning set's runs show (the trajectories' largest x errors:
/// 1.3-5.4 cm over 4.6-8.3 m of path with the wheels' simulated scale errors; with the wheels'
/// distance calibrated, 2.3-4.7 cm over 5.6-9.2 m in the empty world, where the map holds only
/// the vehicle, and 0.4-1.7 cm in the halls), not a measured property of the real robot.
pub const MAP_X_SIGMA_PER_M: f64 = 0.005;

impl BuiltCloud {
    /// Where the lidar's optical centre was at each frame, world frame: the trajectory with the
    /// mount's offset (`lidar_xyz_m`, robot frame) applied. The angle calculator's view checks
    /// need the sensor's height, not the robot's.
    pub fn lidar_path(&self, lidar_xyz_m: V3) -> Vec<V3> {
        self.trajectory
            .iter()
            .map(|t| t.world_from_robot.apply(lidar_xyz_m))
            .collect()
    }

    /// The trajectory's standard uncertainty along the path per metre travelled, for the angle
    /// calculator's budget: over the frames where the refinement did not determine x, the
    /// wheels' stated speed error relative to the run's mean speed; elsewhere
    /// [`MAP_X_SIGMA_PER_M`]. Approximate: a per-frame mix of two stated errors, not a fit.
    pub fn x_sigma_per_m(&self, fusion: &config::FusionConfig) -> f64 {
        let (Some(first), Some(last)) = (self.trajectory.first(), self.trajectory.last()) else {
            return MAP_X_SIGMA_PER_M;
        };
        let t = last.world_from_robot.translation;
        let s = first.world_from_robot.translation;
        let metres = (t[0] - s[0]).hypot(t[1] - s[1]);
        let seconds = last.stamp_s - first.stamp_s;
        let n = self.trajectory.len() as f64;
        let by_wheels = self
            .trajectory
            .iter()
            .filter(|tp| tp.refine_rejected[3])
            .count() as f64
            / n;
        let wheel_per_m = if metres > 0.1 && seconds > 0.0 {
            fusion.wheel_speed_sigma_mps / (metres / seconds)
        } else {
            MAP_X_SIGMA_PER_M
        };
        (by_wheels * wheel_per_m.powi(2) + (1.0 - by_wheels) * MAP_X_SIGMA_PER_M.powi(2)).sqrt()
    }
}

/// Bad input to the pipeline.
#[derive(Debug, Error, PartialEq)]
pub enum PipelineError {
    /// A config value is out of range; names the key.
    #[error("pipeline config: {0}")]
    InvalidConfig(String),
    /// A message's stamp went backwards or is not finite.
    #[error("{what} stamp {stamp_s} s is not after the previous one ({previous_s} s)")]
    StampOrder {
        /// Which stream.
        what: &'static str,
        /// The offending stamp.
        stamp_s: f64,
        /// The stream's previous stamp.
        previous_s: f64,
    },
    /// A depth frame is malformed.
    #[error("{0}")]
    BadDepthFrame(String),
}

/// A lidar frame's points in the robot frame, motion-compensated, with the lidar's firing
/// times and ranges (steps 1-2).
struct RobotFrame {
    points: Vec<V3>,
    times_s: Vec<f64>,
    ranges_m: Vec<f64>,
}

/// Steps 5-6's result for one frame: the fused pose and what it was made of.
struct FusedOdometry {
    /// The interval since the previous frame, seconds.
    dt_s: f64,
    /// The previous frame's pose.
    prev_world: Pose,
    /// The previous pose moved by the fused rate over the interval.
    predicted_world: Pose,
    /// The source of each fused component.
    chosen: [Source; 6],
    /// The laser's degenerate components.
    laser_degenerate: [bool; 6],
    /// Wheel odometry over the interval, if it covers it.
    wheel: Option<SourceRate>,
    /// The laser settings the interval was registered with (see [`unaided`]).
    laser_config: config::LaserOdometryConfig,
}

/// Steps 5-7a's result for one frame.
struct PoseEstimate {
    /// The frame's pose.
    world_from_robot: Pose,
    /// The source of each fused component.
    chosen: [Source; 6],
    /// The laser's degenerate components.
    laser_degenerate: [bool; 6],
    /// The components the refinement left at the fused prediction.
    refine_rejected: [bool; 6],
}

/// The previous frame, kept as the scan-to-scan target.
#[derive(Debug, Clone)]
struct PreviousFrame {
    stamp_s: f64,
    target: Arc<FeatureTarget>,
    world_from_robot: Pose,
}

/// The streaming pipeline. See the module docs.
#[derive(Debug, Clone)]
pub struct Pipeline {
    config: PipelineConfig,
    robot_from_lidar: Pose,
    /// Queued frames with their end stamps (the start plus the last point's firing time).
    pending: VecDeque<(LidarFrame, f64)>,
    wheel: Vec<WheelOdometry>,
    visual: VisualOdometry,
    visual_steps: Vec<VisualStep>,
    last_depth_s: Option<f64>,
    depth_points: VecDeque<(f64, Vec<V3>)>,
    robot_from_camera: Pose,
    fusion: Fusion,
    previous: Option<PreviousFrame>,
    slip: SlipMeter,
    last_rate: Twist6,
    map: FeatureMap,
    cloud: CloudAccumulator,
    /// Ground points of the output when `map.ground-voxel-m` is set (else they go to `cloud`).
    ground_cloud: Option<FloorAccumulator>,
    trajectory: Vec<TrajectoryPoint>,
    stats: PipelineStats,
    /// The ground plane of the first frame, world frame: `(normal, offset)`.
    world_ground: Option<(V3, f64)>,
    /// What the slip replay needs (`fusion.slip-replay-s`).
    replay: Replay,
}

/// The frames of the run's start kept for one replay of steps 2-7 once the wheel scale is first
/// significant (`fusion.slip-replay-s`).
#[derive(Debug, Clone, Default)]
struct Replay {
    /// Lidar frames processed so far, in order.
    frames: Vec<LidarFrame>,
    /// Depth points already added to the cloud, with their stamps, in order.
    depth_points: Vec<(f64, Vec<V3>)>,
    /// Nothing more is kept: replay off, done, or its window passed.
    closed: bool,
}

impl Pipeline {
    /// A pipeline with a checked config.
    pub fn new(config: PipelineConfig) -> Result<Self, PipelineError> {
        config.validate()?;
        Ok(Self::fresh(config))
    }

    /// A pipeline in its initial state for a checked `config`.
    fn fresh(config: PipelineConfig) -> Self {
        let m = &config.mounts;
        let robot_from_camera = Pose::from_xyz_rpy(m.camera_xyz_m, m.camera_rpy_rad);
        Self {
            robot_from_lidar: Pose::from_xyz_rpy(m.lidar_xyz_m, m.lidar_rpy_rad),
            pending: VecDeque::new(),
            wheel: Vec::new(),
            visual: VisualOdometry::new(
                config.visual.clone(),
                robot_from_camera,
                config.laser.degeneracy_eigen_min,
            ),
            visual_steps: Vec::new(),
            last_depth_s: None,
            depth_points: VecDeque::new(),
            robot_from_camera,
            fusion: Fusion::new(config.fusion.clone()),
            previous: None,
            slip: SlipMeter::new(if config.fusion.use_laser && config.fusion.use_wheel {
                config.fusion.wheel_scale_baseline_m
            } else {
                0.0
            }),
            last_rate: [0.0; 6],
            map: FeatureMap::new(
                config.map.feature_voxel_m,
                config.map.points_per_voxel,
                config.map.min_point_spacing_m,
            ),
            cloud: CloudAccumulator::new(config.map.output_voxel_m),
            ground_cloud: (config.map.ground_voxel_m > 0.0)
                .then(|| FloorAccumulator::new(config.map.ground_voxel_m)),
            trajectory: Vec::new(),
            stats: PipelineStats::default(),
            world_ground: None,
            replay: Replay {
                closed: !replays_slip(&config),
                ..Replay::default()
            },
            config,
        }
    }

    /// The trajectory so far.
    pub fn trajectory(&self) -> &[TrajectoryPoint] {
        &self.trajectory
    }

    /// Queue a lidar frame; it is processed once the other sources have caught up with it.
    pub fn push_lidar_frame(&mut self, frame: LidarFrame) -> Result<(), PipelineError> {
        let previous_s = self
            .pending
            .back()
            .map(|(f, _)| f.stamp_s)
            .or(self.previous.as_ref().map(|p| p.stamp_s))
            .unwrap_or(f64::NEG_INFINITY);
        if !(frame.stamp_s > previous_s && frame.stamp_s.is_finite()) {
            return Err(PipelineError::StampOrder {
                what: "lidar frame",
                stamp_s: frame.stamp_s,
                previous_s,
            });
        }
        let end_s = frame.stamp_s
            + frame
                .points
                .iter()
                .map(|p| f64::from(p.time_offset_s))
                .fold(0.0, f64::max);
        self.pending.push_back((frame, end_s));
        self.drain(false);
        Ok(())
    }

    /// Add a wheel odometry message.
    pub fn push_wheel_odometry(&mut self, odometry: WheelOdometry) -> Result<(), PipelineError> {
        let previous_s = self.wheel.last().map_or(f64::NEG_INFINITY, |w| w.stamp_s);
        if !(odometry.stamp_s > previous_s && odometry.stamp_s.is_finite()) {
            return Err(PipelineError::StampOrder {
                what: "wheel odometry",
                stamp_s: odometry.stamp_s,
                previous_s,
            });
        }
        self.stats.wheel_messages += 1;
        self.wheel.push(odometry);
        self.drain(false);
        Ok(())
    }

    /// Keep a depth frame's points for the cloud (where the lidar does not see) and, when the
    /// fusion uses visual odometry, track it.
    pub fn push_depth_frame(&mut self, frame: DepthImage) -> Result<(), PipelineError> {
        if !self.config.visual.enabled {
            return Ok(());
        }
        frame.check().map_err(PipelineError::BadDepthFrame)?;
        let previous_s = self.last_depth_s.unwrap_or(f64::NEG_INFINITY);
        if !(frame.stamp_s > previous_s) {
            return Err(PipelineError::StampOrder {
                what: "depth frame",
                stamp_s: frame.stamp_s,
                previous_s,
            });
        }
        self.stats.depth_frames += 1;
        if self.config.visual.add_to_cloud {
            let lidar_from_robot = self.robot_from_lidar.inverse();
            let min_range_m = self.config.features.min_range_m;
            let points = frame
                .sampled_points(&self.config.visual)
                .into_iter()
                .map(|p| self.robot_from_camera.apply(p))
                .filter(|&p| outside_lidar_view(lidar_from_robot.apply(p), min_range_m))
                .collect();
            self.depth_points.push_back((frame.stamp_s, points));
        }
        let stamp_s = frame.stamp_s;
        // Visual odometry only when the fusion uses it: its steps are read by nothing else.
        if self.config.fusion.use_visual {
            let prior = self
                .last_depth_s
                .and_then(|a| self.wheel_rate(a, stamp_s).map(|r| (a, r)))
                .map_or(Pose::IDENTITY, |(a, r)| {
                    Pose::from_increment(scale_twist(&r.rate, stamp_s - a))
                });
            if let Some(step) = self.visual.push(frame, prior) {
                self.stats.visual_steps += 1;
                self.visual_steps.push(step);
            }
        }
        self.last_depth_s = Some(stamp_s);
        self.drain(false);
        Ok(())
    }

    /// Process everything still queued and return the result.
    pub fn finish(mut self) -> BuiltCloud {
        self.drain(true);
        self.flush_depth_points(f64::INFINITY);
        let mut raw = self.cloud.points();
        if let Some(ground) = &self.ground_cloud {
            raw.extend(ground.points());
        }
        BuiltCloud {
            points_in_world: raw,
            trajectory: self.trajectory,
            stats: self.stats,
        }
    }

    /// Process queued frames whose interval every active source covers (all of them if `all`).
    fn drain(&mut self, all: bool) {
        while let Some(&(_, end_s)) = self.pending.front() {
            let wheel_ready = !self.config.fusion.use_wheel
                || self.wheel.last().is_none_or(|w| w.stamp_s >= end_s);
            let depth_ready = !(self.config.fusion.use_visual && self.config.visual.enabled)
                || self.last_depth_s.is_none_or(|s| s >= end_s);
            if !(all || wheel_ready && depth_ready) {
                break;
            }
            let Some((frame, _)) = self.pending.pop_front() else {
                break;
            };
            self.process(&frame);
            self.keep_for_replay(frame);
        }
    }

    /// Keep a processed frame for the slip replay; run the replay when the wheel scale has just
    /// become significant, or stop keeping frames when the window has passed.
    fn keep_for_replay(&mut self, frame: LidarFrame) {
        if self.replay.closed {
            return;
        }
        let first_s = self
            .replay
            .frames
            .first()
            .map_or(frame.stamp_s, |f| f.stamp_s);
        let elapsed_s = frame.stamp_s - first_s;
        self.replay.frames.push(frame);
        // The scale is exactly 1 until the estimate is significant, at least
        // `fusion.wheel-scale-min-slip` away from 1.
        if (self.fusion.wheel_scale() - 1.0).abs() > 1e-12 {
            self.replay_with_scale();
        } else if elapsed_s > self.config.fusion.slip_replay_s {
            self.replay = Replay {
                closed: true,
                ..Replay::default()
            };
        }
    }

    /// Steps 2-7 again over the kept frames, from a fresh state whose fusion applies the wheel
    /// scale just found from the first frame on: the travel before the scale was significant is
    /// then scaled like the rest (the first pass's map, cloud and trajectory are dropped). The
    /// inputs not yet used and what was derived from them as they arrived (visual odometry's
    /// steps) stay.
    fn replay_with_scale(&mut self) {
        let frames = std::mem::take(&mut self.replay.frames);
        let flushed_depth = std::mem::take(&mut self.replay.depth_points);
        let mut fresh = Self::fresh(self.config.clone());
        fresh.fusion.preset_wheel_scale(self.fusion.wheel_scale());
        fresh.replay.closed = true;
        fresh.pending = std::mem::take(&mut self.pending);
        fresh.wheel = std::mem::take(&mut self.wheel);
        std::mem::swap(&mut fresh.visual, &mut self.visual);
        fresh.visual_steps = std::mem::take(&mut self.visual_steps);
        fresh.last_depth_s = self.last_depth_s;
        fresh.depth_points = std::mem::take(&mut self.depth_points);
        for points in flushed_depth.into_iter().rev() {
            fresh.depth_points.push_front(points);
        }
        // Message counters stay; the per-frame ones are counted again by the second pass.
        fresh.stats = PipelineStats {
            depth_frames: self.stats.depth_frames,
            visual_steps: self.stats.visual_steps,
            wheel_messages: self.stats.wheel_messages,
            slip_replays: self.stats.slip_replays + 1,
            ..PipelineStats::default()
        };
        *self = fresh;
        for frame in &frames {
            self.process(frame);
        }
    }

    /// Velocity for deskewing the frame starting at `t0_s`: wheel odometry's twist if it covers
    /// the frame, else the constant-velocity reference (the last fused rate until there is one).
    fn deskew_velocity(&self, t0_s: f64) -> Velocity {
        let i = self.wheel.partition_point(|w| w.stamp_s < t0_s);
        if self.config.fusion.use_wheel
            && let Some(w) = self.wheel.get(i).or_else(|| self.wheel.last())
            && (w.stamp_s - t0_s).abs() < 0.2
        {
            return Velocity {
                linear_mps: V3::new(w.vx_mps, w.vy_mps, 0.0),
                angular_radps: V3::new(0.0, 0.0, w.wz_radps),
            };
        }
        // The ten-frame constant-velocity reference, not the last frame's rate: deskewing with the
        // last scan-to-scan estimate feeds its error back with gain -1 (an undamped alternation
        // between long and short increments); the mean damps it.
        let r = self.fusion.reference().unwrap_or(self.last_rate);
        Velocity {
            linear_mps: V3::new(r[3], r[4], r[5]),
            angular_radps: V3::new(r[0], r[1], r[2]),
        }
    }

    fn process(&mut self, frame: &LidarFrame) {
        let frame_index = self.stats.frames as u64;
        let robot = self.deskewed_robot_frame(frame);
        let split = self.segment_ground(&robot.points, frame_index);
        let is_ground = split
            .as_ref()
            .map_or_else(|| vec![false; robot.points.len()], |s| s.is_ground.clone());
        let feats = self.extract_features(frame, &robot, &is_ground);

        let step1_planes = step1_planes(&feats, self.config.laser.ground_sample_voxel_m);
        let scan = Scan {
            step1_planes: &step1_planes,
            step2_planes: feats.planes.len(),
            corners: &feats.corners,
        };
        // The frame's floor, which sets its roll, pitch and height (`map.level-with-ground`).
        let floor = split
            .as_ref()
            .filter(|_| self.config.map.level_with_ground)
            .map(|s| (s.plane.normal, s.plane.offset_m));
        let mut pose = self.estimate_pose(frame.stamp_s, scan, floor);
        if let Some(plane) = floor {
            pose.world_from_robot = self.level(&pose.world_from_robot, plane);
        }
        let candidates = Candidates::of(&feats, frame_index);
        self.extend_map(&pose.world_from_robot, &candidates);
        self.add_frame_to_cloud(
            &robot,
            &is_ground,
            &feats.is_outlier,
            &pose.world_from_robot,
        );
        self.trajectory.push(TrajectoryPoint {
            stamp_s: frame.stamp_s,
            world_from_robot: pose.world_from_robot,
            chosen: pose.chosen,
            laser_degenerate: pose.laser_degenerate,
            refine_rejected: pose.refine_rejected,
        });
        self.flush_depth_points(frame.stamp_s);
        let target = Arc::new(FeatureTarget {
            corners: tagged_index(candidates.corners, self.config.laser.max_correspondence_m),
            planes: tagged_index(candidates.planes, self.config.laser.max_correspondence_m),
        });
        self.track_slip(
            frame_index,
            frame.stamp_s,
            scan,
            pose.world_from_robot,
            target,
        );
    }

    /// Steps 1-2: the frame's points in the robot frame (`mounts`), motion-compensated to the
    /// frame's start ([`deskew`]), with their firing times and ranges from the lidar.
    fn deskewed_robot_frame(&mut self, frame: &LidarFrame) -> RobotFrame {
        let n = frame.points.len();
        let mut robot = RobotFrame {
            points: Vec::with_capacity(n),
            times_s: Vec::with_capacity(n),
            ranges_m: Vec::with_capacity(n),
        };
        for p in &frame.points {
            let l = V3::from(p.xyz_in_lidar_m.map(f64::from));
            robot.points.push(self.robot_from_lidar.apply(l));
            robot.times_s.push(f64::from(p.time_offset_s));
            robot.ranges_m.push(l.norm());
        }
        let velocity = self.deskew_velocity(frame.stamp_s);
        if deskew::deskew(
            &mut robot.points,
            &robot.times_s,
            velocity,
            &self.config.deskew,
        ) == DeskewModel::Twist
        {
            self.stats.twist_deskews += 1;
        }
        robot
    }

    /// Step 3: the frame's RANSAC ground plane and its inliers ([`ground`]); `None` (counted)
    /// when the frame has no plane.
    fn segment_ground(&mut self, points: &[V3], frame_index: u64) -> Option<ground::GroundSplit> {
        let split = ground::segment_ground(
            points,
            self.robot_from_lidar.translation[2],
            &self.config.ground,
            frame_index,
        );
        if split.is_none() {
            self.stats.frames_without_ground += 1;
        }
        split
    }

    /// Step 4: per-ring feature extraction and outlier rejection ([`features`]); counts the
    /// frame's points by class.
    fn extract_features(
        &mut self,
        frame: &LidarFrame,
        robot: &RobotFrame,
        is_ground: &[bool],
    ) -> features::Features {
        let ground_enabled = self.config.ground.enabled;
        let ring_points: Vec<RingPoint> = frame
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| RingPoint {
                p: robot.points[i],
                range_m: robot.ranges_m[i],
                azimuth_rad: f64::from(p.azimuth_rad),
                ring: p.ring,
                is_ground: ground_enabled && is_ground[i],
            })
            .collect();
        let feats = features::extract(&ring_points, &self.config.features);
        self.stats.frames += 1;
        self.stats.points_in += robot.points.len();
        self.stats.ground_points += is_ground.iter().filter(|&&g| g).count();
        self.stats.outlier_points += feats.is_outlier.iter().filter(|&&o| o).count();
        self.stats.corners += feats.corners.len();
        self.stats.planes += feats.planes.len();
        feats
    }

    /// Step 7a: the frame's feature candidates join the scan-to-map refinement's map.
    fn extend_map(&mut self, world_from_robot: &Pose, candidates: &Candidates) {
        if self.config.map.refine {
            self.map.add(
                world_from_robot,
                candidates.map_planes(self.config.map.level_with_ground),
                &candidates.corners,
            );
        }
    }

    /// Step 7b: the frame's points, placed at its pose, join the output cloud; outliers, ground
    /// (unless kept) and points beyond `map.output-max-range-m` are left out.
    fn add_frame_to_cloud(
        &mut self,
        robot: &RobotFrame,
        is_ground: &[bool],
        is_outlier: &[bool],
        world_from_robot: &Pose,
    ) {
        let max_range_m = self.config.map.output_max_range_m;
        for (i, &p) in robot.points.iter().enumerate() {
            if is_outlier[i] || robot.ranges_m[i] > max_range_m {
                continue;
            }
            self.add_output(world_from_robot.apply(p), is_ground[i]);
        }
    }

    /// Step 6b's slip evidence ([`slip`]): register the frame against a keyframe a baseline
    /// behind it and hand the laser and wheel distances to fusion, then keep the frame as a
    /// keyframe if the meter wants one; the frame (its feature `target`) becomes the next
    /// scan-to-scan target. Records the wheel scale fusion applied to this frame.
    fn track_slip(
        &mut self,
        frame_index: u64,
        stamp_s: f64,
        scan: Scan<'_>,
        world_from_robot: Pose,
        target: Arc<FeatureTarget>,
    ) {
        self.stats.wheel_scale = self.fusion.wheel_scale();
        self.stats.wheel_scale_estimate = self.fusion.wheel_scale_estimate();
        self.stats.wheel_yaw_bias_radps = self.fusion.wheel_yaw_bias_radps();
        if let Some(wheel) = wheel_pose_at(&self.wheel, stamp_s) {
            let at = ScanAt {
                frame: frame_index,
                stamp_s,
                wheel,
                world_from_robot,
            };
            self.measure_slip(&at, scan);
            if self.slip.wants_keyframe(frame_index, &wheel) {
                self.slip.add_keyframe(at, Arc::clone(&target));
            }
        }
        self.previous = Some(PreviousFrame {
            stamp_s,
            target,
            world_from_robot,
        });
    }

    /// Register the frame against the keyframe a baseline behind it, if any, and hand the
    /// distance pairs and the yaw evidence to fusion.
    fn measure_slip(&mut self, at: &ScanAt, scan: Scan<'_>) {
        if self.slip.is_due(&at.wheel) {
            let measured = self.slip.measure(at, scan, &self.config.laser);
            for (laser_m, wheel_m) in measured.distances {
                self.fusion
                    .add_scale_measurement(laser_m, wheel_m, measured.interval_s);
            }
            if let Some(excess_rad) = measured.yaw {
                self.fusion
                    .add_yaw_measurement(excess_rad, measured.interval_s);
            }
            self.stats.scale_measurements = self.fusion.scale_measurements();
            self.stats.yaw_measurements = self.fusion.yaw_measurements();
        }
    }

    /// A point of the output cloud, world frame; ground points go to the floor's columns if set.
    fn add_output(&mut self, p: V3, is_ground: bool) {
        match &mut self.ground_cloud {
            Some(ground) if is_ground => ground.add(p),
            _ => self.cloud.add(p),
        }
    }

    /// Steps 5-7a: laser odometry, fusion, scan-to-map refinement.
    fn estimate_pose(
        &mut self,
        stamp_s: f64,
        scan: Scan<'_>,
        floor: Option<(V3, f64)>,
    ) -> PoseEstimate {
        let Some(odometry) = self.fuse_odometry(stamp_s, scan) else {
            return PoseEstimate {
                world_from_robot: Pose::IDENTITY,
                chosen: [Source::Zero; 6],
                laser_degenerate: [false; 6],
                refine_rejected: [false; 6],
            };
        };
        let (world_from_robot, refine_rejected) = if self.config.map.refine && !self.map.is_empty()
        {
            self.refine_against_map(&odometry, scan, floor)
        } else {
            (odometry.predicted_world, [false; 6])
        };
        PoseEstimate {
            world_from_robot,
            chosen: odometry.chosen,
            laser_degenerate: odometry.laser_degenerate,
            refine_rejected,
        }
    }

    /// Steps 5-6: scan-to-scan laser odometry against the previous frame from the other sources'
    /// prediction, then fusion (Algorithm 1) of laser, visual and wheel odometry over the
    /// interval. `None` for the first frame.
    fn fuse_odometry(&mut self, stamp_s: f64, scan: Scan<'_>) -> Option<FusedOdometry> {
        let prev = self.previous.as_ref()?;
        let dt_s = stamp_s - prev.stamp_s;
        let prev_world = prev.world_from_robot;
        let wheel = self.wheel_rate(prev.stamp_s, stamp_s);
        let visual = self.visual_rate(prev.stamp_s, stamp_s);
        let predicted = self.fusion.predict(visual.as_ref(), wheel.as_ref());
        let prior = Pose::from_increment(scale_twist(&predicted, dt_s));
        // Without a measured prior (no wheel or visual odometry over the interval) the degeneracy
        // thresholds trade the laser against the constant-velocity guess instead.
        let laser_config = if wheel.is_none() && visual.is_none() {
            unaided(&self.config.laser)
        } else {
            self.config.laser.clone()
        };
        // Without the laser in fusion (e.g. the demo's wheel-only pipeline) it is not registered.
        let laser = self
            .config
            .fusion
            .use_laser
            .then(|| register_two_step(&prev.target, scan, prior, &laser_config));
        let laser_degenerate = laser.map_or([false; 6], |l| l.degenerate);
        if laser_degenerate.iter().any(|&d| d) {
            self.stats.degenerate_frames += 1;
        }
        count(&mut self.stats.laser_degenerate, laser_degenerate);
        let laser_rate = laser.map(|l| SourceRate {
            rate: scale_twist(&l.pose.to_increment(), 1.0 / dt_s),
            available: laser_degenerate.map(|d| !d),
        });
        let fused = self
            .fusion
            .fuse(laser_rate.as_ref(), visual.as_ref(), wheel.as_ref());
        for s in fused.chosen {
            self.stats.chosen[s as usize] += 1;
        }
        self.last_rate = fused.rate;
        let increment = Pose::from_increment(scale_twist(&fused.rate, dt_s));
        Some(FusedOdometry {
            dt_s,
            prev_world,
            predicted_world: prev_world.compose(&increment),
            chosen: fused.chosen,
            laser_degenerate,
            wheel,
            laser_config,
        })
    }

    /// Step 7a: the fused pose refined against the local feature map, with the wheels as a prior
    /// (`map.wheel-prior`) and the refined increment gated by them as Algorithm 1 gates the laser.
    /// Returns the pose and the components left at the fused prediction.
    fn refine_against_map(
        &mut self,
        odometry: &FusedOdometry,
        scan: Scan<'_>,
        floor: Option<(V3, f64)>,
    ) -> (Pose, [bool; 6]) {
        let dt_s = odometry.dt_s;
        let prior_information = (self.config.map.wheel_prior && odometry.wheel.is_some())
            .then(|| self.wheel_prior_information(dt_s));
        // With the frame's floor, roll, pitch and height are the floor's whatever the map says
        // (`process` levels the pose): the prediction is levelled first and the refinement solves
        // the other three ([`Scan::for_refinement`]).
        let mut predicted_world = odometry.predicted_world;
        if let Some(plane) = floor {
            predicted_world = self.level(&predicted_world, plane);
        }
        let ((planes, corners), active) = scan.for_refinement(floor.is_some());
        let refined = register_joint(&JointProblem {
            target: self.map.target(),
            planes,
            corners,
            prior: predicted_world,
            prior_information,
            active,
            iterations: self.config.map.iterations,
            config: &odometry.laser_config,
        });
        count(&mut self.stats.refine_degenerate, refined.degenerate);
        // The refinement's yaw is gated
        // by the wheels like the scan-to-scan laser in Algorithm 1: the refined increment over
        // the interval must agree with the wheels' rate.
        let refined_rate = scale_twist(
            &odometry
                .prev_world
                .inverse()
                .compose(&refined.pose)
                .to_increment(),
            1.0 / dt_s,
        );
        let agrees = self
            .fusion
            .refinement_gate(&refined_rate, odometry.wheel.as_ref());
        for (gated, ok) in self.stats.refine_gated.iter_mut().zip(agrees) {
            *gated += usize::from(!ok);
        }
        let keep: [bool; 6] = std::array::from_fn(|k| agrees[k / 3]);
        let world = if agrees == [true; 2] {
            refined.pose
        } else {
            keep_components(&refined.pose, &predicted_world, keep)
        };
        let rejected = std::array::from_fn(|k| refined.degenerate[k] || !keep[k]);
        (world, rejected)
    }

    /// `world_from_robot` levelled by the frame's floor `plane` (robot frame) against the first
    /// floor seen ([`level_with_ground`]).
    fn level(&mut self, world_from_robot: &Pose, plane: (V3, f64)) -> Pose {
        let world_ground = *self.world_ground.get_or_insert(plane);
        level_with_ground(world_from_robot, plane, world_ground)
    }

    /// The refinement's wheel prior over a frame of `dt_s` (`map.wheel-prior`): information on
    /// yaw, x and y, in the map residuals' units (`residual-sigma-m` squared over the wheels'
    /// variance over the frame). Approximation: the wheels' errors are correlated over about a
    /// second, and a per-frame prior treats them as independent from frame to frame.
    fn wheel_prior_information(&self, dt_s: f64) -> [[f64; 6]; 6] {
        let r2 = self.config.map.residual_sigma_m.powi(2);
        let f = &self.config.fusion;
        let mut l = [[0.0; 6]; 6];
        l[2][2] = r2 / (f.wheel_yaw_rate_sigma_radps * dt_s).powi(2);
        for k in [3, 4] {
            l[k][k] = r2 / (f.wheel_speed_sigma_mps * dt_s).powi(2);
        }
        l
    }

    /// Wheel odometry's rate over `[a_s, b_s]` (robot frame at `a_s`), if it covers the interval.
    fn wheel_rate(&self, a_s: f64, b_s: f64) -> Option<SourceRate> {
        if !self.config.fusion.use_wheel || b_s <= a_s {
            return None;
        }
        let pa = wheel_pose_at(&self.wheel, a_s)?;
        let pb = wheel_pose_at(&self.wheel, b_s)?;
        let inc = pa.inverse().compose(&pb).to_increment();
        Some(SourceRate {
            rate: scale_twist(&inc, 1.0 / (b_s - a_s)),
            available: [false, false, true, true, true, false],
        })
    }

    /// Visual odometry's rate over `[a_s, b_s]`: the overlap-weighted mean of the steps' rates,
    /// if the steps cover at least 90 % of the interval.
    fn visual_rate(&self, a_s: f64, b_s: f64) -> Option<SourceRate> {
        if !(self.config.fusion.use_visual && self.config.visual.enabled) || b_s <= a_s {
            return None;
        }
        let mut rate = [0.0; 6];
        let mut covered = 0.0;
        let mut degenerate = [false; 6];
        let first = self.visual_steps.partition_point(|s| s.to_s <= a_s);
        for step in self.visual_steps[first..]
            .iter()
            .take_while(|s| s.from_s < b_s)
        {
            let overlap = step.to_s.min(b_s) - step.from_s.max(a_s);
            if overlap <= 0.0 {
                continue;
            }
            let r = scale_twist(
                &step.robot_prev_from_cur.to_increment(),
                1.0 / (step.to_s - step.from_s),
            );
            for k in 0..6 {
                rate[k] += r[k] * overlap;
                degenerate[k] |= step.degenerate[k];
            }
            covered += overlap;
        }
        if covered < 0.9 * (b_s - a_s) {
            return None;
        }
        Some(SourceRate {
            rate: scale_twist(&rate, 1.0 / covered),
            available: degenerate.map(|d| !d),
        })
    }

    /// Add the depth points stamped up to `until_s` at poses interpolated on the trajectory.
    fn flush_depth_points(&mut self, until_s: f64) {
        while let Some((stamp_s, _)) = self.depth_points.front() {
            if *stamp_s > until_s {
                break;
            }
            let stamp_s = *stamp_s;
            let Some((_, points)) = self.depth_points.pop_front() else {
                break;
            };
            if !self.replay.closed {
                self.replay.depth_points.push((stamp_s, points.clone()));
            }
            let Some(pose) = pose_on_trajectory(&self.trajectory, stamp_s) else {
                continue;
            };
            self.stats.depth_points += points.len();
            for p in points {
                self.cloud.add(pose.apply(p));
            }
        }
    }
}

/// The VLP-16's field of view above and below its horizontal plane: its lasers fire from -15 to
/// +15 degrees.
pub const LIDAR_HALF_FOV_RAD: f64 = 15.0 * std::f64::consts::PI / 180.0;

/// Whether a point (lidar frame) lies where the lidar does not see from where it is: nearer than
/// `min_range_m`, or more than [`LIDAR_HALF_FOV_RAD`] above or below its horizontal plane. The
/// depth camera's points join the cloud there only (`visual.add-to-cloud`). Where the lidar does
/// see, its returns are the better measurement at the ranges that matter (the camera's noise
/// grows with the square of the depth, 1.5 cm at 1.8 m), and the camera's stereo bands at the
/// tyres' outlines would widen the tyres' silhouettes. Above its top beam the lidar sees nothing:
/// a high bumper 1 m ahead, the underside right above the robot.
fn outside_lidar_view(p: V3, min_range_m: f64) -> bool {
    let horizontal = p[0].hypot(p[1]);
    p.norm() < min_range_m || p[2].abs() > horizontal * LIDAR_HALF_FOV_RAD.tan()
}

/// Whether the run's start is kept for a slip replay: the window is set and the long-baseline
/// scale, the one that turns significant once, is measured.
fn replays_slip(config: &PipelineConfig) -> bool {
    let f = &config.fusion;
    f.slip_replay_s > 0.0 && f.use_laser && f.use_wheel && f.wheel_scale_baseline_m > 0.0
}

/// Correct roll, pitch and height of `world_from_robot` so that the frame's ground plane
/// (`normal . p + offset = 0`, robot frame) lands on the world's ground plane: the smallest
/// rotation taking the rotated normal onto the world normal (yaw untouched to first order), then a
/// shift along the world normal. On a flat floor this removes z, roll and pitch drift entirely.
fn level_with_ground(world_from_robot: &Pose, plane: (V3, f64), world: (V3, f64)) -> Pose {
    let (n_r, d_r) = plane;
    let (n_w, d_w) = world;
    let n_now = world_from_robot.apply_vector(n_r);
    let axis = n_now.cross(&n_w);
    let angle = axis_angle(axis.norm(), n_now.dot(&n_w));
    let fix = if axis.norm() > 1e-12 {
        axis * (angle / axis.norm())
    } else {
        V3::zeros()
    };
    let rotation = geom::exp_so3(fix) * world_from_robot.rotation;
    let mut translation = world_from_robot.translation;
    // Ground points p satisfy n_r . p = -d_r; in the world n_w . (R p + t) = -d_w.
    let shift = (d_r - d_w) - n_w.dot(&translation);
    translation += n_w * shift;
    Pose {
        rotation,
        translation,
    }
}

fn axis_angle(sin: f64, cos: f64) -> f64 {
    sin.atan2(cos)
}

/// Add one to the counters of the flagged components.
fn count(counters: &mut [usize; 6], flags: [bool; 6]) {
    for (c, f) in counters.iter_mut().zip(flags) {
        *c += usize::from(f);
    }
}

fn scale_twist(t: &Twist6, s: f64) -> Twist6 {
    t.map(|v| v * s)
}

/// The two-step registration's step-1 planes ([`Scan`]): the plane features, then one ground
/// candidate per `ground_voxel_m` voxel (`laser.ground-sample-voxel-m`). Public for the
/// diagnostics, which must register as the pipeline does.
pub fn step1_planes(feats: &features::Features, ground_voxel_m: f64) -> Vec<V3> {
    let mut planes = feats.planes.clone();
    planes.extend(
        downsample(&feats.ground_candidates, ground_voxel_m)
            .into_iter()
            .map(|(p, _)| p),
    );
    planes
}

/// One point per occupied voxel of `voxel_m` (the first seen), in the input's order.
fn downsample<T: Copy>(points: &[(V3, T)], voxel_m: f64) -> Vec<(V3, T)> {
    let mut seen: std::collections::HashSet<[i32; 3], _> = std::collections::HashSet::with_hasher(
        std::hash::BuildHasherDefault::<geom::FxHasher>::default(),
    );
    points
        .iter()
        .copied()
        .filter(|&(p, _)| seen.insert(voxel_of(p, voxel_m)))
        .collect()
}

/// A frame's registration target points (the next frame's scan-to-scan target, the feature
/// map's additions, the slip meter's keyframes) with their scan-line tags: frame index * 16 +
/// ring, unique over the run. Public for the diagnostics, which must build targets as the
/// pipeline does.
#[derive(Debug, Clone)]
pub struct Candidates {
    /// The plane candidates one per 5 cm voxel, then the ground candidates one per 10 cm voxel,
    /// tagged with [`GROUND_TAG_BIT`] too (plane fits never mix them with the underbody).
    pub planes: Vec<(V3, u32)>,
    /// How many of `planes`, from the first, are not ground.
    pub above_ground: usize,
    /// The corner candidates.
    pub corners: Vec<(V3, u32)>,
}

impl Candidates {
    /// The candidates of `feats`, frame `frame_index`.
    pub fn of(feats: &features::Features, frame_index: u64) -> Self {
        let tagged = |v: &[(V3, u8)]| -> Vec<(V3, u32)> {
            v.iter()
                .map(|&(p, ring)| (p, frame_index as u32 * 16 + u32::from(ring)))
                .collect()
        };
        let mut planes = tagged(&downsample(&feats.plane_candidates, 0.05));
        let above_ground = planes.len();
        planes.extend(
            tagged(&downsample(&feats.ground_candidates, 0.1))
                .into_iter()
                .map(|(p, t)| (p, t | GROUND_TAG_BIT)),
        );
        Self {
            planes,
            above_ground,
            corners: tagged(&feats.corner_candidates),
        }
    }

    /// The plane candidates the feature map keeps: without the ground when the floor levels the
    /// poses (`map.level-with-ground`), since the levelled refinement registers none
    /// ([`Scan::for_refinement`]).
    pub fn map_planes(&self, level_with_ground: bool) -> &[(V3, u32)] {
        if level_with_ground {
            &self.planes[..self.above_ground]
        } else {
            &self.planes
        }
    }
}

/// The voxel index of tagged points ([`Candidates`]) as the registrations search it. Public for
/// the diagnostics, which must build targets as the pipeline does.
pub fn tagged_index(points: Vec<(V3, u32)>, voxel_m: f64) -> VoxelIndex {
    let (p, t) = points.into_iter().unzip();
    VoxelIndex::new_tagged(p, t, voxel_m)
}

/// The wheel odometry pose at `t_s` (linear interpolation), if the messages bracket it.
fn wheel_pose_at(wheel: &[WheelOdometry], t_s: f64) -> Option<Pose> {
    let i = wheel.partition_point(|w| w.stamp_s < t_s);
    let b = wheel.get(i)?;
    let a = if i == 0 {
        if b.stamp_s > t_s {
            return None;
        }
        b
    } else {
        &wheel[i - 1]
    };
    let s = if b.stamp_s > a.stamp_s {
        (t_s - a.stamp_s) / (b.stamp_s - a.stamp_s)
    } else {
        0.0
    };
    let pose = |w: &WheelOdometry| Pose::from_xyz_rpy([w.x_m, w.y_m, 0.0], [0.0, 0.0, w.yaw_rad]);
    Some(pose(a).interpolate(&pose(b), s))
}

/// `world_from_robot` at `t_s` interpolated between trajectory points; the last pose extrapolated
/// is not used (only stamps inside the trajectory, or at the first pose).
fn pose_on_trajectory(trajectory: &[TrajectoryPoint], t_s: f64) -> Option<Pose> {
    let i = trajectory.partition_point(|p| p.stamp_s < t_s);
    let b = trajectory.get(i)?;
    if i == 0 {
        return (b.stamp_s - t_s < 0.05).then_some(b.world_from_robot);
    }
    let a = &trajectory[i - 1];
    let s = (t_s - a.stamp_s) / (b.stamp_s - a.stamp_s);
    Some(a.world_from_robot.interpolate(&b.world_from_robot, s))
}

#[cfg(test)]
mod test_support;
#[cfg(test)]
mod tests;
