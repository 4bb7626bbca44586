//! Property: once a fault is latched (the contactor opens), no input sequence puts a non-zero
//! current on the bus until a `ClearFaults` is accepted; and whenever a hard interlock is present,
//! latched or not, the currents are zero.
#![allow(clippy::cast_possible_truncation)]

mod common;

use common::{Patch, Sim};
use control::machine::{Command, DriveCommand};
use control::safety::HARD_INTERLOCKS;
use control::{BusState, Config, Twist};
use proptest::prelude::*;

/// One thing that can happen between steps.
#[derive(Debug, Clone)]
enum Op {
    Ticks(u8),
    Heartbeat,
    Drive {
        vx: f32,
        vy: f32,
        wz: f32,
        accel: f32,
        jerk: f32,
    },
    Stop,
    ClearFaults,
    SetConfig,
    Silence {
        slot: usize,
        on: bool,
    },
    Temperature {
        slot: usize,
        c: Option<u8>,
    },
    Current {
        slot: usize,
        a: Option<f32>,
    },
    Lock {
        slot: usize,
        on: bool,
    },
    Bus(BusState),
    HeartbeatsOn(bool),
}

fn op() -> impl Strategy<Value = Op> {
    let slot = 0usize..4;
    prop_oneof![
        4 => (1u8..40).prop_map(Op::Ticks),
        2 => Just(Op::Heartbeat),
        3 => (-1.2f32..1.2, -1.2f32..1.2, -3.0f32..3.0, -0.5f32..3.0, -5.0f32..50.0)
            .prop_map(|(vx, vy, wz, accel, jerk)| Op::Drive { vx, vy, wz, accel, jerk }),
        1 => Just(Op::Stop),
        2 => Just(Op::ClearFaults),
        1 => Just(Op::SetConfig),
        1 => (slot.clone(), any::<bool>()).prop_map(|(slot, on)| Op::Silence { slot, on }),
        1 => (slot.clone(), proptest::option::of(20u8..120)).prop_map(|(slot, c)| Op::Temperature { slot, c }),
        1 => (slot.clone(), proptest::option::of(-20.0f32..20.0)).prop_map(|(slot, a)| Op::Current { slot, a }),
        1 => (slot, any::<bool>()).prop_map(|(slot, on)| Op::Lock { slot, on }),
        1 => prop_oneof![Just(BusState::Active), Just(BusState::Passive), Just(BusState::BusOff)].prop_map(Op::Bus),
        1 => any::<bool>().prop_map(Op::HeartbeatsOn),
    ]
}

/// Tracks the property while applying ops.
struct Checker {
    sim: Sim,
    latched_since_clear: bool,
}

impl Checker {
    fn tick(&mut self) -> Result<(), TestCaseError> {
        let out = self.sim.tick();
        let status = self.sim.machine.status(self.sim.now_us);
        let hard = status.interlocks.0 & HARD_INTERLOCKS.0 != 0;
        if hard {
            prop_assert_eq!(
                out.currents_raw,
                [0; 4],
                "hard interlock {:?} with currents",
                status.interlocks
            );
        }
        if self.latched_since_clear {
            prop_assert_eq!(
                out.currents_raw,
                [0; 4],
                "non-zero current after a latched fault"
            );
        }
        // A latched fault opens the contactor. A present but unlatched `ESC_FEEDBACK_MISSING` (an
        // ESC restarted by `ClearFaults` that has not reported yet) refuses drives without
        // latching, and the drive is allowed once that ESC reports.
        self.latched_since_clear |= !self.sim.machine.contactor_closed();
        Ok(())
    }

    fn apply(&mut self, op: &Op) -> Result<(), TestCaseError> {
        match *op {
            Op::Ticks(n) => {
                for _ in 0..n {
                    self.tick()?;
                }
            }
            Op::Heartbeat => self
                .sim
                .command(Command::Heartbeat)
                .map_err(|e| TestCaseError::fail(format!("{e}")))?,
            Op::Drive {
                vx,
                vy,
                wz,
                accel,
                jerk,
            } => {
                let _ = self.sim.command(Command::Drive(DriveCommand {
                    twist: Twist::new(vx, vy, wz),
                    accel_mps2: accel,
                    jerk_mps3: jerk,
                }));
            }
            Op::Stop => {
                let _ = self.sim.command(Command::Stop { immediate: false });
            }
            Op::ClearFaults => {
                if self.sim.command(Command::ClearFaults).is_ok() {
                    self.latched_since_clear = false;
                }
            }
            Op::SetConfig => {
                let _ = self.sim.command(Command::SetConfig(Config::default()));
            }
            Op::Silence { slot, on } => self.sim.silent[slot] = on,
            Op::Temperature { slot, c } => self.sim.patch[slot].temperature_c = c,
            Op::Current { slot, a } => {
                self.sim.patch[slot] = Patch {
                    current_raw: a.map(protocol::esc::amps_to_raw),
                    ..self.sim.patch[slot]
                };
            }
            Op::Lock { slot, on } => self.sim.plant.motors[slot].locked = on,
            Op::Bus(state) => self.sim.bus = state,
            Op::HeartbeatsOn(on) => self.sim.heartbeat_every = if on { 20 } else { 0 },
        }
        Ok(())
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn no_current_after_a_latched_fault(seed in 0u64..1000, ops in proptest::collection::vec(op(), 1..60)) {
        let mut c = Checker { sim: Sim::default_seeded(seed), latched_since_clear: false };
        c.sim.start_forward(0.3);
        for _ in 0..200 {
            c.tick()?;
        }
        for op in &ops {
            c.apply(op)?;
        }
        for _ in 0..50 {
            c.tick()?;
        }
    }
}

#[test]
fn the_property_checker_can_fail() {
    // A sequence that latches a fault must trip the checker's bookkeeping: after the
    // over-temperature, `latched_since_clear` is set and stays set without a ClearFaults.
    let mut c = Checker {
        sim: Sim::default_seeded(1),
        latched_since_clear: false,
    };
    c.sim.start_forward(0.3);
    c.apply(&Op::Ticks(100)).unwrap();
    assert!(!c.latched_since_clear);
    c.apply(&Op::Temperature {
        slot: 0,
        c: Some(100),
    })
    .unwrap();
    c.apply(&Op::Ticks(2)).unwrap();
    assert!(c.latched_since_clear);
}
