"""The workflow's face to Snakemake: the merged config, the paper's targets, the per-rule cost models, the scheduler's timer."""
