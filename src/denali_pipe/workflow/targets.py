"""The paper's artefacts and the workflow's target file for each: the one
table that `rule all` builds (Snakefile) and `denali targets` lists."""

from __future__ import annotations

from typing import NamedTuple


class Target(NamedTuple):
    artefact: str  # the paper's name for it, or what it is where the paper has none
    what: str
    path: str  # relative to the working directory; `{object}`/`{size}`: one file per twin pair


TARGETS = (
    Target("Table 2", "model comparison: MLP, 1D CNN, 3D CNN, Transformer (random split)", "results/table2.csv"),
    Target("Table 4", "on-disk size per modality and resolution", "results/table4.csv"),
    Target("Table 5", "the 1D CNN under five train/test splits", "results/table5.csv"),
    Target("Table 6", "static AprilTag positions", "results/table6.csv"),
    Target("Table 7", "shape classification per condition", "results/table7.csv"),
    Target("Table 8", "size classification per condition", "results/table8.csv"),
    Target("Table 9", "localisation per condition", "results/table9.csv"),
    Target("Table 10", "parameters, FLOPs, training and inference cost", "results/table10.csv"),
    Target("Fig 9", "sim-to-real: RMSE against real samples per simulation fidelity", "results/fig9.png"),
    Target("Fig 10", "non-retroreflective objects", "results/fig10.png"),
    Target("Fig 11", "italic objects", "results/fig11.png"),
    Target("Fig 12", "AprilTag tracking", "results/fig12.png"),
    Target("Fig 13", "t-SNE of shape embeddings, 3x3", "results/fig13.png"),
    Target("Fig 14", "t-SNE of shape embeddings, 8x8", "results/fig14.png"),
    Target("Fig 16", "1D CNN localisation training curves", "results/fig16.png"),
    Target("Fig 17", "1D CNN shape training curves", "results/fig17.png"),
    Target("Fig 18", "real captures beside their digital twins", "results/fig18.png"),
    Target("jitter sweep", "metrics against timing jitter (paper Sec 5.2)", "results/jitter.png"),
    Target("speed vs accuracy", "training time against headline metric per model", "results/speed_vs_accuracy.png"),
    Target("render benchmark", "the twin's renderers, cost against fidelity", "results/render_benchmark.png"),
    Target("digital twins", "simulated transients per object and size", "results/twin/{object}_{size}.zarr"),
    Target("twin calibration", "zone footprints, time offset and lobe fitted to the training captures", "results/twin_calibration.png"),
    Target("calibrated twins", "simulated transients per object and size, calibrated", "results/twin_calibrated/{object}_{size}.zarr"),
    Target("sim-to-real transforms", "fitted scale, blur and noise", "results/transforms.json"),
    Target("stability", "every failure mode of the run's cells, sim-to-real fit and twin calibration", "results/stability.csv"),
    Target("sensor fit", "the TMF882x's pulse, timing, pile-up and crosstalk fitted to real raw histograms", "results/sensor_fit.json"),
    Target("sensor vs real", "the fitted sensor on real scenes it was not fitted to", "results/sensor_vs_real.csv"),
    Target("rig vs real", "the capture source's histograms beside real DENALI captures", "results/rig_vs_real.png"),
    Target("release networks", "the release's 15 trained generalisation networks scored on this run's captures", "results/release_models.csv"),
    Target("rig examples", "raw histograms beside their background", "results/rig_examples.png"),
    Target("tag detections", "detection and pose rates per lighting and tag", "results/calibration/detections.csv"),
    Target("capture index", "one row per capture", "results/index/captures.parquet"),
)


def target_files(twin_pairs: list[tuple[str, str]]) -> list[str]:
    """Every target file, per-twin patterns expanded over (object, size) pairs."""
    files = []
    for t in TARGETS:
        if "{object}" in t.path:
            files += [t.path.format(object=o, size=s) for o, s in twin_pairs]
        else:
            files.append(t.path)
    return files


def listing() -> str:
    """The table as text: artefact, target file, what it is."""
    width = max(len(t.artefact) for t in TARGETS)
    path_width = max(len(t.path) for t in TARGETS)
    return "\n".join(f"{t.artefact:<{width}}  {t.path:<{path_width}}  {t.what}" for t in TARGETS)
