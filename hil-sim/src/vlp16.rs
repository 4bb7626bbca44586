//! The simulated Velodyne VLP-16: firing timing, ray casting from the moving robot, range noise,
//! quantisation, range limits, dropouts and reflectivity, emitted as byte-exact packets with
//! `vlp16`'s packet `emit` (this crate has no encoder of its own).
//!
//! # Timing (VLP-16 manual, single-return mode)
//! Data packet `k` starts at `k * 12 * 110.592 us` of simulation time. Block `b` of it starts
//! `b * 110.592 us` later and holds two firing sequences 55.296 us apart; laser `i` of a sequence
//! fires `i * 2.304 us` after its start. The head turns clockwise (seen from above) at
//! `rpm / 60` turns per second from azimuth 0 at t = 0; every ray is cast at the true azimuth of
//! its own firing, and each block carries the azimuth of its first firing (0.01 degree units), so
//! the decoder's per-firing interpolation reproduces the firing azimuths to within 0.005 degree.
//!
//! # Motion
//! `world_from_lidar = trajectory.pose_at(t) * robot_from_lidar` is evaluated at the start and end
//! of each packet (1.327 ms) and interpolated linearly, element by element, for each firing
//! sequence (55.296 us: at 0.3 m/s the robot moves 17 um within one sequence, far below the 2 mm
//! range quantum). The interpolation error is second order in the packet time, about
//! `w^2 A dt^2 / 8`: 7e-6 rad for a 0.2 degree RMS vibration at 15 Hz (0.03 mm at 5 m range) and
//! 1e-7 m during a 0.5 m/s^2 ramp, so a sweep of 0.1 s is distorted by the robot's motion as a
//! real one, and the pose costs two trajectory evaluations per packet.
//!
//! # Measurement model
//! Each laser's beam starts at its vertical offset above the optical centre (manual Table 9-1, the
//! same offsets the decoder adds back) and points along `(cos w sin a, cos w cos a, sin w)` in the
//! manual's sensor frame. The true range gets Gaussian noise (sigma `range_noise_sigma_m`, clipped
//! at `range_noise_limit_m`, the +-3 cm of the data sheet), is rounded to 2 mm, and is reported as 0
//! (no return) below `min_range_m`, above `max_range_m`, or with probability `dropout_probability`.
//! Reflectivity is the surface's base value ([`base_reflectivity`]) times the cosine of the
//! incidence angle, at least 1 for any return.
//!
//! # Field effects (each off by default; the scenario's `[lidar]` table turns them on)
//! - **Footprint** (`beam_divergence_mrad`): the beam is not a line. Five rays sample it (centre
//!   and +- half the divergence across and along the scan line); echoes closer than
//!   `mixed_pixel_max_gap_m` merge into one return at their energy-weighted range, so at a depth
//!   edge (a part's silhouette against the floor pan or the ground) the point lands between the
//!   two surfaces (a mixed pixel), and thin edges widen by the footprint.
//! - **Dark rubber** (`tyre_return_s50_per_m`): tyre hits return with a probability falling with
//!   range and grazing incidence (assumed law, `1 / (1 + (s50 / s)^4)`, `s = cos / range`).
//! - **Range bias** (`range_bias_sigma_m`): each laser adds a fixed bias drawn once per seed
//!   (stream `derive_seed(seed, 11)` of the sensor's seed), as the calibration residuals of a real
//!   unit.
//!
//! The extra random draws happen only where an effect is on, so a configuration without them
//! gives the same packets as before they existed.
//!
//! # Randomness
//! Packet `k` draws from `ChaCha8Rng::seed_from_u64(seed)` on stream `k`, so every packet is a pure
//! function of (scenario, seed, k) and can be produced in any order, bit for bit.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;
use vlp16::{
    BlockRepr, ChannelRepr, DataPacketRepr, PositionPacketRepr, PpsStatus, Product, ReturnMode,
};

use crate::geometry::{Isometry, Normalized, Vec3, rot_from_rpy};
use crate::trajectory::Trajectory;
use crate::world::{Candidates, Hit, Scene, SurfaceId, SurfaceKind, base_reflectivity};

/// Elevation of each laser id in firing order, degrees (manual Table 9-1).
pub const ELEVATION_DEG: [f64; 16] = [
    -15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0,
];

/// Vertical offset of each laser id's beam origin, millimetres (manual Table 9-1).
pub const VERTICAL_OFFSET_MM: [f64; 16] = [
    11.2, -0.7, 9.7, -2.2, 8.1, -3.7, 6.6, -5.1, 5.1, -6.6, 3.7, -8.1, 2.2, -9.7, 0.7, -11.2,
];

/// Time between firings, seconds.
pub const FIRING_S: f64 = 2.304e-6;
/// Time of one firing sequence, seconds.
pub const SEQUENCE_S: f64 = 55.296e-6;
/// Time of one data block (two sequences), seconds.
pub const BLOCK_S: f64 = 110.592e-6;
/// Time covered by one data packet, seconds.
pub const PACKET_S: f64 = 12.0 * BLOCK_S;
/// Microseconds per hour (the sensor timestamp wraps here).
pub const HOUR_US: u64 = 3_600_000_000;

