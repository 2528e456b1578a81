"""Finding a libLLVM that drjit can use, and the error when there is none."""

from __future__ import annotations

import subprocess
import sys

import pytest

from denali_pipe.twin.llvm import ENV, configure_llvm, find_libllvm, llvm_major


@pytest.mark.parametrize(
    "name,major",
    [("libLLVM.so.19.1", 19), ("libLLVM-19.so", 19), ("libLLVM-15.so.1", 15), ("libLLVM.so", None), ("/usr/lib/llvm-19/lib/libLLVM.so.19.1", 19)],
)
def test_llvm_major_from_file_name(name, major):
    assert llvm_major(name) == major


def test_finds_19_and_never_15(tmp_path):
    (tmp_path / "libLLVM-15.so.1").write_bytes(b"")
    assert find_libllvm([str(tmp_path / "libLLVM-15.so*")])[0] is None
    (tmp_path / "libLLVM.so.19.1").write_bytes(b"")
    path, tried = find_libllvm([str(tmp_path / "libLLVM-15.so*"), str(tmp_path / "libLLVM.so.19*")])
    assert path == str(tmp_path / "libLLVM.so.19.1")
    assert len(tried) == 2


def test_sets_the_variable_when_unset(tmp_path):
    lib = tmp_path / "libLLVM.so.19.1"
    lib.write_bytes(b"")
    env: dict[str, str] = {}
    assert configure_llvm(env, [str(tmp_path / "libLLVM.so.19*")]) == str(lib)
    assert env[ENV] == str(lib)


def test_honours_an_existing_variable(tmp_path):
    lib = tmp_path / "libLLVM-17.so"
    lib.write_bytes(b"")
    env = {ENV: str(lib)}
    assert configure_llvm(env, []) == str(lib)


@pytest.mark.parametrize("name,what", [("missing.so", "no such file"), ("libLLVM-15.so.1", "LLVM 15")])
def test_a_bad_variable_is_refused(tmp_path, name, what):
    if name != "missing.so":
        (tmp_path / name).write_bytes(b"")
    with pytest.raises(FileNotFoundError) as e:
        configure_llvm({ENV: str(tmp_path / name)}, [])
    assert what in str(e.value) and "apt-get install libllvm19" in str(e.value)


def test_nothing_found_says_what_was_tried_and_how_to_install(tmp_path):
    pattern = str(tmp_path / "libLLVM.so.19*")
    with pytest.raises(FileNotFoundError) as e:
        configure_llvm({}, [pattern])
    msg = str(e.value)
    assert pattern in msg and ENV in msg and "apt-get install libllvm19" in msg


def test_no_llvm_fails_cleanly_before_drjit_loads():
    """In a fresh process (drjit reads the variable once, at import): with the
    search finding nothing, asking for the CPU variant fails with the message,
    not with an LLVM abort."""
    code = (
        "import os; os.environ.pop('DRJIT_LIBLLVM_PATH', None)\n"
        "import denali_pipe.twin.llvm as llvm; llvm.CANDIDATES = ()\n"
        "from denali_pipe.twin.variant import load_mitsuba\n"
        "try:\n"
        "    load_mitsuba('llvm_ad_rgb')\n"
        "except FileNotFoundError as e:\n"
        "    print('ERROR:', e); raise SystemExit(3)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "apt-get install libllvm19" in proc.stdout and ENV in proc.stdout
