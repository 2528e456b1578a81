"""envs/denali.yaml (the conda environment of the rules) pins exactly pyproject.toml's dependencies."""

from __future__ import annotations

import re
import tomllib

import yaml
from conftest import REPO


def _pyproject() -> dict:
    with open(REPO / "pyproject.toml", "rb") as f:
        return tomllib.load(f)


def _env() -> dict:
    with open(REPO / "envs" / "denali.yaml") as f:
        return yaml.safe_load(f)


def _pip_section(env: dict) -> list[str]:
    pips = [d["pip"] for d in env["dependencies"] if isinstance(d, dict) and "pip" in d]
    assert len(pips) == 1, "expected exactly one pip: section"
    return pips[0]


def _name(req: str) -> str:
    return re.split(r"[=<>!~\[; ]", req, maxsplit=1)[0].lower().replace("_", "-")


def test_pip_pins_equal_pyproject_dependencies():
    deps = _pyproject()["project"]["dependencies"]
    pins = _pip_section(_env())
    assert len(pins) == len(set(pins)), "duplicate pins in envs/denali.yaml"
    assert sorted(pins) == sorted(deps)


def test_every_pin_is_exact():
    for req in _pip_section(_env()):
        assert re.fullmatch(r"[A-Za-z0-9_.\-]+==[0-9][A-Za-z0-9.+\-]*", req), req
    for req in _pyproject()["project"]["dependencies"]:
        assert re.fullmatch(r"[A-Za-z0-9_.\-]+==[0-9][A-Za-z0-9.+\-]*", req), req


def test_no_package_pinned_twice_across_conda_and_pip():
    env = _env()
    conda = [d for d in env["dependencies"] if isinstance(d, str)]
    conda_names = {_name(d) for d in conda} - {"python", "pip"}
    assert not conda_names & {_name(p) for p in _pip_section(env)}


def test_python_version_matches_requires_python():
    env = _env()
    pythons = [d for d in env["dependencies"] if isinstance(d, str) and _name(d) == "python"]
    assert pythons == ["python=3.11"]
    assert _pyproject()["project"]["requires-python"] == ">=3.11,<3.12"


def test_pip_is_in_the_env():
    assert "pip" in _env()["dependencies"]
