"""The DENALI release's 15 trained generalisation networks (its
`benchmark/generalization/`): which files they are, where they come from, and
that each is the file the release published.

`RELEASE_FILES` are the files' paths under the release's
`benchmark/generalization/` with their sha256 sums, at commit
`RELEASE_COMMIT` of the release repository (NikhilBehari/denali, MIT). `gather`
puts them in one folder, taken from a local copy of that folder (config
`release_models.weights`: offline machines, the tests) or else downloaded at
that commit (config `release_models.download`, from the URL template
`release_models.url`), checking each file's sha256 either way: a file that
is not the release's is an error naming it. Where neither is possible (no
such folder, downloads off, or the network unreachable), the folder holds
only `STATUS` saying what is missing, and what reads it says so in turn.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import urllib.error
import urllib.request
from dataclasses import asdict, dataclass
from pathlib import Path

from denali_pipe.core.atomic import atomic_dir

# The release repository's commit whose files the sums below are (its 9e10832, "Add light/dark theme toggle to GUI").
RELEASE_COMMIT = "9e1083293a4f6aac5e674c9bf0d948dc0697f8c3"
MANIFEST = "split_checkpoints/preprocessing_manifest.json"
RELEASE_FILES = {
    MANIFEST: "387e65e2bc16bc167679570bf09069cc40c66a5806ae2152f03985b31e9f1eba",
    "split_checkpoints/splits_loc_by_location.pth": "cd4a5e99417bfe87d03d8e270110880e6c4881ef6993b809de61a368eb12c1da",
    "split_checkpoints/splits_loc_by_object.pth": "57bb519f365c68441b97bdeb3cd9196464d3557801e1dc2ea2c5a9cc403a375c",
    "split_checkpoints/splits_loc_by_size.pth": "76c93e46151dbc96de787c4ddb2c00ac1a430ff4e3faccc58aee5f2f9a7c037b",
    "split_checkpoints/splits_loc_random_grouped.pth": "1593a30843ec15d29b36f99fac08b1a3f3053d04f542f0a7b25408f7653eae70",
    "split_checkpoints/splits_obj_by_location.pth": "e000c9aad011ed033025993430a8fedfaa55304f9b5f22ab848746e879d4cb3a",
    "split_checkpoints/splits_obj_by_size.pth": "4321f204d1c8d5ed8b87a5d015628c8adfd4af89f1e32f5f52baea11318d73ab",
    "split_checkpoints/splits_obj_random_grouped.pth": "3c9071242939162bece4601433a8260fdb79151f7c4f626d23f05e3945b3cc44",
    "split_checkpoints/splits_size_by_location.pth": "e377147f68ddb55b662cd2dc6886323da2d7991be06afd0d9ac3131ef6ed5c75",
    "split_checkpoints/splits_size_by_object.pth": "70adb26816646c930087d8d73f53f242e9f54e990298f0f3e2cef63f9e508f71",
    "split_checkpoints/splits_size_random_grouped.pth": "1b7e2304a03ffd81e79c96b8eaee33ddd5b57cabe8ebee658a36e39a8e70e2f6",
    "checkpoints/italics_loc.pth": "a86a6b07aae5f8e92cedc34c7c5fd5bfc60ea82906c0e782cd0a31a29f18f41b",
    "checkpoints/italics_obj.pth": "12b8fe1849ce51120b374ed982fc630e308c33913b5a5810b210f2c2764e46c4",
    "checkpoints/nonrr_loc.pth": "3ee5789985a742f96dcdfabeccb8d2bb71860899b5cdd327969ce06820ed3592",
    "checkpoints/nonrr_obj.pth": "6c17626bab1dce83e72655f60e110230b1838bc1a857617ba73dd0c2e67cd30b",
    "checkpoints/nonrr_size.pth": "19b73e59ed6f50fad23f86d2008b05b6911a7600529e651a72a2f13f8c3ebee4",
}
STATUS = "status.json"
# How a model's training settings name a release checkpoint to start from (config train.models.<name>.<task>.init).
INIT_PREFIX = "release:"
# Seconds a download may wait on the server: an offline machine fails at once, a stalled link within this.
DOWNLOAD_TIMEOUT_S = 60


@dataclass(frozen=True)
class WeightsStatus:
    """What a weights folder holds: `available` (every file of RELEASE_FILES,
    checked), where they came from or were looked for (`source`), and what is
    missing and why (`missing`, '' when available)."""

    available: bool
    source: str
    missing: str = ""
    commit: str = RELEASE_COMMIT

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1) + "\n"

    @classmethod
    def read(cls, folder: Path) -> WeightsStatus:
        """The status a `gather` wrote into `folder`; FileNotFoundError naming it when there is none."""
        path = Path(folder) / STATUS
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such file; {folder} is not a folder of the release's weights (`denali release-weights` writes one)")
        return cls(**json.loads(path.read_text()))


def release_checkpoint(init: str) -> str:
    """The checkpoint (a path of RELEASE_FILES) that `init` ('release:<path>')
    names; ValueError listing them when it names none."""
    name = init.removeprefix(INIT_PREFIX)
    if not init.startswith(INIT_PREFIX) or not name.endswith(".pth") or name not in RELEASE_FILES:
        checkpoints = ", ".join(n for n in RELEASE_FILES if n.endswith(".pth"))
        raise ValueError(f"init {init!r}: expected '{INIT_PREFIX}<file>' naming one of the release's checkpoints ({checkpoints})")
    return name


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def check_file(path: Path, name: str, where: str) -> None:
    """ValueError naming `where` (the file's origin) when `path`'s sha256 is not release file `name`'s."""
    got = sha256(path)
    if got != RELEASE_FILES[name]:
        raise ValueError(f"{where}: sha256 {got}, but the release's {name} at {RELEASE_COMMIT[:7]} has {RELEASE_FILES[name]}: not the release's file")


def _copy(folder: Path, dest: Path) -> None:
    missing = [name for name in RELEASE_FILES if not (folder / name).is_file()]
    if missing:
        raise ValueError(f"{folder}: lacks {', '.join(missing)} (a copy of the release's benchmark/generalization/ holds all {len(RELEASE_FILES)})")
    for name in RELEASE_FILES:
        check_file(folder / name, name, str(folder / name))
        (dest / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(folder / name, dest / name)


def _download(url: str, dest: Path) -> str:
    """Fetch every file from `url` (a template with {commit} and {path}) into
    `dest`; '' when all came, else why not (and `dest` left empty). A file
    that comes but is not the release's raises ValueError."""
    for name in RELEASE_FILES:
        src = url.format(commit=RELEASE_COMMIT, path=name)
        target = dest / name
        target.parent.mkdir(parents=True, exist_ok=True)
        try:
            with urllib.request.urlopen(src, timeout=DOWNLOAD_TIMEOUT_S) as response, open(target, "wb") as out:
                shutil.copyfileobj(response, out)
        except (urllib.error.URLError, OSError) as e:
            for part in {dest / n.split("/")[0] for n in RELEASE_FILES}:
                shutil.rmtree(part, ignore_errors=True)  # what came before, so that the folder holds the status alone
            return f"downloading {src} failed ({getattr(e, 'reason', e)})"
        check_file(target, name, src)
    return ""


def gather(dest: Path, folder: Path | None, url: str | None) -> WeightsStatus:
    """Fill `dest` (atomically) with the release's files and `STATUS`: from
    `folder` where it exists (ValueError naming it when it lacks a file or
    holds another file than the release's), else from `url` (a template with
    {commit} and {path}; None: no download). Returns the status written."""
    no_copy = "no local copy (config release_models.weights is null)" if folder is None else f"no local copy at {folder}"
    with atomic_dir(Path(dest)) as tmp:
        if folder is not None and Path(folder).is_dir():
            _copy(Path(folder), tmp)
            status = WeightsStatus(True, f"folder {folder}")
        elif url is None:
            status = WeightsStatus(False, "nowhere", f"{no_copy}, and downloads are off (config release_models.download)")
        else:
            why = _download(url, tmp)
            status = WeightsStatus(not why, f"download {url}", f"{no_copy}, and {why}" if why else "")
        (tmp / STATUS).write_text(status.to_json())
    return status
