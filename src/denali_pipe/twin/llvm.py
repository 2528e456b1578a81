"""Point drjit at a libLLVM that can compile its CPU kernels.

drjit 1.5 emits an `fminimum` intrinsic that LLVM 15 cannot select on x86:
every `llvm_*` render then aborts the process with `LLVM ERROR: Cannot
select ... fminimum`. Debian 12's `libllvm19` works. drjit reads
DRJIT_LIBLLVM_PATH when it is imported, so `configure_llvm` must run before
the first `import drjit` (or `import mitsuba`) of the process.
"""

from __future__ import annotations

import glob
import os
import re
from typing import Iterable, MutableMapping

ENV = "DRJIT_LIBLLVM_PATH"
# Where Debian/Ubuntu put libLLVM 19 (the `libllvm19` package), most specific first.
CANDIDATES = (
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19*",
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so*",
    "/usr/lib/llvm-19/lib/libLLVM.so.19*",
    "/usr/lib/llvm-19/lib/libLLVM-19.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.19*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so*",
)
INSTALL_HINT = "install Debian's libLLVM 19 (`apt-get install libllvm19`, or `make setup`) or set DRJIT_LIBLLVM_PATH to a libLLVM 16 or newer"
# The major versions drjit 1.5 cannot use (see the module docstring).
BROKEN_MAJORS = (15,)

_MAJOR = re.compile(r"libLLVM(?:-(\d+)|\.so\.(\d+))")


def llvm_major(path: str) -> int | None:
    """The LLVM major version in a library file name (`libLLVM-15.so.1` -> 15,
    `libLLVM.so.19.1` -> 19), or None when the name does not say."""
    m = _MAJOR.search(os.path.basename(path))
    return int(m[1] or m[2]) if m else None


def find_libllvm(candidates: Iterable[str] | None = None) -> tuple[str | None, list[str]]:
    """The first existing file matching the glob patterns `candidates`
    (default CANDIDATES) whose name is not a known-broken LLVM; returns
    (path or None, patterns tried)."""
    tried = []
    for pattern in CANDIDATES if candidates is None else candidates:
        tried.append(pattern)
        for path in sorted(glob.glob(pattern)):
            if os.path.isfile(path) and llvm_major(path) not in BROKEN_MAJORS:
                return path, tried
    return None, tried


def configure_llvm(environ: MutableMapping[str, str] = os.environ, candidates: Iterable[str] | None = None) -> str:
    """Set DRJIT_LIBLLVM_PATH (honouring an existing value) and return it.

    Raises FileNotFoundError naming what was tried and how to install LLVM 19
    when no usable library is found (searching `candidates`, default
    CANDIDATES), or when DRJIT_LIBLLVM_PATH names a missing file or LLVM 15."""
    given = environ.get(ENV)
    if given:
        if not os.path.isfile(given):
            raise FileNotFoundError(f"{ENV}={given}: no such file; {INSTALL_HINT}")
        if llvm_major(given) in BROKEN_MAJORS:
            raise FileNotFoundError(f"{ENV}={given}: LLVM {llvm_major(given)} cannot compile drjit 1.5's kernels (`fminimum`); {INSTALL_HINT}")
        return given
    path, tried = find_libllvm(candidates)
    if path is None:
        raise FileNotFoundError(
            f"no usable libLLVM for drjit's CPU backend: {ENV} is unset and nothing matches {', '.join(tried) or '(no patterns)'}; {INSTALL_HINT}"
        )
    environ[ENV] = path
    return path
