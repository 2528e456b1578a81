"""Readers for the release layout and raw capture streams."""
