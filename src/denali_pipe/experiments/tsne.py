"""Figs 13 and 14 (paper supplement §10): t-SNE of the trained shape
classifier's penultimate-layer embeddings (`evaluate.embed`: the 32 features
the 1D CNN's head reads) at 3x3 and 8x8, for three classes drawn at random
(seeded), 8 in objects, lights off; and how separable the classes are.

The paper judges separation by eye on the t-SNE plane, which distorts
distances by design. Here separability is measured in the embedding space
itself, two ways: k-NN accuracy under stratified cross-validation (can a
sample's class be told from its nearest neighbours? chance is 1 / 3) and the
silhouette (how much closer a sample lies to its own class than to the
nearest other; -1..1, 0 for overlapping classes).

Only samples a cell never trained on are used: its test split, rebuilt with
`train.partition` from the cell's seed, protocol and validation fraction, so
the embedding shows how the classifier generalises, not what it memorised.
Every cell (seed) gets its own panel and scores; the CSV gives them per seed
and as mean +- std over seeds.

The CSV is one long table; `row` says what a row holds:
- `point`: seed, class, set, location, repeat, tsne_1, tsne_2 (one sample);
- `seed`: seed, n_samples, knn_accuracy, silhouette (one cell);
- `mean`: n_seeds, knn_accuracy, knn_accuracy_std, silhouette,
  silhouette_std (ddof 1; 0 for one seed), chance (k-NN accuracy of guessing).
Every row names the resolution and the classes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.manifold import TSNE
from sklearn.metrics import silhouette_score
from sklearn.model_selection import StratifiedKFold, cross_val_score
from sklearn.neighbors import KNeighborsClassifier

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.core.seeds import derive_seed, rng_for
from denali_pipe.train.cell_metrics import METRICS_FILE, CellMetrics
from denali_pipe.train.evaluate import embed, load_cell
from denali_pipe.train.training import partition, targets

N_CLASSES = 3  # the paper's "three randomly selected object classes"
SIZE, LIGHT = "8inch", "lightoff"  # the paper's selection
NEIGHBOURS = 5  # k of the k-NN score
FOLDS = 5  # cross-validation folds of the k-NN score (fewer when a class has fewer samples)
PERPLEXITY = 30.0  # scikit-learn's default; capped at (n - 1) / 3 for small sets
COLUMNS = ("row", "resolution", "classes", "seed", "class", "set", "location", "repeat", "tsne_1", "tsne_2", "n_samples",
           "knn_accuracy", "knn_accuracy_std", "silhouette", "silhouette_std", "n_seeds", "chance")  # fmt: skip


def pick_classes(samples: pd.DataFrame, seed: int) -> list[str]:
    """N_CLASSES classes (ASCII order) drawn with `seed` from those with 8 in,
    lights-off samples; the same for every resolution that holds the same
    objects. ValueError if there are fewer."""
    classes = sorted(samples.loc[(samples["size"] == SIZE) & (samples["light"] == LIGHT), "class"].unique())
    if len(classes) < N_CLASSES:
        raise ValueError(f"t-SNE needs {N_CLASSES} classes with {SIZE} {LIGHT} samples; the dataset has {classes}")
    picks = rng_for(seed, "tsne", "classes").choice(len(classes), N_CLASSES, replace=False)
    return [classes[i] for i in sorted(picks)]


def unseen_rows(samples: pd.DataFrame, metrics: CellMetrics, classes: list[str]) -> np.ndarray:
    """Rows of `samples` (the dataset the shape cell trained on) in the
    cell's test split that are 8 in, lights off and of `classes`."""
    y, _ = targets(samples, "shape")
    split, _ = partition(samples, y, metrics.cell, metrics.validation_fraction)
    test = samples.iloc[split.test]
    keep = (test["size"] == SIZE) & (test["light"] == LIGHT) & test["class"].isin(classes)
    return split.test[keep.to_numpy()]


