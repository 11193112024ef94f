"""The digest of rows of SQL values, on which every stored checksum of the campaign is built.

It lives apart from :mod:`projects.store.digests` (which says which rows each digest covers) so that
the table modules that seal their own rows import it without importing the digest groups.
"""
from __future__ import annotations

import hashlib
import zlib
from collections.abc import Callable, Iterable, Sequence


def value_digest(rows: Iterable[Sequence]) -> str:
    """The digest of rows of SQL values (None, int, float, str, bytes), hex.

    Text and numbers enter BLAKE2b exactly; a blob enters as its length and CRC-32 (blobs are the
    large map previews and series arrays: CRC-32 reads them five times faster, and any damage that
    changes a blob changes its CRC with certainty for bursts up to 32 bits, and otherwise but for
    a chance of one in four billion).

    Examples
    --------
    >>> value_digest([(1, 0.5, "a", None, b"x")]) == value_digest([(1, 0.5, "a", None, b"x")])
    True
    >>> value_digest([(1.0,)]) == value_digest([(1,)])  # a REAL is not an INTEGER
    False
    """
    parts: list[bytes] = []
    for row in rows:
        encode_row(row, parts.append)
    return digest_of(parts)


def encode_row(row: Sequence, add: Callable[[bytes], object]) -> None:
    """Pass to ``add``, piece by piece, the bytes one row enters :func:`value_digest` with.

    A blob enters as its length and CRC-32: a few bytes, however large the blob.
    """
    add(b"(")
    for v in row:
        t = type(v)  # the common types first, by identity (a third faster than isinstance on every value)
        if t is float:
            add(b"F%s;" % v.hex().encode())
        elif t is str:
            s = v.encode()
            add(b"S%d:%s" % (len(s), s))
        elif t is int:
            add(b"I%d;" % v)
        elif v is None:
            add(b"N")
        elif isinstance(v, (bytes, bytearray, memoryview)):
            add(b"B%d:%08x;" % (len(v), zlib.crc32(v)))
        elif isinstance(v, int):  # bool and other int subclasses, as plain integers
            add(b"I%d;" % int(v))
        elif isinstance(v, float):
            add(b"F%s;" % float.hex(v).encode())
        else:
            s = str(v).encode()
            add(b"S%d:%s" % (len(s), s))
    add(b")")


def digest_of(parts: Iterable[bytes]) -> str:
    """The digest of rows already encoded by :func:`encode_row`, hex (what :func:`value_digest` returns)."""
    return hashlib.blake2b(b"".join(parts), digest_size=16).hexdigest()
