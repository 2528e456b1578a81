"""Ingestion: one raw capture set -> its Zarr store (`io/store.py`) and its index rows.

Two sources, one result:
- a release-layout folder `<set>_NLOSdata/` (`ingest_release`): metadata.json,
  spad_histogram/NNN.npy and, where present, the four frame folders of PNGs;
- a raw capture pickle stream `<set>_short_NLOSdata.pkl` (`ingest_pickle`),
  read with the restricted unpickler of `io/pickle_stream.py`.
`ingest_set` dispatches on the path.

Every input is validated while it streams through: a background thread reads,
decodes and checks the next location while the current one is written, so at
most three locations are in memory whatever the set's size. Any problem
raises ValueError naming the file, the capture set and what was expected
versus found. The store is built under a temporary name and
published only when the whole set has passed, so a failed ingest leaves no
`<set>.zarr` and no temporary folder (an older store at `out` stays as it
was). Raw inputs are only ever opened for reading.

Conventions:
- Histograms are stored int32. Integer input must be non-negative and fit
  int32. Float input is accepted only when every value is finite,
  non-negative and integral (then cast); otherwise the error says which rule
  failed.
- Frames are decoded with OpenCV (`cv2.imdecode(..., IMREAD_UNCHANGED)` of
  the very bytes that are checksummed, identical to `cv2.imread`): RGB stays
  in OpenCV's BGR order, uint8 (H, W, 3); depth is uint16 (H, W) in mm. All
  frames of a modality must have the metadata's camera size (or the first
  frame's size when the metadata has none).
- Index rows: one per capture (location x repeat), in store order then
  repeat. Background sets (NOOBJECT, NOOBJECTMOUNT) have no catalogue row:
  their `class` is "none" and their `type` "background".
"""

from __future__ import annotations

import hashlib
import io
import json
import queue
import threading
from pathlib import Path
from typing import Any, Iterator, NamedTuple

import cv2
import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import LIGHTINGS, PICKLE_SUFFIX, CaptureSet, parse_set_name
from denali_pipe.core.objects import ObjectSpec
from denali_pipe.io.pickle_stream import CAMERA_RECORDS, iter_records
from denali_pipe.io.release import FRAME_DIRS, HISTOGRAM_DIR, METADATA_FILE, PUBLIC_LAYOUT, histogram_files, location_span
from denali_pipe.io.store import StoreWriter, frame_spec
from denali_pipe.io.tree import misnamed_reason

BACKGROUND_CLASS = "none"
BACKGROUND_TYPE = "background"
INDEX_COLUMNS = (
    "set", "object", "class", "type", "size", "resolution", "light",
    "location", "repeat", "gantry_row", "gantry_col", "total_counts",
)  # fmt: skip
_INT32_MAX = np.iinfo(np.int32).max
# metadata keys of the camera sizes: the rig's {width, height} records and the
# real capture script's realsense_configs
_RIG_CAMERA_KEYS = {"tracking": "tracking_camera", "colocated": "colocated_camera"}
_REALSENSE_KEYS = {"tracking": "tracking_realsense", "colocated": "colocated_realsense"}


# --- entry points -----------------------------------------------------------------------


def ingest_set(source: Path, out: Path, spec: ObjectSpec | None) -> pd.DataFrame:
    """Ingest one capture set from a release folder or a `.pkl` stream (by the path)."""
    source = Path(source)
    if not source.exists():
        raise FileNotFoundError(f"{source}: no such capture set folder or capture stream")
    if source.is_dir():
        return ingest_release(source, out, spec)
    if source.suffix == ".pkl":
        return ingest_pickle(source, out, spec)
    raise FileNotFoundError(f"{source}: neither a capture set folder nor a .pkl capture stream")


