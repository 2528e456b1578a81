"""Tables and figures of the paper, built from the pipeline's outputs."""
