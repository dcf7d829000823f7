"""MuJoCo behind the adapter protocol: ``mjcf`` writes the model, ``adapter`` runs it."""