def ingest_release(set_dir: Path, out: Path, spec: ObjectSpec | None) -> pd.DataFrame:
    """Ingest a release-layout folder `<set>_NLOSdata/` into the store `out`
    (e.g. `results/store/<set>.zarr`). Returns the set's index rows.

    metadata.json, when present (the rig writes one; the public release has
    none), must list the set's `locations`, else the histogram files name
    them; spad_histogram/ must hold exactly one NNN.npy per listed location, and each frame folder that
    exists exactly one NNN.png per listed location (a frame folder that does
    not exist is a modality the set lacks). Nothing else in the folder (the
    rig's rig_truth.json, Snakemake's .snakemake_timestamp) is read or
    checksummed."""
    set_dir = Path(set_dir)
    cs = _parse_name(set_dir)
    _check_spec(cs, spec, set_dir)
    if not set_dir.is_dir():
        raise FileNotFoundError(f"{set_dir}: capture set {cs.name}: no such folder")
    root = set_dir.parent
    md_path = set_dir / METADATA_FILE
    if md_path.exists():
        md_bytes = _read(md_path, cs, "the set's metadata.json")
        try:
            metadata = json.loads(md_bytes)
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise ValueError(f"{md_path}: capture set {cs.name}: invalid JSON ({e})") from None
        md_sources = [(md_path.relative_to(root).as_posix(), "metadata", len(md_bytes), _sha256(md_bytes))]
    else:
        # The public release ships no metadata.json: its histogram files name the locations.
        files = histogram_files(set_dir)
        if not files:
            raise ValueError(f"{set_dir / HISTOGRAM_DIR}: capture set {cs.name}: no NNN.npy histogram file: a public-layout set holds {PUBLIC_LAYOUT}")
        metadata = {"locations": sorted(files)}
        md_sources = []
    meta = _Metadata.check(metadata, cs, md_path, require_locations=True)
    basis = f"{METADATA_FILE} lists" if md_sources else f"{HISTOGRAM_DIR}/ (which names the locations: no {METADATA_FILE}) holds"

    hist_paths = _listed_files(set_dir / HISTOGRAM_DIR, ".npy", meta.locations, cs, basis)
    frame_paths = {m: _listed_files(set_dir / m, ".png", meta.locations, cs, basis) for m in FRAME_DIRS if (set_dir / m).exists()}

    def locations() -> Iterator[_Location]:
        for k in meta.locations:
            path = hist_paths[k]
            data = _read(path, cs, f"location {k}'s histogram file")
            h = check_histogram(_load_npy(data, path, cs), f"{path}: capture set {cs.name}", cs, meta.repeats)
            meta.repeats = h.shape[0]  # without `samples` in the metadata, the first location decides
            sources = [(path.relative_to(root).as_posix(), "histogram", len(data), _sha256(data))]
            frames = {}
            for m, paths in frame_paths.items():
                fpath = paths[k]
                fdata = _read(fpath, cs, f"location {k}'s {m} frame")
                frames[m] = meta.check_frame(m, _decode_png(fdata, fpath, cs), f"{fpath}: capture set {cs.name}: {m} frame")
                sources.append((fpath.relative_to(root).as_posix(), m, len(fdata), _sha256(fdata)))
            yield _Location(k, h, frames, sources)

    return _write(out, cs, spec, meta, metadata, "release", md_sources, locations())


