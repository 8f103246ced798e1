"""The codec's wire format: versions, field tables, limits, reason codes, header and fields.

What every message type shares (:mod:`protocol.codec` re-exports the public names): the
``[version, type, fields...]`` layout (:data:`VERSIONS`), the header check
(:func:`read_header`), the field readers that validate one field each and raise
:class:`Rejected`, and the packed Gaussian-mixture block. The underscored helpers are the codec
modules' own (:mod:`protocol.codec_messages` uses them), not an API.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import msgpack
import numpy as np

try:
    from numpy.linalg import _umath_linalg as _lapack
except ImportError:  # pragma: no cover
    _lapack = None

from sensornet.tracking.mixture import GaussianMixture

VERSION = 1
"""The protocol version of every message type: the first element of ``[version, type, ...]``."""
TRACKS_VERSION = 2
"""Protocol 2 exists for Tracks (``"K"``) with identities, covariances, existence and status,
Estimate (``"E"``) with component labels and Scan (``"S"``) with its plots' ages; a message
without them is still written (and read) as protocol 1, byte for byte."""
LABELS_VERSION = TRACKS_VERSION
"""The protocol of a labelled Estimate."""
MASKS_VERSION = 3
"""Protocol 3 exists for an Estimate whose labels' holder masks need more words than the
origin column's (more than 39 peers: peers.label_support): protocol 2's fields and ``"m"``;
an Estimate without them is written as protocol 2 (or 1), byte for byte."""
_F8 = np.dtype("<f8")
_F4 = np.dtype("<f4")
_I8 = np.dtype("<i8")

REASONS = (
    "malformed",  # not msgpack, truncated, or not a map
    "version",  # unknown protocol version
    "type",  # unknown message type
    "field",  # missing field or wrong field type
    "shape",  # array bytes do not match the declared shape
    "nonfinite",  # NaN or infinity
    "weight",  # negative weight
    "not-psd",  # covariance not positive definite
    "too-many",  # more components / measurements / dimensions than allowed
    "too-large",  # message larger than allowed
)


class Rejected(ValueError):
    """A decoded message failed validation; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass(frozen=True)
class Limits:
    """What a receiver accepts; anything larger is rejected before it costs memory."""

    max_bytes: int = 1 << 20
    max_components: int = 2000
    max_measurements: int = 20000
    max_dim: int = 6
    max_name: int = 64
    max_entries: int = 256
    """Scans (origins) in one flooding forward."""
    max_mask_words: int = 64
    """Label holder-mask words a component (Estimate protocol 3; 39 peers a word, so 2,496
    peers): without it one component's words could fill the message, and every label a
    receiver stores would take that width."""


DEFAULT_LIMITS = Limits()


