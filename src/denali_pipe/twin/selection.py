"""Which twins and captures the DAG asks for (used by rules/twin.smk)."""

from __future__ import annotations

from denali_pipe.core.capture_sets import CaptureSet, select_objects
from denali_pipe.core.objects import ObjectSpec
from denali_pipe.core.seeds import rng_for

# The resolution the DAG renders twins at: every reader of a twin (the sim-to-real
# fit, Figs 9 and 18, the explorer) reads the 3x3 zones, as the reference's
# twin models its 3x3 centre zone; render_twin draws any grid it is given.
RESOLUTION = "3x3"


def twin_pairs(catalogue: dict[str, ObjectSpec], config: dict) -> list[tuple[str, str]]:
    """(object name, size) of every configured object size: one twin job each
    (backgrounds have no object, so no twin)."""
    return [(spec.name, size) for spec in select_objects(catalogue, config["objects"]) for size in spec.sizes if size in config["sizes"]]


def fig18_sets(sets: list[CaptureSet], n: int, seed: int) -> list[CaptureSet]:
    """Up to `n` light-on 3x3 object sets drawn with `seed`, in name order.
    Raises ValueError when there is none."""
    lit = sorted((s for s in sets if not s.is_background and s.resolution == "3x3" and s.light_on), key=lambda s: s.name)
    if not lit:
        raise ValueError("Fig 18 needs light-on 3x3 capture sets (config `resolutions` and `lightings`)")
    picks = rng_for(seed, "fig18", "sets").choice(len(lit), size=min(n, len(lit)), replace=False)
    return [lit[i] for i in sorted(picks)]
