"""The reference side: the closed forms the engines are judged against, written out here.

Solid-shape mass properties (``mass_properties``), the spring-damper and constant load laws
and the spring energy on the scene's own spring list (``loads``), quaternion algebra
(``rotation``) and the Newton–Euler motion integrated by SciPy's DOP853 (``newton_euler``).
Nothing here imports ``mini_engine``, the engine under test, so a mistake in its formulas
cannot move the values it is judged against (``tests/test_architecture.py`` checks this).
"""
