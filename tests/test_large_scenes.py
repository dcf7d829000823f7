"""Scenes of 10,000+ bodies can be written and loaded.

The value cap scales with the file-size cap (``yaml_source.BYTES_PER_VALUE``): a file of
plain values, however many bodies it lists, stays under ``MAX_VALUES`` as long as it is under
``MAX_BYTES``; only aliases can expand past it (the billion-laughs test in
test_scenario_loader.py)."""

from __future__ import annotations

from validation.scenario import load_scenario, yaml_source

BODIES = 12_600
"""The issue's scene, which the old value cap refused."""


def write_grid(path, count: int) -> None:
    """``count`` spheres one per line (block style), the way a script writes a big scene."""
    lines = ["dt: 0.002", "duration: 0.3", "engines: [mini, mujoco, pybullet]", "ground: {}"]
    lines.append("bodies:")
    side = 100
    for k in range(count):
        i, j, layer = k % side, (k // side) % side, k // (side * side)
        lines.append(
            f"  - {{name: s{k}, shape: {{type: sphere, radius: 0.05}}, mass: 1.0, "
            f"position: [{0.11 * i:.2f}, {0.11 * j:.2f}, {0.1 + 0.11 * layer:.2f}], "
            "restitution: 0.5}"
        )
    path.write_text("\n".join(lines) + "\n")


def test_a_12600_body_scene_loads_and_its_values_scale_with_its_bytes(tmp_path, monkeypatch):
    path = tmp_path / "grid.yaml"
    write_grid(path, BODIES)
    size = path.stat().st_size
    assert size < yaml_source.MAX_BYTES
    # the cap this file's own size would have: a file of plain values is under it at any size
    monkeypatch.setattr(yaml_source, "MAX_VALUES", size // yaml_source.BYTES_PER_VALUE)
    scenario = load_scenario(path)
    assert len(scenario.bodies) == BODIES
    assert scenario.bodies[-1].name == f"s{BODIES - 1}"
    assert scenario.bodies[-1].position == (10.89, 2.75, 0.21)


def test_a_20000_body_scene_can_be_written_under_the_size_cap(tmp_path):
    path = tmp_path / "grid.yaml"
    write_grid(path, 20_000)
    size = path.stat().st_size
    assert size < yaml_source.MAX_BYTES / 2, size
    assert size // yaml_source.BYTES_PER_VALUE <= yaml_source.MAX_VALUES
