"""A small defmt log decoder for the emulated board: rzCOBS frames from the RTT buffer, the
format string and level from the ELF's `.defmt` symbols, the uptime timestamp. Arguments are
shown raw (hex) after the format string: enough to read the log, without a full defmt decoder.
"""

import json
import struct

from elftools.elf.elffile import ELFFile


def rzcobs_decode(data):
    """Reverse zero-compressing COBS, as defmt-rtt's `encoding-rzcobs` writes it."""
    out = bytearray()
    it = reversed(data)
    for x in it:
        if x == 0:
            raise ValueError("zero inside a frame")
        if x < 0x80:
            for i in range(7):
                if x & (1 << (6 - i)) == 0:
                    out.append(next(it))
                else:
                    out.append(0)
        elif x < 0xFF:
            out.append(0)
            for _ in range((x & 0x7F) + 7):
                out.append(next(it))
        else:
            for _ in range(134):
                out.append(next(it))
    out.reverse()
    return bytes(out)


class DefmtDecoder:
    def __init__(self, elf_path):
        self.table = {}
        with open(elf_path, "rb") as f:
            elf = ELFFile(f)
            sec = elf.get_section_by_name(".defmt")
            shndx = None
            for i, s in enumerate(elf.iter_sections()):
                if s.name == ".defmt":
                    shndx = i
            symtab = elf.get_section_by_name(".symtab")
            if sec is not None:
                for sym in symtab.iter_symbols():
                    if sym["st_shndx"] == shndx and sym.name.startswith("{"):
                        try:
                            meta = json.loads(sym.name)
                        except ValueError:
                            continue
                        self.table[sym["st_value"]] = meta
        self.buf = bytearray()
        self.lines = []
        self.errors = 0

    def feed(self, data, cycle):
        self.buf += data
        while True:
            try:
                end = self.buf.index(0)
            except ValueError:
                return
            frame = bytes(self.buf[:end])
            del self.buf[: end + 1]
            if not frame:
                continue
            try:
                raw = rzcobs_decode(frame)
            except (ValueError, StopIteration):
                self.errors += 1
                continue
            self.lines.append(self.render(raw))

    def render(self, raw):
        if len(raw) < 2:
            return "<short frame %s>" % raw.hex()
        index = struct.unpack_from("<H", raw)[0]
        meta = self.table.get(index)
        rest = raw[2:]
        ts = ""
        if len(rest) >= 8 and meta is not None and meta.get("tag", "").startswith("defmt_"):
            stamp = struct.unpack_from("<Q", rest)[0]
            ts = "%10.6f " % (stamp / 1e6)
            rest = rest[8:]
        if meta is None:
            return "%s<unknown index %d> %s" % (ts, index, rest.hex())
        level = meta.get("tag", "").replace("defmt_", "").upper()
        args = (" [%s]" % rest.hex()) if rest else ""
        return "%s%-5s %s%s" % (ts, level, meta.get("data", ""), args)
