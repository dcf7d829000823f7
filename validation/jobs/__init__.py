"""Jobs: planning what to run, the executor that runs it, and one module per command."""
