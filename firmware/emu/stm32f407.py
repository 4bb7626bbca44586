"""An STM32F407 model under Unicorn, with just the peripherals the passangle firmware uses.

The release ELF runs unmodified. Unicorn executes the Thumb-2 code; this module models what
Unicorn does not: the exception model (NVIC entry/return, priorities, PRIMASK/BASEPRI, FPU
context), the system control space (SCB, NVIC, DWT, DCB, SysTick registers) and the
peripherals: RCC, FLASH, PWR, GPIO, TIM2 (embassy's time driver), USART6 with DMA2 streams 1
(RX, circular) and 6 (TX), bxCAN1 (mailboxes, FIFO 0, error states, NART), ADC3, IWDG, and the
RTT control block defmt-rtt writes its log into.

Time is virtual: one instruction is one cycle of the 168 MHz core. The CPU runs in slices of a
few hundred instructions; between slices the peripherals advance to the current cycle and
pending interrupts are taken. When the firmware sleeps (WFE/WFI with nothing pending) time
jumps to the next peripheral event, so idle time costs nothing.

What it does not model is listed in firmware/README.md ("The emulated board").
"""

import struct

from elftools.elf.elffile import ELFFile
from unicorn import (UC_ARCH_ARM, UC_HOOK_CODE, UC_MODE_MCLASS, UC_MODE_THUMB,
                     UC_PROT_ALL, Uc, UcError)
from unicorn import arm_const as A

CPU_HZ = 168_000_000
APB1_TIMER_HZ = 84_000_000
CYCLES_PER_US = CPU_HZ // 1_000_000
LSI_HZ = 32_000

# Exception numbers (16 + IRQn) of the interrupts the firmware uses.
IRQ = {
    "CAN1_TX": 16 + 19,
    "CAN1_RX0": 16 + 20,
    "CAN1_RX1": 16 + 21,
    "CAN1_SCE": 16 + 22,
    "TIM2": 16 + 28,
    "UART4": 16 + 52,
    "DMA2_STREAM1": 16 + 57,
    "DMA2_STREAM6": 16 + 69,
    "USART6": 16 + 71,
}
HARDFAULT = 3
PENDSV = 14
SYSTICK = 15

EXC_RETURN_PAGE = 0xFFFFF000


class Reset(Exception):
    """The MCU reset (watchdog or software request)."""

    def __init__(self, reason):
        super().__init__(reason)
        self.reason = reason


class Lockup(Exception):
    """The emulated CPU hit something it cannot continue from."""


def bits(value, lo, width):
    return (value >> lo) & ((1 << width) - 1)


class Regs:
    """A register file with reset values: plain storage for registers without behaviour."""

    def __init__(self, resets=None):
        self.r = dict(resets or {})

    def get(self, off):
        return self.r.get(off, 0)

    def set(self, off, value):
        self.r[off] = value & 0xFFFFFFFF


class Peripheral:
    name = "?"

    def __init__(self, board):
        self.board = board
        self.regs = Regs()

    def read(self, off):
        return self.regs.get(off)

    def write(self, off, value):
        self.regs.set(off, value)

    def advance(self, now):
        """Brings the model up to cycle `now`."""

    def next_event(self, now):
        """The next cycle at which this model changes something by itself, or None."""
        return None


class Rcc(Peripheral):
    name = "RCC"

    def __init__(self, board):
        super().__init__(board)
        self.regs = Regs({0x00: 0x0000_0083, 0x04: 0x2400_3010, 0x74: 0x0E00_0000})

    def read(self, off):
        v = self.regs.get(off)
        if off == 0x00:  # CR: every oscillator and PLL is ready as soon as it is on
            for on, rdy in ((0, 1), (16, 17), (24, 25), (26, 27)):
                v = (v | (1 << rdy)) if v & (1 << on) else (v & ~(1 << rdy))
        elif off == 0x08:  # CFGR: SWS follows SW
            v = (v & ~0xC) | ((v & 3) << 2)
        elif off == 0x70:  # BDCR: LSERDY follows LSEON
            v = (v | 2) if v & 1 else (v & ~2)
        elif off == 0x74:  # CSR: LSIRDY follows LSION
            v = (v | 2) if v & 1 else (v & ~2)
        return v


class Pwr(Peripheral):
    name = "PWR"

    def read(self, off):
        v = self.regs.get(off)
        if off == 0x04:  # CSR: VOSRDY
            v |= 1 << 14
        return v


class Gpio(Peripheral):
    def __init__(self, board, port):
        super().__init__(board)
        self.port = port
        self.name = "GPIO" + port
        self.odr = 0
        self.changes = []  # (cycle, odr)

    def read(self, off):
        if off in (0x10, 0x14):
            return self.odr
        return self.regs.get(off)

    def _set_odr(self, value):
        value &= 0xFFFF
        if value != self.odr:
            self.odr = value
            self.changes.append((self.board.cycles, value))
            self.board.world.gpio_changed(self.port, self.board.cycles, value)

    def write(self, off, value):
        if off == 0x14:
            self._set_odr(value)
        elif off == 0x18:
            self._set_odr((self.odr | (value & 0xFFFF)) & ~(value >> 16))
        else:
            self.regs.set(off, value)

    def is_output(self, pin):
        return bits(self.regs.get(0x00), 2 * pin, 2) == 1

    def level(self, pin):
        return bool(self.odr & (1 << pin))


