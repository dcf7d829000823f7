"""freeflight: bodies in free flight under gravity and constant loads, nothing else.

``declaration`` tells physval what the engine is and can do (imported by ``physval list``,
``check`` and spec parsing); ``adapter`` is the engine behind physval's adapter protocol
(imported only when a scene runs in it)."""
