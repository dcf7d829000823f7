"""Rapier (rapier3d) adapter: ``declaration`` (no engine import) and ``adapter``."""
