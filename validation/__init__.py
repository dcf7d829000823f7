"""physval validation layer: scenarios, engine adapters, metrics, reports (later issues)."""
