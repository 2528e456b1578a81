"""Atomic outputs (core/atomic.py): a killed writer's temporaries are cleared by the next write."""

from denali_pipe.core.atomic import atomic_dir, atomic_file

DEAD = 2**22 + 1  # above Linux's largest pid: no process has it


def test_the_next_write_clears_the_temporaries_of_dead_writers_only(tmp_path):
    out = tmp_path / "set.zarr"
    dead, dead_old, live = (tmp_path / f".set.zarr.{k}" for k in (f"tmp-{DEAD}", f"old-{DEAD}", "tmp-1"))
    for d in (dead, dead_old, live):
        d.mkdir()
        (d / "chunk").write_bytes(b"half")
    with atomic_dir(out) as tmp:
        (tmp / "chunk").write_bytes(b"whole")
    assert (out / "chunk").read_bytes() == b"whole"
    assert not dead.exists() and not dead_old.exists() and live.exists()  # pid 1 is alive: not ours to clear
    table, left = tmp_path / "index.parquet", tmp_path / f".index.parquet.tmp-{DEAD}"
    left.write_bytes(b"half")
    with atomic_file(table) as tmp:
        tmp.write_bytes(b"whole")
    assert table.read_bytes() == b"whole" and not left.exists()
