import pandas as pd
import pytest

from denali_pipe.report.paper import TABLE4_GB
from denali_pipe.report.table4 import MODALITY_ARRAYS, store_sizes, table4


def fake_store(root, name, sizes):
    """A store folder whose arrays hold files of the given byte sizes."""
    store = root / f"{name}.zarr"
    store.mkdir()
    (store / "zarr.json").write_bytes(b"x" * sizes.pop("metadata"))
    for modality, n in sizes.items():
        arr = store / MODALITY_ARRAYS[modality]
        (arr / "c").mkdir(parents=True)
        (arr / "zarr.json").write_bytes(b"x" * 10)
        (arr / "c" / "0").write_bytes(b"x" * (n - 10))
    return store


def test_table4_sums_per_modality_and_resolution(tmp_path):
    sizes = {"lidar_histograms": 100, "tracking_rgb": 1000, "tracking_depth": 500, "colocated_rgb": 300, "colocated_depth": 200, "metadata": 42}
    stores = [
        fake_store(tmp_path, "A_4inch_3x3_lighton", dict(sizes)),
        fake_store(tmp_path, "A_8inch_3x3_lighton", dict(sizes)),
        fake_store(tmp_path, "NOOBJECT_8inch_8x8_lightoff", dict(sizes)),
    ]
    assert store_sizes(stores[0]) == sizes
    t = table4(stores).set_index("modality")
    for m, n in sizes.items():
        assert t.loc[m, "size_3x3_bytes"] == 2 * n and t.loc[m, "size_8x8_bytes"] == n
        assert t.loc[m, "total_gb"] == pytest.approx(3 * n / 1e9)
        assert t.loc[m, "paper_size_8x8_gb"] == TABLE4_GB[m]["8x8"]
    assert t.loc["total", "total_bytes"] == 3 * sum(sizes.values())
    assert t.loc["total", "paper_total_gb"] == pytest.approx(96.50, abs=0.01)
    assert pd.api.types.is_integer_dtype(t.total_bytes)