/// Sensor settings (the scenario's `[lidar]` table; every key optional).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Vlp16Config {
    /// Rotation rate, revolutions per minute (300..=1200, i.e. 5-20 Hz).
    pub rpm: f64,
    /// Standard deviation of the range noise, metres.
    pub range_noise_sigma_m: f64,
    /// Range noise is clipped to +- this, metres (data sheet accuracy).
    pub range_noise_limit_m: f64,
    /// No return closer than this, metres.
    pub min_range_m: f64,
    /// No return farther than this, metres.
    pub max_range_m: f64,
    /// Probability that a firing with a hit returns nothing.
    pub dropout_probability: f64,
    /// Optical centre in the robot frame, metres.
    pub mount_xyz_m: [f64; 3],
    /// Mount roll, pitch, yaw in degrees; all zero puts azimuth 0 along the robot's +x.
    pub mount_rpy_deg: [f64; 3],
    /// Sensor clock at simulation time 0, microseconds past the hour.
    pub clock_offset_us: u64,
    /// One position packet after every this many data packets (0: none).
    pub position_packet_every: u32,
    /// Head azimuth at simulation time 0, degrees. A real pass starts at whatever phase the
    /// spinning head has, and the phase decides where the rings' passes land on the vehicle (at
    /// 5 Hz and 0.35 m/s the robot moves 7 cm per rotation). Absent: a scenario draws it from its
    /// seed ([`crate::scenario::Scenario::lidar_config`]); the bare sensor starts at 0.
    pub start_azimuth_deg: Option<f64>,
    /// Full beam divergence, milliradians, horizontal and vertical (the VLP-16's is about 3 x
    /// 1.5). All zero (the default): a thin beam, one ray per firing. Otherwise each firing casts
    /// its centre ray and four rays at +- half the divergence horizontally and vertically, and
    /// their echoes make the return (see "Footprint" in the module docs).
    pub beam_divergence_mrad: [f64; 2],
    /// Echoes of one footprint closer together than this merge into one return at their
    /// energy-weighted range (a mixed pixel); farther apart, the stronger group wins. Metres.
    pub mixed_pixel_max_gap_m: f64,
    /// Dark rubber: a tyre hit returns with probability `1 / (1 + (s50 / s)^4)`, `s = cos(incidence)
    /// / range` in 1/m, `s50` this value. 0 (the default): tyres return like everything else.
    pub tyre_return_s50_per_m: f64,
    /// Standard deviation of each laser's fixed range bias (a calibration residual), metres,
    /// drawn once per seed and clipped at 3 sigma. 0 (the default): no bias.
    pub range_bias_sigma_m: f64,
}

impl Default for Vlp16Config {
    fn default() -> Self {
        Self {
            rpm: 600.0,
            range_noise_sigma_m: 0.015,
            range_noise_limit_m: 0.03,
            min_range_m: 0.5,
            max_range_m: 100.0,
            dropout_probability: 0.002,
            mount_xyz_m: [0.0, 0.0, 0.12],
            mount_rpy_deg: [0.0, 0.0, 0.0],
            clock_offset_us: 0,
            position_packet_every: 14,
            start_azimuth_deg: None,
            beam_divergence_mrad: [0.0, 0.0],
            mixed_pixel_max_gap_m: 1.0,
            tyre_return_s50_per_m: 0.0,
            range_bias_sigma_m: 0.0,
        }
    }
}

impl Vlp16Config {
    /// Check every field; on failure `(field, reason)` with the field named as in the scenario file.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |f: &str, r: &str| Err((format!("lidar.{f}"), r.to_owned()));
        if !(300.0..=1200.0).contains(&self.rpm) {
            return bad("rpm", "must lie in 300..=1200 (5-20 Hz)");
        }
        if !(self.range_noise_sigma_m >= 0.0 && self.range_noise_limit_m >= 0.0) {
            return bad("range_noise_sigma_m", "noise sigma and limit must be >= 0");
        }
        if !(self.min_range_m >= 0.0
            && self.min_range_m < self.max_range_m
            && self.max_range_m <= 131.0)
        {
            return bad(
                "min_range_m",
                "need 0 <= min_range_m < max_range_m <= 131 m",
            );
        }
        if !(0.0..=1.0).contains(&self.dropout_probability) {
            return bad("dropout_probability", "must lie in 0..=1");
        }
        if self
            .mount_xyz_m
            .iter()
            .chain(&self.mount_rpy_deg)
            .any(|v| !v.is_finite())
        {
            return bad("mount_xyz_m", "mount values must be finite");
        }
        if self.start_azimuth_deg.is_some_and(|a| !a.is_finite()) {
            return bad("start_azimuth_deg", "must be finite");
        }
        if self
            .beam_divergence_mrad
            .iter()
            .any(|d| !(0.0..=20.0).contains(d))
        {
            return bad("beam_divergence_mrad", "both must lie in 0..=20 mrad");
        }
        if !(0.0..=10.0).contains(&self.mixed_pixel_max_gap_m) {
            return bad("mixed_pixel_max_gap_m", "must lie in 0..=10 m");
        }
        if !(0.0..=10.0).contains(&self.tyre_return_s50_per_m) {
            return bad("tyre_return_s50_per_m", "must lie in 0..=10 per metre");
        }
        if !(0.0..=0.1).contains(&self.range_bias_sigma_m) {
            return bad("range_bias_sigma_m", "must lie in 0..=0.1 m");
        }
        Ok(())
    }

    /// `robot_from_lidar`: the mount, with the manual's sensor frame (x right, y forward at azimuth 0,
    /// z up) turned so that azimuth 0 looks along the robot's +x before the mount angles apply.
    pub fn robot_from_lidar(&self) -> Isometry {
        let [x, y, z] = self.mount_xyz_m;
        let [r, p, w] = self.mount_rpy_deg.map(f64::to_radians);
        let sensor_to_robot_axes = rot_from_rpy(0.0, 0.0, -std::f64::consts::FRAC_PI_2);
        Isometry {
            rotation: rot_from_rpy(r, p, w) * sensor_to_robot_axes,
            translation: Vec3::new(x, y, z),
        }
    }
}

