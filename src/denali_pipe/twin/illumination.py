"""What lights the twin's wall (`twin.illumination`), and which renderer can
draw it. Kept free of heavy imports: the workflow checks its config with it
before it builds the DAG."""

from __future__ import annotations

# `spot`: the paper's one laser spot on the sensor's axis; `flood`: the
# sensor's VCSEL lighting its whole field of view (twin/layout.py, twin/analytic.py).
ILLUMINATIONS = ("spot", "flood")
# mitransient's NLOS integrator traces from one laser point (capture_type 1).
SPOT_ONLY_RENDERERS = ("mitransient",)


def check_illumination(illumination: str) -> None:
    if illumination not in ILLUMINATIONS:
        raise ValueError(f"unknown twin illumination {illumination!r}; expected one of {list(ILLUMINATIONS)}")


def check_renderer(renderer: str, illumination: str) -> None:
    """Raise ValueError, saying what to set, when `renderer` cannot draw `illumination`."""
    check_illumination(illumination)
    if renderer in SPOT_ONLY_RENDERERS and illumination != "spot":
        raise ValueError(f"twin.renderer {renderer} traces one laser spot: set twin.illumination: spot, or use renderer analytic for the {illumination}")
