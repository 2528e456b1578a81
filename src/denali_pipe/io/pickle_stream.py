"""Reading raw capture pickle streams `<set>_short_NLOSdata.pkl`.

A stream is a sequence of pickles written one after another to the same file
(the capture script calls `pickle.dump` once per record): first the metadata
record (a dict: object, size, light, spad_res, samples, grid, ...), then one
record per gantry location:

    {"iter": gantry location,
     "histogram": (repeats, n, n, 128) int,
     "spad_realsense_data":      {"aligned_depth_image": (H, W) uint16, "aligned_rgb_image": (H, W, 3) uint8 BGR},
     "tracking_realsense_data":  {"aligned_depth_image": ..., "aligned_rgb_image": ...}}

Pickles from disk are untrusted: unpickling calls whatever callables the
stream names. `RestrictedUnpickler` resolves only the globals a capture needs
(`ALLOWED_GLOBALS`: numpy's array, dtype and scalar reconstructors as pickle
and cloudpickle write them with protocols 0-5, numpy 1.x and 2.x spellings)
and refuses every other global with `UnsafePickleError` before anything is
called. dict, list, tuple, str, int, float, bool, None and bytes (protocol
3+) need no globals at all.
"""

from __future__ import annotations

import _compat_pickle
import pickle
from pathlib import Path
from typing import Any, Iterator

import numpy as np

# Keys of a location record, and of each of its two camera dicts.
RECORD_KEYS = ("iter", "histogram", "spad_realsense_data", "tracking_realsense_data")
CAMERA_KEYS = ("aligned_depth_image", "aligned_rgb_image")
# Camera dict of a location record -> camera name of the release layout
# (`spad_realsense_data` is the RealSense co-located with the SPAD sensor).
CAMERA_RECORDS = {"spad_realsense_data": "colocated", "tracking_realsense_data": "tracking"}


class UnsafePickleError(pickle.UnpicklingError, ValueError):
    """A pickle names a global outside `ALLOWED_GLOBALS`; nothing was called."""


def _latin1_encode(text: str, encoding: str = "latin1") -> bytes:
    """`_codecs.encode` as protocol 2 uses it for bytes objects: a str with
    latin-1 only (any other codec name could import codec modules)."""
    if not isinstance(encoding, str) or encoding.lower().replace("-", "").replace("_", "") not in ("latin1", "iso88591"):
        raise UnsafePickleError(f"_codecs.encode called with encoding {encoding!r:.40}; only latin1 is admitted")
    if not isinstance(text, str):
        raise UnsafePickleError(f"_codecs.encode called on a {type(text).__name__}; only str is admitted")
    return text.encode("latin1")


def _empty_bytes(*args: object) -> bytes:
    """`bytes()` as protocol 2 writes b'' (no arguments only: `bytes(n)` would allocate n bytes)."""
    if args:
        raise UnsafePickleError(f"builtins.bytes called with arguments {args!r:.80}; only bytes() is admitted")
    return b""


class _NdarrayClass:
    """What `numpy.ndarray` resolves to: numpy's pickles only pass the class to
    `_reconstruct` (then set the state from the stream's own bytes). Calling it
    (`ndarray(shape)` would allocate any size) or using it with NEWOBJ is refused."""

    def __call__(self, *args, **kwargs):
        raise UnsafePickleError("numpy.ndarray called directly; numpy's pickles only pass it to _reconstruct")

    def __repr__(self) -> str:
        return "numpy.ndarray (pickle token)"


_NDARRAY = _NdarrayClass()


def _reconstruct(subtype, shape, typecode):
    """`numpy._core.multiarray._reconstruct` as numpy's pickles call it:
    (ndarray, (0,), b'b'); the data then comes from ndarray.__setstate__."""
    if subtype is not _NDARRAY or tuple(shape) != (0,):
        raise UnsafePickleError(f"numpy _reconstruct called with ({subtype!r:.60}, {shape!r:.40}); only (ndarray, (0,)) is admitted")
    return np._core.multiarray._reconstruct(np.ndarray, (0,), typecode)


def _allowed_globals() -> dict[tuple[str, str], Any]:
    multiarray = np._core.multiarray
    numeric = np._core.numeric
    allowed = {
        # arrays, protocols 0-4 (and protocol 5 for non-contiguous arrays):
        # _reconstruct(ndarray, (0,), b"b") then ndarray.__setstate__(stream bytes)
        ("numpy", "ndarray"): _NDARRAY,
        ("numpy", "dtype"): np.dtype,
        # numpy scalars (np.int64(5), np.float32(...)): scalar(dtype, bytes)
        # protocol 5 / cloudpickle, contiguous arrays: _frombuffer(buf, dtype, shape, order)
        # protocol 2 spells bytes objects _codecs.encode(str, "latin1"), and b'' as bytes()
        ("_codecs", "encode"): _latin1_encode,
        ("builtins", "bytes"): _empty_bytes,
    }
    # numpy >= 2 writes numpy._core.*, numpy 1.x wrote numpy.core.*; both load here.
    for pkg in ("numpy._core", "numpy.core"):
        allowed[(f"{pkg}.multiarray", "_reconstruct")] = _reconstruct
        allowed[(f"{pkg}.multiarray", "scalar")] = multiarray.scalar
        allowed[(f"{pkg}.numeric", "_frombuffer")] = numeric._frombuffer
    return allowed


