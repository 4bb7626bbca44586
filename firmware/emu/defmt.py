"""A small defmt log decoder for the emulated board: rzCOBS frames from the RTT buffer, the
format string and level from the ELF's `.defmt` symbols, the uptime timestamp, and the argument
types this firmware logs (`{}` of strings and integers, `{=u8}`..`{=u64}`, `{=i16}`, `{=i32}`,
`{=bool}`, `{=str}`). Anything else ends the decoding of that line: the rest is shown as hex.
"""

import json
import re
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
        text, rest = self.format(meta.get("data", ""), rest, depth=0)
        # rzCOBS pads the last group with zeros: a tail of zeros is not an argument.
        tail = (" [%s]" % rest.hex()) if rest.strip(b"\0") else ""
        return "%s%-5s %s%s" % (ts, level, text, tail)

    PRIMS = {"u8": "<B", "u16": "<H", "u32": "<I", "u64": "<Q", "usize": "<I", "i8": "<b",
             "i16": "<h", "i32": "<i", "i64": "<q", "isize": "<i", "f32": "<f", "bool": "<?"}

    def format(self, fmt, data, depth):
        """Renders `fmt` with arguments from `data`; returns (text, bytes not consumed)."""
        out = []
        pos = 0
        for m in re.finditer(r"\{(=?[^}]*)\}", fmt):
            out.append(fmt[pos:m.start()])
            pos = m.end()
            spec = m.group(1).split(":")[0]
            value, data = self.argument(spec, data, depth)
            if value is None:
                out.append(m.group(0))
                out.append(fmt[pos:])
                return "".join(out), data
            out.append(value)
        out.append(fmt[pos:])
        return "".join(out), data

    def argument(self, spec, data, depth):
        try:
            if spec in ("", "?"):  # a Format value: its own format index, then its arguments
                if depth > 4 or len(data) < 2:
                    return None, data
                nested = self.table.get(struct.unpack_from("<H", data)[0])
                if nested is None:
                    return None, data
                return self.format(nested.get("data", ""), data[2:], depth + 1)
            t = spec.lstrip("=")
            if t == "str":
                (n,) = struct.unpack_from("<I", data)
                return data[4:4 + n].decode("utf-8", "replace"), data[4 + n:]
            if t in self.PRIMS:
                fmt = self.PRIMS[t]
                (v,) = struct.unpack_from(fmt, data)
                return str(v), data[struct.calcsize(fmt):]
        except struct.error:
            pass
        return None, data
