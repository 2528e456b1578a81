"""The Zarr v3 store of one capture set, `<set>.zarr`, and its reader.

Layout (one group; every array's first axis is the store position i, in the
order the locations were written, i.e. the capture order):

    location         (L,)                     int16   gantry location of position i
    histogram        (L, repeats, n, n, 128)  int32   chunk (1, repeats, n, n, 128)
    tracking_rgb     (L, H, W, 3)             uint8   BGR (OpenCV order), chunk = one frame
    tracking_depth   (L, H, W)                uint16  mm, chunk = one frame
    colocated_rgb    (L, h, w, 3)             uint8   BGR
    colocated_depth  (L, h, w)                uint16  mm

A frame modality is present only when its frames were ingested (the public
release, for one, has only `tracking_rgb`). Codecs: Blosc zstd level 1, one
chunk per location (or frame); byte shuffle for int32 histograms, bitshuffle
for uint16 depth (a third smaller than byte shuffle at the same speed), no
shuffle for uint8 RGB (a one-byte shuffle is a no-op).

Root attributes (JSON):

    denali_store     format version (STORE_VERSION)
    set, object, size, resolution, light, n_zones, repeats, n_bins
    modalities       the frame arrays present, e.g. ["tracking_rgb", ...]
    frames           {"color_order": "BGR", "depth_unit": "mm"}
    metadata         the capture's metadata record, verbatim (made JSON-safe)
    source_format    "release" or "pickle"
    sources          [{"path", "modality", "bytes", "sha256"}, ...] every raw
                     file read, path relative to the raw tree's root

`StoreWriter` builds a store under a temporary name and publishes it only
when complete; `CaptureStore` (`open_set`) reads one lazily.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
import zarr
from zarr.codecs import BloscCodec

from denali_pipe.core.atomic import atomic_dir
from denali_pipe.core.capture_sets import CaptureSet, parse_set_name
from denali_pipe.core.geometry import N_BINS
from denali_pipe.io.release import FRAME_DIRS

STORE_VERSION = 1
STORE_SUFFIX = ".zarr"
MODALITIES = FRAME_DIRS  # tracking_rgb, tracking_depth, colocated_rgb, colocated_depth
HISTOGRAM = "histogram"
LOCATION = "location"
COLOR_ORDER = "BGR"
DEPTH_UNIT = "mm"

HISTOGRAM_CODEC = dict(cname="zstd", clevel=1, shuffle="shuffle")
RGB_CODEC = dict(cname="zstd", clevel=1, shuffle="noshuffle")
# bitshuffle: 2.96-2.99x on the rig's depth against 1.98-2.26x with byte
# shuffle, encoding and decoding at a similar 400-900 MB/s (scripts/bench_ingest.py)
DEPTH_CODEC = dict(cname="zstd", clevel=1, shuffle="bitshuffle")

_INITIAL_CAPACITY = 16  # positions allocated before the first growth


def frame_spec(modality: str) -> tuple[np.dtype, int | None]:
    """(dtype, channels) of a frame modality: BGR uint8 (H, W, 3) or depth uint16 (H, W)."""
    if modality not in MODALITIES:
        raise ValueError(f"unknown frame modality {modality!r}: expected one of {list(MODALITIES)}")
    return (np.dtype(np.uint8), 3) if modality.endswith("_rgb") else (np.dtype(np.uint16), None)


def jsonable(obj: Any, where: str = "value") -> Any:
    """`obj` as plain JSON types: numpy scalars -> Python, arrays and tuples ->
    lists, non-finite floats -> "nan"/"inf"/"-inf". Other types raise ValueError."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else str(x)
    if isinstance(obj, np.ndarray):
        if obj.dtype.hasobject or obj.size > 100_000:
            raise ValueError(f"{where}: array of dtype {obj.dtype} and size {obj.size} cannot go into JSON attributes")
        return jsonable(obj.tolist(), where)
    if isinstance(obj, Mapping):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, (str, int, np.integer)):
                raise ValueError(f"{where}: key {k!r} of type {type(k).__name__} cannot go into JSON attributes")
            out[str(k)] = jsonable(v, f"{where}.{k}")
        return out
    if isinstance(obj, (list, tuple)):
        return [jsonable(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    raise ValueError(f"{where}: a {type(obj).__name__} cannot go into JSON attributes")


class StoreWriter:
    """Write `<set>.zarr` location by location, atomically.

        with StoreWriter(out, capture_set, repeats=3, metadata=md, source_format="release") as w:
            w.add_source("A_..._NLOSdata/metadata.json", "metadata", nbytes, sha256)
            for location, hist, frames in ...:
                w.write_location(location, hist, frames)

    The store is built in a temporary folder beside `out` and renamed to
    `out` when the `with` block ends without an error; on any error the
    temporary folder is removed and an existing `out` is left untouched.
    `repeats` None: the first histogram decides. `frame_shapes`:
    {modality: (height, width)} where known beforehand. Memory: one
    location's arrays at a time (arrays grow by doubling and are trimmed at
    the end, so the location count need not be known).

    `write_location` checks the histogram's shape (repeats, n, n, 128) and
    integer dtype that fits int32 losslessly, frames' dtype and size (fixed by
    `frame_shapes` or by the first frame of each modality), the same set of
    modalities at every location, and that no location repeats; violations
    raise ValueError naming the store.
    """

    def __init__(
        self,
        out: Path,
        capture_set: CaptureSet,
        *,
        repeats: int | None = None,
        metadata: Mapping[str, Any],
        source_format: str,
        frame_shapes: Mapping[str, tuple[int, int]] | None = None,
    ):
        self.out = Path(out)
        self.capture_set = capture_set
        self.repeats = None if repeats is None else int(repeats)
        self.metadata = jsonable(dict(metadata), f"{self.out}: metadata")
        self.source_format = source_format
        self.frame_shapes = {m: tuple(map(int, s)) for m, s in (frame_shapes or {}).items()}
        for m in self.frame_shapes:
            frame_spec(m)
        if self.repeats is not None and self.repeats < 1:
            raise ValueError(f"{self.out}: repeats must be >= 1, got {repeats}")
        self.sources: list[dict] = []
        self.locations: list[int] = []
        self._seen: set[int] = set()
        self._modalities: tuple[str, ...] | None = None
        self._arrays: dict[str, zarr.Array] = {}
        self._capacity = 0
        self._ctx = None

    # -- context ------------------------------------------------------------------

    def __enter__(self) -> "StoreWriter":
        self._ctx = atomic_dir(self.out)
        self.tmp = self._ctx.__enter__()
        try:
            self.group = zarr.open_group(self.tmp, mode="w", zarr_format=3)
        except BaseException as e:
            self._ctx.__exit__(type(e), e, e.__traceback__)
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            try:
                self._finish()
            except BaseException as e:
                self._ctx.__exit__(type(e), e, e.__traceback__)
                raise
            self._ctx.__exit__(None, None, None)
            return False
        return bool(self._ctx.__exit__(exc_type, exc, tb))

    # -- writing ------------------------------------------------------------------

    def add_source(self, path: str, modality: str, nbytes: int, sha256: str) -> None:
        """Record one raw input file (path relative to the raw tree's root)."""
        self.sources.append({"path": str(path), "modality": modality, "bytes": int(nbytes), "sha256": sha256})

    def write_location(self, location: int, histogram: np.ndarray, frames: Mapping[str, np.ndarray] | None = None) -> int:
        """Append one gantry location: its (repeats, n, n, 128) histograms and
        its frames {modality: array}. Returns the store position."""
        location = int(location)
        frames = dict(frames or {})
        where = f"{self.out}: location {location}"
        if location in self._seen:
            raise ValueError(f"{where}: duplicated location (already written)")
        if not 0 <= location <= np.iinfo(np.int16).max:
            raise ValueError(f"{where}: location out of range 0..{np.iinfo(np.int16).max}")
        hist = self._check_histogram(histogram, where)
        if HISTOGRAM not in self._arrays:
            n = self.capture_set.n_zones
            self._arrays[HISTOGRAM] = self._create(
                HISTOGRAM, (self.repeats, n, n, N_BINS), np.int32, HISTOGRAM_CODEC,
                ("location", "repeat", "zone_row", "zone_col", "bin"),
            )  # fmt: skip
        mods = tuple(m for m in MODALITIES if m in frames)
        unknown = sorted(set(frames) - set(MODALITIES))
        if unknown:
            raise ValueError(f"{where}: unknown frame modalities {unknown} (expected some of {list(MODALITIES)})")
        if self._modalities is None:
            self._modalities = mods
        elif mods != self._modalities:
            raise ValueError(f"{where}: frames {list(mods)}, but earlier locations had {list(self._modalities)}")
        checked = {m: self._check_frame(m, frames[m], where) for m in mods}

        i = len(self.locations)
        self._grow(i + 1)
        self._arrays[HISTOGRAM][i] = hist
        for m, frame in checked.items():
            self._arrays[m][i] = frame
        self.locations.append(location)
        self._seen.add(location)
        return i

    # -- internals ----------------------------------------------------------------

    def _create(self, name, shape, dtype, codec, dims) -> zarr.Array:
        return self.group.create_array(
            name,
            shape=(max(self._capacity, 0), *shape),
            chunks=(1, *shape),
            dtype=dtype,
            compressors=BloscCodec(typesize=np.dtype(dtype).itemsize, **codec),
            fill_value=0,
            dimension_names=dims,
            # every chunk is data; skipping zarr's all-fill-value test per chunk saves ~40 % of write time
            config={"write_empty_chunks": True},
        )

    def _check_histogram(self, h: np.ndarray, where: str) -> np.ndarray:
        h = np.asarray(h)
        n = self.capture_set.n_zones
        if self.repeats is None and h.ndim == 4:
            self.repeats = h.shape[0]  # the first location fixes repeats
        expected = (self.repeats, n, n, N_BINS)
        if h.shape != expected:
            raise ValueError(f"{where}: histogram shape {h.shape}, expected {expected}")
        if not np.can_cast(h.dtype, np.int32, casting="safe"):
            raise ValueError(f"{where}: histogram dtype {h.dtype}, expected int32 (or an integer type that fits it)")
        return h.astype(np.int32, copy=False)

    def _check_frame(self, modality: str, frame: np.ndarray, where: str) -> np.ndarray:
        frame = np.asarray(frame)
        dtype, channels = frame_spec(modality)
        if frame.dtype != dtype or frame.ndim != (2 if channels is None else 3) or (channels and frame.shape[2] != channels):
            want = f"({'H, W' if channels is None else 'H, W, 3'}) {dtype}"
            raise ValueError(f"{where}: {modality} frame {frame.shape} {frame.dtype}, expected {want}")
        hw = frame.shape[:2]
        if modality not in self.frame_shapes:
            self.frame_shapes[modality] = hw
        if hw != self.frame_shapes[modality]:
            raise ValueError(f"{where}: {modality} frame is {hw[1]}x{hw[0]} (WxH), expected {self.frame_shapes[modality][1]}x{self.frame_shapes[modality][0]}")
        if modality not in self._arrays:
            shape = (*hw, channels) if channels else hw
            dims = ("location", "y", "x", "channel") if channels else ("location", "y", "x")
            codec = RGB_CODEC if channels else DEPTH_CODEC
            self._arrays[modality] = self._create(modality, shape, dtype, codec, dims)
        return frame

    def _grow(self, needed: int) -> None:
        if needed > self._capacity:
            self._capacity = max(_INITIAL_CAPACITY, 2 * self._capacity, needed)
            self._resize_all(self._capacity)

    def _resize_all(self, length: int) -> None:
        for arr in self._arrays.values():
            if arr.shape[0] != length:
                arr.resize((length, *arr.shape[1:]))

    def _finish(self) -> None:
        if not self.locations:
            raise ValueError(f"{self.out}: no locations were written")
        self._resize_all(len(self.locations))
        self._capacity = len(self.locations)
        self.group.create_array(
            LOCATION, data=np.asarray(self.locations, dtype=np.int16), chunks=(len(self.locations),),
            dimension_names=("location",),
        )  # fmt: skip
        cs = self.capture_set
        self.group.attrs.update(
            {
                "denali_store": STORE_VERSION,
                "set": cs.name,
                "object": cs.object,
                "size": cs.size,
                "resolution": cs.resolution,
                "light": cs.light,
                "n_zones": cs.n_zones,
                "repeats": self.repeats,
                "n_bins": N_BINS,
                "modalities": list(self._modalities or ()),
                "frames": {"color_order": COLOR_ORDER, "depth_unit": DEPTH_UNIT},
                "metadata": self.metadata,
                "source_format": self.source_format,
                "sources": self.sources,
            }
        )


class CaptureStore:
    """Lazy reader of one `<set>.zarr` store (nothing but the attributes and
    the location array is read on opening).

    Positions i (0..len-1) index the arrays; `locations[i]` is the gantry
    location at position i, `index_of(location)` the inverse. RGB frames are
    BGR uint8 (OpenCV order), depth frames uint16 mm.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"{self.path}: no such capture store")
        try:
            self.group = zarr.open_group(self.path, mode="r", zarr_format=3)
        except Exception as e:  # noqa: BLE001 -- zarr raises several types for a non-store
            raise ValueError(f"{self.path}: not a Zarr v3 capture store ({type(e).__name__}: {e})") from None
        self.attrs: dict = dict(self.group.attrs)
        version = self.attrs.get("denali_store")
        if version != STORE_VERSION:
            raise ValueError(f"{self.path}: not a denali capture store (attribute denali_store={version!r}, expected {STORE_VERSION})")
        missing = [a for a in (LOCATION, HISTOGRAM, *self.attrs.get("modalities", [])) if a not in self.group]
        if missing:
            raise ValueError(f"{self.path}: capture store lacks arrays {missing}")
        self.capture_set: CaptureSet = parse_set_name(self.attrs["set"])
        self._locations = np.asarray(self.group[LOCATION][:], dtype=np.int64)
        lengths = {a: self.group[a].shape[0] for a in (HISTOGRAM, *self.modalities)}
        bad = {a: n for a, n in lengths.items() if n != len(self._locations)}
        if bad:
            raise ValueError(f"{self.path}: arrays {bad} do not match {len(self._locations)} locations")
        self._position = {int(k): i for i, k in enumerate(self._locations)}

    def __repr__(self) -> str:
        return f"CaptureStore({str(self.path)!r}, set={self.name!r}, locations={len(self)}, modalities={list(self.modalities)})"

    def __len__(self) -> int:
        return len(self._locations)

    # -- description --------------------------------------------------------------

    @property
    def name(self) -> str:
        return self.capture_set.name

    @property
    def locations(self) -> np.ndarray:
        """Gantry location of every position, int64 (a copy)."""
        return self._locations.copy()

    @property
    def metadata(self) -> dict:
        """The capture's metadata record."""
        return self.attrs["metadata"]

    @property
    def sources(self) -> list[dict]:
        """Every raw file ingested: {path, modality, bytes, sha256}."""
        return self.attrs["sources"]

    @property
    def n_zones(self) -> int:
        return int(self.attrs["n_zones"])

    @property
    def repeats(self) -> int:
        return int(self.attrs["repeats"])

    @property
    def modalities(self) -> tuple[str, ...]:
        return tuple(self.attrs.get("modalities", ()))

    def index_of(self, location: int) -> int:
        """Store position of a gantry location."""
        try:
            return self._position[int(location)]
        except KeyError:
            raise KeyError(f"{self.path}: no gantry location {location} (store has {self._locations.tolist()})") from None

    def stored_bytes(self, array: str | None = None) -> int:
        """Bytes on disk of one array (chunks and metadata) or of the whole store."""
        root = self.path if array is None else self.path / array
        if array is not None and array not in self.group:
            raise KeyError(f"{self.path}: no array {array!r}")
        return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())

    # -- histograms ---------------------------------------------------------------

    @property
    def histograms(self) -> zarr.Array:
        """The (L, repeats, n, n, 128) int32 array, lazy (index it to read)."""
        return self.group[HISTOGRAM]

    def histogram(self, i: int) -> np.ndarray:
        """Histograms (repeats, n, n, 128) int32 at store position i."""
        return self.histograms[self._check_position(i)]

    def iter_histograms(self) -> Iterator[tuple[int, np.ndarray]]:
        """(gantry location, (repeats, n, n, 128) int32) in store order, one chunk at a time."""
        arr = self.histograms
        for i, k in enumerate(self._locations):
            yield int(k), arr[i]

    # -- frames -------------------------------------------------------------------

    def frames(self, modality: str) -> zarr.Array:
        """The (L, H, W[, 3]) array of one frame modality, lazy."""
        if modality not in self.modalities:
            raise KeyError(f"{self.path}: no {modality!r} frames (store has {list(self.modalities)})")
        return self.group[modality]

    def frame(self, modality: str, i: int) -> np.ndarray:
        """The frame of one modality at store position i (BGR uint8 or depth uint16)."""
        return self.frames(modality)[self._check_position(i)]

    def iter_frames(self, modality: str) -> Iterator[tuple[int, np.ndarray]]:
        """(gantry location, frame) of one modality in store order, one frame at a time."""
        arr = self.frames(modality)
        for i, k in enumerate(self._locations):
            yield int(k), arr[i]

    def _check_position(self, i: int) -> int:
        i = int(i)
        if not 0 <= i < len(self):
            raise IndexError(f"{self.path}: position {i} out of range 0..{len(self) - 1}")
        return i


def open_set(path: Path) -> CaptureStore:
    """Open a capture store for reading (see CaptureStore)."""
    return CaptureStore(path)
