"""Which renderer draws which illumination, refused with what to set."""

import pytest

from denali_pipe.twin.illumination import check_illumination, check_renderer


def test_every_renderer_draws_the_spot_and_analytic_the_flood():
    for renderer in ("analytic", "mitransient"):
        check_renderer(renderer, "spot")
    check_renderer("analytic", "flood")


def test_mitransient_is_refused_the_flood_with_what_to_set():
    with pytest.raises(ValueError, match="twin.renderer mitransient traces one laser spot: set twin.illumination: spot"):
        check_renderer("mitransient", "flood")


def test_an_unknown_illumination_is_refused():
    with pytest.raises(ValueError, match="unknown twin illumination 'floods'"):
        check_illumination("floods")
