"""Shared fixtures of the Python tests (run by tools/test.sh against the installed wheel).

They need the repository (fixtures/, the oracle vectors), the Rust side of the oracle comparison
(``$ORACLE_VALUES``, else cargo builds it) and a built slam-app: ``$SLAM_APP``, else
``target/release/slam-app``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]


def slam_app_path() -> Path:
    given = os.environ.get("SLAM_APP")
    path = Path(given) if given else REPO / "target" / "release" / "slam-app"
    if not path.is_file():
        pytest.fail(f"{path}: no slam-app (build it with cargo build --release -p slam-app, or set SLAM_APP)")
    return path


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture(scope="session")
def oracle() -> dict:
    with open(REPO / "fixtures" / "oracle" / "quadric_vectors.json", encoding="utf-8") as f:
        return json.load(f)


@pytest.fixture(scope="session")
def rust_values(tmp_path_factory) -> dict:
    """The geometry crate's own values on the oracle's inputs (its example oracle_values): the executable
    named by ``$ORACLE_VALUES`` (tools/test.sh passes the one its cargo test built, so that the crate is not
    built a second time with other features), else built and run by cargo."""
    out = tmp_path_factory.mktemp("rust") / "values.json"
    given = os.environ.get("ORACLE_VALUES")
    if given:
        if not (Path(given).is_file() and os.access(given, os.X_OK)):
            pytest.fail(f"ORACLE_VALUES={given}: not an executable")
        command = [given, str(out)]
    else:
        cargo = shutil.which("cargo")
        if cargo is None:
            pytest.fail("cargo not found: the oracle comparison runs the Rust side with it")
        command = [cargo, "run", "--release", "-q", "-p", "slam-quadric", "--example", "oracle_values", "--", str(out)]
    subprocess.run(command, cwd=REPO, check=True)
    with open(out, encoding="utf-8") as f:
        return json.load(f)


@pytest.fixture(scope="session")
def slam_app() -> Path:
    return slam_app_path()


@pytest.fixture(scope="session")
def main_job(tmp_path_factory, slam_app) -> Path:
    """The main job's output (tools/run.sh without the overlays): slam-app run on the shipped odometry
    excerpt with the shipped detector."""
    out = tmp_path_factory.mktemp("main") / "run"
    done = subprocess.run(
        [str(slam_app), "run", "--out", str(out)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert done.returncode == 0, done.stderr[-2000:]
    (out.parent / "stdout.txt").write_text(done.stdout)
    return out
