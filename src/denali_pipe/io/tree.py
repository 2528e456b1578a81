"""A capture tree (config `raw_dir`) against the configured grid: the capture
sets it holds, those it lacks, entries whose names are not read, and each
release set's gantry locations (the NNN files of its folders).

Only directory listings are read, never file contents, so a survey of the
96.5 GB release takes seconds; ingest validates every file of a set later.

Folder names. The release names a set's folder `<set>_NLOSdata`; the capture
script names its output `<set>_short_NLOSdata` (its range-mode suffix). A
`_short` folder is refused with the rename that makes it read, rather than
read under either name: a set then has one name in the tree, the stores and
every provenance record, and a tree holding both spellings of one set cannot
be ambiguous. A `_long` entry is the sensor's long-range mode (the driver's
260 ps bins against short range's 100 ps): not the benchmark's captures, and
not read. Raw capture streams (`source: pickle`) keep the script's
`<set>_short_NLOSdata.pkl`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, CaptureSet, background_of, parse_set_name
from denali_pipe.core.geometry import N_LOCATIONS
from denali_pipe.io.release import FRAME_DIRS, HISTOGRAM_DIR, location_span

SOURCES = ("release", "pickle")
SUFFIX = {"release": FOLDER_SUFFIX, "pickle": PICKLE_SUFFIX}
_STREAM = ".pkl"
# Archives a download may leave packed beside (or instead of) a set's folder.
_ARCHIVES = (".zip", ".tar", ".tar.gz", ".tgz")
_SHORT, _LONG = "_short", "_long"
# How many names a one-screen message lists before it says how many more.
_SHOWN = 12


@dataclass(frozen=True)
class Misnamed:
    """An entry of the tree that names a capture set in a spelling the pipeline does not read."""

    name: str
    reason: str


@dataclass(frozen=True)
class SetFiles:
    """The NNN files of one release set folder, by name only."""

    histograms: frozenset[int] | None  # spad_histogram/NNN.npy; None: no spad_histogram/ folder
    frames: dict[str, frozenset[int]]  # each frame folder present -> its NNN.png
    unexpected: tuple[str, ...]  # files in those folders that are not NNN.npy / NNN.png


def set_files(set_dir: Path) -> SetFiles:
    """List a release set folder's spad_histogram/ and frame folders."""
    set_dir = Path(set_dir)
    unexpected: list[str] = []

    def numbered(folder: Path, ext: str) -> frozenset[int]:
        locs = set()
        for p in folder.iterdir():
            stem = p.name.removesuffix(ext)
            if p.name.endswith(ext) and len(stem) == 3 and stem.isdigit():
                locs.add(int(stem))
            else:
                unexpected.append(f"{folder.name}/{p.name}")
        return frozenset(locs)

    hist_dir = set_dir / HISTOGRAM_DIR
    histograms = numbered(hist_dir, ".npy") if hist_dir.is_dir() else None
    frames = {m: numbered(set_dir / m, ".png") for m in FRAME_DIRS if (set_dir / m).is_dir()}
    return SetFiles(histograms, frames, tuple(sorted(unexpected)))