def ingest_pickle(pkl: Path, out: Path, spec: ObjectSpec | None) -> pd.DataFrame:
    """Ingest a raw capture stream `<set>_short_NLOSdata.pkl` into the store
    `out`. Returns the set's index rows.

    Record 0 is the metadata record; every further record is one location
    (`iter`, `histogram`, and the two RealSense dicts: `spad_realsense_data`
    -> colocated_*, `tracking_realsense_data` -> tracking_*). Locations are
    stored in stream order. If the metadata lists `locations`, the stream must
    hold exactly those."""
    pkl = Path(pkl)
    cs = _parse_name(pkl)
    _check_spec(cs, spec, pkl)
    if not pkl.is_file():
        raise FileNotFoundError(f"{pkl}: capture set {cs.name}: no such capture stream")
    nbytes, digest = _sha256_file(pkl)
    records = _records(pkl, cs)
    _, metadata = next(records)
    meta = _Metadata.check(metadata, cs, pkl, require_locations=False)
    listed = set(meta.locations) if meta.locations is not None else None

    def locations() -> Iterator[_Location]:
        seen: dict[int, int] = {}
        for index, rec in records:
            where = f"{pkl}: capture set {cs.name}: record {index}"
            k = int(rec["iter"])
            if k in seen:
                raise ValueError(f"{where}: duplicated location {k} (also record {seen[k]})")
            seen[k] = index
            _check_location(k, where)
            if listed is not None and k not in listed:
                raise ValueError(f"{where}: location {k} is not among the metadata's locations {sorted(listed)}")
            h = rec["histogram"]
            if not isinstance(h, np.ndarray):
                _not_array(h, where, "histogram")
            h = check_histogram(h, f"{where} (location {k}) histogram", cs, meta.repeats)
            meta.repeats = h.shape[0]
            frames = {}
            for key, cam in CAMERA_RECORDS.items():
                for kind, field in (("rgb", "aligned_rgb_image"), ("depth", "aligned_depth_image")):
                    m = f"{cam}_{kind}"
                    img = rec[key][field]
                    if not isinstance(img, np.ndarray):
                        _not_array(img, where, f"{key}.{field}")
                    frames[m] = meta.check_frame(m, img, f"{where} (location {k}) {key}.{field}")
            del rec
            yield _Location(k, h, frames, [])
        if not seen:
            raise ValueError(f"{pkl}: capture set {cs.name}: the stream holds a metadata record but no location records")
        if listed is not None and len(seen) != len(listed):
            missing = sorted(listed - set(seen))
            raise ValueError(f"{pkl}: capture set {cs.name}: missing location records {missing} (listed in the metadata record)")

    return _write(out, cs, spec, meta, metadata, "pickle", [(pkl.name, "pickle", nbytes, digest)], locations())


class _Location(NamedTuple):
    """One validated location, ready to store."""

    location: int
    histogram: np.ndarray  # (repeats, n, n, 128) int32
    frames: dict[str, np.ndarray]
    sources: list[tuple[str, str, int, str]]  # (path, modality, bytes, sha256) of the files read


def _write(out: Path, cs: CaptureSet, spec, meta: "_Metadata", metadata: dict, fmt: str, sources: list, items: Iterator[_Location]) -> pd.DataFrame:
    """Store validated locations (read and checked one location ahead in a
    background thread, so decoding overlaps writing) and return the index rows."""
    totals: list[np.ndarray] = []
    with StoreWriter(out, cs, repeats=meta.repeats, metadata=metadata, source_format=fmt) as w:
        for src in sources:
            w.add_source(*src)
        for loc in _in_background(items):
            for src in loc.sources:
                w.add_source(*src)
            w.write_location(loc.location, loc.histogram, loc.frames)
            totals.append(loc.histogram.sum(axis=(1, 2, 3), dtype=np.int64))
        locations = list(w.locations)
    return index_rows(cs, spec, locations, np.asarray(totals))


def _in_background(items: Iterator, depth: int = 1) -> Iterator:
    """Iterate `items` in a background thread, at most `depth` items ahead of
    the consumer (memory stays bounded); the producer's exceptions are raised
    in the consumer, in order. Leaving the loop early stops the producer."""
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def put(entry) -> bool:
        while not stop.is_set():
            try:
                q.put(entry, timeout=0.05)
                return True
            except queue.Full:
                pass
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put((True, item)):
                    return
            put((True, done))
        except BaseException as e:  # noqa: BLE001 -- handed to the consumer
            put((False, e))
        finally:
            close = getattr(items, "close", None)
            if close is not None:
                close()

    thread = threading.Thread(target=produce, name="ingest-reader", daemon=True)
    thread.start()
    try:
        while True:
            ok, item = q.get()
            if not ok:
                raise item
            if item is done:
                return
            yield item
    finally:
        stop.set()
        thread.join()


# --- index rows -------------------------------------------------------------------------


