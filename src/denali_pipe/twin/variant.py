"""Import Mitsuba 3 with mitransient's plugins in a variant that has them.

mitransient registers its transient/NLOS plugins for the variant that is set
when it is first imported, and none in `scalar_*` variants, so a process
uses one vectorised variant: `llvm_ad_rgb` on CPU, `cuda_ad_rgb` on a GPU
(`mono` variants cost the same; `rgb` also serves the tracking-camera view).
"""

from __future__ import annotations

from types import ModuleType

from denali_pipe.twin.llvm import configure_llvm

VARIANTS = ("auto", "llvm_ad_rgb", "cuda_ad_rgb")


def resolve_variant(variant: str, cuda_available: bool) -> str:
    """The Mitsuba variant to set for config `variant`: `auto` is
    `cuda_ad_rgb` when drjit finds a CUDA device, else `llvm_ad_rgb`; a
    named variant is itself. ValueError for an unknown variant."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown Mitsuba variant {variant!r}; expected one of {list(VARIANTS)}")
    if variant == "auto":
        return "cuda_ad_rgb" if cuda_available else "llvm_ad_rgb"
    return variant


def load_mitsuba(variant: str = "auto") -> ModuleType:
    """Set the Mitsuba variant (`auto`: CUDA when drjit finds a GPU, else
    LLVM), import mitransient, and return the `mitsuba` module.

    Raises FileNotFoundError (from `llvm.configure_llvm`) when the LLVM
    backend is needed and no usable libLLVM is installed, ValueError for an
    unknown variant or when another variant is already set in this process."""
    resolve_variant(variant, cuda_available=False)  # an unknown variant fails before drjit loads
    try:
        configure_llvm()  # before drjit is imported: it reads the variable once
        llvm_error = None
    except FileNotFoundError as e:
        llvm_error = e
    import drjit as dr

    variant = resolve_variant(variant, dr.has_backend(dr.JitBackend.CUDA))
    if variant.startswith("llvm") and llvm_error is not None:
        raise llvm_error
    import mitsuba as mi

    current = mi.variant()
    if current is None:
        mi.set_variant(variant)
    elif current != variant:
        raise ValueError(f"Mitsuba variant {current} is already set in this process; the twin asked for {variant}")
    import mitransient  # noqa: F401 -- registers transient_nlos_path, nlos_capture_meter, transient_hdr_film

    return mi
