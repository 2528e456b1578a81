# Training cells: one job per model x task x split x resolution x protocol x seed.
# A cell gets only its own settings as JSON, so changing one model's
# hyperparameters reruns only that model's cells and the tables.


rule train:
    input:
        x="results/datasets/{res}.zarr",
        table="results/datasets/{res}.parquet",
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
    shell:
        "{DENALI} train {input.x} --table {input.table} --cell {params.cell} --hyper {params.hyper} {params.factory}"
        " --validation-fraction {params.validation} {params.budget} --threads {threads} --precision {params.precision} --outdir {params.outdir} > {log} 2>&1"