def index_rows(cs: CaptureSet, spec: ObjectSpec | None, locations: list[int], totals: np.ndarray) -> pd.DataFrame:
    """The index of one set: a row per (location, repeat) in store order.
    `totals` is (L, repeats) int64: the sum of each repeat's histogram."""
    locations = np.asarray(locations, dtype=np.int64)
    totals = np.asarray(totals, dtype=np.int64)
    n_loc, repeats = totals.shape
    loc = np.repeat(locations, repeats)
    row, col = geo.gantry_row_col(loc)
    n = len(loc)
    return pd.DataFrame(
        {
            "set": [cs.name] * n,
            "object": [cs.object] * n,
            "class": [BACKGROUND_CLASS if spec is None else spec.cls] * n,
            "type": [BACKGROUND_TYPE if spec is None else spec.type] * n,
            "size": [cs.size] * n,
            "resolution": [cs.resolution] * n,
            "light": [cs.light] * n,
            "location": loc,
            "repeat": np.tile(np.arange(repeats, dtype=np.int64), n_loc),
            "gantry_row": np.asarray(row, dtype=np.int64),
            "gantry_col": np.asarray(col, dtype=np.int64),
            "total_counts": totals.reshape(-1),
        },
        columns=list(INDEX_COLUMNS),
    )


# --- validation -------------------------------------------------------------------------


def check_histogram(h: np.ndarray, where: str, cs: CaptureSet, repeats: int | None) -> np.ndarray:
    """One location's histograms as int32 (repeats, n, n, 128), or ValueError
    prefixed by `where` (which names the file and the set)."""
    n = cs.n_zones
    expected = f"(repeats, {n}, {n}, {geo.N_BINS}) for a {cs.resolution} set"
    if h.dtype.kind not in "iuf":
        raise ValueError(f"{where}: expected integer counts, found dtype {h.dtype}")
    if h.ndim != 4 or h.shape[1:] != (n, n, geo.N_BINS):
        raise ValueError(f"{where}: expected shape {expected}, found {h.shape}")
    if repeats is not None and h.shape[0] != repeats:
        raise ValueError(f"{where}: expected {repeats} repeats (shape ({repeats}, {n}, {n}, {geo.N_BINS})), found shape {h.shape}")
    if h.dtype.kind == "f":
        bad = ~np.isfinite(h)
        if bad.any():
            n_nan = int(np.isnan(h).sum())
            raise ValueError(
                f"{where}: float counts with {n_nan} NaN and {int(bad.sum()) - n_nan} infinite values; expected finite, non-negative, integral counts"
            )
    neg = h < 0
    if neg.any():
        raise ValueError(f"{where}: {int(neg.sum())} negative counts (minimum {h.min()}); expected counts >= 0")
    if h.dtype.kind == "f" and not np.array_equal(h, np.floor(h)):
        raise ValueError(f"{where}: float counts that are not integral (e.g. {float(h[h != np.floor(h)].flat[0])}); expected whole counts")
    if h.size and h.max() > _INT32_MAX:
        raise ValueError(f"{where}: counts up to {h.max()} exceed int32 (max {_INT32_MAX})")
    return h.astype(np.int32, copy=False)


class _Metadata:
    """What ingestion needs from a metadata record, checked against the set name."""

    def __init__(self, locations, repeats, frame_shapes, where):
        self.locations: list[int] | None = locations
        self.repeats: int | None = repeats
        self.frame_shapes: dict[str, tuple[int, int]] = frame_shapes  # modality -> (H, W)
        self.where = where
        self._first: dict[str, str] = {}  # modality -> the frame whose size set frame_shapes

    @classmethod
    def check(cls, md: Any, cs: CaptureSet, path: Path, require_locations: bool) -> "_Metadata":
        where = f"{path}: capture set {cs.name}: metadata"
        if not isinstance(md, dict):
            raise ValueError(f"{where}: expected a JSON object / dict, found {type(md).__name__}")
        _check_consistent(md, cs, where)
        locations = md.get("locations")
        if locations is None:
            if require_locations:
                raise ValueError(f"{where}: no `locations` list (expected the gantry locations captured, e.g. [0, 1, ..., 99])")
        else:
            if not isinstance(locations, list) or not locations or not all(_is_int(k) for k in locations):
                raise ValueError(f"{where}: `locations` must be a non-empty list of integers, found {locations!r:.80}")
            locations = [int(k) for k in locations]
            dups = sorted({k for k in locations if locations.count(k) > 1})
            if dups:
                raise ValueError(f"{where}: duplicated location(s) {dups} in `locations`")
            for k in locations:
                _check_location(k, where)
        repeats = md.get("samples", md.get("samples_per_capture"))
        if repeats is not None and (not _is_int(repeats) or int(repeats) < 1):
            raise ValueError(f"{where}: `samples` must be a positive integer, found {repeats!r}")
        return cls(locations, None if repeats is None else int(repeats), _frame_shapes(md, where), where)

    def check_frame(self, modality: str, img: np.ndarray, prefix: str) -> np.ndarray:
        """`img` if it has the modality's dtype, channels and size; else ValueError
        starting with `prefix` (which names the file, the set and the frame)."""
        dtype, channels = frame_spec(modality)
        layout = "(H, W, 3) BGR" if channels else "(H, W)"
        if img.dtype != dtype or img.ndim != (3 if channels else 2) or (channels and img.shape[2] != channels):
            raise ValueError(f"{prefix}: expected a {layout} {dtype} image, found shape {img.shape} dtype {img.dtype}")
        hw = tuple(img.shape[:2])
        if modality not in self.frame_shapes:
            self.frame_shapes[modality] = hw  # no camera size in the metadata: the first frame decides
            self._first[modality] = prefix
        want = self.frame_shapes[modality]
        if hw != want:
            source = self._first.get(modality)
            basis = f"the first frame's size ({source})" if source else "the metadata's camera size"
            raise ValueError(f"{prefix}: size {hw[1]}x{hw[0]} (WxH), expected {want[1]}x{want[0]}, {basis}")
        return img