/// Ground truth of one firing (for tests and diagnostics).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FiringTruth {
    /// Simulation time of the firing, seconds.
    pub time_s: f64,
    /// Block 0..12 within the packet.
    pub block: usize,
    /// Channel 0..32 within the block (sequence * 16 + laser id).
    pub channel: usize,
    /// `world_from_lidar` at the firing.
    pub world_from_lidar: Isometry,
    /// The surface hit and the exact hit point in the world frame (`None`: nothing within range).
    pub hit: Option<(SurfaceId, Vec3)>,
    /// The reported distance in 2 mm units (0: no return).
    pub distance_raw: u16,
}

/// One output datagram of the simulated sensor.
#[derive(Clone, Debug, PartialEq)]
pub enum Datagram {
    /// A 1206-byte data packet for UDP port 2368.
    Data {
        /// Simulation time at which the sensor sends it (after its last firing), seconds.
        send_s: f64,
        /// The payload.
        payload: Box<[u8; 1206]>,
    },
    /// A 512-byte position packet for UDP port 8308.
    Position {
        /// Simulation time of sending, seconds.
        send_s: f64,
        /// The payload.
        payload: Box<[u8; 512]>,
    },
}

/// pcap time of simulation time 0, seconds since the UNIX epoch: a fixed instant, so that a
/// simulated capture's bytes depend only on its scenario.
pub const PCAP_EPOCH_S: u64 = 1_767_225_600;

/// The simulated sensor's address (the VLP-16's factory default).
pub const SENSOR_IP: std::net::Ipv4Addr = std::net::Ipv4Addr::new(192, 168, 1, 201);

impl Datagram {
    /// When it is sent, simulation time, seconds.
    pub fn send_s(&self) -> f64 {
        match self {
            Self::Data { send_s, .. } | Self::Position { send_s, .. } => *send_s,
        }
    }

    /// The payload and the UDP port it goes to (2368 data, 8308 position).
    pub fn payload_and_port(&self) -> (&[u8], u16) {
        match self {
            Self::Data { payload, .. } => (&payload[..], 2368),
            Self::Position { payload, .. } => (&payload[..], 8308),
        }
    }

    /// Append it to a pcap as the sensor broadcasts it: from [`SENSOR_IP`] to 255.255.255.255
    /// on its port, stamped [`PCAP_EPOCH_S`] + its send time.
    pub fn write_pcap<W: std::io::Write>(
        &self,
        w: &mut vlp16::pcap::PcapWriter<W>,
    ) -> std::io::Result<()> {
        use std::net::{Ipv4Addr, SocketAddrV4};
        let (payload, port) = self.payload_and_port();
        let stamp_ns = PCAP_EPOCH_S * 1_000_000_000 + (self.send_s() * 1e9).round() as u64;
        w.write_udp(
            stamp_ns,
            SocketAddrV4::new(SENSOR_IP, port),
            SocketAddrV4::new(Ipv4Addr::BROADCAST, port),
            payload,
        )
    }
}

/// The simulated sensor looking at `scene` from a robot moving along `trajectory`.
pub struct Vlp16Sim<'a, T: Trajectory> {
    scene: &'a Scene,
    trajectory: &'a T,
    config: Vlp16Config,
    seed: u64,
    robot_from_lidar: Isometry,
    /// Per laser: (sin elevation, cos elevation, vertical offset m).
    lasers: [(f64, f64, f64); 16],
    /// Per channel (sequence * 16 + laser): sin and cos of the azimuth turned since the block start.
    channel_offsets: [(f64, f64); 32],
    omega_rad_per_s: f64,
    /// Head azimuth at t = 0, radians.
    start_azimuth_rad: f64,
    /// Test only the primitives in the wedge each packet sweeps (see `packet_candidates`).
    culling: bool,
    /// Fixed range bias of each laser, metres.
    range_bias_m: [f64; 16],
}

impl<'a, T: Trajectory> Vlp16Sim<'a, T> {
    /// A sensor; `config` must have passed [`Vlp16Config::validate`].
    pub fn new(scene: &'a Scene, trajectory: &'a T, config: Vlp16Config, seed: u64) -> Self {
        let lasers = std::array::from_fn(|i| {
            let (s, c) = ELEVATION_DEG[i].to_radians().sin_cos();
            (s, c, VERTICAL_OFFSET_MM[i] / 1000.0)
        });
        let omega_rad_per_s = config.rpm / 60.0 * std::f64::consts::TAU;
        let channel_offsets = std::array::from_fn(|c| {
            let dt = (c / 16) as f64 * SEQUENCE_S + (c % 16) as f64 * FIRING_S;
            (omega_rad_per_s * dt).sin_cos()
        });
        let range_bias_m = if config.range_bias_sigma_m > 0.0 {
            let mut rng = ChaCha8Rng::seed_from_u64(crate::scenario::derive_seed(seed, 11));
            let mut normals = NormalPairs::default();
            let sigma = config.range_bias_sigma_m;
            std::array::from_fn(|_| {
                (normals.next(&mut rng) * sigma).clamp(-3.0 * sigma, 3.0 * sigma)
            })
        } else {
            [0.0; 16]
        };
        Self {
            scene,
            trajectory,
            range_bias_m,
            robot_from_lidar: config.robot_from_lidar(),
            channel_offsets,
            omega_rad_per_s,
            start_azimuth_rad: config.start_azimuth_deg.unwrap_or(0.0).to_radians(),
            culling: true,
            config,
            seed,
            lasers,
        }
    }