@dataclass
class TreeSurvey:
    """What a capture tree holds against the configured capture sets."""

    raw_dir: Path
    source: str
    configured: list[CaptureSet]
    found: dict[str, Path]  # configured set name -> its folder (release) or stream (pickle)
    misnamed: list[Misnamed]
    unconfigured: list[str]  # well-named sets the config does not ask for
    other: list[str]  # entries that name no capture set
    files: dict[str, SetFiles]  # release: each found set's NNN files
    elsewhere: list[Path]  # where set folders lie one or two levels down, when none lie here

    @property
    def missing(self) -> list[str]:
        return [s.name for s in self.configured if s.name not in self.found]

    @property
    def locations(self) -> frozenset[int]:
        """Every gantry location some found set's spad_histogram/ holds: the
        tree's grid, which each set must hold (the full 100 in the release)."""
        return frozenset().union(*(f.histograms or frozenset() for f in self.files.values()))

    def set_problems(self) -> dict[str, list[str]]:
        """{found set: what its folders lack or hold beyond the tree's grid, or disagree on}."""
        grid = self.locations
        frame_dirs = sorted({m for f in self.files.values() for m in f.frames})
        problems: dict[str, list[str]] = {}
        for name, f in self.files.items():
            out = []
            if f.histograms is None:
                out.append(f"no {HISTOGRAM_DIR}/ folder")
            elif not f.histograms:
                out.append(f"{HISTOGRAM_DIR}/ holds no NNN.npy file")
            else:
                lacks = grid - f.histograms
                if lacks:
                    out.append(
                        f"{HISTOGRAM_DIR}/ lacks location(s) {location_span(lacks)}: it holds {len(f.histograms)} "
                        f"({location_span(f.histograms)}) of the {len(grid)} locations of the tree's other sets"
                    )
            for m in frame_dirs:
                if m not in f.frames:
                    out.append(f"no {m}/ folder (other sets of the tree have one)")
                elif f.histograms:
                    if f.histograms - f.frames[m]:
                        out.append(f"{m}/ lacks location(s) {location_span(f.histograms - f.frames[m])} that {HISTOGRAM_DIR}/ holds")
                    if f.frames[m] - f.histograms:
                        out.append(f"{m}/ holds location(s) {location_span(f.frames[m] - f.histograms)} that {HISTOGRAM_DIR}/ lacks")
            if f.unexpected:
                out.append(f"files that are not NNN.npy / NNN.png: {_names(f.unexpected)}")
            if out:
                problems[name] = out
        return problems

    def grid_note(self) -> str | None:
        """A line when the tree's sets all hold fewer locations than the gantry
        grid (consistent, so readable, but not the release's 100)."""
        grid = self.locations
        if self.files and grid and len(grid) < N_LOCATIONS:
            return f"{self.raw_dir}: its capture sets hold {len(grid)} of the gantry grid's {N_LOCATIONS} locations ({location_span(grid)})"
        return None

    @property
    def complete(self) -> bool:
        return not self.missing and not self.set_problems()

    def refusal(self, named: bool) -> str | None:
        """Why the workflow must not run on this tree (None: it holds every
        configured set whole). `named`: the config names the sets to use."""
        if self.complete:
            return None
        problems = self.set_problems()
        what = "the capture sets named in config `sets`" if named else "the benchmark the config asks for"
        lines = [
            f"source {self.source}: the capture tree {self.raw_dir} does not hold {what} ({len(self.found)} of {len(self.configured)} capture sets found):"
        ]
        if self.missing:
            lines.append(f"  missing ({len(self.missing)}): {_names(self.missing)}")
        lines += [f"  misnamed, not read: {m.name}: {m.reason}" for m in self.misnamed[:_SHOWN]]
        lines += [f"  {name}: {'; '.join(p)}" for name, p in list(problems.items())[:_SHOWN]]
        if len(problems) > _SHOWN:
            lines.append(f"  ... and {len(problems) - _SHOWN} more sets with gaps")
        lines += [f"  capture sets lie in {p}: point raw_dir there" for p in self.elsewhere]
        lines.append(f"`denali check-release {self.raw_dir}` with this run's --configfile lists every set.")
        if named:
            lines.append("To proceed: complete these sets in the tree, or take them out of config `sets`.")
        else:
            lines.append(
                "To proceed: complete the tree; or name the sets to use in config `sets` "
                "(`denali check-release --write-sets FILE` writes the complete ones found as a config file to add); "
                "or narrow config `objects`, `sizes`, `resolutions` or `lightings`."
            )
        return "\n".join(lines)

    def usable(self) -> list[str]:
        """The configured sets found whole (every object set with its background found whole too)."""
        whole = {n for n in self.found if n not in self.set_problems()}
        return [s.name for s in self.configured if s.name in whole and (s.is_background or background_of(s).name in whole)]

    def listing(self) -> str:
        """The whole survey, one line per configured set, for `denali check-release`."""
        problems = self.set_problems()
        lines = [f"capture tree {self.raw_dir} (source {self.source}): {len(self.configured)} capture sets configured"]
        lines.append(f"found ({len(self.found)}):")
        for s in self.configured:
            if s.name not in self.found:
                continue
            f = self.files.get(s.name)
            detail = ""
            if f is not None and f.histograms is not None:
                detail = f"{HISTOGRAM_DIR} {len(f.histograms):3d} ({location_span(f.histograms)})"
                detail += "".join(f"  {m} {len(locs)}" for m, locs in f.frames.items())
            flag = "  GAPS: " + "; ".join(problems[s.name]) if s.name in problems else ""
            lines.append(f"  {s.name:<40s} {detail}{flag}")
        lines.append(f"missing ({len(self.missing)}):")
        lines += [f"  {n}" for n in self.missing]
        lines.append(f"misnamed, not read ({len(self.misnamed)}):")
        lines += [f"  {m.name}: {m.reason}" for m in self.misnamed]
        lines.append(f"well-named but not configured, not read ({len(self.unconfigured)}): {_names(self.unconfigured, len(self.unconfigured))}")
        lines.append(f"other entries, not read ({len(self.other)}): {_names(self.other)}")
        lines += [f"capture sets lie in {p}: point raw_dir there" for p in self.elsewhere]
        if self.source == "release" and self.files:
            lines.append(self.grid_note() or f"locations: every set holds the gantry grid's {N_LOCATIONS} ({location_span(range(N_LOCATIONS))})")
        if self.complete:
            lines.append("complete: every configured set is here, whole")
        else:
            lines.append(f"incomplete: {len(self.missing)} missing, {len(problems)} with gaps; the workflow refuses to run on this tree as configured")
        return "\n".join(lines)