def _check_consistent(md: dict, cs: CaptureSet, where: str) -> None:
    """Fields of the metadata that restate the set name must agree with it."""
    checks = []
    res = md.get("spad_res")
    by_map = {f"ID{fw.spad_map}": r for r, fw in geo.FIRMWARE.items()}  # the real script writes SPADID names
    if res in geo.RESOLUTIONS:
        checks.append(("spad_res", res, cs.resolution))
    elif res in by_map and by_map[res] != cs.resolution:
        raise ValueError(f"{where}: `spad_res` is {res!r} (the SPAD map of {by_map[res]}) but the set name says {cs.resolution!r}")
    light = md.get("light", md.get("light_mode"))
    if light in LIGHTINGS:
        checks.append(("light", light, cs.light))
    if "size" in md:
        checks.append(("size", md["size"], cs.size))
    obj = md.get("object")
    if obj is not None and obj not in (cs.object, cs.name, f"{cs.name}_short"):
        checks.append(("object", obj, cs.object))
    for key, found, expected in checks:
        if found != expected:
            raise ValueError(f"{where}: `{key}` is {found!r} but the set name says {expected!r}")


def _frame_shapes(md: dict, where: str) -> dict[str, tuple[int, int]]:
    """{modality: (H, W)} from the metadata's camera records, where it has them."""
    shapes = {}
    for cam in ("tracking", "colocated"):
        rig = md.get(_RIG_CAMERA_KEYS[cam])
        configs = md.get("realsense_configs")
        rs = configs.get(_REALSENSE_KEYS[cam]) if isinstance(configs, dict) else None
        wh = None
        if isinstance(rig, dict) and "width" in rig and "height" in rig:
            wh = rig["width"], rig["height"]
        elif isinstance(rs, dict) and "color_width" in rs and "color_height" in rs:
            wh = rs["color_width"], rs["color_height"]  # depth is aligned to the colour frame
        if wh is not None:
            if not all(_is_int(v) and int(v) > 0 for v in wh):
                raise ValueError(f"{where}: {cam} camera size must be positive integers, found {wh!r}")
            for kind in ("rgb", "depth"):
                shapes[f"{cam}_{kind}"] = (int(wh[1]), int(wh[0]))
    return shapes


def _check_spec(cs: CaptureSet, spec: ObjectSpec | None, source: Path) -> None:
    if cs.is_background:
        if spec is not None:
            raise ValueError(f"{source}: capture set {cs.name} is a background set, but an object spec ({spec.name}) was given")
        return
    if spec is None:
        raise ValueError(f"{source}: capture set {cs.name}: an object spec for {cs.object!r} is required (none given)")
    if spec.name != cs.object:
        raise ValueError(f"{source}: capture set {cs.name}: object spec is for {spec.name!r}, expected {cs.object!r}")
    if cs.size not in spec.sizes:
        raise ValueError(f"{source}: capture set {cs.name}: object {spec.name!r} has sizes {list(spec.sizes)}, not {cs.size}")