# -- packed arrays ----------------------------------------------------------------------
@lru_cache(maxsize=16)
def _tri_index(d: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of the upper triangle of a ``d x d`` matrix (cached)."""
    return np.triu_indices(d)


@lru_cache(maxsize=16)
def _tri_to_full(d: int) -> np.ndarray:
    """For each of the ``d * d`` entries of a symmetric matrix, its column in the packed upper
    triangle (cached): ``tri[:, _tri_to_full(d)]`` is the full matrix, one gather."""
    r, c = _tri_index(d)
    col = np.empty((d, d), dtype=np.intp)
    col[r, c] = np.arange(r.size)
    col[c, r] = np.arange(r.size)
    return col.reshape(-1)


@lru_cache(maxsize=16)
def _row_to_full(d: int) -> np.ndarray:
    """:func:`_tri_to_full` as columns of a whole packed row (weight, mean, triangle)."""
    return _tri_to_full(d) + 1 + d


def pack_mixture(mix: GaussianMixture) -> bytes:
    """``(n, 1 + d + d(d+1)/2)`` float64 rows: weight, mean, upper triangle of covariance."""
    iu = _tri_index(mix.dim)
    rows = np.concatenate(
        [mix.weights[:, None], mix.means, mix.covs[:, iu[0], iu[1]]], axis=1
    )
    return np.ascontiguousarray(rows, dtype=_F8).tobytes()


def _array(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=_F8).tobytes()


_KINDS = ("posterior", "prediction", "returns")  # "returns": seed 003 before Returns ("R")
_FIELDS = {
    # type letter: field names after [version, type], in wire order
    "E": ("s", "k", "r", "q", "ts", "p", "o", "d", "x"),
    "S": ("s", "k", "q", "ts", "x"),
    "K": ("s", "k", "q", "ts", "d", "x"),
    "T": ("k", "ts", "d", "x", "i"),
    "C": ("c", "id", "pa", "ts"),
    "F": ("s", "k", "r", "q", "ts", "o", "n", "x"),
    "R": ("s", "k", "r", "q", "ts", "x"),
    # Telemetry (live views only): value names "vn" and their float64 "vx", event lines
    # "ev", point sets' names "pn", row counts "pc" and (m, 2) float64 rows "px", the fused
    # mixture's dimension "d" (0: none) and packed rows "x"
    "Y": ("s", "k", "ts", "vn", "vx", "ev", "pn", "pc", "px", "d", "x"),
}
_FIELDS_V2 = {
    # Tracks with identities: ids "i" (n, 3) int64, covariances "c" (n, d(d+1)/2) upper
    # triangles, existence "e" (n,) float64, status "u" (n,) int8; each bytes or nil (not
    # sent). The states "x" stay last, as in protocol 1.
    "K": ("s", "k", "q", "ts", "d", "i", "c", "e", "u", "x"),
    # Estimate with component labels: "i" (n, 3) int64 bytes, one row per component of "x"
    "E": ("s", "k", "r", "q", "ts", "p", "o", "d", "i", "x"),
    # Scan with each plot's age "a" (m,) float64 bytes (seconds before the scan's time)
    "S": ("s", "k", "q", "ts", "a", "x"),
    # Telemetry with its (m, 2) map points as float32 rows "pf" (for the eye: half the
    # bytes of "px"); a report whose points do not fit float32 is still protocol 1
    "Y": ("s", "k", "ts", "vn", "vx", "ev", "pn", "pc", "pf", "d", "x"),
}
_FIELDS_V3 = {
    # Estimate with labels and holder-mask words 1.. "m" (n, W) int64 bytes (W >= 1)
    "E": ("s", "k", "r", "q", "ts", "p", "o", "d", "i", "m", "x"),
}
VERSIONS = {VERSION: _FIELDS, TRACKS_VERSION: _FIELDS_V2, MASKS_VERSION: _FIELDS_V3}
"""Protocol version -> the message types it has -> their field names in wire order."""

def _rows(blob: bytes, width: int, limit: int, what: str, size: int = 8) -> int:
    """Number of rows of ``width`` float64 (``size`` bytes each: 4 for float32) in ``blob``,
    checked against ``limit``."""
    if width <= 0 or len(blob) % (size * width):
        raise Rejected("shape", f"{len(blob)} bytes is not a whole number of {what}")
    n = len(blob) // (size * width)
    if n > limit:
        raise Rejected("too-many", f"{n} {what} > {limit}")
    return n



# -- header and fields ------------------------------------------------------------------
def read_header(data: bytes, limits: Limits) -> tuple[int, str, dict]:
    """``(version, type letter, body by field name)`` of a message, its size, msgpack, version,
    type and field count checked; anything else raises :class:`Rejected`."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise Rejected("malformed", f"payload of type {type(data).__name__}")
    if len(data) > limits.max_bytes:
        raise Rejected("too-large", f"{len(data)} bytes > {limits.max_bytes}")
    try:
        body = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True,
                               max_bin_len=limits.max_bytes, max_str_len=4096,
                               max_array_len=1024, max_map_len=64)
    except Exception as exc:  # msgpack raises several unrelated types on bad input
        raise Rejected("malformed", f"not a msgpack message ({type(exc).__name__})") from None
    if not isinstance(body, list) or len(body) < 2:
        raise Rejected("malformed", f"top level is {type(body).__name__}, not a message array")
    version = body[0]
    if type(version) is not int or version not in VERSIONS:
        raise Rejected("version", f"protocol version {version!r}, expected one of "
                                  f"{sorted(VERSIONS)}")
    kind = body[1]
    if not isinstance(kind, str) or kind not in _FIELDS:
        raise Rejected("type", f"unknown message type {kind!r}")
    if kind not in VERSIONS[version]:
        raise Rejected("version", f"protocol version {version} has no message type {kind!r}")
    names = VERSIONS[version][kind]
    if len(body) != 2 + len(names):
        raise Rejected("field", f"{len(body) - 2} fields for type {kind}, {len(names)} expected")
    return version, kind, dict(zip(names, body[2:], strict=True))


def _get(body: dict, key: str, kind: type | tuple[type, ...]):
    if key not in body:
        raise Rejected("field", f"missing field {key!r}")
    value = body[key]
    if isinstance(value, bool) and kind is not bool:
        raise Rejected("field", f"field {key!r} has type bool")
    if not isinstance(value, kind):
        raise Rejected("field", f"field {key!r} has type {type(value).__name__}")
    return value


def _name(body: dict, key: str, limits: Limits) -> str:
    s = _get(body, key, str)
    if not s or len(s) > limits.max_name:
        raise Rejected("field", f"field {key!r} must be a name of 1-{limits.max_name} characters")
    return s


def _index(body: dict, key: str) -> int:
    v = _get(body, key, int)
    if not 0 <= v < 1 << 53:
        raise Rejected("field", f"field {key!r}={v} is not a valid index")
    return v


