"""The README's Python examples run as printed: the geometry one, and the plotting one on the main job's output."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
import numpy as np

import quadric_slam as qs

matplotlib.use("Agg")

README = Path(__file__).resolve().parents[3] / "README.md"


def example(name: str) -> str:
    """The README's Python block marked as tested here under `name`."""
    text = README.read_text()
    found = re.search(
        r"<!-- tested by crates/slam-py/tests/test_readme\.py: " + name + r" -->\n```python\n(.*?)```", text, re.S
    )
    assert found, f"the README's tested example '{name}' is gone"
    return found[1]


def test_the_readme_geometry_example_runs_and_finds_the_car(capsys):
    scope: dict = {}
    exec(compile(example("geometry"), "README.md", "exec"), scope)
    # the single box: around the car's projected centre, inside the image, and below the principal
    # point's row 172.9 (the car's top is 0.1 m below the camera's axis, y down)
    box = scope["box"]
    u, v = scope["camera"].project_point(scope["car"].centre)
    assert box.shape == (4,)
    assert 0 <= box[0] < u < box[2] <= 1242 and 172.9 < box[1] < v < box[3] <= 375
    # the batch: one box per pose, each the same as projecting that ellipsoid alone
    boxes, poses = scope["boxes"], scope["poses"]
    assert boxes.shape == (50, 4)
    for k in (0, 25, 49):
        one = qs.project(qs.Ellipsoid(poses[k], [2.1, 0.8, 0.85]), scope["camera"]).clipped_bounds((1242, 375))
        np.testing.assert_allclose(boxes[k], one, rtol=1e-12)
    # the initialiser comes back to the car within what the comment says
    found, car = scope["found"], scope["car"]
    assert qs.e_trans(found, car) < 0.25
    np.testing.assert_allclose(found.axes, car.axes, atol=0.1)
    printed = capsys.readouterr().out.split()
    assert float(printed[-1]) == qs.e_trans(found, car)


def test_the_readme_plot_example_runs(main_job, tmp_path, monkeypatch):
    code = example("plot")
    assert 'qs.load_run("out/run")' in code
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    exec(compile(code.replace('"out/run"', repr(str(main_job))), "README.md", "exec"), {})
    png = tmp_path / "out" / "run.png"
    assert png.is_file() and png.stat().st_size > 20_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