class Tim2(Peripheral):
    """General-purpose timer as embassy's gp16 time driver uses it: a 16-bit count at
    84 MHz / (PSC + 1), the update event at wrap and compare flags on CCR1..4."""

    name = "TIM2"

    def __init__(self, board):
        super().__init__(board)
        self.cr1 = 0
        self.dier = 0
        self.sr = 0
        self.psc = 0
        self.arr = 0xFFFF
        self.ccr = [0, 0, 0, 0]
        self.base_ticks = 0  # counter ticks at base_cycle
        self.base_cycle = 0
        self.last_ticks = 0  # ticks up to which flags have been evaluated
        self.stalled = False  # a scenario can stop the interrupt (not the counter)

    def cycles_per_tick(self):
        return (CPU_HZ // APB1_TIMER_HZ) * (self.psc + 1)

    def ticks(self, now):
        if not self.cr1 & 1:
            return self.base_ticks
        return self.base_ticks + (now - self.base_cycle) // self.cycles_per_tick()

    def rebase(self, now, ticks=None):
        self.base_ticks = self.ticks(now) if ticks is None else ticks
        self.base_cycle = now
        self.last_ticks = self.base_ticks

    def period(self):
        return self.arr + 1

    def advance(self, now):
        t = self.ticks(now)
        if t <= self.last_ticks:
            return
        p = self.period()
        lo = self.last_ticks
        # Update event: the counter passed a multiple of the period.
        if t // p > lo // p:
            self.sr |= 1
        for i, c in enumerate(self.ccr):
            c %= p
            nxt = lo - (lo % p) + c
            if nxt <= lo:
                nxt += p
            if nxt <= t:
                self.sr |= 1 << (i + 1)
        self.last_ticks = t
        self.update_irq()

    def update_irq(self):
        if self.sr & self.dier & 0x1F and not self.stalled:
            self.board.nvic.pend(IRQ["TIM2"])

    def next_event(self, now):
        if not self.cr1 & 1 or not self.dier & 0x1F:
            return None
        t = self.last_ticks
        p = self.period()
        cands = []
        if self.dier & 1:
            cands.append((t // p + 1) * p)
        for i, c in enumerate(self.ccr):
            if self.dier & (1 << (i + 1)):
                c %= p
                nxt = t - (t % p) + c
                if nxt <= t:
                    nxt += p
                cands.append(nxt)
        nxt = min(cands)
        return self.base_cycle + (nxt - self.base_ticks) * self.cycles_per_tick()

    def read(self, off):
        now = self.board.cycles
        self.advance(now)
        if off == 0x00:
            return self.cr1
        if off == 0x0C:
            return self.dier
        if off == 0x10:
            return self.sr
        if off == 0x24:
            return self.ticks(now) % self.period()
        if off == 0x28:
            return self.psc
        if off == 0x2C:
            return self.arr
        if 0x34 <= off <= 0x40:
            return self.ccr[(off - 0x34) // 4]
        return self.regs.get(off)

    def write(self, off, value):
        now = self.board.cycles
        self.advance(now)
        if off == 0x00:
            if (value ^ self.cr1) & 1:
                self.rebase(now)
            self.cr1 = value
        elif off == 0x0C:
            self.dier = value
        elif off == 0x10:
            self.sr &= value  # rc_w0
        elif off == 0x14:
            if value & 1:  # UG: counter to 0; UIF unless URS
                self.rebase(now, ticks=0)
                if not self.cr1 & (1 << 2):
                    self.sr |= 1
        elif off == 0x24:
            self.rebase(now, ticks=value & 0xFFFF)
        elif off == 0x28:
            self.rebase(now)
            self.psc = value & 0xFFFF
        elif off == 0x2C:
            self.arr = value & 0xFFFF
        elif 0x34 <= off <= 0x40:
            self.ccr[(off - 0x34) // 4] = value & 0xFFFF
        else:
            self.regs.set(off, value)
        self.update_irq()


class Iwdg(Peripheral):
    """Independent watchdog: counts down from the reload value at LSI / prescaler."""

    name = "IWDG"

    def __init__(self, board):
        super().__init__(board)
        self.running = False
        self.unlocked = False
        self.pr = 0
        self.rlr = 0xFFF
        self.reload_cycle = 0
        self.starts = []  # cycles at which it was started

    def timeout_cycles(self):
        return (self.rlr + 1) * (4 << self.pr) * CPU_HZ // LSI_HZ

    def write(self, off, value):
        now = self.board.cycles
        if off == 0x00:
            key = value & 0xFFFF
            if key == 0xCCCC:
                if not self.running:
                    self.starts.append(now)
                self.running = True
                self.reload_cycle = now
            elif key == 0xAAAA:
                self.reload_cycle = now
            elif key == 0x5555:
                self.unlocked = True
            else:
                self.unlocked = False
        elif off == 0x04 and self.unlocked:
            self.pr = value & 7
        elif off == 0x08 and self.unlocked:
            self.rlr = value & 0xFFF

    def read(self, off):
        if off == 0x04:
            return self.pr
        if off == 0x08:
            return self.rlr
        return 0

    def next_event(self, now):
        return self.reload_cycle + self.timeout_cycles() if self.running else None

    def advance(self, now):
        if self.running and now >= self.reload_cycle + self.timeout_cycles():
            raise Reset("iwdg")


class Adc3(Peripheral):
    """ADC3 with the battery divider on channel 8: a conversion completes 8 us after SWSTART."""

    name = "ADC3"

    def __init__(self, board):
        super().__init__(board)
        self.sr = 0
        self.dr = 0
        self.done_at = None
        self.conversions = 0

    def battery_raw(self):
        v = self.board.world.battery_v * 22.0 / 222.0
        return max(0, min(4095, round(v / 3.3 * 4095)))

    def advance(self, now):
        if self.done_at is not None and now >= self.done_at:
            self.done_at = None
            self.dr = self.battery_raw()
            self.sr |= 1 << 1
            self.conversions += 1

    def next_event(self, now):
        return self.done_at

    def read(self, off):
        self.advance(self.board.cycles)
        if off < 0x200 or off >= 0x300:
            return self.regs.get(off)
        off -= 0x200
        if off == 0x00:
            return self.sr
        if off == 0x4C:
            self.sr &= ~(1 << 1)
            return self.dr
        return self.regs.get(off + 0x200)

    def write(self, off, value):
        if off < 0x200 or off >= 0x300:
            self.regs.set(off, value)
            return
        off -= 0x200
        if off == 0x00:
            self.sr &= value
        elif off == 0x08:
            self.regs.set(off + 0x200, value & ~(1 << 30))
            if value & (1 << 30) and value & 1:
                self.done_at = self.board.cycles + 8 * CYCLES_PER_US
                self.sr |= 1 << 4
        else:
            self.regs.set(off + 0x200, value)


class Dma2(Peripheral):
    """DMA2: the register file of all eight streams; streams 1 (USART6 RX) and 6 (USART6 TX)
    are moved by the USART model."""

    name = "DMA2"
    FLAG_SHIFT = [0, 6, 16, 22]

    def __init__(self, board):
        super().__init__(board)
        self.isr = [0, 0]
        self.cr = [0] * 8
        self.ndtr = [0] * 8
        self.ndtr_init = [0] * 8
        self.par = [0] * 8
        self.m0ar = [0] * 8
        self.fcr = [0x21] * 8

    def flag(self, stream, bit):
        self.isr[stream // 4] |= 1 << (self.FLAG_SHIFT[stream % 4] + bit)
        self.update_irq(stream)

    def update_irq(self, stream):
        flags = bits(self.isr[stream // 4], self.FLAG_SHIFT[stream % 4], 6)
        cr = self.cr[stream]
        enabled = 0
        if cr & (1 << 4):
            enabled |= 1 << 5  # TCIE -> TCIF
        if cr & (1 << 3):
            enabled |= 1 << 4  # HTIE -> HTIF
        if cr & (1 << 2):
            enabled |= 1 << 3  # TEIE -> TEIF
        if cr & (1 << 1):
            enabled |= 1 << 2  # DMEIE -> DMEIF
        if self.fcr[stream] & (1 << 7):
            enabled |= 1  # FEIE -> FEIF
        if flags & enabled:
            name = {1: "DMA2_STREAM1", 6: "DMA2_STREAM6"}.get(stream)
            if name:
                self.board.nvic.pend(IRQ[name])

    def enabled(self, stream):
        return bool(self.cr[stream] & 1)

    def read(self, off):
        if off in (0x00, 0x04):
            return self.isr[off // 4]
        if 0x10 <= off < 0x10 + 0x18 * 8:
            s, r = divmod(off - 0x10, 0x18)
            self.board.usart6.advance(self.board.cycles)
            return [self.cr[s], self.ndtr[s], self.par[s], self.m0ar[s], 0, self.fcr[s]][r // 4]
        return self.regs.get(off)

    def write(self, off, value):
        if off in (0x08, 0x0C):
            self.isr[(off - 0x08) // 4] &= ~value
            return
        if 0x10 <= off < 0x10 + 0x18 * 8:
            s, r = divmod(off - 0x10, 0x18)
            self.board.usart6.advance(self.board.cycles)
            if r == 0:
                was = self.cr[s] & 1
                self.cr[s] = value
                if value & 1 and not was:
                    self.ndtr_init[s] = self.ndtr[s]
                    self.board.usart6.dma_enabled(s)
                self.update_irq(s)
            elif r == 4:
                self.ndtr[s] = value & 0xFFFF
            elif r == 8:
                self.par[s] = value
            elif r == 12:
                self.m0ar[s] = value
            elif r == 20:
                self.fcr[s] = value
            return
        self.regs.set(off, value)


class Usart6(Peripheral):
    """USART6 at the programmed baud rate (BRR from APB2 = 84 MHz), 10 bits per byte, DMA RX
    (stream 1, circular) and TX (stream 6), IDLE/TC/RXNE flags and their interrupt."""

    name = "USART6"
    APB2_HZ = 84_000_000
    SR_PE, SR_FE, SR_NF, SR_ORE, SR_IDLE, SR_RXNE, SR_TC, SR_TXE = (1 << i for i in range(8))

    def __init__(self, board):
        super().__init__(board)
        self.sr = self.SR_TC | self.SR_TXE
        self.dr_rx = 0
        self.cr1 = 0
        self.cr3 = 0
        self.brr = 0
        self.rx_queue = bytearray()  # from the host, not yet on the wire
        self.rx_next = None  # cycle at which the next byte completes
        self.idle_at = None
        self.tx_next = None  # cycle at which the byte in the shift register completes
        self.tx_pending = None
        self.sr_read = False
        self.rx_overruns = 0
        self.tx_out = bytearray()  # to the host

    def byte_cycles(self):
        if not self.brr:
            return 10 * CPU_HZ // 921_600
        baud = self.APB2_HZ * 16 // (16 * (self.brr >> 4) + (self.brr & 15)) // 16
        return 10 * CPU_HZ // max(baud, 1)

    def enabled(self):
        return bool(self.cr1 & (1 << 13))

    def host_send(self, data):
        self.rx_queue += data
        if self.rx_next is None and self.rx_queue:
            self.rx_next = self.board.cycles + self.byte_cycles()

    def dma_enabled(self, stream):
        if stream == 6:
            self.start_tx_dma()

    def start_tx_dma(self):
        dma = self.board.dma2
        if self.tx_next is None and dma.enabled(6) and self.cr3 & (1 << 7) and dma.ndtr[6]:
            self.load_tx_from_dma()

    def load_tx_from_dma(self):
        dma = self.board.dma2
        addr = dma.m0ar[6] + (dma.ndtr_init[6] - dma.ndtr[6])
        byte = self.board.mem_read(addr, 1)[0]
        dma.ndtr[6] -= 1
        self.tx_pending = byte
        self.tx_next = self.board.cycles + self.byte_cycles()
        self.sr &= ~self.SR_TC
        if dma.ndtr[6] == 0:
            dma.cr[6] &= ~1
            dma.flag(6, 5)
        elif dma.ndtr[6] == dma.ndtr_init[6] // 2:
            dma.flag(6, 4)

    def receive_byte(self, byte):
        dma = self.board.dma2
        if self.cr3 & (1 << 6) and dma.enabled(1):
            n = dma.ndtr_init[1]
            addr = dma.m0ar[1] + (n - dma.ndtr[1])
            self.board.mem_write(addr, bytes([byte]))
            dma.ndtr[1] -= 1
            if dma.ndtr[1] == n // 2:
                dma.flag(1, 4)
            if dma.ndtr[1] == 0:
                dma.flag(1, 5)
                if dma.cr[1] & (1 << 8):
                    dma.ndtr[1] = n
                else:
                    dma.cr[1] &= ~1
        else:
            if self.sr & self.SR_RXNE:
                self.sr |= self.SR_ORE
                self.rx_overruns += 1
            else:
                self.dr_rx = byte
                self.sr |= self.SR_RXNE

    def advance(self, now):
        while self.rx_next is not None and self.rx_next <= now:
            t = self.rx_next
            if self.enabled() and self.cr1 & (1 << 2):
                self.receive_byte(self.rx_queue[0])
            del self.rx_queue[0]
            if self.rx_queue:
                self.rx_next = t + self.byte_cycles()
            else:
                self.rx_next = None
                self.idle_at = t + self.byte_cycles()
        if self.idle_at is not None and self.idle_at <= now:
            self.idle_at = None
            self.sr |= self.SR_IDLE
        while self.tx_next is not None and self.tx_next <= now:
            t = self.tx_next
            self.tx_out.append(self.tx_pending)
            self.tx_next = None
            dma = self.board.dma2
            if dma.enabled(6) and self.cr3 & (1 << 7) and dma.ndtr[6]:
                saved = self.board.cycles
                self.board.cycles = t
                self.load_tx_from_dma()
                self.board.cycles = saved
            else:
                self.sr |= self.SR_TC
        self.update_irq()

    def next_event(self, now):
        c = [x for x in (self.rx_next, self.idle_at, self.tx_next) if x is not None]
        return min(c) if c else None

    def update_irq(self):
        cr1, sr = self.cr1, self.sr
        if ((cr1 & (1 << 4) and sr & self.SR_IDLE) or (cr1 & (1 << 5) and sr & (self.SR_RXNE | self.SR_ORE))
                or (cr1 & (1 << 6) and sr & self.SR_TC) or (cr1 & (1 << 7) and sr & self.SR_TXE)
                or (self.cr3 & 1 and sr & (self.SR_ORE | self.SR_FE | self.SR_NF))):
            self.board.nvic.pend(IRQ["USART6"])

    def read(self, off):
        self.advance(self.board.cycles)
        if off == 0x00:
            self.sr_read = True
            return self.sr
        if off == 0x04:
            if self.sr_read:
                self.sr &= ~(self.SR_IDLE | self.SR_ORE | self.SR_NF | self.SR_FE | self.SR_PE)
            self.sr_read = False
            self.sr &= ~self.SR_RXNE
            return self.dr_rx
        if off == 0x08:
            return self.brr
        if off == 0x0C:
            return self.cr1
        if off == 0x14:
            return self.cr3
        return self.regs.get(off)

    def write(self, off, value):
        self.advance(self.board.cycles)
        if off == 0x00:
            self.sr &= value | ~(self.SR_TC | self.SR_RXNE)
        elif off == 0x04:
            self.tx_pending = value & 0xFF
            self.tx_next = self.board.cycles + self.byte_cycles()
            self.sr &= ~self.SR_TC
        elif off == 0x08:
            self.brr = value
        elif off == 0x0C:
            self.cr1 = value
        elif off == 0x14:
            self.cr3 = value
            self.start_tx_dma()
        else:
            self.regs.set(off, value)
        self.update_irq()


class BxCan(Peripheral):
    """bxCAN1: init/sleep handshakes, three TX mailboxes sent one at a time in priority order
    (with NART, a frame nobody acknowledges fails once; without it, it retries), FIFO 0 (three
    deep, overrun counted), the error counters and bus-off with automatic recovery, and the four
    interrupts. Acceptance filters are not modelled: the bus carries only the ESCs' frames."""

    name = "CAN1"

    def __init__(self, board):
        super().__init__(board)
        self.regs = Regs({0x200: 0x2A1C_0E01})  # FMR: CAN2SB = 14
        self.mcr = 0x0001_0002
        self.init = False
        self.sleep = True
        self.synced_at = None
        self.tsr_flags = 0  # RQCP/TXOK/ALST/TERR bits of the three mailboxes
        self.mailbox = [None, None, None]  # (tir, tdtr, tdlr, tdhr) while TXRQ
        self.tx_busy = None  # (mailbox, done_cycle)
        self.fifo = []
        self.fifo_overruns = 0
        self.ier = 0
        self.esr = 0
        self.tec = 0
        self.rec = 0
        self.msr_erri = False
        self.bus_off = False
        self.bus_off_until = None
        self.fault_until = None  # bus faulted (every frame errors) until this cycle
        self.stuck_dominant = False
        self.sent = []  # (cycle, id, data) that left with an ACK
        self.attempt_log = []  # (cycle, id, data) of every transmission attempt
        self.attempts = 0

    # --- state helpers ---
    def running(self):
        return not self.init and not self.sleep and self.synced_at is not None

    def frame_cycles(self):
        return 130 * CYCLES_PER_US  # an 8-byte standard frame with stuffing at 1 Mbit/s

    def update_irq(self):
        nv = self.board.nvic
        if self.ier & 1 and self.tsr_flags & 0x010101:
            nv.pend(IRQ["CAN1_TX"])
        if self.ier & (1 << 1) and self.fifo:
            nv.pend(IRQ["CAN1_RX0"])
        if self.ier & (1 << 15) and self.msr_erri:
            nv.pend(IRQ["CAN1_SCE"])

    def error(self, kind):
        """Raises ERRI for an error the interrupt mask selects."""
        mask = {"boff": 1 << 10, "epv": 1 << 9, "ewg": 1 << 8, "lec": 1 << 11}[kind]
        if self.ier & mask:
            self.msr_erri = True

    def esr_value(self):
        v = (self.tec << 16) | (self.rec << 24) | (self.esr & 0x70)
        if self.tec >= 96 or self.rec >= 96:
            v |= 1
        if self.tec > 127 or self.rec > 127:
            v |= 2
        if self.bus_off:
            v |= 4
        return v

    def tx_error(self, now, lec):
        self.esr = (self.esr & ~0x70) | (lec << 4)
        self.error("lec")
        passive_before = self.tec > 127
        if self.tec < 128 or lec != 3:  # ACK errors stop counting up when error passive
            self.tec += 8
        if self.tec > 127 and not passive_before:
            self.error("epv")
        if self.tec > 255:
            self.bus_off = True
            self.tec = 255
            self.error("boff")
            if self.mcr & (1 << 6):  # ABOM: recovers after 128 x 11 recessive bits
                self.bus_off_until = now + 1408 * CYCLES_PER_US

    # --- the bus ---
    def advance(self, now):
        if self.bus_off and self.bus_off_until is not None and now >= self.bus_off_until:
            if self.fault_until is None or now >= self.fault_until:
                self.bus_off = False
                self.bus_off_until = None
                self.tec = 0
                self.rec = 0
            else:
                self.bus_off_until = self.fault_until + 1408 * CYCLES_PER_US
        if self.tx_busy is not None and self.tx_busy[1] <= now:
            m, t = self.tx_busy
            self.tx_busy = None
            self.finish_tx(m, t)
        if self.tx_busy is None and self.running() and not self.bus_off:
            self.start_next_tx(now)
        self.update_irq()

    def start_next_tx(self, now):
        pending = [m for m in range(3) if self.mailbox[m] is not None]
        if not pending:
            return
        if self.mcr & (1 << 2):  # TXFP: by request order
            m = min(pending, key=lambda m: self.mailbox[m][4])
        else:
            m = min(pending, key=lambda m: (self.mailbox[m][0] >> 21, m))
        self.tx_busy = (m, now + self.frame_cycles())

    def finish_tx(self, m, t):
        box = self.mailbox[m]
        if box is None:
            return
        self.attempts += 1
        tir, tdtr, tdlr, tdhr, _ = box
        self.attempt_log.append((t, tir >> 21, struct.pack("<II", tdlr, tdhr)[: tdtr & 0xF]))
        faulted = self.fault_until is not None and t < self.fault_until
        acked = self.board.world.can_acked()
        nart = self.mcr & (1 << 4)
        shift = 8 * m
        if faulted or not acked:
            self.tx_error(t, 5 if faulted else 3)  # bit error, or no ACK
            if nart or self.bus_off:
                self.mailbox[m] = None
                self.tsr_flags = (self.tsr_flags & ~(0xF << shift)) | ((1 | 8) << shift)  # RQCP, TERR
            return
        if self.tec:
            self.tec -= 1
        self.mailbox[m] = None
        self.tsr_flags = (self.tsr_flags & ~(0xF << shift)) | (3 << shift)  # RQCP, TXOK
        data = struct.pack("<II", tdlr, tdhr)[: tdtr & 0xF]
        sid = tir >> 21
        self.sent.append((t, sid, bytes(data)))
        self.board.world.can_frame_sent(t, sid, bytes(data))

    def deliver(self, sid, data):
        """A frame from another node; lands in FIFO 0 if the controller is on the bus."""
        if not self.running() or self.bus_off:
            return False
        if len(self.fifo) >= 3:
            self.fifo_overruns += 1
            return False
        t16 = (self.board.cycles // CYCLES_PER_US) & 0xFFFF
        d = bytes(data) + bytes(8 - len(data))
        lo, hi = struct.unpack("<II", d)
        self.fifo.append(((sid << 21), (t16 << 16) | len(data), lo, hi))
        self.update_irq()
        return True

    def next_event(self, now):
        c = []
        if self.tx_busy is not None:
            c.append(self.tx_busy[1])
        if self.bus_off_until is not None:
            c.append(self.bus_off_until)
        return min(c) if c else None

    # --- registers ---
    def read(self, off):
        now = self.board.cycles
        self.advance(now)
        if off == 0x00:
            return self.mcr
        if off == 0x04:
            v = (1 if self.init else 0) | (2 if self.sleep else 0) | (0x800)
            if self.msr_erri:
                v |= 4
            return v
        if off == 0x08:
            v = self.tsr_flags
            for m in range(3):
                if self.mailbox[m] is None:
                    v |= 1 << (26 + m)
            free = [m for m in range(3) if self.mailbox[m] is None]
            v |= (free[0] if free else 0) << 24
            return v
        if off == 0x0C:
            return len(self.fifo) | (8 if len(self.fifo) >= 3 else 0)
        if off == 0x10:
            return 0
        if off == 0x14:
            return self.ier
        if off == 0x18:
            return self.esr_value()
        if 0x180 <= off < 0x1B0:
            m, r = divmod(off - 0x180, 0x10)
            box = self.mailbox[m]
            return box[r // 4] if box else self.regs.get(off)
        if 0x1B0 <= off < 0x1D0:
            f, r = divmod(off - 0x1B0, 0x10)
            if f == 0 and self.fifo:
                return self.fifo[0][r // 4]
            return 0
        return self.regs.get(off)

    def write(self, off, value):
        now = self.board.cycles
        self.advance(now)
        if off == 0x00:
            if value & (1 << 15):  # RESET
                self.__init__(self.board)
                return
            self.mcr = value & ~(1 << 15)
            was_running = self.running()
            self.init = bool(value & 1)
            self.sleep = bool(value & 2) and not self.init
            if self.init or self.sleep:
                self.synced_at = None
            elif not was_running and not self.stuck_dominant:
                self.synced_at = now
        elif off == 0x04:
            if value & 4:
                self.msr_erri = False
        elif off == 0x08:
            for m in range(3):
                shift = 8 * m
                if value & (1 << shift):  # RQCP: clears RQCP, TXOK, ALST, TERR
                    self.tsr_flags &= ~(0xF << shift)
                if value & (1 << (shift + 7)) and self.mailbox[m] is not None:  # ABRQ
                    if not (self.tx_busy and self.tx_busy[0] == m):
                        self.mailbox[m] = None
                        self.tsr_flags = (self.tsr_flags & ~(0xF << shift)) | (1 << shift)
        elif off == 0x0C:
            if value & (1 << 5) and self.fifo:
                self.fifo.pop(0)
        elif off == 0x14:
            self.ier = value
        elif off == 0x18:
            self.esr = (self.esr & ~0x70) | (value & 0x70)
        elif 0x180 <= off < 0x1B0:
            m, r = divmod(off - 0x180, 0x10)
            base = 0x180 + 0x10 * m
            self.regs.set(off, value)
            if r == 0 and value & 1 and self.mailbox[m] is None:
                self.attempt_seq = getattr(self, "attempt_seq", 0) + 1
                self.mailbox[m] = (value, self.regs.get(base + 4), self.regs.get(base + 8),
                                   self.regs.get(base + 12), self.attempt_seq)
        else:
            self.regs.set(off, value)
        self.advance(now)


class Nvic:
    """Exception state: enables, pending, priorities, active stack (the CPU's IPSR stays 0;
    handler mode lives here)."""

    def __init__(self, board):
        self.board = board
        self.enabled = set()
        self.pending = set()
        self.prio = {}
        self.active = []  # exception numbers, innermost last
        self.taken = {}

    def pend(self, exc):
        self.pending.add(exc)

    def priority(self, exc):
        if exc == HARDFAULT:
            return -1
        return self.prio.get(exc, 0) >> 4

    def exec_priority(self):
        p = 16
        for e in self.active:
            p = min(p, self.priority(e))
        basepri = self.board.uc.reg_read(A.UC_ARM_REG_BASEPRI) & 0xFF
        if basepri:
            p = min(p, basepri >> 4)
        return p

    def deliverable(self):
        if not self.pending:
            return None
        if self.board.uc.reg_read(A.UC_ARM_REG_PRIMASK) & 1:
            return None
        cands = [e for e in self.pending if e < 16 or e in self.enabled]
        if not cands:
            return None
        best = min(cands, key=lambda e: (self.priority(e), e))
        if self.priority(best) < self.exec_priority():
            return best
        return None


class Scs:
    """System control space: NVIC registers, SCB, SysTick (registers only), DWT, DCB, DBGMCU."""

    def __init__(self, board):
        self.board = board
        self.regs = Regs({0xED00: 0x410FC241})
        self.dwt_ctrl = 0
        self.cyccnt_base = 0

    def read(self, addr):
        nv = self.board.nvic
        off = addr - 0xE0000000
        if off == 0x1004:
            return (self.board.cycles - self.cyccnt_base) & 0xFFFFFFFF if self.dwt_ctrl & 1 else 0
        if off == 0x1000:
            return self.dwt_ctrl | 0x40000000
        if 0xE100 <= off < 0xE120 or 0xE180 <= off < 0xE1A0:
            base = 16 + 32 * ((off & 0x1F) // 4)
            return sum(1 << i for i in range(32) if base + i in nv.enabled)
        if 0xE200 <= off < 0xE220 or 0xE280 <= off < 0xE2A0:
            base = 16 + 32 * ((off & 0x1F) // 4)
            return sum(1 << i for i in range(32) if base + i in nv.pending)
        if 0xE300 <= off < 0xE320:
            base = 16 + 32 * ((off & 0x1F) // 4)
            return sum(1 << i for i in range(32) if base + i in nv.active)
        if 0xE400 <= off < 0xE4F0:
            base = 16 + (off - 0xE400)
            return sum(nv.prio.get(base + i, 0) << (8 * i) for i in range(4))
        if 0xED18 <= off < 0xED24:
            base = 4 + (off - 0xED18)
            return sum(nv.prio.get(base + i, 0) << (8 * i) for i in range(4))
        if off == 0xED04:
            v = nv.active[-1] if nv.active else 0
            if PENDSV in nv.pending:
                v |= 1 << 28
            if SYSTICK in nv.pending:
                v |= 1 << 26
            return v
        return self.regs.get(off)

    def write(self, addr, value):
        nv = self.board.nvic
        off = addr - 0xE0000000
        if off == 0x1000:
            if value & 1 and not self.dwt_ctrl & 1:
                self.cyccnt_base = self.board.cycles
            self.dwt_ctrl = value
        elif off == 0x1004:
            self.cyccnt_base = self.board.cycles - value
        elif 0xE100 <= off < 0xE120:
            base = 16 + 32 * ((off - 0xE100) // 4)
            nv.enabled |= {base + i for i in range(32) if value >> i & 1}
        elif 0xE180 <= off < 0xE1A0:
            base = 16 + 32 * ((off - 0xE180) // 4)
            nv.enabled -= {base + i for i in range(32) if value >> i & 1}
        elif 0xE200 <= off < 0xE220:
            base = 16 + 32 * ((off - 0xE200) // 4)
            nv.pending |= {base + i for i in range(32) if value >> i & 1}
        elif 0xE280 <= off < 0xE2A0:
            base = 16 + 32 * ((off - 0xE280) // 4)
            nv.pending -= {base + i for i in range(32) if value >> i & 1}
        elif 0xE400 <= off < 0xE4F0:
            for i in range(4):
                nv.prio[16 + off - 0xE400 + i] = (value >> (8 * i)) & 0xF0
        elif 0xED18 <= off < 0xED24:
            for i in range(4):
                nv.prio[4 + off - 0xED18 + i] = (value >> (8 * i)) & 0xF0
        elif off == 0xED04:
            if value & (1 << 28):
                nv.pend(PENDSV)
            if value & (1 << 27):
                nv.pending.discard(PENDSV)
            if value & (1 << 26):
                nv.pend(SYSTICK)
        elif off == 0xED0C:
            if value >> 16 == 0x05FA and value & 4:
                raise Reset("sysresetreq")
            self.regs.set(off, value & 0x700)
        elif off == 0xEF00:
            nv.pend(16 + (value & 0x1FF))
        else:
            self.regs.set(off, value)


class Board:
    """The MCU: memory, CPU, exception model, peripherals. `world` is what is outside the chip
    (the CAN bus with its ESCs, the host end of the MCU link, the battery)."""

    SLICE = 400

    def __init__(self, elf_path, world):
        self.world = world
        self.cycles = 0
        with open(elf_path, "rb") as f:
            elf = ELFFile(f)
            self.segments = [(s["p_paddr"], s.data()) for s in elf.iter_segments()
                             if s["p_type"] == "PT_LOAD" and s["p_filesz"]]
            symtab = elf.get_section_by_name(".symtab")
            self.symbols = {}
            for sym in symtab.iter_symbols():
                if sym.name:
                    self.symbols[sym.name] = sym["st_value"]
            text = elf.get_section_by_name(".text")
            self.text_addr = text["sh_addr"]
            self.text = text.data()
        self.rtt_addr = self.symbols.get("_SEGGER_RTT")
        self.rtt = bytearray()
        self.resets = []
        self.build()

    # --- construction and reset ---
    def build(self):
        uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(A.UC_CPU_ARM_CORTEX_M4)
        self.uc = uc
        uc.mem_map(0x0800_0000, 0x10_0000, UC_PROT_ALL)
        uc.mem_map(0x0000_0000, 0x10_0000, UC_PROT_ALL)
        uc.mem_map(0x1000_0000, 0x1_0000, UC_PROT_ALL)
        uc.mem_map(0x2000_0000, 0x2_0000, UC_PROT_ALL)
        uc.mem_map(EXC_RETURN_PAGE, 0x1000, UC_PROT_ALL)
        for addr, data in self.segments:
            if 0x0800_0000 <= addr < 0x0810_0000:
                uc.mem_write(addr, data)
                uc.mem_write(addr - 0x0800_0000, data)
        uc.mmio_map(0x4000_0000, 0x8_0000, self._mmio_read, None, self._mmio_write, None)
        uc.mmio_map(0xE000_0000, 0x10_0000, self._scs_read, None, self._scs_write, None)
        self.nvic = Nvic(self)
        self.scs = Scs(self)
        self.rcc = Rcc(self)
        self.tim2 = Tim2(self)
        self.iwdg = Iwdg(self)
        self.adc3 = Adc3(self)
        self.dma2 = Dma2(self)
        self.usart6 = Usart6(self)
        self.can1 = BxCan(self)
        self.gpio = {p: Gpio(self, p) for p in "ABCDEFGHI"}
        self.periph = {
            0x4000_0000: self.tim2,
            0x4000_3000: self.iwdg,
            0x4000_6400: self.can1,
            0x4000_7000: Pwr(self),
            0x4001_1400: self.usart6,
            0x4001_2000: self.adc3,
            0x4002_3800: self.rcc,
            0x4002_6400: self.dma2,
        }
        for i, p in enumerate("ABCDEFGHI"):
            self.periph[0x4002_0000 + 0x400 * i] = self.gpio[p]
        self.unknown = {}
        self.timed = [self.tim2, self.iwdg, self.adc3, self.usart6, self.can1]
        # Hooks: WFE/WFI/SEV (found by scanning the code) and the exception-return page.
        self.stop_reason = None
        self.event = False
        self.sleeping = False
        for i in range(0, len(self.text) - 1, 2):
            hw = self.text[i] | (self.text[i + 1] << 8)
            if hw in (0xBF20, 0xBF30, 0xBF40):
                a = self.text_addr + i
                uc.hook_add(UC_HOOK_CODE, self._hint_hook, hw, a, a)
        uc.hook_add(UC_HOOK_CODE, self._excret_hook, None, EXC_RETURN_PAGE, EXC_RETURN_PAGE + 0xFFF)
        self.fp_stack = []
        self.locked_up = False
        self.faults = getattr(self, "faults", [])
        vt = struct.unpack("<II", bytes(uc.mem_read(0, 8)))
        uc.reg_write(A.UC_ARM_REG_MSP, vt[0])
        uc.reg_write(A.UC_ARM_REG_SP, vt[0])
        self.pc = vt[1] & ~1

    def reset(self, reason):
        self.resets.append((self.cycles, reason))
        world = self.world
        world.on_reset(self.cycles, reason)
        ram = bytes(self.uc.mem_read(0x2000_0000, 0x2_0000))
        self.build()
        self.uc.mem_write(0x2000_0000, ram)  # SRAM keeps its contents over a reset

    # --- memory access helpers ---
    def mem_read(self, addr, n):
        return bytes(self.uc.mem_read(addr, n))

    def mem_write(self, addr, data):
        self.uc.mem_write(addr, bytes(data))

    def _periph_for(self, addr):
        base = addr & ~0x3FF
        p = self.periph.get(base)
        if p is None:
            p = self.unknown.get(base)
            if p is None:
                p = Peripheral(self)  # unmodelled: plain storage
                p.name = "@%08x" % base
                self.unknown[base] = p
        return p, addr - base

    # Cycles one peripheral access costs (bus bridge and wait states). Accesses also move time
    # on inside a slice, so a busy-wait on a status bit sees the peripheral progress.
    ACCESS_CYCLES = 6

    def _mmio_read(self, uc, offset, size, user):
        self.cycles += self.ACCESS_CYCLES
        addr = 0x4000_0000 + offset
        p, off = self._periph_for(addr)
        aligned = off & ~3
        v = p.read(aligned)
        return (v >> (8 * (off & 3))) & ((1 << (8 * size)) - 1)

    def _mmio_write(self, uc, offset, size, value, user):
        self.cycles += self.ACCESS_CYCLES
        addr = 0x4000_0000 + offset
        p, off = self._periph_for(addr)
        aligned = off & ~3
        if size < 4:
            shift = 8 * (off & 3)
            mask = ((1 << (8 * size)) - 1) << shift
            old = p.regs.get(aligned)  # byte/halfword writes only hit plain registers here
            value = (old & ~mask) | ((value << shift) & mask)
        try:
            p.write(aligned, value)
        except Reset as r:
            self.pending_reset = r.reason
            uc.emu_stop()

    def _scs_read(self, uc, offset, size, user):
        addr = 0xE000_0000 + offset
        v = self.scs.read(addr & ~3)
        return (v >> (8 * (addr & 3))) & ((1 << (8 * size)) - 1)

    def _scs_write(self, uc, offset, size, value, user):
        addr = 0xE000_0000 + offset
        if size < 4:
            shift = 8 * (addr & 3)
            if 0xE000_E400 <= addr < 0xE000_E4F0 or 0xE000_ED18 <= addr < 0xE000_ED24:
                old = self.scs.read(addr & ~3)
                mask = ((1 << (8 * size)) - 1) << shift
                value = (old & ~mask) | ((value << shift) & mask)
            else:
                value <<= shift
        try:
            self.scs.write(addr & ~3, value)
        except Reset as r:
            self.pending_reset = r.reason
            uc.emu_stop()

    # --- hooks ---
    def _hint_hook(self, uc, address, size, hw):
        self.hint_at = address
        if hw == 0xBF40:  # SEV
            self.event = True
            return
        if hw == 0xBF20 and self.event:  # WFE with the event register set: clear, go on
            self.event = False
            return
        self.stop_reason = "sleep"
        self.sleep_pc = address + 2
        uc.emu_stop()

    def _excret_hook(self, uc, address, size, user):
        self.stop_reason = "excret"
        uc.emu_stop()

    # --- exceptions ---
    FP_REGS = [getattr(A, "UC_ARM_REG_S%d" % i) for i in range(16)]

    def enter_exception(self, exc):
        uc = self.uc
        self.nvic.pending.discard(exc)
        sp = uc.reg_read(A.UC_ARM_REG_MSP)
        realign = sp & 4
        sp = (sp - 32) & ~7
        xpsr = uc.reg_read(A.UC_ARM_REG_XPSR)
        xpsr = (xpsr & ~0x1FF & ~(1 << 9)) | (1 << 24) | ((1 << 9) if realign else 0)
        frame = [uc.reg_read(r) for r in (A.UC_ARM_REG_R0, A.UC_ARM_REG_R1, A.UC_ARM_REG_R2,
                                          A.UC_ARM_REG_R3, A.UC_ARM_REG_R12, A.UC_ARM_REG_LR)]
        frame += [self.pc, xpsr]
        try:
            uc.mem_write(sp, struct.pack("<8I", *frame))
        except UcError:
            self.locked_up = True  # stacking failed (stack overflow below RAM): lockup
            return
        self.fp_stack.append(([uc.reg_read(r) for r in self.FP_REGS],
                              uc.reg_read(A.UC_ARM_REG_FPSCR)))
        uc.reg_write(A.UC_ARM_REG_MSP, sp)
        uc.reg_write(A.UC_ARM_REG_SP, sp)
        uc.reg_write(A.UC_ARM_REG_LR, 0xFFFFFFF9 if not self.nvic.active else 0xFFFFFFF1)
        vtor = self.scs.regs.get(0xED08)
        vector = struct.unpack("<I", self.mem_read(vtor + 4 * exc, 4))[0]
        self.nvic.active.append(exc)
        self.nvic.taken[exc] = self.nvic.taken.get(exc, 0) + 1
        self.pc = vector & ~1
        self.sleeping = False

    def return_from_exception(self):
        uc = self.uc
        sp = uc.reg_read(A.UC_ARM_REG_MSP)
        frame = struct.unpack("<8I", self.mem_read(sp, 32))
        for r, v in zip((A.UC_ARM_REG_R0, A.UC_ARM_REG_R1, A.UC_ARM_REG_R2, A.UC_ARM_REG_R3,
                         A.UC_ARM_REG_R12, A.UC_ARM_REG_LR), frame[:6]):
            uc.reg_write(r, v)
        xpsr = frame[7]
        sp += 32 + (4 if xpsr & (1 << 9) else 0)
        uc.reg_write(A.UC_ARM_REG_MSP, sp)
        uc.reg_write(A.UC_ARM_REG_SP, sp)
        uc.reg_write(A.UC_ARM_REG_XPSR, xpsr & 0xF80F0000 | (1 << 24))
        fp, fpscr = self.fp_stack.pop()
        for r, v in zip(self.FP_REGS, fp):
            uc.reg_write(r, v)
        uc.reg_write(A.UC_ARM_REG_FPSCR, fpscr)
        self.nvic.active.pop()
        self.pc = frame[6] & ~1
        self.event = True

    # --- running ---
    def advance_peripherals(self):
        now = self.cycles
        for p in self.timed:
            p.advance(now)
        self.world.advance(now)

    def next_event(self):
        c = [p.next_event(self.cycles) for p in self.timed]
        c.append(self.world.next_event(self.cycles))
        c = [x for x in c if x is not None]
        return min(c) if c else None

    def run_until(self, cycle):
        """Runs the MCU until virtual time `cycle` (a reset restarts it and is recorded)."""
        while self.cycles < cycle:
            try:
                self.step(cycle)
            except Reset as r:
                self.reset(r.reason)

    def step(self, limit):
        self.advance_peripherals()
        if self.locked_up:
            nxt = self.next_event()
            self.cycles = limit if nxt is None else min(max(nxt, self.cycles + 1), limit)
            return
        exc = self.nvic.deliverable()
        if exc is not None:
            self.enter_exception(exc)
        if self.sleeping:
            # Nothing deliverable (a pending interrupt below the current priority does not
            # wake the core): time jumps to the next event.
            nxt = self.next_event()
            target = limit if nxt is None else min(max(nxt, self.cycles + 1), limit)
            self.cycles = target
            return
        self.stop_reason = None
        self.pending_reset = None
        self.hint_at = None
        n = self.SLICE
        try:
            self.uc.emu_start(self.pc | 1, 0xFFFFFFFF, count=n)
        except UcError as e:
            # Unicorn reports WFE/WFI as an invalid instruction after the hook has run: the
            # hook already decided (sleep, or go on because the event register was set).
            pc = self.uc.reg_read(A.UC_ARM_REG_PC)
            if pc >= EXC_RETURN_PAGE:
                self.stop_reason = "excret"
            elif self.hint_at == pc - 2 or self.stop_reason == "sleep":
                if self.stop_reason is None:
                    self.uc.reg_write(A.UC_ARM_REG_PC, pc | 1)
            else:
                # An undefined instruction (UDF, as panic handlers use) or a bad access: the
                # core takes HardFault; a fault inside HardFault locks the core up, and only
                # the watchdog gets it out.
                self.faults.append((self.cycles, pc, str(e)))
                self.cycles += n // 2
                self.pc = pc
                if HARDFAULT in self.nvic.active:
                    self.locked_up = True
                else:
                    self.enter_exception(HARDFAULT)
                return
        self.cycles += n if self.stop_reason is None else n // 2
        self.pc = self.uc.reg_read(A.UC_ARM_REG_PC)
        if self.pending_reset:
            raise Reset(self.pending_reset)
        if self.stop_reason == "sleep":
            self.pc = self.sleep_pc
            if not self.nvic.deliverable():
                self.sleeping = True
        elif self.stop_reason == "excret":
            self.return_from_exception()

    # --- RTT (defmt) ---
    def drain_rtt(self):
        """Moves new bytes of RTT up-channel 0 out of target RAM; returns them."""
        if self.rtt_addr is None:
            return b""
        cb = self.rtt_addr
        hdr = self.mem_read(cb, 48)
        if hdr[:10] != b"SEGGER RTT":
            return b""
        buf, size, wr, rd = struct.unpack("<IIII", hdr[28:44])
        if not size or wr == rd:
            return b""
        if wr > rd:
            data = self.mem_read(buf + rd, wr - rd)
        else:
            data = self.mem_read(buf + rd, size - rd) + self.mem_read(buf, wr)
        self.mem_write(cb + 40, struct.pack("<I", wr))
        self.rtt += data
        return data
