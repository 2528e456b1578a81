"""The capture explorer (`denali explore`): a Dash app over the workflow's
outputs, read only.

- `outputs`: what results/ holds, what is missing and the `snakemake`
  target that builds it;
- `capture`: one capture's arrays (frame, raw and background histograms,
  features, twin) and the calibration's geometry;
- `predictions`: training cells loaded on demand, their outputs for one
  capture and their per-location test error;
- `figures`: the Plotly figures, from plain arrays;
- `app`: the Dash layout and callbacks.
"""
