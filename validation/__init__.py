"""physval's harness: scenarios, engine adapters, measuring, jobs and reports (see docs/architecture.md)."""
