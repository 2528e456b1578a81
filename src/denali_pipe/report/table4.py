"""Table 4: on-disk size of the ingested captures per modality and resolution.

Sizes are measured from the Zarr stores: the bytes of every file under each
array's folder (chunks and array metadata), and for `metadata` the group's
own files (attributes: the capture's metadata record and source checksums).
The paper's published sizes of the real release stand in adjacent columns.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.core.atomic import atomic_file
from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.report.paper import TABLE4_GB

# Table 4's modality -> the store's array holding it ("metadata": the group itself)
MODALITY_ARRAYS = {
    "lidar_histograms": "histogram",
    "tracking_rgb": "tracking_rgb",
    "tracking_depth": "tracking_depth",
    "colocated_rgb": "colocated_rgb",
    "colocated_depth": "colocated_depth",
}
RESOLUTIONS = ("3x3", "8x8")


def _folder_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def store_sizes(store: Path) -> dict[str, int]:
    """Bytes on disk per Table 4 modality of one `<set>.zarr` store."""
    sizes = {m: _folder_bytes(store / a) for m, a in MODALITY_ARRAYS.items()}
    sizes["metadata"] = _folder_bytes(store) - sum(sizes.values())
    return sizes


def table4(stores: list[Path]) -> pd.DataFrame:
    """Rows: modalities then `total`; columns: GB and bytes per resolution and
    in total, then the paper's GB."""
    acc = {m: dict.fromkeys(RESOLUTIONS, 0) for m in TABLE4_GB}
    for store in stores:
        res = parse_set_name(store.name.removesuffix(".zarr")).resolution
        for m, b in store_sizes(store).items():
            acc[m][res] += b
    rows = []
    for m, by_res in acc.items():
        row = {"modality": m}
        for r in RESOLUTIONS:
            row[f"size_{r}_gb"] = by_res[r] / 1e9
        row["total_gb"] = sum(by_res.values()) / 1e9
        for r in RESOLUTIONS:
            row[f"size_{r}_bytes"] = by_res[r]
        row["total_bytes"] = sum(by_res.values())
        for r in RESOLUTIONS:
            row[f"paper_size_{r}_gb"] = TABLE4_GB[m][r]
        row["paper_total_gb"] = sum(TABLE4_GB[m].values())
        rows.append(row)
    df = pd.DataFrame(rows)
    total = df.drop(columns="modality").sum().to_dict()
    df = pd.concat([df, pd.DataFrame([{"modality": "total", **total}])], ignore_index=True)
    byte_cols = [c for c in df if c.endswith("_bytes")]
    return df.astype(dict.fromkeys(byte_cols, "int64"))


def write_table4(stores: list[Path], out: Path) -> None:
    df = table4(stores)
    with atomic_file(out) as tmp:
        df.to_csv(tmp, index=False, float_format="%.6g")