def _time(body: dict) -> float:
    v = float(_get(body, "ts", (float, int)))
    if not math.isfinite(v):  # a Python float: no NumPy scalar call
        raise Rejected("nonfinite", "send time is not finite")
    return v


def _count(body: dict, key: str, limit: int) -> int:
    n = _get(body, key, int)
    if n < 0 or n > limit:
        raise Rejected("too-many", f"{key}={n} outside [0, {limit}]")
    return n


def _floats(blob: bytes, shape: tuple[int, ...], dtype: np.dtype = _F8) -> np.ndarray:
    """``blob`` as a float64 array of ``shape`` (stored as ``dtype``: little-endian float64
    or float32), its size and finiteness checked."""
    expected = math.prod(shape) * dtype.itemsize
    if len(blob) != expected:
        raise Rejected("shape", f"{len(blob)} bytes for shape {shape} ({expected} expected)")
    a = np.frombuffer(blob, dtype=dtype).reshape(shape).astype(float)
    if not np.isfinite(a).all():
        raise Rejected("nonfinite", "array holds NaN or infinity")
    return a


def unpack_mixture(blob: bytes, n: int, d: int) -> GaussianMixture:
    """Inverse of :func:`pack_mixture`, validating weights and covariances (``nonfinite``,
    ``weight``, ``not-psd``, in that order). Under one ``errstate``, each finiteness check is
    a sum first (finite only if every term is, and no sum of finite rows or Cholesky factors
    overflows a float64 short of ~1e150 a number), the element-wise check only when it is not;
    a few weights are compared in Python: an estimate's few components cost no NumPy call
    more than they need (about 2 decodes a peer-scan in a host, issue 38)."""
    t = d * (d + 1) // 2
    width = 1 + d + t
    if len(blob) != n * width * 8:
        raise Rejected("shape", f"{len(blob)} bytes for shape {(n, width)} "
                                f"({n * width * 8} expected)")
    rows = np.frombuffer(blob, dtype=_F8).reshape(n, width).astype(float)
    w, m = rows[:, 0], rows[:, 1:1 + d]
    P = rows.take(_row_to_full(d), axis=1).reshape(n, d, d)
    with np.errstate(all="ignore"):
        if not (math.isfinite(_sum(rows, None)) or np.isfinite(rows).all()):
            raise Rejected("nonfinite", "array holds NaN or infinity")
        if n and (min(w.tolist()) if n <= _FEW else _min(w)) < 0:  # finite by now
            raise Rejected("weight", "negative component weight")
        if n and not _factors(P):
            raise Rejected("not-psd", "a covariance is not positive definite")
    return GaussianMixture.trusted(w, m, P)  # float, (n,), (n, d), (n, d, d) by construction


_sum, _min = np.add.reduce, np.minimum.reduce
_FEW = 32
"""Up to this many weights, their smallest is found in Python (cheaper than a NumPy call)."""


def _factors(P: np.ndarray) -> bool:
    """:func:`_positive_definite` for a caller that holds ``errstate(all="ignore")``: a factor
    is finite (its sum too: each entry is at most the square root of a finite variance) or
    NaN, so a finite sum says every matrix has one."""
    if _lapack is None:  # pragma: no cover (NumPy without the private module)
        return _positive_definite(P)
    L = _lapack.cholesky_lo(P, signature="d->d")
    return math.isfinite(_sum(L, None)) or bool(np.isfinite(L).all())


def _positive_definite(P: np.ndarray) -> bool:
    """Whether every matrix of the finite stack ``P`` has a Cholesky factor: the LAPACK call of
    ``np.linalg.cholesky`` without its wrapper (which costs more than a few 4x4 factors); a
    matrix that is not positive definite gives NaN there instead of an exception."""
    if _lapack is None:  # pragma: no cover (NumPy without the private module)
        try:
            np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            return False
        return True
    with np.errstate(all="ignore"):
        L = _lapack.cholesky_lo(P, signature="d->d")
    return bool(np.isfinite(L).all())


def _optional(body: dict, key: str, nbytes: int, what: str) -> bytes | None:
    """Field ``key``: nil (not sent) or exactly ``nbytes`` bytes (checked before decoding)."""
    blob = body[key]
    if blob is None:
        return None
    if not isinstance(blob, bytes):
        raise Rejected("field", f"field {key!r} has type {type(blob).__name__}")
    if len(blob) != nbytes:
        raise Rejected("shape", f"{len(blob)} bytes of {what} ({nbytes} expected)")
    return blob


def _names(body: dict, key: str, limits: Limits, most: int) -> list[str]:
    """A list of at most ``most`` names of 1-``max_name`` characters."""
    names = _get(body, key, list)
    if len(names) > most:
        raise Rejected("too-many", f"{len(names)} entries in {key!r} > {most}")
    if not all(type(n) is str and 0 < len(n) <= limits.max_name for n in names):
        raise Rejected("field", f"{key!r} must hold names of 1-{limits.max_name} characters")
    return names
