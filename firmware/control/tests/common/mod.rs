//! Shared test harness: the drive state machine closed around the plant on a 1 ms clock.
// Test harness: panics on broken invariants are the point; indices are ESC slots.
#![allow(
    dead_code,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::unwrap_used,
    clippy::needless_range_loop
)]

pub mod plant;

use control::machine::{Command, DriveCommand, EscSample, Machine, StepOutput};
use control::{BusState, Config, Twist};
use plant::{Plant, PlantParams};

/// Control period, microseconds.
pub const STEP_US: u64 = 1000;

/// Machine + plant + clock.
pub struct Sim {
    pub machine: Machine,
    pub plant: Plant,
    pub now_us: u64,
    pub last: StepOutput,
    /// Send a heartbeat every this many steps (0 = none).
    pub heartbeat_every: u64,
    /// ESC slots whose feedback frames are dropped.
    pub silent: [bool; 4],
    pub bus: BusState,
    /// Overrides applied to every feedback frame of a slot.
    pub patch: [Patch; 4],
}

/// Replaces fields of an ESC's feedback (fault injection).
#[derive(Debug, Clone, Copy, Default)]
pub struct Patch {
    pub temperature_c: Option<u8>,
    pub current_raw: Option<i16>,
}

impl Sim {
    pub fn new(config: Config, params: PlantParams, seed: u64) -> Self {
        Self {
            machine: Machine::new(config).expect("valid config"),
            plant: Plant::new(params, seed),
            now_us: 0,
            last: StepOutput {
                currents_raw: [0; 4],
                recover_bus: false,
            },
            heartbeat_every: 20,
            silent: [false; 4],
            bus: BusState::Active,
            patch: [Patch::default(); 4],
        }
    }

    pub fn default_seeded(seed: u64) -> Self {
        Self::new(Config::default(), PlantParams::default(), seed)
    }

    /// One 1 ms period: plant moves under the last currents, ESCs report, machine steps.
    pub fn tick(&mut self) -> StepOutput {
        self.plant
            .advance(self.last.currents_raw, STEP_US as f32 * 1e-6);
        self.now_us += STEP_US;
        let step = self.now_us / STEP_US;
        if self.heartbeat_every > 0 && step.is_multiple_of(self.heartbeat_every) {
            self.machine
                .command(self.now_us, Command::Heartbeat)
                .expect("heartbeat");
        }
        let mut samples = heapless::Vec::<EscSample, 4>::new();
        if self.bus != BusState::BusOff {
            for slot in 0..4 {
                if self.silent[slot] {
                    continue;
                }
                let mut fb = self.plant.feedback(slot);
                let patch = self.patch[slot];
                fb.temperature_c = patch.temperature_c.unwrap_or(fb.temperature_c);
                fb.current_raw = patch.current_raw.unwrap_or(fb.current_raw);
                let esc_id = slot as u8 + 1;
                samples
                    .push(EscSample {
                        esc_id,
                        feedback: fb,
                        stamp_us: self.now_us,
                    })
                    .unwrap();
            }
        }
        self.last = self.machine.step(self.now_us, &samples, self.bus);
        self.last
    }

    pub fn run(&mut self, steps: usize) {
        for _ in 0..steps {
            self.tick();
        }
    }

    pub fn command(&mut self, cmd: Command) -> Result<(), control::Reject> {
        self.machine.command(self.now_us, cmd)
    }

    /// Heartbeat + a few ticks so that every ESC has reported, then a forward drive.
    pub fn start_forward(&mut self, vx_mps: f32) {
        self.command(Command::Hello).unwrap();
        self.command(Command::Heartbeat).unwrap();
        self.run(3);
        self.command(Command::Drive(DriveCommand {
            twist: Twist::new(vx_mps, 0.0, 0.0),
            accel_mps2: 0.5,
            jerk_mps3: 5.0,
        }))
        .expect("drive accepted");
    }

    /// True body twist from the plant's wheel speeds (wheel-forward positive via the map signs).
    pub fn true_twist(&self) -> Twist {
        let c = self.machine.config();
        let mut wheels = [0.0f32; 4];
        for wheel in 0..4 {
            let slot = usize::from(c.wheels.esc_id[wheel]) - 1;
            wheels[wheel] = c.wheels.sign_f(wheel) * self.plant.motors[slot].speed_radps;
        }
        control::kinematics::forward(&c.geometry, wheels)
    }
}
