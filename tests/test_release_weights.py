"""`io/release_weights.py`: the release's network files from a local copy or
downloaded (here from file:// URLs), each checked against its pinned sha256;
a folder saying what is missing where neither works."""

from __future__ import annotations

import hashlib

import pytest
from conftest import REPO

from denali_pipe.io import release_weights as rw

RELEASE = REPO.parent / "shared" / "denali-release"


@pytest.fixture
def files(tmp_path, monkeypatch):
    """A two-file stand-in for the release (its sums pinned as RELEASE_FILES) in `tmp_path/src`."""
    src = tmp_path / "src"
    contents = {"split_checkpoints/preprocessing_manifest.json": b"{}", "checkpoints/italics_loc.pth": b"weights"}
    for name, data in contents.items():
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        (src / name).write_bytes(data)
    monkeypatch.setattr(rw, "RELEASE_FILES", {name: hashlib.sha256(data).hexdigest() for name, data in contents.items()})
    return src


def test_a_local_copy_is_checked_and_copied(files, tmp_path):
    status = rw.gather(tmp_path / "out", files, "file:///nowhere/{path}")
    assert status.available and status.source == f"folder {files}" and rw.WeightsStatus.read(tmp_path / "out") == status
    assert (tmp_path / "out/checkpoints/italics_loc.pth").read_bytes() == b"weights"


def test_a_download_at_the_pinned_commit_is_checked(files, tmp_path):
    files.rename(tmp_path / rw.RELEASE_COMMIT)  # served at <commit>/<path>, as the release repository serves it
    status = rw.gather(tmp_path / "out", tmp_path / "absent", f"file://{tmp_path}/{{commit}}/{{path}}")
    assert status.available and status.commit == rw.RELEASE_COMMIT
    assert (tmp_path / "out/split_checkpoints/preprocessing_manifest.json").read_bytes() == b"{}"


def test_a_file_that_is_not_the_releases_is_an_error_naming_it(files, tmp_path):
    (files / "checkpoints/italics_loc.pth").write_bytes(b"tampered")
    with pytest.raises(ValueError, match=r"checkpoints/italics_loc.pth: sha256 [0-9a-f]{64}, but the release's checkpoints/italics_loc.pth at 9e10832 has"):
        rw.gather(tmp_path / "out", files, None)
    with pytest.raises(ValueError, match=r"file://.*italics_loc.pth: sha256 .* not the release's file"):
        rw.gather(tmp_path / "out", None, f"file://{files}/{{path}}")
    assert not (tmp_path / "out").exists()  # nothing half-written


def test_a_local_copy_lacking_a_file_is_an_error(files, tmp_path):
    (files / "checkpoints/italics_loc.pth").unlink()
    with pytest.raises(ValueError, match="lacks checkpoints/italics_loc.pth"):
        rw.gather(tmp_path / "out", files, None)


def test_without_a_copy_or_a_download_the_folder_says_what_is_missing(files, tmp_path):
    off = rw.gather(tmp_path / "off", tmp_path / "absent", None)
    assert not off.available and off.missing == f"no local copy at {tmp_path / 'absent'}, and downloads are off (config release_models.download)"
    failed = rw.gather(tmp_path / "failed", None, f"file://{tmp_path}/gone/{{path}}")
    assert not failed.available and failed.missing.startswith("no local copy (config release_models.weights is null), and downloading file://")
    # what came before the failure is gone: the folder holds the status alone
    assert [p.name for p in (tmp_path / "failed").iterdir()] == [rw.STATUS]
    with pytest.raises(FileNotFoundError, match="not a folder of the release's weights"):
        rw.WeightsStatus.read(tmp_path)


@pytest.mark.skipif(not (RELEASE / "SHA256SUMS").is_file(), reason="needs ../shared/denali-release")
def test_the_pinned_sums_are_the_releases():
    listed = dict(reversed(line.split()) for line in (RELEASE / "SHA256SUMS").read_text().splitlines())
    assert listed == rw.RELEASE_FILES


def test_an_init_names_a_release_checkpoint():
    assert rw.release_checkpoint("release:checkpoints/nonrr_obj.pth") == "checkpoints/nonrr_obj.pth"
    for bad in ("checkpoints/nonrr_obj.pth", "release:checkpoints/other.pth", f"release:{rw.MANIFEST}"):
        with pytest.raises(ValueError, match="naming one of the release's checkpoints"):
            rw.release_checkpoint(bad)
