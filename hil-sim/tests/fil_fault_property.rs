//! A seeded property over random fault schedules, firmware in the loop: whatever single fault
//! hits the robot at cruise (an ESC going silent, over-temperature, a stuck over-current, a
//! bus-off of random length), the firmware reports it by name within a bounded time and, from the
//! step it latches, puts only all-zero 0x200 frames on the bus for the rest of the run.

use hil_sim::esc_model::EscFault;
use hil_sim::fil::{Action, Event, FilConfig};
use hil_sim::fil_scenarios::{self, BusChoice, LinkChoice};
use protocol::mcu::{DriveMode, EscFaults, Interlocks};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[derive(Debug, Clone, Copy)]
enum Expect {
    Esc(u8, EscFaults),
    BusOff,
}

#[test]
fn any_single_fault_is_named_and_zeroes_the_bus() {
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    for case in 0..24 {
        let at_us = rng.random_range(1_200_000..2_500_000u64) / 1000 * 1000;
        let (action, expect, max_latency_us) = random_fault(&mut rng);
        let (mut fil, _) = fil_scenarios::build(
            FilConfig {
                seed: case,
                ..FilConfig::default()
            },
            &BusChoice::InProcess { record: false },
            LinkChoice::Memory,
        )
        .unwrap();
        let mut events = fil_scenarios::start_events(fil_scenarios::DRIVE_AT_US);
        events.push(Event {
            at_us,
            action: action.clone(),
        });
        fil.schedule(events);
        fil.run_until(at_us + 600_000).unwrap();
        let trace = fil.take_trace();
        let reported = trace.statuses().find(|(t, s)| {
            *t >= at_us
                && s.mode == DriveMode::Faulted
                && match expect {
                    Expect::Esc(id, f) => {
                        s.esc.iter().any(|e| e.esc_id == id && e.faults.contains(f))
                    }
                    Expect::BusOff => s.interlocks.contains(Interlocks::CAN_BUS_OFF),
                }
        });
        let Some((t_report, _)) = reported else {
            panic!("case {case}: {action:?} at {at_us} us was never reported as {expect:?}");
        };
        assert!(
            t_report - at_us <= max_latency_us,
            "case {case}: {action:?} reported after {} us",
            t_report - at_us
        );
        // No ESC other than the faulty one is blamed.
        if let Expect::Esc(id, _) = expect {
            let (_, s) = trace.statuses().find(|(t, _)| *t == t_report).unwrap();
            assert!(
                s.esc.iter().all(|e| e.esc_id == id || e.faults.is_empty()),
                "case {case}: other ESCs blamed: {:?}",
                s.esc
            );
        }
        let nonzero_after = trace
            .commands
            .iter()
            .find(|(t, c)| *t >= t_report && *c != [0; 4]);
        assert!(
            nonzero_after.is_none(),
            "case {case}: {action:?}: non-zero command {nonzero_after:?} after the fault latched at {t_report}"
        );
    }
}

/// A random single fault: the action, what the firmware must report, and its latency bound (us).
fn random_fault(rng: &mut ChaCha8Rng) -> (Action, Expect, u64) {
    let esc_id = rng.random_range(1..=4u8);
    match rng.random_range(0..4) {
        0 => (
            Action::Fault {
                esc_id,
                fault: EscFault::Silent,
            },
            Expect::Esc(esc_id, EscFaults::MISSING),
            10_000,
        ),
        1 => (
            Action::Fault {
                esc_id,
                fault: EscFault::OverTemperature(rng.random_range(80.0..120.0)),
            },
            Expect::Esc(esc_id, EscFaults::OVER_TEMPERATURE),
            2_000,
        ),
        2 => {
            let amps = rng.random_range(16.0..20.0) * if rng.random() { 1.0 } else { -1.0 };
            (
                Action::Fault {
                    esc_id,
                    fault: EscFault::StuckCurrent(amps),
                },
                Expect::Esc(esc_id, EscFaults::OVER_CURRENT),
                // over_current_time_us (3 ms) + the step it is seen in.
                5_000,
            )
        }
        _ => (
            Action::BusOff {
                duration_us: rng.random_range(1_000..50_000),
            },
            Expect::BusOff,
            1_000,
        ),
    }
}
