"""Sim-to-real transforms (rules/fit.smk): scale, blur and noise fitted from digital twins to captures."""
