"""The README's plotting example runs as printed, on the main job's output."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

README = Path(__file__).resolve().parents[3] / "README.md"


def test_the_readme_plot_example_runs(main_job, tmp_path, monkeypatch):
    text = README.read_text()
    found = re.search(r"<!-- tested by crates/slam-py/tests/test_readme\.py -->\n```python\n(.*?)```", text, re.S)
    assert found, "the README's tested example is gone"
    code = found[1]
    assert 'qs.load_run("out/run")' in code
    monkeypatch.chdir(tmp_path)
    exec(compile(code.replace('"out/run"', repr(str(main_job))), "README.md", "exec"), {})
    png = tmp_path / "run.png"
    assert png.is_file() and png.stat().st_size > 20_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