def _parse_name(source: Path) -> CaptureSet:
    try:
        return parse_set_name(source.name)
    except ValueError as e:
        kind = "capture stream" if source.suffix == ".pkl" else "capture set folder"
        hint = f" (expected <set>{PICKLE_SUFFIX})" if source.suffix == ".pkl" else ""
        # a set named in another spelling (the capture script's _short suffix, ...) is told which
        raise ValueError(f"{source}: {kind} name does not parse{hint}: {misnamed_reason(source) or e}") from None


def _check_location(k: int, where: str) -> None:
    if not 0 <= k < geo.N_LOCATIONS:
        raise ValueError(f"{where}: gantry location {k} out of range 0..{geo.N_LOCATIONS - 1}")


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _not_array(obj: Any, where: str, field: str):
    raise ValueError(f"{where}: `{field}` is a {type(obj).__name__}, expected a numpy array")


def _listed_files(folder: Path, ext: str, locations: list[int], cs: CaptureSet, basis: str) -> dict[int, Path]:
    """{location: folder/NNN<ext>} for every listed location; ValueError for a
    missing file or a file of a location not listed. `basis` says what lists
    the locations (metadata.json, or spad_histogram/ where there is none), and
    each message says what `folder` holds beside it."""
    if not folder.is_dir():
        raise ValueError(f"{folder}: capture set {cs.name}: expected a folder of NNN{ext} files, found {'a file' if folder.exists() else 'nothing'}")
    found = {}
    for p in folder.iterdir():
        stem = p.name[: -len(ext)] if p.name.endswith(ext) else None
        if stem is None or len(stem) != 3 or not stem.isdigit():
            raise ValueError(f"{p}: capture set {cs.name}: unexpected file in {folder.name}/ (expected NNN{ext})")
        found[int(stem)] = p
    holds = f"{folder.name}/ holds {len(found)} location(s) ({location_span(found)}), {basis} {len(locations)} ({location_span(locations)})"
    missing = [k for k in locations if k not in found]
    if missing:
        names = ", ".join(f"{folder / f'{k:03d}{ext}'}" for k in missing[:5])
        raise ValueError(f"{names}: capture set {cs.name}: missing location file(s) for location(s) {missing}: {holds}")
    extra = sorted(set(found) - set(locations))
    if extra:
        raise ValueError(f"{found[extra[0]]}: capture set {cs.name}: location(s) {extra} in {folder.name}/ are not among the set's locations: {holds}")
    return {k: found[k] for k in locations}


# --- reading --------------------------------------------------------------------------------


def _records(pkl: Path, cs: CaptureSet) -> Iterator[tuple[int, dict]]:
    """`iter_records`, with the capture set named in its errors (same exception types)."""
    it = iter_records(pkl)
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except ValueError as e:
            msg = str(e)
            if msg.startswith(f"{pkl}: ") and "capture set" not in msg:
                raise type(e)(msg.replace(f"{pkl}: ", f"{pkl}: capture set {cs.name}: ", 1)) from None
            raise
        yield item


def _read(path: Path, cs: CaptureSet, what: str) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise ValueError(f"{path}: capture set {cs.name}: missing {what}") from None
    except OSError as e:
        raise ValueError(f"{path}: capture set {cs.name}: cannot read {what} ({e})") from None


def _load_npy(data: bytes, path: Path, cs: CaptureSet) -> np.ndarray:
    try:
        return np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as e:
        raise ValueError(f"{path}: capture set {cs.name}: truncated or unreadable .npy ({len(data)} bytes: {e})") from None


def _decode_png(data: bytes, path: Path, cs: CaptureSet) -> np.ndarray:
    img = None
    if data:
        try:
            img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        except cv2.error:
            img = None
    if img is None:
        raise ValueError(f"{path}: capture set {cs.name}: unreadable PNG ({len(data)} bytes; truncated or not an image)")
    return img


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _sha256_file(path: Path, block: int = 1 << 20) -> tuple[int, str]:
    h, n = hashlib.sha256(), 0
    with open(path, "rb") as f:
        while chunk := f.read(block):
            h.update(chunk)
            n += len(chunk)
    return n, h.hexdigest()