    /// Number of data packets that start within `duration_s`.
    pub fn packets_in(duration_s: f64) -> u64 {
        (duration_s / PACKET_S).ceil().max(0.0) as u64
    }

    /// Each laser's fixed range bias, metres (the truth a range calibration estimates).
    pub fn range_bias_m(&self) -> [f64; 16] {
        self.range_bias_m
    }

    /// Sensor azimuth at simulation time `t_s`, radians in `[0, 2 pi)`.
    pub fn azimuth_at(&self, t_s: f64) -> f64 {
        (self.start_azimuth_rad + self.omega_rad_per_s * t_s).rem_euclid(std::f64::consts::TAU)
    }

    /// Data packet `index`, as a repr (emit it with `to_bytes`).
    pub fn data_packet(&self, index: u64) -> DataPacketRepr {
        self.data_packet_with_truth(index, |_| {})
    }

    /// Data packet `index`, calling `truth` for every firing in order.
    pub fn data_packet_with_truth(
        &self,
        index: u64,
        mut truth: impl FnMut(&FiringTruth),
    ) -> DataPacketRepr {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(index);
        let t0 = index as f64 * PACKET_S;
        let empty = ChannelRepr {
            distance_raw: 0,
            reflectivity: 0,
        };
        let mut blocks = [BlockRepr {
            azimuth_raw: 0,
            channels: [empty; 32],
        }; 12];
        let mut normals = NormalPairs::default();
        let pose_start = self.world_from_lidar_at(t0);
        let pose_end = self.world_from_lidar_at(t0 + PACKET_S);
        let candidates = if self.culling {
            self.packet_candidates(&pose_start, &pose_end, t0)
        } else {
            Candidates::ALL
        };
        for (b, block) in blocks.iter_mut().enumerate() {
            let t_block = t0 + b as f64 * BLOCK_S;
            let azimuth_block = self.azimuth_at(t_block);
            block.azimuth_raw =
                ((azimuth_block.to_degrees() * 100.0).round() as u32 % 36_000) as u16;
            let (sin_b, cos_b) = azimuth_block.sin_cos();
            for seq in 0..2 {
                let t_seq = t_block + seq as f64 * SEQUENCE_S;
                let world_from_lidar =
                    lerp_isometry(&pose_start, &pose_end, (t_seq - t0) / PACKET_S);
                for laser in 0..16 {
                    let channel = seq * 16 + laser;
                    // Azimuth of this firing = block azimuth + the channel's fixed offset.
                    let (sin_d, cos_d) = self.channel_offsets[channel];
                    let azimuth = (sin_b * cos_d + cos_b * sin_d, cos_b * cos_d - sin_b * sin_d);
                    let (repr, hit) = self.fire(
                        &world_from_lidar,
                        azimuth,
                        laser,
                        candidates,
                        &mut rng,
                        &mut normals,
                    );
                    block.channels[channel] = repr;
                    truth(&FiringTruth {
                        time_s: t_seq + laser as f64 * FIRING_S,
                        block: b,
                        channel,
                        world_from_lidar,
                        hit,
                        distance_raw: repr.distance_raw,
                    });
                }
            }
        }
        DataPacketRepr {
            blocks,
            timestamp_us: self.sensor_clock_us(t0),
            return_mode: ReturnMode::Strongest,
            product: Product::Vlp16,
        }
    }

