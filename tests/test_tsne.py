"""Figs 13/14: the classes drawn, separability measured in the embedding,
and only samples the cell never trained on."""

import numpy as np
import pandas as pd
import pytest
import torch
from test_train import _cell, data  # noqa: F401 (the fixture)

from denali_pipe.experiments.tsne import N_CLASSES, pick_classes, run_tsne, separability, unseen_rows, write_tsne
from denali_pipe.train.training import Hyper, partition, run_cell, targets


def test_classes_are_drawn_with_the_seed_among_the_8in_lights_off_ones():
    samples = pd.DataFrame({"class": list("ABCDEF") + ["G"], "size": ["8inch"] * 6 + ["4inch"], "light": "lightoff"})
    picks = pick_classes(samples, 7)
    assert picks == pick_classes(samples, 7) and picks == sorted(picks) and len(picks) == N_CLASSES and "G" not in picks
    assert any(pick_classes(samples, s) != picks for s in range(8, 20))
    with pytest.raises(ValueError, match="needs 3 classes"):
        pick_classes(samples.iloc[:2], 7)


def test_separability_tells_clusters_from_a_cloud():
    rng = np.random.default_rng(0)
    labels = np.repeat(["a", "b", "c"], 12)
    clusters = rng.normal(size=(36, 8)) + 10 * np.repeat(np.eye(3, 8), 12, axis=0)
    apart = separability(clusters, labels, 1)
    assert apart["knn_accuracy"] == 1.0 and apart["silhouette"] > 0.5
    cloud = separability(rng.normal(size=(36, 8)), labels, 1)
    assert cloud["knn_accuracy"] < 0.7 and abs(cloud["silhouette"]) < 0.1
    with pytest.raises(ValueError, match="a class has 1 sample"):
        separability(clusters[:25], labels[:25], 1)


def test_run_tsne_scores_only_the_cells_test_samples(tmp_path, data):  # noqa: F811
    x, samples = data
    cell = _cell(task="shape")
    result = run_cell(
        x, samples, cell, Hyper(lr=3e-3, epochs=1, batch_size=64, norm="raw"), validation_fraction=0.2, factory=f"denali_pipe.train.models:{cell.model}"
    )
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text(result.metrics.to_json())
    torch.save(result.state, run / "model.pt")
    y, _ = targets(samples, "shape")
    split, val = partition(samples, y, cell, 0.2)
    rows = unseen_rows(samples, result.metrics, ["A", "B", "circle"])
    assert set(rows) <= set(split.test) and not set(rows) & (set(split.train) | set(val))
    assert set(samples.iloc[rows]["size"]) == {"8inch"} and set(samples.iloc[rows]["light"]) == {"lightoff"}

    table = run_tsne([run], x, samples, seed=3)
    points, seed, mean = (table[table["row"] == k] for k in ("point", "seed", "mean"))
    assert len(points) == len(rows) == seed["n_samples"].item() and set(points["class"]) == {"A", "B", "circle"}
    assert mean["n_seeds"].item() == 1 and mean["knn_accuracy_std"].item() == 0 and mean["chance"].item() == pytest.approx(1 / 3)
    assert mean["knn_accuracy"].item() == seed["knn_accuracy"].item() and set(table["resolution"]) == {"3x3"}
    write_tsne(table, "t-SNE", tmp_path / "fig13.png")
    assert (tmp_path / "fig13.png").stat().st_size > 10_000 and len(pd.read_csv(tmp_path / "fig13.csv")) == len(table)
