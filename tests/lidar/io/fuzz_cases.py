"""Seeded mutations of one sample file of every supported format.

Each case is a damaged copy of a valid file: random header bytes, one header
field set to 0 / its maximum / NaN, a truncation at every header boundary and
inside the data, flipped bytes. The cases are deterministic (seeded), so a
failure can be reproduced by its name.
"""
from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lidar.io import write_scan
from lidar.io.e57 import write_e57
from lidar.scan import Scan, normalise_intensity

DATA = Path(__file__).resolve().parents[2] / "data"


@dataclass(frozen=True)
class Case:
    name: str
    suffix: str
    blob: bytes


def sample_scan(n: int = 300) -> Scan:
    rng = np.random.default_rng(11)
    xyz = rng.uniform(-20, 20, (n, 3))
    raw = rng.integers(0, 65535, n).astype(np.uint16)
    pose = np.eye(4)
    pose[:3, 3] = (10.0, 20.0, 1.5)
    return Scan(xyz_socs=xyz, intensity=normalise_intensity(raw), intensity_raw=raw, pose=pose, name="fuzz")


def samples(folder: Path) -> dict[str, tuple[str, bytes, int]]:
    """name -> (suffix, bytes, header length) of one valid file per format and variant."""
    scan = sample_scan()
    out: dict[str, tuple[str, bytes, int]] = {}

    def keep(name: str, path: Path, header_len: int) -> None:
        out[name] = (path.suffix, path.read_bytes(), header_len)

    for suffix in (".las", ".laz"):
        p = write_scan(scan, folder / f"s{suffix}")
        keep(suffix[1:], p, 375)
    keep("las12", DATA / "las" / "simple.las", 227)
    p = folder / "s.e57"
    write_e57(scan, p)
    keep("e57", p, 48)
    from lidar.io.ply import write_ply

    keep("ply_bin", write_ply(scan, folder / "b.ply"), _text_header_len(folder / "b.ply", b"end_header\n"))
    keep("ply_ascii", write_ply(scan, folder / "a.ply", binary=False), _text_header_len(folder / "a.ply", b"end_header\n"))
    p = write_scan(scan, folder / "s.pcd")
    keep("pcd_bin", p, _text_header_len(p, b"DATA binary\n"))
    p = folder / "c.pcd"
    p.write_bytes(_pcd_compressed(scan))
    keep("pcd_lzf", p, _text_header_len(p, b"DATA binary_compressed\n"))
    p = folder / "a.pcd"
    p.write_bytes(_pcd_ascii(scan))
    keep("pcd_ascii", p, _text_header_len(p, b"DATA ascii\n"))
    p = write_scan(scan, folder / "s.ptx")
    keep("ptx", p, len(b"\n".join(p.read_bytes().split(b"\n")[:10])) + 1)
    p = write_scan(scan, folder / "s.xyz")
    keep("xyz", p, len(p.read_bytes().split(b"\n")[0]) + 1)
    p = folder / "s.pts"
    p.write_bytes(_pts(scan))
    keep("pts", p, len(p.read_bytes().split(b"\n")[0]) + 1)
    return out


def _text_header_len(path: Path, marker: bytes) -> int:
    blob = path.read_bytes()
    return blob.index(marker) + len(marker)