    /// The primitives this packet's rays can hit: the wedge the head sweeps during the packet, seen
    /// from above, widened by 0.02 rad plus twice the sensor's tilt from vertical (a tilted head's
    /// rays, at most 15 degrees off its equator, bend sideways by less than 0.27 x the tilt). No
    /// culling when the head is tilted more than 0.3 rad.
    fn packet_candidates(&self, start: &Isometry, end: &Isometry, t0: f64) -> Candidates {
        let tilt = |m: &Isometry| m.rotation[(2, 2)].clamp(-1.0, 1.0).acos();
        let tilt_rad = tilt(start).max(tilt(end));
        if tilt_rad > 0.3 {
            return Candidates::ALL;
        }
        let bearing = |m: &Isometry, t: f64| {
            let (s, c) = self.azimuth_at(t).sin_cos();
            let d = m.apply_vector(Vec3::new(s, c, 0.0));
            d.y.atan2(d.x)
        };
        let (a, b) = (bearing(start, t0), bearing(end, t0 + PACKET_S));
        let sweep =
            (b - a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        self.scene.candidates_in_wedge(
            start.translation,
            a + sweep / 2.0,
            sweep.abs() / 2.0 + 0.02 + 2.0 * tilt_rad,
        )
    }

    /// The same sensor without per-packet culling (every ray tests every primitive); for tests
    /// and for the benchmark's comparison.
    #[must_use]
    pub fn without_culling(mut self) -> Self {
        self.culling = false;
        self
    }

    /// `world_from_lidar` at simulation time `t_s`.
    pub fn world_from_lidar_at(&self, t_s: f64) -> Isometry {
        self.trajectory
            .pose_at(t_s)
            .to_isometry()
            .compose(&self.robot_from_lidar)
    }

    /// The sensor clock (microseconds past the hour) at simulation time `t_s`.
    pub fn sensor_clock_us(&self, t_s: f64) -> u32 {
        ((self.config.clock_offset_us + (t_s * 1e6).round() as u64) % HOUR_US) as u32
    }

    /// One firing at azimuth `(sin, cos)`: cast, then apply the measurement model.
    fn fire(
        &self,
        world_from_lidar: &Isometry,
        (sin_a, cos_a): (f64, f64),
        laser: usize,
        candidates: Candidates,
        rng: &mut ChaCha8Rng,
        normals: &mut NormalPairs,
    ) -> (ChannelRepr, Option<(SurfaceId, Vec3)>) {
        let (sin_w, cos_w, offset_m) = self.lasers[laser];
        let dir = world_from_lidar.apply_vector(Vec3::new(cos_w * sin_a, cos_w * cos_a, sin_w));
        let origin = world_from_lidar.apply(Vec3::new(0.0, 0.0, offset_m));
        let none = ChannelRepr {
            distance_raw: 0,
            reflectivity: 0,
        };
        let max_cast = self.config.max_range_m + 1.0;
        let [h_mrad, v_mrad] = self.config.beam_divergence_mrad;
        let found = if h_mrad > 0.0 || v_mrad > 0.0 {
            // Unit vectors across the beam: along the azimuth and along the elevation.
            let across = world_from_lidar.apply_vector(Vec3::new(cos_a, -sin_a, 0.0));
            let up =
                world_from_lidar.apply_vector(Vec3::new(-sin_w * sin_a, -sin_w * cos_a, cos_w));
            self.footprint(origin, dir, across, up, candidates)
        } else {
            self.scene
                .cast_among(origin, dir, max_cast, candidates)
                .map(|hit| (hit, dir, hit.range_m))
        };
        let Some((hit, hit_dir, echo_range_m)) = found else {
            return (none, None);
        };
        let truth = Some((hit.surface, origin + hit_dir * hit.range_m));
        let (u_drop, noise) = (rng.random::<f64>(), normals.next(rng));
        let limit = self.config.range_noise_limit_m;
        let range_m = echo_range_m
            + self.range_bias_m[laser]
            + (noise * self.config.range_noise_sigma_m).clamp(-limit, limit);
        if u_drop < self.config.dropout_probability
            || range_m < self.config.min_range_m
            || range_m > self.config.max_range_m
        {
            return (none, truth);
        }
        let cos_incidence = -hit.normal.dot(&hit_dir);
        let s50 = self.config.tyre_return_s50_per_m;
        if s50 > 0.0 && hit.surface.kind == SurfaceKind::Tyre {
            let s = cos_incidence.max(0.0) / echo_range_m.max(1e-3);
            let p_return = 1.0 / (1.0 + (s50 / s.max(1e-12)).powi(4));
            if rng.random::<f64>() >= p_return {
                return (none, truth);
            }
        }
        let reflectivity = (base_reflectivity(hit.surface.kind) * cos_incidence)
            .round()
            .clamp(1.0, 255.0) as u8;
        let distance_raw = (range_m / 0.002).round().clamp(1.0, f64::from(u16::MAX)) as u16;
        (
            ChannelRepr {
                distance_raw,
                reflectivity,
            },
            truth,
        )
    }

    /// A finite footprint: the centre ray (weight 0.4) and four rays at +- half the divergence
    /// across (`across`) and along (`up`) the scan line (0.15 each). Each hit's echo energy is its
    /// weight x the surface's base reflectivity x cos(incidence) / range^2. Echoes sorted by range
    /// form groups wherever neighbours lie within `mixed_pixel_max_gap_m`; the group of most
    /// energy is the return, at its energy-weighted mean range (between the surfaces at a depth
    /// edge: a mixed pixel), reported as its strongest hit. `None` when no ray hits.
    fn footprint(
        &self,
        origin: Vec3,
        dir: Vec3,
        across: Vec3,
        up: Vec3,
        candidates: Candidates,
    ) -> Option<(Hit, Vec3, f64)> {
        let [h, v] = self.config.beam_divergence_mrad.map(|m| m * 0.5e-3);
        let rays = [
            (dir, 0.4),
            ((dir + across * h).normalized(), 0.15),
            ((dir - across * h).normalized(), 0.15),
            ((dir + up * v).normalized(), 0.15),
            ((dir - up * v).normalized(), 0.15),
        ];
        let max_cast = self.config.max_range_m + 1.0;
        let mut echoes: Vec<(Hit, Vec3, f64)> = Vec::with_capacity(5);
        for (d, w) in rays {
            if let Some(hit) = self.scene.cast_among(origin, d, max_cast, candidates) {
                let cos = (-hit.normal.dot(&d)).max(0.0);
                let energy = w * base_reflectivity(hit.surface.kind) * cos.max(0.01)
                    / hit.range_m.max(0.1).powi(2);
                echoes.push((hit, d, energy));
            }
        }
        echoes.sort_by(|a, b| a.0.range_m.total_cmp(&b.0.range_m));
        let gap = self.config.mixed_pixel_max_gap_m;
        let mut best: Option<(f64, f64, usize)> = None; // (energy, weighted range, strongest echo)
        let mut start = 0;
        while start < echoes.len() {
            let mut end = start + 1;
            while end < echoes.len() && echoes[end].0.range_m - echoes[end - 1].0.range_m <= gap {
                end += 1;
            }
            let group = &echoes[start..end];
            let energy: f64 = group.iter().map(|e| e.2).sum();
            let range = group.iter().map(|e| e.2 * e.0.range_m).sum::<f64>() / energy;
            let strongest = (start..end)
                .max_by(|&a, &b| echoes[a].2.total_cmp(&echoes[b].2))
                .unwrap_or(start);
            if best.is_none_or(|b| energy > b.0) {
                best = Some((energy, range, strongest));
            }
            start = end;
        }
        best.map(|(_, range, i)| (echoes[i].0, echoes[i].1, range))
    }

    /// Position packet sent at simulation time `t_s` (no GPS: PPS absent, an empty-fix `$GPRMC`).
    pub fn position_packet(&self, t_s: f64) -> PositionPacketRepr {
        let stamp = self.sensor_clock_us(t_s);
        let (minute, second) = (stamp / 60_000_000, (stamp / 1_000_000) % 60);
        let body = format!("GPRMC,00{minute:02}{second:02},V,,,,,,,,,,N");
        let checksum = body.bytes().fold(0u8, |acc, b| acc ^ b);
        PositionPacketRepr::new(
            stamp,
            PpsStatus::Absent,
            &format!("${body}*{checksum:02X}\r\n"),
        )
    }

    /// Every datagram the sensor sends during `[0, duration_s)`, in sending order: data packets
    /// and, after every `position_packet_every` of them, a position packet.
    pub fn datagrams(&self, duration_s: f64) -> impl Iterator<Item = Datagram> + '_ {
        let every = u64::from(self.config.position_packet_every);
        (0..Self::packets_in(duration_s)).flat_map(move |k| {
            let send_s = (k + 1) as f64 * PACKET_S;
            let data = Datagram::Data {
                send_s,
                payload: Box::new(self.data_packet(k).to_bytes()),
            };
            let position = (every > 0 && (k + 1) % every == 0).then(|| Datagram::Position {
                send_s,
                payload: Box::new(self.position_packet(send_s).to_bytes()),
            });
            std::iter::once(data).chain(position)
        })
    }
}