def survey_tree(raw_dir: Path, configured: list[CaptureSet], source: str) -> TreeSurvey:
    """Survey `raw_dir` (a release tree of `<set>_NLOSdata/` folders, or a
    folder of `<set>_short_NLOSdata.pkl` streams) for the `configured` sets."""
    if source not in SOURCES:
        raise ValueError(f"source {source!r}: a capture tree is surveyed for the sources {list(SOURCES)}")
    raw_dir = Path(raw_dir)
    if not raw_dir.is_dir():
        raise FileNotFoundError(f"raw_dir {raw_dir}: no such folder (the capture tree of source {source})")
    names = {s.name for s in configured}
    by_casefold = {n.casefold(): n for n in names}
    found: dict[str, Path] = {}
    misnamed, unconfigured, other = [], [], []
    for entry in sorted(raw_dir.iterdir()):
        name = _well_named(entry, source)
        if name in names:
            found[name] = entry
        elif name is not None and name.casefold() in by_casefold:
            misnamed.append(Misnamed(entry.name, f"names are case-sensitive: expected {by_casefold[name.casefold()]}{SUFFIX[source]}"))
        elif name is not None:
            unconfigured.append(name)
        elif (m := _misnamed(entry, source, by_casefold)) is not None:
            misnamed.append(m)
        else:
            other.append(entry.name)
    files = {n: set_files(p) for n, p in found.items()} if source == "release" else {}
    elsewhere = [] if found or unconfigured else _set_folders_below(raw_dir, source)
    return TreeSurvey(raw_dir, source, list(configured), found, misnamed, unconfigured, other, files, elsewhere)


def _well_named(entry: Path, source: str) -> str | None:
    """The set an entry holds when named and shaped as `source` reads it."""
    suffix = SUFFIX[source]
    if not entry.name.endswith(suffix) or entry.is_dir() != (source == "release"):
        return None
    try:
        return parse_set_name(entry.name.removesuffix(suffix)).name
    except ValueError:
        return None


def _misnamed(entry: Path, source: str, by_casefold: dict[str, str]) -> Misnamed | None:
    """Why an entry that names a capture set in another spelling is not read;
    None for an entry that names none (or the other source's kind: a release
    tree may hold the capture streams beside its folders)."""
    archive = next((a for a in _ARCHIVES if entry.name.endswith(a)), "")
    if archive and source == "release" and not entry.is_dir():
        stem, _ = _split_range(entry.name.removesuffix(archive).removesuffix(FOLDER_SUFFIX))
        if _set_name(stem, by_casefold) is None:
            return None
        return Misnamed(entry.name, f"an archive, not a folder: unpack it in {entry.parent}")
    stream = entry.name.endswith(_STREAM)
    if stream != (source == "pickle") or entry.is_dir() == stream:
        return None
    stem = entry.name.removesuffix(_STREAM)
    has_suffix = stem.endswith(FOLDER_SUFFIX)
    stem, rng = _split_range(stem.removesuffix(FOLDER_SUFFIX))
    set_name = _set_name(stem, by_casefold)
    kind = "folder" if source == "release" else "stream"
    if set_name is None:
        if has_suffix:
            return Misnamed(entry.name, f"does not parse as a capture set {kind} <object>_<4inch|8inch>_<3x3|8x8>_<lighton|lightoff>{SUFFIX[source]}")
        return None
    expected = f"{set_name}{SUFFIX[source]}"
    if rng == _LONG:
        return Misnamed(
            entry.name, "a long-range capture (the sensor's long-range mode: 260 ps bins, not short range's 100 ps); the benchmark is short-range only"
        )
    if source == "release" and rng == _SHORT:
        return Misnamed(entry.name, f"the capture script's `_short` range suffix, which the release's folder names drop; rename it to {expected}")
    if set_name != stem:
        return Misnamed(entry.name, f"names are case-sensitive: expected {expected}")
    return Misnamed(entry.name, f"expected the {kind} name {expected}")


def _split_range(stem: str) -> tuple[str, str]:
    """(`stem` without its range-mode suffix, the suffix or "")."""
    rng = next((r for r in (_SHORT, _LONG) if stem.endswith(r)), "")
    return stem.removesuffix(rng), rng


def _set_name(stem: str, by_casefold: dict[str, str]) -> str | None:
    """The capture set `stem` names: a configured set's spelling first (any
    case), else the stem itself where it parses; None where it names none."""
    try:
        parsed = parse_set_name(stem).name
    except ValueError:
        parsed = None
    return by_casefold.get(stem.casefold(), parsed)


def misnamed_reason(path: Path) -> str | None:
    """Why a set folder or stream at `path` is not read, where its name
    spells a capture set in a way the pipeline does not read (None: it names none)."""
    path = Path(path)
    source = "pickle" if path.name.endswith(_STREAM) else "release"
    m = None if _well_named(path, source) else _misnamed(path, source, {})
    return None if m is None else m.reason


def _set_folders_below(raw_dir: Path, source: str) -> list[Path]:
    """Folders one or two levels below `raw_dir` that hold capture sets (a
    release unpacked as denali-data/data/...), when `raw_dir` itself holds none."""
    pattern = f"*{SUFFIX[source]}"
    below = {p.parent for depth in ("*", "*/*") for p in raw_dir.glob(f"{depth}/{pattern}") if _well_named(p, source)}
    return sorted(below)


def _names(names, shown: int = _SHOWN) -> str:
    names = list(names)
    if not names:
        return "none"
    more = f" ... and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more
