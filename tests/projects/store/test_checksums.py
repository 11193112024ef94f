"""The stored digests' byte format: every campaign's checksums were written with it, so it may not drift."""
from __future__ import annotations

import hashlib
import zlib

import numpy as np

from projects.store.checksums import value_digest


def _as_written(rows) -> str:
    """The format as the first campaigns wrote it (schema 10): one part a value, then BLAKE2b-128."""
    parts: list[bytes] = []
    for row in rows:
        parts.append(b"(")
        for v in row:
            if v is None:
                parts.append(b"N")
            elif isinstance(v, (bytes, bytearray, memoryview)):
                parts.append(b"B%d:%08x;" % (len(v), zlib.crc32(v)))
            elif isinstance(v, int):
                parts.append(b"I%d;" % int(v))
            elif isinstance(v, float):
                parts.append(b"F" + float.hex(v).encode() + b";")
            else:
                s = str(v).encode()
                parts.append(b"S%d:" % len(s))
                parts.append(s)
        parts.append(b")")
    return hashlib.blake2b(b"".join(parts), digest_size=16).hexdigest()


class _Text(str):
    pass


def test_digest_of_every_kind_of_value_is_as_written():
    rng = np.random.default_rng(3)
    rows = [("SELECT epoch FROM t WHERE epoch = ?",), ()]
    rows += [tuple(float(x) for x in rng.normal(size=5)) for _ in range(20)]
    rows += [(True, False, 0, -7, 2**70, 1.0, -0.0, 0.0, float("nan"), float("inf"), float("-inf"), 1e-300)]
    rows += [("", "é€", "a;b:(c)", _Text("sub"), None, b"", b"\x00\xff", bytearray(b"xy"), memoryview(b"mv"))]
    rows += [(np.float64(0.25), np.int64(3), np.bool_(True))]  # numpy scalars: float and int subclasses or not
    assert value_digest(rows) == _as_written(rows)


def test_digest_tells_real_from_integer_and_order():
    assert value_digest([(1.0,)]) != value_digest([(1,)])
    assert value_digest([(1, 2)]) != value_digest([(2, 1)])
    assert value_digest([(1,), (2,)]) != value_digest([(1, 2)])
