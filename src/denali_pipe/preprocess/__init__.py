"""Preprocessing (rules/preprocess.smk): temporal alignment, background subtraction, cropping and normalisation of histograms."""
