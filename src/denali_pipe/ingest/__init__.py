"""Ingestion (rules/ingest.smk): one raw capture set, release layout or pickle stream, into its Zarr store and index rows."""
