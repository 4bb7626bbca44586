//! The onboard end of the MCU link for the emulated board (firmware/emu): the project's own codec
//! (`protocol`'s framing, CRC and message set) behind a line protocol on stdin/stdout, so the
//! Python board model never frames or parses a byte itself.
//!
//! Requests, one per line; every answer ends with a line `end`:
//! - `hello`, `heartbeat N`, `heartbeat_ack N` (asks for an ack), `drive VX VY WZ ACCEL JERK`, `stop 0|1`, `clear`, `garbage N SEED`:
//!   answered with `frame HEX` (the encoded frame, or N pseudo-random bytes for `garbage`);
//! - `rx HEX`: bytes the firmware sent, fed to one persistent deframer; answered with one line per
//!   frame completed: `msg SEQ KIND key=value...`, `ack SEQ MSG_ID`, `bad ERROR` (the frame layer
//!   rejected it: COBS, CRC, length) or `undecodable SEQ MSG_ID ERROR` (framing fine, payload not a
//!   message of this protocol version).
//!
//! Run: `cargo run -p control --example emu_link` (stdin/stdout; errors on stderr, exit 1 on a
//! request it cannot parse).

use std::fmt::Write as _;
use std::io::{self, BufRead, Write};
use std::process::ExitCode;

use protocol::frame::{Flags, MAX_FRAME_LEN};
use protocol::mcu::{ClearFaults, Drive, FromFirmware, Stop};
use protocol::{Deframer, Heartbeat, Hello, Message, Role};

fn hex(bytes: &[u8]) -> String {
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

fn unhex(s: &str) -> Result<Vec<u8>, String> {
    if !s.len().is_multiple_of(2) {
        return Err(format!("odd hex length {}", s.len()));
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).map_err(|e| format!("hex at {i}: {e}")))
        .collect()
}

fn encode<M: Message>(msg: &M, seq: u16) -> Result<String, String> {
    encode_with(msg, seq, Flags::NONE)
}

fn encode_with<M: Message>(msg: &M, seq: u16, flags: Flags) -> Result<String, String> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = msg
        .encode_frame(seq, flags, &mut buf)
        .map_err(|e| format!("encode: {e:?}"))?;
    Ok(format!("frame {}", hex(&buf[..len])))
}

fn args<const N: usize>(words: &[&str]) -> Result<[f32; N], String> {
    if words.len() != N {
        return Err(format!("expected {N} numbers, got {}", words.len()));
    }
    let mut out = [0.0; N];
    for (o, w) in out.iter_mut().zip(words) {
        *o = w.parse().map_err(|e| format!("number `{w}`: {e}"))?;
    }
    Ok(out)
}

fn describe(msg: &FromFirmware) -> String {
    match msg {
        FromFirmware::Hello(h) => format!("hello version={} role={}", h.version, h.role),
        FromFirmware::Odometry(o) => format!(
            "odometry stamp_us={} x_m={} y_m={} yaw_rad={} vx_mps={} vy_mps={} wz_radps={}",
            o.stamp_us, o.x_m, o.y_m, o.yaw_rad, o.vx_mps, o.vy_mps, o.wz_radps
        ),
        FromFirmware::Status(s) => {
            let interlocks: Vec<&str> = s.interlocks.names().collect();
            let faults: Vec<String> = s
                .esc
                .iter()
                .map(|e| {
                    let names: Vec<&str> = e.faults.names().collect();
                    if names.is_empty() {
                        "-".to_owned()
                    } else {
                        names.join("|")
                    }
                })
                .collect();
            let currents: Vec<String> = s.esc.iter().map(|e| format!("{}", e.current_a)).collect();
            format!(
                "status stamp_us={} mode={:?} interlocks={} esc_faults={} esc_current_a={} \
                 bus_off_count={} link_errors={} rejected_count={} battery_mv={} \
                 control_step_max_us={}",
                s.stamp_us,
                s.mode,
                if interlocks.is_empty() {
                    "-".to_owned()
                } else {
                    interlocks.join("|")
                },
                faults.join(","),
                currents.join(","),
                s.bus_off_count,
                s.link_errors,
                s.rejected_count,
                s.battery_mv,
                s.control_step_max_us
            )
        }
        FromFirmware::Rejected(r) => format!(
            "rejected msg_id={} seq={} reason={:?} field={}",
            r.msg_id,
            r.seq,
            r.reason,
            if r.field.as_str().is_empty() {
                "-"
            } else {
                r.field.as_str()
            }
        ),
        FromFirmware::LogLine(l) => format!("log level={:?} text={}", l.level, l.text.as_str()),
    }
}

