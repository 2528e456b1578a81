# The DENALI release's 15 trained generalisation networks (experiments/release_models.py,
# docs/release_models.md): their files (config release_models), then each scored on its
# own test part of the run's 3x3 captures, read as the `paper` protocol reads them
# (raw counts of every repeat, rule paper_dataset).

RELEASE_MODELS = config["release_models"]
# The datasets the networks are scored on: the base objects' and each held-out variant's, at 3x3.
RELEASE_DATASETS = {"base": "3x3", **{v: f"{v}_3x3" for v in HELD_OUT}}


def release_weights_files(wildcards):
    """A configured local copy's files where it holds them all (the job then
    reruns when one changes); else nothing, and the job says what it found."""
    folder = RELEASE_MODELS["weights"]
    files = [] if folder is None else [Path(folder) / name for name in RELEASE_FILES]
    return [str(f) for f in files] if files and all(f.is_file() for f in files) else []


def release_weights_args():
    folder, url = RELEASE_MODELS["weights"], RELEASE_MODELS["url"]
    args = [] if folder is None else ["--folder", shlex.quote(folder)]
    return " ".join(args + (["--url", shlex.quote(url)] if RELEASE_MODELS["download"] else []))


def release_model_datasets():
    """{base | variant: paper dataset} of the datasets the run has 3x3 captures for."""
    captured = {CATALOGUE[s.object].variant for s in SETS if s.resolution == "3x3" and not s.is_background}
    return {name: dataset for name, dataset in RELEASE_DATASETS.items() if name in captured}


def release_models_inputs(wildcards):
    files = {"weights": "results/release_weights"}
    for name, dataset in release_model_datasets().items():
        paper = dataset_files(dataset, "paper")
        files[f"{name}_x"], files[f"{name}_table"] = paper["x"], paper["table"]
    return files


# The download runs where the workflow runs: cluster nodes may have no network.
localrules:
    release_weights,


rule release_weights:
    input:
        release_weights_files,
    output:
        directory("results/release_weights"),
    log:
        "logs/release_weights.log",
    params:
        args=lambda w: release_weights_args(),  # a function: the URL's {commit} and {path} are no wildcards
    shell:
        "{DENALI} release-weights {params.args} --out {output} > {log} 2>&1"


rule release_models:
    input:
        unpack(release_models_inputs),
    output:
        "results/release_models.csv",
    log:
        "logs/release_models.log",
    benchmark:
        "benchmarks/release_models.tsv"
    params:
        datasets=lambda w, input: " ".join(f"--{name} {input[name + '_x']} {input[name + '_table']}" for name in release_model_datasets()),
    shell:
        "{DENALI} release-models --weights {input.weights} {params.datasets} --out {output} > {log} 2>&1"
