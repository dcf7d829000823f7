"""mini_engine behind the adapter protocol."""
