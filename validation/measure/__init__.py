"""Measuring one scene in one engine: run, record, check stability, compute metrics,
compare with tolerances."""