/// A small xorshift generator for `garbage` (reproducible from the seed).
fn garbage(n: usize, seed: u64) -> Vec<u8> {
    let mut x = seed | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x.to_le_bytes()[0]
        })
        .collect()
}

struct Session {
    deframer: Deframer<MAX_FRAME_LEN>,
    seq: u16,
}

impl Session {
    fn next_seq(&mut self) -> u16 {
        self.seq = self.seq.wrapping_add(1);
        self.seq
    }

    fn handle(&mut self, line: &str, out: &mut Vec<String>) -> Result<(), String> {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&cmd, rest)) = words.split_first() else {
            return Ok(());
        };
        match cmd {
            "hello" => out.push(encode(&Hello::new(Role::Onboard), self.next_seq())?),
            "heartbeat" | "heartbeat_ack" => {
                let counter = rest
                    .first()
                    .ok_or("heartbeat needs a counter")?
                    .parse()
                    .map_err(|e| format!("heartbeat counter: {e}"))?;
                let flags = if cmd == "heartbeat_ack" {
                    Flags::ACK_REQUESTED
                } else {
                    Flags::NONE
                };
                out.push(encode_with(&Heartbeat { counter }, self.next_seq(), flags)?);
            }
            "drive" => {
                let [vx, vy, wz, accel, jerk] = args::<5>(rest)?;
                let drive = Drive {
                    vx_mps: vx,
                    vy_mps: vy,
                    wz_radps: wz,
                    accel_mps2: accel,
                    jerk_mps3: jerk,
                };
                out.push(encode(&drive, self.next_seq())?);
            }
            "stop" => {
                let immediate = rest.first() == Some(&"1");
                out.push(encode(&Stop { immediate }, self.next_seq())?);
            }
            "clear" => out.push(encode(&ClearFaults {}, self.next_seq())?),
            "garbage" => {
                let [n, seed] = args::<2>(rest)?;
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                out.push(format!("frame {}", hex(&garbage(n as usize, seed as u64))));
            }
            "rx" => {
                let bytes = unhex(rest.first().copied().unwrap_or(""))?;
                self.deframer.feed_all(&bytes, |f| match f {
                    Err(e) => out.push(format!("bad {e:?}")),
                    Ok(frame) => {
                        let h = frame.header;
                        if h.flags.contains(Flags::IS_ACK) {
                            out.push(format!("ack {} {}", h.seq, h.msg_id));
                        } else {
                            match FromFirmware::decode(&frame) {
                                Ok(msg) => out.push(format!("msg {} {}", h.seq, describe(&msg))),
                                Err(e) => {
                                    out.push(format!("undecodable {} {} {e:?}", h.seq, h.msg_id));
                                }
                            }
                        }
                    }
                });
            }
            other => return Err(format!("unknown request `{other}`")),
        }
        Ok(())
    }
}

fn main() -> ExitCode {
    let stdin = io::stdin();
    let mut stdout = io::stdout().lock();
    let mut session = Session {
        deframer: Deframer::new(),
        seq: 0,
    };
    for (n, line) in stdin.lock().lines().enumerate() {
        let line = match line {
            Ok(line) => line,
            Err(e) => {
                eprintln!("emu_link: reading stdin: {e}");
                return ExitCode::FAILURE;
            }
        };
        let mut out = Vec::new();
        if let Err(e) = session.handle(&line, &mut out) {
            eprintln!("emu_link: line {}: {e}", n + 1);
            return ExitCode::FAILURE;
        }
        for l in out {
            let _ = writeln!(stdout, "{l}");
        }
        if writeln!(stdout, "end")
            .and_then(|()| stdout.flush())
            .is_err()
        {
            return ExitCode::SUCCESS;
        }
    }
    ExitCode::SUCCESS
}
