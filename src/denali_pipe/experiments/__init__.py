"""One module per experiment beyond the benchmark cells: its computation, called by a thin `denali` verb; its rules live in rules/<name>.smk."""
