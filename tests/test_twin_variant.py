"""Which Mitsuba variant the twin's renders use (`twin.variant`)."""

from __future__ import annotations

import pytest

from denali_pipe.twin.variant import resolve_variant


def test_auto_is_cuda_with_a_gpu_and_llvm_without():
    # drjit's CUDA check is passed in as a flag, so both branches run on a machine without a GPU
    assert resolve_variant("auto", cuda_available=True) == "cuda_ad_rgb"
    assert resolve_variant("auto", cuda_available=False) == "llvm_ad_rgb"


@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "cuda_ad_rgb"])
def test_a_named_variant_is_kept_whatever_the_machine(variant):
    assert resolve_variant(variant, cuda_available=True) == variant
    assert resolve_variant(variant, cuda_available=False) == variant


def test_an_unknown_variant_is_refused():
    with pytest.raises(ValueError, match="scalar_rgb"):
        resolve_variant("scalar_rgb", cuda_available=False)
