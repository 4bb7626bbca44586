"""Everything outside the emulated STM32F407: four C620 ESCs with M3508 wheels on the CAN bus,
the onboard computer's end of the MCU link (the project's own codec, `emu_link`), the battery,
and the motor contactor the firmware switches on PE9.
"""

import math
import struct
import subprocess

import stm32f407 as mcu

MS = mcu.CPU_HZ // 1000
US = mcu.CYCLES_PER_US

# M3508 at the output shaft: torque per amp, inertia and viscous load per wheel (a 6 kg robot).
KT_NM_PER_A = 0.3
J_KG_M2 = 0.01
B_NM_S = 0.05
GEAR = 3591.0 / 187.0
CURRENT_TAU_S = 0.0005
ESC_BOOT_MS = 20


class Esc:
    """One C620 + M3508: follows the commanded current (first order), integrates the wheel, and
    sends its feedback frame (0x200 + id) every millisecond while powered and present."""

    def __init__(self, esc_id):
        self.esc_id = esc_id
        self.present = True
        self.silent = False  # stops sending (a loose CAN stub), keeps driving
        self.stuck_a = None  # current stuck at this value whatever is commanded
        self.command_raw = 0
        self.current_a = 0.0
        self.omega = 0.0  # output shaft, rad/s
        self.rotor_angle = 0.0  # rad
        self.temperature_c = 30
        self.powered_since = 0
        self.powered = True

    def advance(self, dt):
        if not self.powered or not self.present:
            target = 0.0
        elif self.stuck_a is not None:
            target = self.stuck_a
        else:
            target = self.command_raw * 20.0 / 16384.0
        if self.stuck_a is not None and self.powered and self.present:
            self.current_a = target
        else:
            self.current_a += (target - self.current_a) * (dt / (CURRENT_TAU_S + dt))
        torque = KT_NM_PER_A * self.current_a - B_NM_S * self.omega
        self.omega += torque / J_KG_M2 * dt
        self.rotor_angle += self.omega * GEAR * dt

    def feedback(self):
        angle = int((self.rotor_angle % (2 * math.pi)) / (2 * math.pi) * 8192) % 8192
        rpm = int(round(self.omega * GEAR * 60 / (2 * math.pi)))
        rpm = max(-32768, min(32767, rpm))
        cur = int(round(self.current_a * 16384 / 20.0))
        cur = max(-32768, min(32767, cur))
        return struct.pack(">HhhBB", angle, rpm, cur, self.temperature_c, 0)


class Link:
    """The `emu_link` codec process (control/examples/emu_link.rs)."""

    def __init__(self, exe):
        self.p = subprocess.Popen([exe], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  text=True, bufsize=1)

    def ask(self, line):
        self.p.stdin.write(line + "\n")
        self.p.stdin.flush()
        out = []
        while True:
            reply = self.p.stdout.readline()
            if not reply:
                raise RuntimeError("emu_link exited on `%s`" % line[:40])
            reply = reply.rstrip("\n")
            if reply == "end":
                return out
            out.append(reply)

    def frame(self, line):
        (reply,) = self.ask(line)
        assert reply.startswith("frame ")
        return bytes.fromhex(reply[6:])

    def close(self):
        self.p.stdin.close()
        self.p.wait(timeout=10)


def parse_fields(text):
    fields = {}
    for word in text.split():
        if "=" in word:
            k, v = word.split("=", 1)
            fields[k] = v
    return fields


