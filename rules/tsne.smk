# Figs 13 and 14 (experiments/tsne.py): t-SNE of the random-split benchmark
# model's (train.benchmark_model) shape cells' penultimate-layer embeddings at 3x3 and 8x8, with the classes'
# separability in the embedding space.

TSNE_RESOLUTION = {"fig13": "3x3", "fig14": "8x8"}


rule tsne:
    input:
        models=lambda w: run_files([BENCHMARK_MODEL], ["shape"], ["random"], "model.pt", TSNE_RESOLUTION[w.fig]),
        metrics=lambda w: run_files([BENCHMARK_MODEL], ["shape"], ["random"], "metrics.json", TSNE_RESOLUTION[w.fig]),
        x=lambda w: dataset_files(TSNE_RESOLUTION[w.fig])["x"],
        table=lambda w: dataset_files(TSNE_RESOLUTION[w.fig])["table"],
    output:
        png=report("results/{fig}.png", caption="../report/tsne.rst", category="7. Embeddings"),
        csv="results/{fig}.csv",
    log:
        "logs/{fig}.log",
    benchmark:
        "benchmarks/{fig}.tsv"
    wildcard_constraints:
        fig="fig13|fig14",
    threads: config["train"]["threads"]
    params:
        runs=lambda w, input: [Path(p).parent for p in input.models],
        seed=config["seed"],
        title=lambda w: shlex.quote(
            f"t-SNE of the {BENCHMARK_LABEL} shape classifier's penultimate layer ({TSNE_RESOLUTION[w.fig]}, random split, {TRAIN['protocol']} protocol)"
        ),
    shell:
        "{DENALI} tsne {params.runs} --dataset {input.x} --table {input.table} --seed {params.seed} --title {params.title}"
        " --threads {threads} --out {output.png} > {log} 2>&1"
