"""Scenarios on the emulated board: the release ELF, unmodified, against simulated C620s and the
onboard's end of the MCU link. Each scenario is a test that can fail; the process exits non-zero
if any fails.

    python3 scenarios.py --elf passangle-stm32 --link emu_link [--only NAME ...] [--log DIR]
    python3 scenarios.py --elf OTHER.elf --link emu_link --only drive --report-only
"""

import argparse
import json
import os
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import stm32f407 as mcu  # noqa: E402
from defmt import DefmtDecoder  # noqa: E402
from world import MS, US, World  # noqa: E402


class Fail(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Fail(what)


class Run:
    """One boot of the board with a world around it."""

    def __init__(self, args, escs_present=True):
        self.world = World(args.link, escs_present=escs_present)
        self.board = mcu.Board(args.elf, self.world)
        self.world.attach(self.board)
        self.defmt = DefmtDecoder(args.elf)
        self.heartbeat_counter = 0
        self.heartbeats_on = False
        self.figures = {}

    @property
    def now(self):
        return self.board.cycles

    def run_ms(self, ms):
        self.run_to(self.now + int(ms * MS))

    def run_to(self, cycle):
        while self.now < cycle:
            self.board.run_until(min(cycle, self.now + 5 * MS))
            self.defmt.feed(self.board.drain_rtt(), self.now)
        self.world.poll_link(force=True)

    def start_heartbeats(self, period_ms=20):
        self.heartbeats_on = True

        def beat():
            if not self.heartbeats_on:
                return
            self.heartbeat_counter += 1
            self.world.send("heartbeat %d" % self.heartbeat_counter)
            self.world.at(self.now + period_ms * MS, beat)

        beat()

    def hello(self):
        self.world.send("hello")

    def drive(self, vx=0.3, accel=0.5, jerk=2.0):
        self.world.send("drive %g 0 0 %g %g" % (vx, accel, jerk))

    def last_status(self):
        st = self.world.messages("status")
        check(st, "no status report received")
        return st[-1][1]

    def commands_after(self, cycle):
        return [(t, c) for t, c in self.world.commands if t >= cycle]

    def close(self):
        self.world.close()


def ms_of(cycles):
    return cycles / MS


def boot_and_drive(r, vx=0.3, settle_ms=300):
    """Boots, says Hello, heartbeats, waits for the ESCs, drives at `vx`."""
    r.run_ms(30)
    r.hello()
    r.start_heartbeats()
    r.run_ms(100)
    r.drive(vx)
    r.run_ms(settle_ms)


# --- scenarios -------------------------------------------------------------------------------

def scenario_boot(r):
    r.run_ms(30)
    t_hello = r.now
    r.hello()
    r.run_ms(20)
    hellos = r.world.messages("hello", since=t_hello)
    check(hellos, "Hello not answered within 20 ms")
    check(hellos[0][1].get("role") == "3", "Hello answered with role %s" % hellos[0][1].get("role"))
    r.figures["hello answered after (ms)"] = round(ms_of(hellos[0][0] - t_hello), 2)
    cmds = r.world.commands
    check(cmds and cmds[0][1] == [0, 0, 0, 0], "first 0x200 frame after reset is not all zero")
    r.figures["first 0x200 (zero) at (ms)"] = round(ms_of(cmds[0][0]), 3)
    starts = r.board.iwdg.starts
    check(starts, "IWDG never started")
    r.figures["IWDG started at (us)"] = round(starts[0] / US, 1)
    check(starts[0] < 200 * US, "IWDG started late, at %.0f us" % (starts[0] / US))
    r.start_heartbeats()
    r.run_ms(200)
    st = r.last_status()
    check(st["mode"] == "Idle", "mode %s after boot" % st["mode"])
    check("NO_HOST" not in st["interlocks"], "NO_HOST still set after Hello")
    step_max = int(st.get("control_step_max_us", "0"))
    r.figures["control_step_max_us (Status)"] = step_max
    check(0 < step_max < 1000, "control_step_max_us %d is not within (0, 1000)" % step_max)
    check(r.defmt.lines, "no defmt log decoded")
    # The wiring as the binary sets it up.
    can = r.board.can1
    check(can.mcr & (1 << 4), "NART not set (automatic retransmission is on)")
    btr = can.regs.get(0x1C)
    timing = (btr & 0x3FF) + 1, ((btr >> 16) & 0xF) + 1, ((btr >> 20) & 0x7) + 1, ((btr >> 24) & 3) + 1
    r.figures["CAN prescaler, BS1, BS2, SJW"] = list(timing)
    check(timing == (3, 10, 3, 1), "CAN bit timing %s, expected prescaler 3, BS1 10, BS2 3, SJW 1" % (timing,))
    nv = r.board.nvic
    uart4, tim2 = mcu.IRQ["UART4"], mcu.IRQ["TIM2"]
    steps = nv.taken.get(uart4, 0)
    r.figures["control executor interrupts (UART4) in %.0f ms" % ms_of(r.now)] = steps
    check(steps >= 0.9 * ms_of(r.now - 60 * MS), "the control step does not run on the UART4 executor")
    check(nv.priority(uart4) > nv.priority(tim2) and nv.priority(uart4) > 0,
          "UART4 executor priority %d (TIM2 %d)" % (nv.priority(uart4), nv.priority(tim2)))


def scenario_drive(r, burst=40):
    """Drive and stop with odometry and status streaming and a 40-frame burst."""
    t0 = r.now
    boot_and_drive(r, settle_ms=900)
    t_burst = r.now
    burst_bytes = b"".join(r.world.link.frame("heartbeat_ack %d" % (1000 + i)) for i in range(burst))
    r.world.send_raw(burst_bytes)
    r.run_ms(1100)
    t_cruise = r.now
    odo = r.world.messages("odometry", since=t_cruise - 500 * MS)
    check(odo, "no odometry while cruising")
    vx = sum(float(f["vx_mps"]) for _, f in odo) / len(odo)
    r.figures["cruise vx (m/s, commanded 0.3)"] = round(vx, 3)
    check(0.2 < vx < 0.4, "cruise speed %.3f m/s (0.3 commanded)" % vx)
    r.world.send("stop 0")
    r.run_ms(1800)
    t_end = r.now
    odo_end = r.world.messages("odometry", since=t_end - 100 * MS)
    check(odo_end and abs(float(odo_end[-1][1]["vx_mps"])) < 0.02,
          "still moving after the stop: %s" % (odo_end[-1][1]["vx_mps"] if odo_end else "no odometry"))
    last_cmds = r.commands_after(t_end - 50 * MS)
    check(last_cmds and all(c == [0, 0, 0, 0] for _, c in last_cmds), "currents not zero after the stop")
    span_s = (t_end - t0) / mcu.CPU_HZ
    n_odo = len(r.world.messages("odometry", since=t0))
    n_status = len(r.world.messages("status", since=t0))
    acks = [a for a in r.world.acks if a[0] >= t_burst]
    r.figures["seconds emulated"] = round(span_s, 2)
    r.figures["odometry frames"] = n_odo
    r.figures["status frames"] = n_status
    r.figures["corrupted link frames (firmware -> host)"] = len(r.world.bad_frames)
    r.figures["undecodable payloads"] = len(r.world.undecodable)
    r.figures["burst frames acked (of %d)" % burst] = len(acks)
    st = r.last_status()
    r.figures["link_errors reported by the firmware"] = int(st.get("link_errors", 0) or 0)
    r.figures["control_step_max_us (Status)"] = int(st.get("control_step_max_us", 0) or 0)
    gaps = [b[0] - a[0] for a, b in zip(r.world.commands, r.world.commands[1:]) if a[0] > t0 + 50 * MS]
    r.figures["0x200 period max (us)"] = round(max(gaps) / US, 1) if gaps else None
    check(n_odo >= 90 * span_s, "only %d odometry frames in %.1f s" % (n_odo, span_s))
    check(n_status >= 9 * span_s, "only %d status frames in %.1f s" % (n_status, span_s))
    check(not r.world.bad_frames, "%d corrupted link frames: %s" % (len(r.world.bad_frames), r.world.bad_frames[:3]))
    check(len(acks) == burst, "%d of %d burst frames acked" % (len(acks), burst))
    check(int(st.get("link_errors", 0) or 0) == 0, "firmware counted %s link errors" % st.get("link_errors"))


def scenario_escs_absent(r):
    r.run_ms(30)
    r.hello()
    r.start_heartbeats()
    r.run_ms(100)
    t = r.now
    r.drive()
    r.run_ms(50)
    rej = r.world.messages("rejected", since=t)
    check(rej, "drive with no ESCs was not rejected")
    check(rej[0][1]["reason"] == "Interlocked", "rejected for %s" % rej[0][1]["reason"])
    st = r.last_status()
    check("ESC_FEEDBACK_MISSING" in st["interlocks"], "interlocks %s" % st["interlocks"])
    cmds = r.commands_after(0)
    check(all(c == [0, 0, 0, 0] for _, c in cmds), "non-zero current with no ESCs")
    can = r.board.can1
    r.figures["0x200 attempts in %.0f ms (no ACK)" % ms_of(r.now)] = can.attempts
    r.figures["TEC"] = can.tec
    check(can.attempts >= 0.8 * ms_of(r.now - 30 * MS), "the firmware stopped trying to send")


def scenario_feedback_stall(r):
    boot_and_drive(r)
    t = r.now
    r.world.escs[2].silent = True
    r.run_ms(30)
    cmds = r.commands_after(t)
    nonzero = [ms_of(tc - t) for tc, c in cmds if c != [0, 0, 0, 0]]
    last_nonzero = max(nonzero) if nonzero else 0.0
    r.figures["last non-zero 0x200 after the ESC went silent (ms)"] = round(last_nonzero, 2)
    check(last_nonzero <= 12, "currents non-zero %.1f ms after the ESC went silent" % last_nonzero)
    st = r.last_status()
    check(st["esc_faults"].split(",")[2] == "MISSING", "ESC 3 faults %s" % st["esc_faults"])
    check(st["mode"] == "Faulted", "mode %s" % st["mode"])
    opened = [tc for tc, closed in r.world.contactor_log if tc >= t and not closed]
    check(opened, "contactor still closed")
    r.figures["contactor opened after (ms)"] = round(ms_of(opened[0] - t), 2)


def scenario_bus_off(r):
    boot_and_drive(r)
    t = r.now
    can = r.board.can1
    can.fault_until = t + 60 * MS  # every frame fails with a bit error for 60 ms
    r.run_ms(150)
    st = r.last_status()
    check(int(st["bus_off_count"]) >= 1, "no bus-off counted")
    check("CAN_BUS_OFF" in st["interlocks"], "interlocks %s" % st["interlocks"])
    # The contactor opened with the fault, so the ESCs are off and nobody acknowledges: look at
    # what the firmware tries to send once the controller is back on the bus.
    after = [(tc, list(struct.unpack(">4h", d))) for tc, sid, d in can.attempt_log
             if tc >= t + 62 * MS and sid == 0x200 and len(d) == 8]
    check(after, "no 0x200 frames attempted after the bus recovered")
    check(all(c == [0, 0, 0, 0] for _, c in after), "non-zero currents after bus-off")
    check(not r.world.contactor_closed(), "contactor closed after bus-off")
    t_clear = r.now
    r.world.send("clear")
    r.run_ms(60)
    st = r.last_status()
    check(st["mode"] == "Idle", "mode %s after ClearFaults" % st["mode"])
    check(r.world.contactor_closed(), "contactor still open after ClearFaults")
    r.figures["bus_off_count"] = int(st["bus_off_count"])
    r.figures["frames sent after recovery"] = len(r.commands_after(t_clear))


def scenario_link_flood(r):
    r.run_ms(30)
    r.hello()
    r.start_heartbeats()
    r.run_ms(100)
    t = r.now
    # One second of line-rate traffic: garbage with valid heartbeats between.
    chunks = []
    for i in range(60):
        chunks.append(r.world.link.frame("garbage 1400 %d" % (i + 7)))
        chunks.append(bytes([0]))
        chunks.append(r.world.link.frame("heartbeat_ack %d" % (5000 + i)))
    flood = b"".join(chunks)
    r.world.send_raw(flood)
    r.figures["flood bytes"] = len(flood)
    r.run_ms(1100)
    cmds = r.commands_after(t)
    gaps = [b[0] - a[0] for a, b in zip(cmds, cmds[1:])]
    r.figures["0x200 period max during the flood (us)"] = round(max(gaps) / US, 1)
    check(max(gaps) < 1500 * US, "control step stalled %.0f us during the flood" % (max(gaps) / US))
    check(not r.board.resets, "reset during the flood: %s" % r.board.resets)
    acks = [a for a in r.world.acks if a[0] >= t]
    r.figures["heartbeats acked through the flood (of 60)"] = len(acks)
    check(len(acks) >= 55, "only %d of 60 valid frames got through the flood" % len(acks))
    st = r.last_status()
    r.figures["link_errors counted"] = int(st["link_errors"])
    check(int(st["link_errors"]) > 0, "garbage not counted")
    t2 = r.now
    r.hello()
    r.run_ms(20)
    check(r.world.messages("hello", since=t2), "Hello not answered after the flood")
    r.figures["control_step_max_us (Status)"] = int(st.get("control_step_max_us", 0) or 0)


def scenario_panic(r):
    boot_and_drive(r)
    cmds = r.commands_after(r.now - 20 * MS)
    check(cmds and any(c != [0, 0, 0, 0] for _, c in cmds), "not driving before the fault")
    dma = r.board.dma2
    injected = {}

    def inject():
        # A DMA transfer error on the link's TX stream: embassy's DMA interrupt panics on it.
        if dma.cr[6] & 1 and dma.cr[6] & (1 << 2):
            dma.flag(6, 3)
            injected["t"] = r.board.cycles
        else:
            r.world.at(r.board.cycles + 20 * US, inject)

    r.world.at(r.now + 1 * MS, inject)
    r.run_ms(100)
    check("t" in injected, "could not inject the DMA error")
    t = injected["t"]
    check(r.board.resets, "no reset after the panic")
    t_reset, reason = r.board.resets[0]
    r.figures["reset after (ms)"] = round(ms_of(t_reset - t), 2)
    r.figures["reset reason"] = reason
    before_reset = [(tc, c) for tc, c in r.world.commands if tc <= t_reset]
    last_t, last_c = before_reset[-1]
    r.figures["last 0x200 before the reset"] = last_c
    r.figures["last 0x200 at (ms after the fault)"] = round(ms_of(last_t - t), 3)
    check(last_c == [0, 0, 0, 0], "last 0x200 frame before the reset is %s" % last_c)
    check(last_t - t <= 2 * MS, "zero frame %.2f ms after the fault" % ms_of(last_t - t))
    opened = [tc for tc, closed in r.world.contactor_log if tc >= t and not closed]
    check(opened and opened[0] - t <= 2 * MS, "contactor not open within 2 ms of the panic")
    r.figures["contactor open after (ms)"] = round(ms_of(opened[0] - t), 3)


def scenario_stalled_task(r):
    boot_and_drive(r)
    t = r.now
    r.board.tim2.stalled = True  # the time driver's interrupt never comes: every task stalls
    r.run_ms(120)
    check(r.board.resets, "no reset within 120 ms of the stall")
    t_reset, reason = r.board.resets[0]
    r.figures["reset after (ms)"] = round(ms_of(t_reset - t), 2)
    r.figures["reset reason"] = reason
    check(reason == "iwdg", "reset by %s" % reason)
    check(t_reset - t <= 60 * MS, "IWDG reset %.1f ms after the stall" % ms_of(t_reset - t))
    after = r.commands_after(t_reset)
    check(after and after[0][1] == [0, 0, 0, 0], "first 0x200 after the reset is not zero")


def scenario_stuck_esc(r):
    boot_and_drive(r)
    t = r.now
    r.world.escs[0].stuck_a = 18.0
    r.run_ms(50)
    opened = [tc for tc, closed in r.world.contactor_log if tc >= t and not closed]
    check(opened, "contactor still closed with ESC 1 stuck at 18 A")
    r.figures["contactor opened after (ms)"] = round(ms_of(opened[0] - t), 2)
    check(opened[0] - t <= 10 * MS, "contactor opened %.1f ms after the fault" % ms_of(opened[0] - t))
    st = r.last_status()
    check("ESC_OVER_CURRENT" in st["interlocks"], "interlocks %s" % st["interlocks"])
    r.run_ms(1000)
    w = [abs(e.omega) for e in r.world.escs]
    r.figures["wheel speeds 1 s after (rad/s)"] = [round(x, 3) for x in w]
    check(max(w) < 0.2, "wheels still turning 1 s after the cut: %s" % w)


SCENARIOS = {
    "boot": (scenario_boot, {}),
    "drive": (scenario_drive, {}),
    "escs-absent": (scenario_escs_absent, {"escs_present": False}),
    "feedback-stall": (scenario_feedback_stall, {}),
    "bus-off": (scenario_bus_off, {}),
    "link-flood": (scenario_link_flood, {}),
    "panic": (scenario_panic, {}),
    "stalled-task": (scenario_stalled_task, {}),
    "stuck-esc": (scenario_stuck_esc, {}),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--elf", required=True)
    ap.add_argument("--link", required=True, help="the emu_link executable")
    ap.add_argument("--only", nargs="*", help="scenario names (default: all)")
    ap.add_argument("--log", help="directory for each scenario's decoded defmt log")
    ap.add_argument("--report-only", action="store_true", help="print figures, exit 0 on failures")
    args = ap.parse_args()
    for path in (args.elf, args.link):
        if not os.path.exists(path):
            sys.exit("not found: %s" % path)
    names = args.only or list(SCENARIOS)
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        sys.exit("unknown scenario(s): %s (known: %s)" % (", ".join(unknown), ", ".join(SCENARIOS)))
    failed = []
    for name in names:
        fn, kw = SCENARIOS[name]
        t0 = time.time()
        r = Run(args, **kw)
        result = "ok"
        try:
            fn(r)
        except Fail as e:
            result = "FAIL: %s" % e
            failed.append(name)
        except mcu.Lockup as e:
            result = "FAIL (emulation stopped): %s" % e
            failed.append(name)
        finally:
            r.close()
        wall = time.time() - t0
        print("%-15s %s  [%.1f s emulated in %.1f s]" % (name, result, r.now / mcu.CPU_HZ, wall))
        for k, v in r.figures.items():
            print("    %s: %s" % (k, json.dumps(v)))
        if args.log:
            os.makedirs(args.log, exist_ok=True)
            with open(os.path.join(args.log, name + ".log"), "w") as f:
                f.write("\n".join(r.defmt.lines) + "\n")
        sys.stdout.flush()
    print("%d of %d scenarios passed" % (len(names) - len(failed), len(names)))
    if failed and not args.report_only:
        print("failed: %s" % ", ".join(failed))
        sys.exit(1)


if __name__ == "__main__":
    main()
