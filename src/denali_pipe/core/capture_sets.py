"""Capture-set names (`<object>_<size>_<res>_<light>`) and which sets a config asks for."""

from __future__ import annotations

import re
from dataclasses import dataclass

from denali_pipe.core.geometry import RESOLUTIONS
from denali_pipe.core.objects import BACKGROUND_SIZE, BACKGROUNDS, ObjectSpec

LIGHTINGS = ("lighton", "lightoff")
FOLDER_SUFFIX = "_NLOSdata"
PICKLE_SUFFIX = "_short_NLOSdata.pkl"

_NAME = re.compile(r"^(?P<object>[A-Za-z0-9]+)_(?P<size>4inch|8inch)_(?P<res>3x3|8x8)_(?P<light>lighton|lightoff)$")


@dataclass(frozen=True, order=True)
class CaptureSet:
    object: str
    size: str
    resolution: str
    light: str

    @property
    def name(self) -> str:
        return f"{self.object}_{self.size}_{self.resolution}_{self.light}"

    @property
    def is_background(self) -> bool:
        return self.object in BACKGROUNDS

    @property
    def light_on(self) -> bool:
        return self.light == "lighton"

    @property
    def n_zones(self) -> int:
        return RESOLUTIONS[self.resolution]


def parse_set_name(name: str) -> CaptureSet:
    """`A_4inch_3x3_lighton` (optionally with the `_NLOSdata` suffix) -> CaptureSet."""
    stem = name.removesuffix(FOLDER_SUFFIX).removesuffix(PICKLE_SUFFIX)
    m = _NAME.fullmatch(stem)
    if m is None:
        raise ValueError(f"capture set name {name!r} does not parse: expected <object>_<4inch|8inch>_<3x3|8x8>_<lighton|lightoff>[_NLOSdata]")
    return CaptureSet(m["object"], m["size"], m["res"], m["light"])


def background_of(cs: CaptureSet) -> CaptureSet:
    """The mount-only (NOOBJECT) set captured at the same resolution and lighting."""
    return CaptureSet("NOOBJECT", BACKGROUND_SIZE, cs.resolution, cs.light)


def select_objects(catalogue: dict[str, ObjectSpec], selection: str | list[str]) -> list[ObjectSpec]:
    """The catalogue rows named by the config's `objects` key (`all` or a list)."""
    if selection == "all":
        return list(catalogue.values())
    missing = [n for n in selection if n not in catalogue]
    if missing:
        raise ValueError(f"config `objects` names {missing} that are not in the objects sheet")
    return [catalogue[n] for n in selection]


def expected_sets(catalogue: dict[str, ObjectSpec], config: dict) -> list[CaptureSet]:
    """Every capture set a config asks for, backgrounds included, sorted by name."""
    sets = []
    for res in config["resolutions"]:
        for light in config["lightings"]:
            sets += [CaptureSet(b, BACKGROUND_SIZE, res, light) for b in BACKGROUNDS]
            for spec in select_objects(catalogue, config["objects"]):
                sets += [CaptureSet(spec.name, s, res, light) for s in spec.sizes if s in config["sizes"]]
    return sorted(sets, key=lambda s: s.name)


def select_sets(sets: list[CaptureSet], selection: str | list[str]) -> list[CaptureSet]:
    """The configured `sets` that the config's `sets` key keeps: `all`, or the
    named ones. Each named set must be one the grid asks for, and each named
    object set's background must be named too (preprocessing subtracts it)."""
    if selection == "all":
        return list(sets)
    by_name = {s.name: s for s in sets}
    unknown = [n for n in selection if n not in by_name]
    if unknown:
        raise ValueError(f"config `sets` names {unknown}, which the grid (config `objects`, `sizes`, `resolutions`, `lightings`) does not ask for")
    chosen = [by_name[n] for n in sorted(set(selection))]
    lacking = sorted({background_of(s).name for s in chosen if not s.is_background} - set(selection))
    if lacking:
        raise ValueError(f"config `sets` names object sets without their background sets {lacking}, which preprocessing subtracts: name them too")
    return chosen
