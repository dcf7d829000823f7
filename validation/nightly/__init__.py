"""The nightly validation run's bookkeeping: known findings, baselines, history, comparisons.

Rows come from ``results.csv`` (or the comparator's row dicts); nothing here runs an engine.
"""