def _pcd_ascii(scan: Scan) -> bytes:
    n = len(scan)
    head = (f"VERSION .7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {n}\n"
            f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA ascii\n")
    rows = "".join(f"{x:.4f} {y:.4f} {z:.4f} {i}\n"
                   for (x, y, z), i in zip(scan.xyz_socs, scan.intensity_raw, strict=True))
    return (head + rows).encode()


def _pcd_compressed(scan: Scan) -> bytes:
    import lzf

    n = len(scan)
    cols = [scan.xyz_socs[:, k].astype("<f4").tobytes() for k in range(3)]
    cols.append(scan.intensity_raw.astype("<f4").tobytes())
    raw = b"".join(cols)
    comp = lzf.compress(raw, len(raw) + len(raw) // 16 + 64)
    head = (f"VERSION .7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {n}\n"
            f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary_compressed\n").encode()
    return head + struct.pack("<II", len(comp), len(raw)) + comp


def _pts(scan: Scan) -> bytes:
    vals = (scan.intensity * 4095 - 2048).astype(int)
    rows = "".join(f"{x:.4f} {y:.4f} {z:.4f} {i} 10 20 30\n" for (x, y, z), i in zip(scan.xyz_socs, vals, strict=False))
    return f"{len(scan)}\n{rows}".encode()


#: (offset, struct format) of the LAS 1.4 public header fields worth attacking.
LAS_FIELDS = [(24, "B"), (25, "B"), (94, "H"), (96, "I"), (100, "I"), (104, "B"), (105, "H"), (107, "I"),
              (131, "d"), (139, "d"), (147, "d"), (155, "d"), (163, "d"), (171, "d"), (179, "d"), (187, "d"),
              (235, "Q"), (243, "I"), (247, "Q")]
#: E57 physical header: version, file length, XML offset, XML length, page size.
E57_FIELDS = [(8, "I"), (12, "I"), (16, "Q"), (24, "Q"), (32, "Q"), (40, "Q")]
_MAX = {"B": 0xFF, "H": 0xFFFF, "I": 0xFFFFFFFF, "Q": 0xFFFFFFFFFFFFFFFF}


def _set_field(blob: bytes, at: int, fmt: str, value) -> bytes:
    b = bytearray(blob)
    if at + struct.calcsize(fmt) > len(b):
        return bytes(b)
    struct.pack_into("<" + fmt, b, at, value)
    return bytes(b)


def _binary_field_cases(name: str, suffix: str, blob: bytes, fields) -> list[Case]:
    cases = []
    for at, fmt in fields:
        values = [("nan", float("nan")), ("inf", float("inf")), ("0", 0.0)] if fmt == "d" else \
                 [("0", 0), ("max", _MAX[fmt]), ("max-15", _MAX[fmt] - 15)]
        for label, v in values:
            cases.append(Case(f"{name}-field{at}-{label}", suffix, _set_field(blob, at, fmt, v)))
    return cases


_NUM = re.compile(rb"(?<![A-Za-z_])\d+(?:\.\d+)?")


def _text_field_cases(name: str, suffix: str, blob: bytes, header_len: int) -> list[Case]:
    """Each number in a text header replaced by 0, a huge value, -1 and NaN."""
    head = blob[:header_len]
    cases = []
    for k, m in enumerate(_NUM.finditer(head)):
        for label, v in (("0", b"0"), ("huge", b"4294967295000"), ("neg", b"-1"), ("nan", b"nan")):
            new = head[:m.start()] + v + head[m.end():]
            cases.append(Case(f"{name}-num{k}-{label}", suffix, new + blob[header_len:]))
    return cases


def _truncations(name: str, suffix: str, blob: bytes, header_len: int, fields=()) -> list[Case]:
    cuts = {0, 1, 4, 8, header_len // 2, header_len - 1, header_len, header_len + 1}
    cuts |= {at for at, _ in fields}
    if suffix in (".ply", ".pcd", ".ptx", ".xyz", ".pts"):
        cuts |= {m.end() for m in re.finditer(rb"\n", blob[:header_len])}
    body = len(blob) - header_len
    cuts |= {header_len + int(body * f) for f in (0.1, 0.5, 0.9, 0.999)}
    return [Case(f"{name}-cut{c}", suffix, blob[:c]) for c in sorted(cuts) if 0 <= c < len(blob)]


def _random_bytes(name: str, suffix: str, blob: bytes, header_len: int, seeds=range(6)) -> list[Case]:
    cases = []
    for seed in seeds:
        rng = np.random.default_rng(1000 + seed)
        b = bytearray(blob)
        keep = 4 if suffix in (".las", ".laz") else (8 if suffix == ".e57" else 0)
        span = max(header_len - keep, 1)
        for at in rng.integers(keep, keep + span, 1 + seed * 3):
            if at < len(b):
                b[at] = int(rng.integers(0, 256))
        cases.append(Case(f"{name}-randhead{seed}", suffix, bytes(b)))
        # the whole header random, magic kept
        r = bytearray(blob)
        r[keep:header_len] = rng.integers(0, 256, max(header_len - keep, 0), dtype=np.uint8).tobytes()
        cases.append(Case(f"{name}-randwhole{seed}", suffix, bytes(r)))
    return cases


def _flips(name: str, suffix: str, blob: bytes, seeds=range(4)) -> list[Case]:
    cases = []
    for seed in seeds:
        rng = np.random.default_rng(2000 + seed)
        b = bytearray(blob)
        for at in rng.integers(0, len(b), 8):
            b[at] ^= 1 << int(rng.integers(0, 8))
        cases.append(Case(f"{name}-flip{seed}", suffix, bytes(b)))
    return cases


def e57_with_xml(blob: bytes, edit) -> bytes:
    """An E57 file whose XML section is replaced by ``edit(xml)``, with valid page checksums.

    The new XML is appended as new pages and the header points to it, so the
    damage is semantic (a lying count, a wrong offset), not a checksum error.
    """
    import crc32c

    major, minor, _flen, xml_off, xml_len, _page = struct.unpack_from("<IIQQQQ", blob, 8)
    xml = bytearray()
    off = xml_off
    while len(xml) < xml_len:
        page, inpage = divmod(off, 1024)
        take = min(1020 - inpage, xml_len - len(xml))
        xml += blob[off:off + take]
        off = (page + 1) * 1024
    new = edit(bytes(xml))
    out = bytearray(blob)
    start = len(out)
    for k in range(0, len(new), 1020):
        chunk = new[k:k + 1020].ljust(1020, b"\0")
        out += chunk + struct.pack(">I", crc32c.crc32c(chunk))
    struct.pack_into("<IIQQQQ", out, 8, major, minor, len(out), start, len(new), 1024)
    out[1020:1024] = struct.pack(">I", crc32c.crc32c(bytes(out[:1020])))
    return bytes(out)


def _e57_xml_cases(name: str, blob: bytes) -> list[Case]:
    def sub(pattern: bytes, repl: bytes):
        return lambda xml: re.sub(pattern, repl, xml, count=1)

    edits = {
        "count-huge": sub(rb'recordCount="\d+"', b'recordCount="4294967295000"'),
        "count-neg": sub(rb'recordCount="\d+"', b'recordCount="-5"'),
        "count-zero": sub(rb'recordCount="\d+"', b'recordCount="0"'),
        "offset-huge": sub(rb'fileOffset="\d+"', b'fileOffset="99999999999"'),
        "offset-zero": sub(rb'fileOffset="\d+"', b'fileOffset="0"'),
        "offset-header": sub(rb'fileOffset="\d+"', b'fileOffset="48"'),
        "xml-cut": lambda xml: xml[: len(xml) // 2],
        "no-data3d": sub(rb"<data3D", b"<dataXX"),
        "range-flip": sub(rb'minimum="(-?\d+)" maximum="(-?\d+)"', rb'minimum="\2" maximum="\1"'),
        "float-single": lambda xml: xml.replace(b'precision="double"', b'precision="single"'),
    }
    return [Case(f"{name}-xml-{label}", ".e57", e57_with_xml(blob, fn)) for label, fn in edits.items()]


def build_cases(folder: Path) -> list[Case]:
    """Every fuzz case, from samples written into ``folder``."""
    cases: list[Case] = []
    for name, (suffix, blob, header_len) in samples(folder).items():
        if suffix in (".las", ".laz"):
            fields = [f for f in LAS_FIELDS if f[0] < header_len] if name != "las12" else \
                [f for f in LAS_FIELDS if f[0] < 227]
            cases += _binary_field_cases(name, suffix, blob, fields)
        elif suffix == ".e57":
            fields = E57_FIELDS
            cases += _binary_field_cases(name, suffix, blob, fields)
            cases += _e57_xml_cases(name, blob)
        else:
            fields = ()
            cases += _text_field_cases(name, suffix, blob, header_len)
        cases += _truncations(name, suffix, blob, header_len, fields)
        cases += _random_bytes(name, suffix, blob, header_len)
        cases += _flips(name, suffix, blob)
    # The reported attack: 'LASF' and 4 KB of random bytes.
    for seed in range(5):
        rng = np.random.default_rng(seed)
        cases.append(Case(f"lasf-random{seed}", ".las", b"LASF" + rng.integers(0, 256, 4092, dtype=np.uint8).tobytes()))
    return cases
