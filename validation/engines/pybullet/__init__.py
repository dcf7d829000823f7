"""PyBullet behind the adapter protocol: ``pair_fit`` maps pair values to per-body values,
``adapter`` runs it."""