def separability(embedding: np.ndarray, labels: np.ndarray, seed: int) -> dict[str, float]:
    """k-NN accuracy (stratified `FOLDS`-fold cross-validation, folds
    shuffled with `seed`) and silhouette of `embedding` (n, D) with class
    labels (n,), Euclidean distances in the embedding space."""
    fewest = int(pd.Series(labels).value_counts().min())
    if fewest < 2:
        raise ValueError(f"a class has {fewest} sample(s); the k-NN score needs 2 per class")
    folds = StratifiedKFold(min(FOLDS, fewest), shuffle=True, random_state=seed % 2**32)
    smallest_fit = len(labels) - -(-len(labels) // folds.n_splits)  # samples the k-NN holds in its smallest fold
    knn = KNeighborsClassifier(n_neighbors=min(NEIGHBOURS, smallest_fit))
    return {
        "knn_accuracy": float(cross_val_score(knn, embedding, labels, cv=folds).mean()),
        "silhouette": float(silhouette_score(embedding, labels)),
    }


def run_tsne(run_dirs: list[Path], x: np.ndarray, samples: pd.DataFrame, seed: int) -> pd.DataFrame:
    """Embed, project and score the unseen 8 in lights-off samples of the
    picked classes for every shape cell in `run_dirs` (one resolution, the
    dataset x (N, n, n, T) with sample table `samples` they trained on);
    `seed` (the config's) draws the classes and seeds t-SNE and the folds.
    Returns the long table of the module docstring."""
    classes = pick_classes(samples, seed)
    cells = [(Path(d), CellMetrics.read(Path(d) / METRICS_FILE)) for d in run_dirs]
    resolutions = {m.cell.resolution for _, m in cells}
    if len(resolutions) != 1 or {m.cell.task for _, m in cells} != {"shape"}:
        raise ValueError(f"t-SNE takes shape cells of one resolution; got {[m.cell for _, m in cells]}")
    common = {"resolution": resolutions.pop(), "classes": " ".join(classes)}
    points, scores = [], []
    for run_dir, m in cells:
        picked = unseen_rows(samples, m, classes)
        emb = embed(load_cell(run_dir), x[picked])
        labels = samples["class"].to_numpy()[picked]
        s = derive_seed(seed, "tsne", m.cell.resolution, m.cell.seed)
        tsne = TSNE(2, perplexity=min(PERPLEXITY, (len(picked) - 1) / 3), init="pca", random_state=s % 2**32)
        xy = tsne.fit_transform(emb)
        table = samples.iloc[picked][["class", "set", "location", "repeat"]].reset_index(drop=True)
        points.append(table.assign(row="point", seed=m.cell.seed, tsne_1=xy[:, 0], tsne_2=xy[:, 1], **common))
        scores.append({"row": "seed", "seed": m.cell.seed, "n_samples": len(picked), **separability(emb, labels, s), **common})
    per_seed = pd.DataFrame(scores)
    mean = {"row": "mean", "n_seeds": len(per_seed), "chance": 1 / N_CLASSES, **common}
    for k in ("knn_accuracy", "silhouette"):
        mean[k] = float(per_seed[k].mean())
        mean[f"{k}_std"] = float(per_seed[k].std(ddof=1)) if len(per_seed) > 1 else 0.0
    return pd.concat([*points, per_seed, pd.DataFrame([mean])], ignore_index=True).reindex(columns=list(COLUMNS))


def write_tsne(table: pd.DataFrame, title: str, out_png: Path) -> None:
    """One t-SNE panel per seed, its scores in its title, the mean +- std in
    the figure's; writes the PNG and `table` beside it."""
    seeds = table[table["row"] == "seed"]
    mean = table[table["row"] == "mean"].iloc[0]
    classes = mean["classes"].split(" ")
    fig, axes = plt.subplots(1, len(seeds), figsize=(max(3.8 * len(seeds), 7.0), 4.6), squeeze=False)
    for ax, s in zip(axes[0], seeds.itertuples()):
        points = table[(table["row"] == "point") & (table["seed"] == s.seed)]
        for colour, cls in zip(("tab:blue", "tab:orange", "tab:green"), classes):
            p = points[points["class"] == cls]
            ax.scatter(p["tsne_1"], p["tsne_2"], s=14, color=colour, label=cls, alpha=0.8)
        ax.set_title(
            f"seed {int(s.seed)}: {NEIGHBOURS}-NN accuracy {s.knn_accuracy:.2f}, silhouette {s.silhouette:.2f}\n({int(s.n_samples)} unseen test samples)",
            fontsize=8,
        )
        ax.set_xlabel("t-SNE 1 (arbitrary units)")
        ax.set_ylabel("t-SNE 2 (arbitrary units)")
        ax.legend(fontsize=7, title="class", title_fontsize=7)
    n = int(mean["n_seeds"])
    fig.suptitle(
        f"{title}\nseparability in the 32-D embedding, mean +- std over {n} seed{'s' if n != 1 else ''}:\n"
        f"{NEIGHBOURS}-NN accuracy {mean['knn_accuracy']:.2f} +- {mean['knn_accuracy_std']:.2f} (chance {mean['chance']:.2f}), "
        f"silhouette {mean['silhouette']:.2f} +- {mean['silhouette_std']:.2f} (0: overlapping)",
        fontsize=8,
    )
    fig.tight_layout()
    save_figure(fig, out_png, table)