/// Element-wise linear interpolation of two nearby transforms (`f` in 0..=1). Valid only for
/// transforms a tiny rotation apart (here: one packet, 1.3 ms, apart), where the result stays
/// orthonormal to second order in the rotation between them.
fn lerp_isometry(a: &Isometry, b: &Isometry, f: f64) -> Isometry {
    Isometry {
        rotation: a.rotation + (b.rotation - a.rotation) * f,
        translation: a.translation + (b.translation - a.translation) * f,
    }
}

/// Standard normal draws by Box-Muller: one 64-bit draw split into two 32-bit uniforms gives two
/// independent normals; the second is kept for the next call.
#[derive(Default)]
struct NormalPairs {
    spare: Option<f64>,
}

impl NormalPairs {
    fn next(&mut self, rng: &mut ChaCha8Rng) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let bits: u64 = rng.random();
        let u1 = ((bits >> 32) as f64 + 0.5) / 4_294_967_296.0;
        let u2 = ((bits & 0xffff_ffff) as f64) / 4_294_967_296.0;
        let radius = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare = Some(radius * s);
        radius * c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use crate::trajectory::{StraightRun, Vibration};
    use crate::vehicle::tests::test_sedan;
    use vlp16::Vlp16Packet;

    pub(crate) fn run() -> StraightRun {
        StraightRun {
            start_m: Vec3::new(-0.8, 0.05, 0.0),
            heading_rad: std::f64::consts::PI,
            yaw_misalignment_rad: 0.01,
            speed_mps: 0.3,
            accel_mps2: 0.0,
            slip: 0.0,
            vibration: Vibration::new(0.002, 0.002, 5),
            still_s: 0.0,
            stop_after_m: None,
        }
    }

    #[test]
    fn mount_puts_azimuth_zero_along_robot_x() {
        let m = Vlp16Config::default().robot_from_lidar();
        let d = m.apply_vector(Vec3::new(0.0, 1.0, 0.0));
        assert!((d - Vec3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        let right = m.apply_vector(Vec3::new(1.0, 0.0, 0.0));
        assert!(
            (right - Vec3::new(0.0, -1.0, 0.0)).norm() < 1e-12,
            "sensor x is the robot's right"
        );
    }

    #[test]
    fn interpolated_pose_within_a_packet_matches_the_trajectory() {
        let scene = Scene::from_vehicle(&test_sedan());
        // 0.2 degree RMS vibration (the strongest shipped scenario's) and an acceleration ramp.
        let sigma = 0.2f64.to_radians();
        let traj = StraightRun {
            accel_mps2: 0.5,
            vibration: Vibration::new(sigma, sigma, 3),
            ..run()
        };
        let sim = Vlp16Sim::new(&scene, &traj, Vlp16Config::default(), 1);
        for t0 in [0.1, 0.55, 3.0] {
            let (a, b) = (
                sim.world_from_lidar_at(t0),
                sim.world_from_lidar_at(t0 + PACKET_S),
            );
            for f in [0.25, 0.5, 0.9] {
                let exact = sim.world_from_lidar_at(t0 + f * PACKET_S);
                let lerp = lerp_isometry(&a, &b, f);
                let p = Vec3::new(3.0, -2.0, 0.5);
                let error = (exact.apply(p) - lerp.apply(p)).norm();
                assert!(error < 5e-5, "t0 {t0} f {f}: {error} m at 3.6 m");
            }
        }
    }

    #[test]
    fn culling_never_changes_a_packet() {
        // Strong vibration and a tilted mount make the wedges as uncertain as the model allows.
        let scene = Scene::from_vehicle(&test_sedan());
        let sigma = 2f64.to_radians();
        let traj = StraightRun {
            vibration: Vibration::new(sigma, sigma, 8),
            ..run()
        };
        for (rpm, mount_rpy_deg) in [
            (600.0, [0.0, 0.0, 0.0]),
            (1200.0, [3.0, -5.0, 30.0]),
            (300.0, [0.0, 0.0, 90.0]),
        ] {
            let cfg = Vlp16Config {
                rpm,
                mount_rpy_deg,
                ..Vlp16Config::default()
            };
            let fast = Vlp16Sim::new(&scene, &traj, cfg.clone(), 3);
            let full = Vlp16Sim::new(&scene, &traj, cfg, 3).without_culling();
            for k in (0..6000).step_by(7) {
                assert_eq!(
                    fast.data_packet(k),
                    full.data_packet(k),
                    "packet {k} at {rpm} rpm"
                );
            }
        }
    }

    #[test]
    fn the_starting_azimuth_turns_every_block() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = run();
        let base = Vlp16Sim::new(&scene, &traj, Vlp16Config::default(), 1);
        let turned = Vlp16Sim::new(
            &scene,
            &traj,
            Vlp16Config {
                start_azimuth_deg: Some(90.0),
                ..Vlp16Config::default()
            },
            1,
        );
        for k in [0, 3, 250] {
            let (a, b) = (base.data_packet(k), turned.data_packet(k));
            for (x, y) in a.blocks.iter().zip(&b.blocks) {
                let d = (i32::from(y.azimuth_raw) - i32::from(x.azimuth_raw)).rem_euclid(36_000);
                assert!((8_999..=9_001).contains(&d), "packet {k}: {d}");
            }
        }
    }

    #[test]
    fn packets_are_reproducible_and_seed_dependent() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = run();
        let a = Vlp16Sim::new(&scene, &traj, Vlp16Config::default(), 1);
        let b = Vlp16Sim::new(&scene, &traj, Vlp16Config::default(), 1);
        let c = Vlp16Sim::new(&scene, &traj, Vlp16Config::default(), 2);
        for k in [0, 5, 700] {
            assert_eq!(a.data_packet(k).to_bytes(), b.data_packet(k).to_bytes());
        }
        assert_ne!(a.data_packet(5).to_bytes(), c.data_packet(5).to_bytes());
    }

