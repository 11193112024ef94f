"""Check an E57 file's structure before libE57Format (through pye57) trusts it.

An E57 file is made of 1024-byte pages, each ending in a CRC-32C of its first
1020 bytes. A 48-byte physical header (page 0) gives the file length, where the
XML section starts and how long it is. The XML describes each scan
(``data3D``): its point count (``recordCount``), where its binary section lies
(``fileOffset``) and the record prototype (which fields, how many bits each).

:func:`check_e57` verifies the header and the XML pages' checksums, parses the
XML, and checks that every scan's binary section exists and is long enough for
the points it claims, so pye57 never allocates buffers for points that are not
there.
"""
from __future__ import annotations

import math
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import crc32c

from common.errors import ScanFormatError

PAGE = 1024
PAGE_DATA = 1020
#: Upper bound on the XML section (real files: a few kB to a few MB).
MAX_XML_BYTES = 64 << 20
NS = "{http://www.astm.org/COMMIT/E57/2010-e57-v1.0}"


@dataclass(frozen=True)
class E57ScanFacts:
    """What an E57 file says of one of its scans (checked against the file before anything is read)."""

    name: str
    record_count: int
    bits_per_record: int
    section_bytes: int
    fields: tuple[str, ...]


@dataclass(frozen=True)
class E57Facts:
    """What an E57 file's header and XML section say (version, scans, pages), checked against its size."""

    version: str
    scans: tuple[E57ScanFacts, ...]
    images: int


def _crc32c(data: bytes) -> int:
    return crc32c.crc32c(data)


def logical_bytes(p: Path, fh: BinaryIO, physical: int, length: int, size: int) -> bytes:
    """Read ``length`` logical bytes from a physical offset, checking each page's CRC."""
    out = bytearray()
    off = physical
    while len(out) < length:
        page, inpage = divmod(off, PAGE)
        if inpage >= PAGE_DATA:
            raise ScanFormatError(p, f"E57 offset {off} points into a page checksum")
        if (page + 1) * PAGE > size:
            raise ScanFormatError(p, f"truncated: E57 page {page} runs past the end of the file")
        fh.seek(page * PAGE)
        blob = fh.read(PAGE)
        if struct.unpack(">I", blob[PAGE_DATA:])[0] != _crc32c(blob[:PAGE_DATA]):
            raise ScanFormatError(p, f"checksum mismatch in E57 page {page}: the file is damaged")
        take = min(PAGE_DATA - inpage, length - len(out))
        out += blob[inpage:inpage + take]
        off = (page + 1) * PAGE
    return bytes(out)


def _child(node, name):
    return node.find(NS + name) if node is not None else None


def _bits(p: Path, proto) -> tuple[int, tuple[str, ...]]:
    bits = 0
    names = []
    for field in list(proto):
        tag = field.tag.replace(NS, "")
        names.append(tag)
        kind = field.get("type", "")
        try:
            if kind == "Float":
                bits += 32 if field.get("precision", "double") == "single" else 64
            elif kind in ("Integer", "ScaledInteger"):
                lo, hi = int(field.get("minimum", "0")), int(field.get("maximum", "0"))
                if hi < lo:
                    raise ScanFormatError(p, f"E57 field {tag} has maximum {hi} below its minimum {lo}")
                bits += math.ceil(math.log2(hi - lo + 1)) if hi > lo else 0
        except ValueError as exc:
            raise ScanFormatError(p, f"E57 field {tag} has a non-numeric range") from exc
    return bits, tuple(names)


def check_e57(path: str | Path) -> E57Facts:
    """Validate an E57 file's pages, XML and point sections against its size.

    Returns
    -------
    E57Facts
        Version, each scan's claims (all possible for the file) and the image count.

    Raises
    ------
    ScanFormatError
        Naming the header field, page or scan that the file cannot hold.
    """
    p = Path(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(48)
        if len(head) < 48 or head[:8] != b"ASTM-E57":
            raise ScanFormatError(p, "not an E57 file (it does not start with 'ASTM-E57' and a 48-byte header)")
        major, minor, file_len, xml_off, xml_len, page = struct.unpack_from("<IIQQQQ", head, 8)
        if major != 1:
            raise ScanFormatError(p, f"E57 version field says {major}.{minor}; only version 1 exists")
        if page != PAGE:
            raise ScanFormatError(p, f"E57 page size field is {page}; the standard fixes it at 1024")
        if file_len != size:
            what = "truncated" if file_len > size else "damaged"
            raise ScanFormatError(p, f"{what}: the E57 header says {file_len} bytes, the file has {size}")
        if size % PAGE:
            raise ScanFormatError(p, f"damaged E57 file: {size} bytes is not a whole number of 1024-byte pages")
        if xml_len == 0 or xml_len > min(MAX_XML_BYTES, size):
            raise ScanFormatError(p, f"E57 header claims an XML section of {xml_len} bytes (file: {size})")
        if xml_off < 48 or xml_off >= size:
            raise ScanFormatError(p, f"E57 XML offset {xml_off} lies outside the file")
        logical_bytes(p, fh, 0, 48, size)  # page 0's checksum covers the header itself
        text = logical_bytes(p, fh, xml_off, xml_len, size)
        try:
            root = ET.fromstring(text)
        except ET.ParseError as exc:
            raise ScanFormatError(p, f"damaged E57 XML section ({exc})") from exc
        scans = []
        data3d = _child(root, "data3D")
        for k, child in enumerate(list(data3d) if data3d is not None else []):
            name_node = _child(child, "name")
            name = (name_node.text or "").strip() if name_node is not None else f"scan{k}"
            pts = _child(child, "points")
            if pts is None:
                raise ScanFormatError(p, f"E57 scan {k} ({name}) has no points element")
            try:
                count = int(pts.get("recordCount", "-1"))
                offset = int(pts.get("fileOffset", "-1"))
            except ValueError as exc:
                raise ScanFormatError(p, f"E57 scan {k} ({name}): recordCount/fileOffset are not numbers") from exc
            if count < 0 or offset < 0 or offset + 32 > size:
                raise ScanFormatError(p, f"E57 scan {k} ({name}): recordCount {count} / fileOffset {offset} "
                                         "outside the file")
            bits, fields = _bits(p, _child(pts, "prototype"))
            section_bytes = 0
            if count:
                sec = logical_bytes(p, fh, offset, 32, size)
                if sec[0] != 1:
                    raise ScanFormatError(p, f"E57 scan {k} ({name}): fileOffset {offset} is not a point section")
                section_bytes = struct.unpack_from("<Q", sec, 8)[0]
                if section_bytes > size:
                    raise ScanFormatError(p, f"E57 scan {k} ({name}): its section claims {section_bytes} bytes, "
                                             f"the file has {size}")
                need = count * max(bits, 1) / 8.0
                if need > section_bytes:
                    raise ScanFormatError(p, f"E57 scan {k} ({name}) claims {count} points of {bits} bits; its "
                                             f"{section_bytes}-byte section holds at most "
                                             f"{int(section_bytes * 8 / max(bits, 1))}")
            scans.append(E57ScanFacts(name, count, bits, section_bytes, fields))
        images = _child(root, "images2D")
        return E57Facts(f"{major}.{minor}", tuple(scans), len(list(images)) if images is not None else 0)