ALLOWED_GLOBALS: dict[tuple[str, str], Any] = _allowed_globals()


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that resolves only `ALLOWED_GLOBALS` (exact module and
    name after mapping Python 2 spellings; dotted attribute paths are refused) and raises `UnsafePickleError`
    naming the file, the record and the global for anything else.

    Out-of-band buffers (protocol 5) are not supported: a stream that refers to
    them fails with UnpicklingError. Persistent ids fail the same way.
    """

    def __init__(self, file, *, source: str = "<stream>", record: int | None = None):
        super().__init__(file)
        self.source = source
        self.record = record

    def find_class(self, module: str, name: str) -> Any:
        py3 = _python3_name(module, name)
        try:
            return ALLOWED_GLOBALS[py3]
        except (KeyError, TypeError):
            where = self.source if self.record is None else f"{self.source}: record {self.record}"
            spelled = "" if py3 == (module, name) else f" (written as {module}.{name})"
            raise UnsafePickleError(
                f"{where}: refusing to unpickle global {py3[0]}.{py3[1]}{spelled} "
                "(a capture stream holds only numpy arrays, dtypes, scalars and builtin containers)"
            ) from None


def _python3_name(module: str, name: str) -> tuple[str, str]:
    """Python 2 spellings (protocols 0-2 write `__builtin__.bytes`,
    `commands.call`, ...) mapped to Python 3 as pickle's own fix_imports does."""
    if (module, name) in _compat_pickle.NAME_MAPPING:
        return _compat_pickle.NAME_MAPPING[(module, name)]
    return _compat_pickle.IMPORT_MAPPING.get(module, module), name


def restricted_loads(data: bytes, source: str = "<bytes>") -> Any:
    """Unpickle one object from bytes with `RestrictedUnpickler`."""
    import io

    return RestrictedUnpickler(io.BytesIO(data), source=source).load()


def _is_location_record(obj: object) -> bool:
    return isinstance(obj, dict) and "iter" in obj and "histogram" in obj


def _load_one(f, path: Path, index: int) -> Any:
    """The pickle starting at the current position of `f` (not at EOF)."""
    try:
        return RestrictedUnpickler(f, source=str(path), record=index).load()
    except UnsafePickleError as e:
        if str(e).startswith(str(path)):
            raise
        raise UnsafePickleError(f"{path}: record {index}: {e}") from None
    except (EOFError, pickle.UnpicklingError) as e:
        raise ValueError(f"{path}: record {index} is cut or corrupt ({type(e).__name__}: {e}); the stream ends mid-record (truncated file?)") from None
    except MemoryError:
        raise ValueError(f"{path}: record {index} could not be unpickled: out of memory (a corrupt length field, or a record larger than memory)") from None
    except Exception as e:  # noqa: BLE001 -- any other failure is a malformed record
        raise ValueError(f"{path}: record {index} does not unpickle ({type(e).__name__}: {e})") from None


def _check_record(path: Path, index: int, rec: object) -> dict:
    if not isinstance(rec, dict):
        raise ValueError(f"{path}: record {index} is a {type(rec).__name__}, expected a dict with keys {list(RECORD_KEYS)}")
    missing = [k for k in RECORD_KEYS if k not in rec]
    if missing:
        raise ValueError(f"{path}: record {index} lacks keys {missing} (expected {list(RECORD_KEYS)}, found {sorted(map(str, rec))})")
    for cam in CAMERA_RECORDS:
        sub = rec[cam]
        if not isinstance(sub, dict):
            raise ValueError(f"{path}: record {index} ({cam}) is a {type(sub).__name__}, expected a dict with keys {list(CAMERA_KEYS)}")
        missing = [k for k in CAMERA_KEYS if k not in sub]
        if missing:
            raise ValueError(f"{path}: record {index} ({cam}) lacks keys {missing}")
    it = rec["iter"]
    if isinstance(it, (bool, np.bool_)) or not isinstance(it, (int, np.integer)):
        raise ValueError(f"{path}: record {index}: `iter` must be an integer gantry location, found {it!r:.60}")
    return rec


def iter_records(path: Path) -> Iterator[tuple[int, dict]]:
    """Yield (record index, record) for every record of a capture stream, lazily.

    Record 0 is the metadata dict (unwrapped when the stream holds it as
    {"metadata": {...}}, as the real capture script writes it); records 1.. are location records, checked to
    be dicts with `RECORD_KEYS` (and `CAMERA_KEYS` in both camera dicts) and
    an integer `iter`. Only one record is in memory at a time (a fresh
    unpickler per record, so no memo keeps earlier records alive).

    Raises FileNotFoundError for a missing file, `UnsafePickleError` for a
    forbidden global, and ValueError naming the file and the record for an
    empty stream, a missing metadata record, a record cut mid-way, or a record
    that is not a dict or lacks keys.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such capture stream")
    size = path.stat().st_size
    with open(path, "rb") as f:
        if size == 0:
            raise ValueError(f"{path}: empty capture stream (expected a metadata record, then one record per location)")
        meta = _load_one(f, path, 0)
        if _is_location_record(meta):
            raise ValueError(f"{path}: record 0 is a location record (iter={meta['iter']!r}); the metadata record is missing")
        if not isinstance(meta, dict):
            raise ValueError(f"{path}: record 0 is a {type(meta).__name__}, expected the metadata dict")
        if set(meta) == {"metadata"} and isinstance(meta["metadata"], dict):
            meta = meta["metadata"]  # the real capture script wraps it: {"metadata": {...}}
        yield 0, meta
        del meta
        index = 1
        while f.tell() < size:
            rec = _check_record(path, index, _load_one(f, path, index))
            yield index, rec
            del rec
            index += 1


def read_metadata(path: Path) -> dict:
    """The metadata record (record 0) of a capture stream; reads nothing else."""
    for _, meta in iter_records(path):
        return meta
    raise AssertionError("unreachable")
