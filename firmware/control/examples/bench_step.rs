//! Host proxy for the firmware's worst-case `Controller::step` time (docs/architecture.md section 5 figure).
//!
//! Runs the controller closed around the plant model through a scripted run (handshake, ramp,
//! cruise with 4 feedback frames and MCU-link traffic every step, a fault, recovery) and prints the
//! step-time distribution, as a share of the 1 ms control period. The host is much faster than a
//! 168 MHz Cortex-M4F without a data cache: treat the figures as relative (a regression signal),
//! not as the board's timing.
//!
//!     cargo run -p control --release --example bench_step
#![allow(
    clippy::cast_precision_loss,
    clippy::cast_possible_truncation,
    clippy::unwrap_used
)]

#[path = "../tests/common/plant.rs"]
mod plant;

use std::time::Instant;

use control::machine::EscSample;
use control::{BusState, Config, Controller, Inputs};
use plant::{Plant, PlantParams};
use protocol::frame::{Flags, MAX_FRAME_LEN};
use protocol::mcu::Drive;
use protocol::{Heartbeat, Hello, Message, Role};

/// Timed repetitions of each step (on clones); the minimum is kept.
const REPEATS: usize = 5;

fn frame<M: Message>(msg: &M, seq: u16) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = msg.encode_frame(seq, Flags::NONE, &mut buf).unwrap();
    buf[..len].to_vec()
}

/// CAN bits on the wire during a run: (frames, total bits).
#[derive(Default)]
struct BusTally {
    frames: u64,
    bits: u64,
}

impl BusTally {
    fn add(&mut self, id: u16, data: &[u8]) {
        self.frames += 1;
        self.bits += u64::from(control::busload::frame_bits(id, data));
    }
}

/// Runs the scripted scenario once; returns per-step wall times in nanoseconds and the CAN
/// traffic (every feedback frame and every 0x200 command, with their real payloads).
fn run(steps: u64) -> (Vec<u64>, BusTally) {
    let mut bus = BusTally::default();
    let mut ctl = Controller::new(Config::default()).unwrap();
    let mut plant = Plant::new(PlantParams::default(), 42);
    let mut currents = [0i16; 4];
    let mut times = Vec::with_capacity(steps as usize);
    let hello = frame(&Hello::new(Role::Onboard), 1);
    let drive = frame(
        &Drive {
            vx_mps: 0.3,
            vy_mps: 0.0,
            wz_radps: 0.1,
            accel_mps2: 0.5,
            jerk_mps3: 5.0,
        },
        2,
    );
    for step in 1..=steps {
        let now_us = step * 1000;
        plant.advance(currents, 1e-3);
        // Over-temperature on ESC 2 for a while in the second half, to exercise the fault path.
        if step == steps * 2 / 3 {
            plant.motors[1].temperature_c = 90;
        }
        if step == steps * 2 / 3 + 500 {
            plant.motors[1].temperature_c = 40;
        }
        let esc: Vec<EscSample> = (0..4usize)
            .map(|slot| EscSample {
                esc_id: slot as u8 + 1,
                feedback: plant.feedback(slot),
                stamp_us: now_us,
            })
            .collect();
        for sample in &esc {
            bus.add(0x200 + u16::from(sample.esc_id), &sample.feedback.encode());
        }
        let mut link_rx = Vec::new();
        match step {
            2 => link_rx.extend_from_slice(&hello),
            5 => link_rx.extend_from_slice(&drive),
            _ => {}
        }
        if step % 20 == 0 {
            link_rx.extend_from_slice(&frame(
                &Heartbeat {
                    counter: step as u32,
                },
                step as u16,
            ));
        }
        let inputs = Inputs {
            esc: &esc,
            link_rx: &link_rx,
            bus: BusState::Active,
            battery_mv: 24_000,
        };
        // The minimum over a few clones of the same step removes OS preemption from the figure
        // (this machine is shared); the step's own cost is what the firmware cares about.
        let mut best = u64::MAX;
        for _ in 0..REPEATS {
            let mut probe = ctl.clone();
            let t0 = Instant::now();
            std::hint::black_box(probe.step(now_us, &inputs));
            best = best.min(t0.elapsed().as_nanos() as u64);
        }
        times.push(best);
        let out = ctl.step(now_us, &inputs);
        currents = std::hint::black_box(out.currents_raw);
        bus.add(
            protocol::esc::CMD_ID_1_4,
            &protocol::esc::encode_command(currents),
        );
    }
    (times, bus)
}

fn main() {
    let steps = 60_000; // one simulated minute
    let _ = run(2000); // warm caches
    let (mut times, bus) = run(steps);
    times.sort_unstable();
    let pct = |p: f64| times[((times.len() - 1) as f64 * p) as usize];
    let mean = times.iter().sum::<u64>() as f64 / times.len() as f64;
    let max = *times.last().unwrap();
    println!(
        "Controller::step on the host, {steps} steps (scripted run with link traffic and a fault), \
         min of {REPEATS} timed clones per step:"
    );
    println!(
        "  mean {:.2} us, p50 {:.2} us, p99 {:.2} us, p99.9 {:.2} us, max {:.2} us",
        mean / 1e3,
        pct(0.5) as f64 / 1e3,
        pct(0.99) as f64 / 1e3,
        pct(0.999) as f64 / 1e3,
        max as f64 / 1e3
    );
    println!(
        "  worst case = {:.2} % of the 1 ms control period (host proxy; the M4F is slower)",
        max as f64 / 1e4
    );
    let mean_bits = bus.bits as f64 / bus.frames as f64;
    let seconds = steps as f64 / 1000.0;
    println!(
        "CAN bus load at 1 Mbit/s: {:.1} % ({} frames in {seconds:.0} s, mean {mean_bits:.1} bits per frame \
         with stuffing; 4 feedback + 1 command frame per ms)",
        100.0 * bus.bits as f64 / (seconds * 1.0e6),
        bus.frames
    );
}