    #[test]
    fn packet_fields_follow_the_timing() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = run();
        let cfg = Vlp16Config {
            clock_offset_us: HOUR_US - 500,
            ..Vlp16Config::default()
        };
        let sim = Vlp16Sim::new(&scene, &traj, cfg, 1);
        let bytes = sim.data_packet(3).to_bytes();
        let p = Vlp16Packet::new_checked(&bytes[..]).expect("1206 bytes");
        let parsed = DataPacketRepr::parse(&p).expect("valid packet");
        // Packet 3 starts 3981.312 us in: the clock wrapped past the hour.
        assert_eq!(parsed.timestamp_us, 3981 - 500);
        // 600 rpm: 0.398 degree per 110.592 us block.
        let step =
            i32::from(parsed.blocks[1].azimuth_raw) - i32::from(parsed.blocks[0].azimuth_raw);
        assert!((39..=40).contains(&step), "{step}");
        assert_eq!(parsed.return_mode, ReturnMode::Strongest);
    }

    #[test]
    fn stationary_sensor_sees_the_floor_at_the_right_range() {
        // Robot parked at mid-wheelbase: the +15 degree laser looking straight ahead hits the floor
        // (0.14 m) at range (0.14 - 0.12 - offset) / sin 15 deg, before noise.
        let v = test_sedan();
        let scene = Scene::from_vehicle(&v);
        let still = crate::trajectory::SampledTrajectory::new(vec![(
            0.0,
            Pose {
                position_m: Vec3::new(-1.4, 0.0, 0.0),
                ..Pose::default()
            },
            0.0,
        )])
        .expect("one sample");
        let cfg = Vlp16Config {
            range_noise_sigma_m: 0.0,
            dropout_probability: 0.0,
            min_range_m: 0.0,
            ..Vlp16Config::default()
        };
        let sim = Vlp16Sim::new(&scene, &still, cfg, 1);
        let mut seen = false;
        sim.data_packet_with_truth(0, |f| {
            if f.channel == 15 {
                // The floor rises 1 cm over 0.95 m toward the front: allow 6 mm for it.
                let expected = (0.14 - (0.12 - 0.0112)) / 15f64.to_radians().sin();
                assert!(
                    (f64::from(f.distance_raw) * 0.002 - expected).abs() <= 0.006,
                    "{f:?}"
                );
                seen = true;
            }
        });
        assert!(seen);
    }

    /// The five footprint rays' ranges (centre, across +-, up +-), as `footprint` casts them.
    fn sub_ranges(
        scene: &Scene,
        o: Vec3,
        d: Vec3,
        across: Vec3,
        up: Vec3,
        div: [f64; 2],
    ) -> Vec<f64> {
        let [h, v] = div.map(|m| m * 0.5e-3);
        [d, d + across * h, d - across * h, d + up * v, d - up * v]
            .iter()
            .filter_map(|r| scene.cast(o, r.normalized(), 200.0).map(|hit| hit.range_m))
            .collect()
    }

    #[test]
    fn mixed_pixels_put_returns_between_foreground_and_background() {
        // From under the test sedan, a fan of rays 2 degrees down sweeps across the front-left
        // tyre's silhouette (1.5-1.8 m away) against the ground behind it (3.4 m away).
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = run();
        let between = |gap: f64| -> (usize, usize) {
            let cfg = Vlp16Config {
                beam_divergence_mrad: [3.0, 1.5],
                mixed_pixel_max_gap_m: gap,
                ..Vlp16Config::default()
            };
            let sim = Vlp16Sim::new(&scene, &traj, cfg, 1);
            let o = Vec3::new(-1.4, 0.0, 0.12);
            let e = -2f64.to_radians();
            let (mut between, mut edges) = (0, 0);
            for k in 0..4000 {
                let a = (10.0 + 40.0 * f64::from(k) / 4000.0).to_radians();
                let d = Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
                let across = Vec3::new(-a.sin(), a.cos(), 0.0);
                let up = Vec3::new(-e.sin() * a.cos(), -e.sin() * a.sin(), e.cos());
                let Some((hit, _, range)) = sim.footprint(o, d, across, up, Candidates::ALL) else {
                    continue;
                };
                let subs = sub_ranges(&scene, o, d, across, up, [3.0, 1.5]);
                let (lo, hi) = subs
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(l, h), r| (l.min(*r), h.max(*r)));
                assert!(
                    range >= lo - 1e-9 && range <= hi + 1e-9,
                    "{range} outside {lo}..{hi}"
                );
                assert!(scene.distance_to_surface(hit.surface, o + d * 0.0) >= 0.0);
                if hi - lo > 1.0 {
                    edges += 1;
                    if range > lo + 0.3 && range < hi - 0.3 {
                        between += 1;
                    }
                }
            }
            (between, edges)
        };
        let (mixed, edges) = between(3.0);
        assert!(
            edges > 4 && mixed > 2,
            "{mixed} mixed of {edges} edge footprints"
        );
        // Echoes farther apart than the gap stay apart: the stronger one is the return.
        let (separate, edges) = between(0.5);
        assert!(edges > 4 && separate == 0, "{separate} mixed of {edges}");
    }

    /// Every firing of packets `0..n` with the scene's surface, the true range and incidence.
    fn firings(
        sim: &Vlp16Sim<'_, StraightRun>,
        scene: &Scene,
        n: u64,
    ) -> Vec<(SurfaceKind, f64, f64, u16, usize)> {
        let mut out = Vec::new();
        for k in 0..n {
            sim.data_packet_with_truth(k, |f| {
                if let Some((surface, point)) = f.hit {
                    let laser = f.channel % 16;
                    let origin = f.world_from_lidar.apply(Vec3::new(
                        0.0,
                        0.0,
                        VERTICAL_OFFSET_MM[laser] / 1000.0,
                    ));
                    let range = (point - origin).norm();
                    let dir = (point - origin) * (1.0 / range);
                    let cos = scene
                        .cast(origin, dir, range + 1.0)
                        .map_or(0.0, |h| -h.normal.dot(&dir));
                    out.push((surface.kind, range, cos, f.distance_raw, laser));
                }
            });
        }
        out
    }

    #[test]
    fn dark_rubber_drops_out_at_the_rate_the_law_gives() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = run();
        let s50 = 0.25;
        let cfg = Vlp16Config {
            tyre_return_s50_per_m: s50,
            range_noise_sigma_m: 0.0,
            dropout_probability: 0.0,
            ..Vlp16Config::default()
        };
        let sim = Vlp16Sim::new(&scene, &traj, cfg, 4);
        let (mut expected, mut variance, mut returned, mut n) = (0.0, 0.0, 0.0, 0);
        let mut others_lost = 0;
        for (kind, range, cos, raw, _) in firings(&sim, &scene, 1500) {
            if !(0.5..100.0).contains(&range) {
                continue;
            }
            if kind == SurfaceKind::Tyre {
                let p = 1.0 / (1.0 + (s50 * range / cos.max(1e-12)).powi(4));
                expected += p;
                variance += p * (1.0 - p);
                returned += f64::from(u8::from(raw != 0));
                n += 1;
            } else {
                others_lost += usize::from(raw == 0);
            }
        }
        assert!(n > 500, "{n} tyre firings");
        assert_eq!(others_lost, 0, "only tyres drop out");
        assert!(
            (returned - expected).abs() < 4.0 * variance.sqrt(),
            "returned {returned} of {n}, expected {expected:.1} +- {:.1}",
            variance.sqrt()
        );
        assert!(
            returned < 0.95 * f64::from(n),
            "the law bites: {returned} of {n}"
        );
    }

    #[test]
    #[allow(clippy::float_cmp)] // the same seed gives the same biases to the bit
    fn each_laser_has_a_fixed_range_bias_per_seed() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = run();
        let cfg = Vlp16Config {
            range_bias_sigma_m: 0.01,
            range_noise_sigma_m: 0.0,
            dropout_probability: 0.0,
            ..Vlp16Config::default()
        };
        let sim = Vlp16Sim::new(&scene, &traj, cfg.clone(), 9);
        assert_eq!(
            sim.range_bias_m,
            Vlp16Sim::new(&scene, &traj, cfg.clone(), 9).range_bias_m
        );
        assert_ne!(
            sim.range_bias_m,
            Vlp16Sim::new(&scene, &traj, cfg, 10).range_bias_m
        );
        let mut per_laser: Vec<Vec<f64>> = vec![Vec::new(); 16];
        for (_, range, _, raw, laser) in firings(&sim, &scene, 300) {
            if raw != 0 {
                per_laser[laser].push(f64::from(raw) * 0.002 - range);
            }
        }
        let mut means = Vec::new();
        for (laser, residuals) in per_laser.iter().enumerate() {
            // Upward lasers under the low test floor see it closer than the minimum range.
            if residuals.len() < 50 {
                continue;
            }
            let (lo, hi) = residuals
                .iter()
                .fold((f64::MAX, f64::MIN), |(l, h), r| (l.min(*r), h.max(*r)));
            // Constant but for the 2 mm quantum.
            assert!(hi - lo <= 0.002 + 1e-9, "laser {laser}: {lo}..{hi}");
            assert!((f64::midpoint(lo, hi) - sim.range_bias_m[laser]).abs() < 0.0011);
            assert!(sim.range_bias_m[laser].abs() <= 0.03 + 1e-12);
            means.push(f64::midpoint(lo, hi));
        }
        assert!(means.len() >= 8, "{} lasers with returns", means.len());
        let spread = means.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        assert!(spread > 0.005, "biases {means:?}");
    }
}