class World:
    def __init__(self, link_exe, escs_present=True):
        self.board = None
        self.escs = [Esc(i + 1) for i in range(4)]
        for e in self.escs:
            e.present = escs_present
        self.battery_v = 24.0
        self.link = Link(link_exe)
        self.t_model = 0
        # The ESCs are not synchronised: each sends on its own phase of the millisecond.
        self.next_feedback = [i * 250 * US + 37 * US * i for i in range(4)]
        self.commands = []  # (cycle, [4 raw]) of every 0x200 frame on the bus
        self.received = []  # (cycle, kind, fields) of every message from the firmware
        self.bad_frames = []  # (cycle, error)
        self.undecodable = []
        self.acks = []
        self.resets = []
        self.rx_pending = bytearray()
        self.last_link_poll = 0
        self.events = []  # (cycle, callable) one-shot scenario actions
        self.contactor_log = []

    # --- wiring to the board ---
    def attach(self, board):
        self.board = board

    def contactor_gates_power(self):
        g = self.board.gpio["E"]
        return g.is_output(9)

    def contactor_closed(self):
        g = self.board.gpio["E"]
        return (not g.is_output(9)) or g.level(9)

    def can_acked(self):
        return any(e.present and e.powered for e in self.escs)

    def can_frame_sent(self, t, sid, data):
        if sid == 0x200 and len(data) == 8:
            cur = list(struct.unpack(">4h", data))
            self.commands.append((t, cur))
            for e, c in zip(self.escs, cur):
                e.command_raw = c

    def gpio_changed(self, port, t, odr):
        if port == "E" and self.board.gpio["E"].is_output(9):
            closed = bool(odr & (1 << 9))
            if not self.contactor_log or self.contactor_log[-1][1] != closed:
                self.contactor_log.append((t, closed))

    def on_reset(self, t, reason):
        self.resets.append((t, reason))
        if self.contactor_log and self.contactor_log[-1][1]:
            self.contactor_log.append((t, False))  # the pin floats at reset: the relay opens
        self.poll_link(force=True)

    # --- time ---
    def advance(self, now):
        # Scenario actions due.
        while self.events and self.events[0][0] <= now:
            _, action = self.events.pop(0)
            action()
        # Physics in 250 us steps, feedback frames on each ESC's own 1 ms phase.
        step = 250 * US
        while self.t_model + step <= now:
            self.t_model += step
            closed = self.contactor_closed()
            for i, e in enumerate(self.escs):
                was = e.powered
                e.powered = closed or not self.contactor_gates_power()
                if e.powered and not was:
                    e.powered_since = self.t_model
                e.advance(step / mcu.CPU_HZ)
                if self.t_model >= self.next_feedback[i]:
                    self.next_feedback[i] = self.t_model + MS
                    booted = self.t_model - e.powered_since >= ESC_BOOT_MS * MS
                    if e.present and e.powered and booted and not e.silent:
                        self.board.can1.deliver(0x200 + e.esc_id, e.feedback())
        if now - self.last_link_poll >= 2 * MS:
            self.poll_link()

    def next_event(self, now):
        c = [self.t_model + 250 * US]
        if self.events:
            c.append(self.events[0][0])
        return min(c)

    def at(self, cycle, action):
        self.events.append((cycle, action))
        self.events.sort(key=lambda e: e[0])

    # --- the MCU link ---
    def send(self, request):
        self.board.usart6.host_send(self.link.frame(request))

    def send_raw(self, data):
        self.board.usart6.host_send(data)

    def poll_link(self, force=False):
        b = self.board
        self.last_link_poll = b.cycles
        data = bytes(b.usart6.tx_out)
        b.usart6.tx_out.clear()
        if not data:
            return
        for line in self.link.ask("rx " + data.hex()):
            kind, _, rest = line.partition(" ")
            if kind == "msg":
                seq, _, body = rest.partition(" ")
                name, _, fields = body.partition(" ")
                self.received.append((b.cycles, name, parse_fields(fields)))
            elif kind == "bad":
                self.bad_frames.append((b.cycles, rest))
            elif kind == "undecodable":
                self.undecodable.append((b.cycles, rest))
            elif kind == "ack":
                self.acks.append((b.cycles, rest))

    def messages(self, name, since=0):
        return [(t, f) for t, n, f in self.received if n == name and t >= since]

    def close(self):
        self.link.close()
