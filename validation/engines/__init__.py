"""Engine adapters: the protocol (``base``), the registry, the parity gate, and one
sub-package per engine."""
