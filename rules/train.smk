# Training cells: one job per model x task x split x resolution x protocol x seed.
# A cell gets only its own settings as JSON, so changing one model's
# hyperparameters reruns only that model's cells and the tables. `clean` cells
# read the preprocessed features' datasets; `paper` cells the raw counts of the
# capture stores, as the reference trains (paper_dataset; dataset_files).


rule train:
    input:
        x=lambda w: dataset_files(w.res, w.protocol)["x"],
        table=lambda w: dataset_files(w.res, w.protocol)["table"],
        release_weights=release_weights_input,
    output:
        metrics=f"{RUN_DIR}/metrics.json",
        curves=f"{RUN_DIR}/curves.csv",
        model=f"{RUN_DIR}/model.pt",
    log:
        f"logs/{RUN_DIR}.log",
    benchmark:
        f"benchmarks/{RUN_DIR}.tsv"
    threads: config["train"]["threads"]
    resources:
        gpu=request_gpus,
        runtime=request_runtime("train"),
        mem_mb=request_mem_mb("train"),
    params:
        cell=cell_arg,
        hyper=hyper_arg,
        factory=factory_arg,
        outdir=lambda w, output: Path(output.metrics).parent,
        validation=config["train"]["validation_fraction"],
        budget=budget_arg,
        precision=config["train"]["precision"],
        time_axis=cell_time_axis_arg,
        release_weights=lambda w, input: f"--release-weights {input.release_weights}" if input.release_weights else "",
    shell:
        "{DENALI} train {input.x} --table {input.table} --cell {params.cell} --hyper {params.hyper} {params.factory}"
        " --validation-fraction {params.validation} {params.budget} --threads {threads} --precision {params.precision} {params.time_axis}"
        " {params.release_weights}"
        " --outdir {params.outdir} > {log} 2>&1"


rule paper_dataset:
    input:
        stores=lambda w: [store(name) for name in paper_dataset_sets(w.dataset)[0]],
        positions="results/calibration/tag1_positions.parquet",
        sheet=config["objects_sheet"],
    output:
        x=directory(f"results/{DATASET_DIRS['paper']}/{{dataset}}.zarr"),
        table=f"results/{DATASET_DIRS['paper']}/{{dataset}}.parquet",
    log:
        "logs/datasets/paper/{dataset}.log",
    wildcard_constraints:
        dataset=rf"(({'|'.join(HELD_OUT)})_)?(3x3|8x8)",
    params:
        variant=lambda w: paper_dataset_sets(w.dataset)[1],
    shell:
        "{DENALI} paper-dataset {input.stores} --variant {params.variant} --positions {input.positions} --objects-sheet {input.sheet}"
        " --out {output.x} --table {output.table} > {log} 2>&1"
