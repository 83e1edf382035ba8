"""The built wheel: portable (abi3, manylinux2014, no instruction beyond x86-64-v1 in its native
library, no OpenCV), installable with pip into a fresh virtual environment without a Rust toolchain, and
its type stubs in step with the module."""

from __future__ import annotations

import ast
import os
import re
import shutil
import subprocess
import venv
import zipfile
from pathlib import Path

import pytest

import quadric_slam
from quadric_slam import _quadric_slam

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def wheel() -> Path:
    given = os.environ.get("QUADRIC_SLAM_WHEEL")
    if given:
        return Path(given)
    wheels = sorted((REPO / "target" / "wheels").glob("quadric_slam-*.whl"), key=lambda p: p.stat().st_mtime)
    if not wheels:
        pytest.fail("no wheel: build it with bash tools/wheel.sh (or set QUADRIC_SLAM_WHEEL)")
    return wheels[-1]


@pytest.fixture(scope="module")
def native_library(wheel, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    with zipfile.ZipFile(wheel) as z:
        names = [n for n in z.namelist() if n.endswith(".so")]
        assert names == ["quadric_slam/_quadric_slam.abi3.so"], names
        z.extract(names[0], out)
    return out / names[0]


def test_tags_say_abi3_and_manylinux2014(wheel):
    assert re.fullmatch(r"quadric_slam-[0-9.]+-cp39-abi3-manylinux2014_x86_64\.manylinux_2_17_x86_64\.whl", wheel.name)
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    for part in ("__init__.py", "results.py", "fleet.py", "_quadric_slam.pyi", "py.typed"):
        assert f"quadric_slam/{part}" in names, part


def test_no_instruction_beyond_x86_64_v1(native_library):
    """No AVX or AVX-512 register anywhere in the disassembly (a runtime-dispatched kernel would show)."""
    objdump = shutil.which("objdump")
    assert objdump is not None, "objdump (binutils) is needed for this test"
    text = subprocess.run([objdump, "-d", "--no-show-raw-insn", str(native_library)], capture_output=True, text=True, check=True).stdout
    assert len(text) > 100_000  # a real disassembly
    wide = [line for line in text.splitlines() if re.search(r"%[yz]mm\d", line)]
    assert not wide, f"{len(wide)} instructions use AVX/AVX-512 registers, e.g. {wide[:3]}"


def test_links_the_c_library_only(native_library):
    text = subprocess.run(["objdump", "-p", str(native_library)], capture_output=True, text=True, check=True).stdout
    needed = set(re.findall(r"NEEDED\s+(\S+)", text))
    assert needed <= {"libc.so.6", "libm.so.6", "libpthread.so.0", "libdl.so.2", "ld-linux-x86-64.so.2", "libgcc_s.so.1", "librt.so.1"}, needed
    assert not any("opencv" in n or "python" in n for n in needed)
    versions = re.findall(r"GLIBC_(\d+)\.(\d+)", subprocess.run(["objdump", "-T", str(native_library)], capture_output=True, text=True, check=True).stdout)
    assert max((int(a), int(b)) for a, b in versions) <= (2, 17)


def test_installs_into_a_fresh_venv_without_rust(wheel, tmp_path):
    env_dir = tmp_path / "fresh"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    python = env_dir / "bin" / "python"
    # no cargo, rustc or build tools on the PATH: a binary wheel needs none
    clean = dict(os.environ, PATH=f"{env_dir / 'bin'}:/usr/bin:/bin")
    clean.pop("CARGO_HOME", None)
    clean.pop("RUSTUP_HOME", None)
    done = subprocess.run([str(python), "-m", "pip", "install", "-q", "--only-binary=:all:", str(wheel)], env=clean, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    code = (
        "import numpy as np, quadric_slam as qs;"
        "c = qs.Camera.from_intrinsics(700.0, 700.0, 600.0, 180.0);"
        "e = qs.Ellipsoid.from_centre([0, 0, 20], [2, 1, 1]);"
        "b = qs.project(e, c).clipped_bounds((1200, 360));"
        "print(qs.__file__, b.round(3).tolist())"
    )
    ran = subprocess.run([str(python), "-c", code], env=clean, capture_output=True, text=True, cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    here = quadric_slam.project(
        quadric_slam.Ellipsoid.from_centre([0, 0, 20], [2, 1, 1]), quadric_slam.Camera.from_intrinsics(700.0, 700.0, 600.0, 180.0)
    ).clipped_bounds((1200, 360))
    assert str(env_dir) in ran.stdout and str(here.round(3).tolist()) in ran.stdout


def test_stubs_name_everything_the_module_has():
    stub = ast.parse((Path(quadric_slam.__file__).with_name("_quadric_slam.pyi")).read_text())
    declared = {}
    for node in stub.body:
        if isinstance(node, ast.ClassDef):
            declared[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)} - {"__init__"}
        elif isinstance(node, ast.FunctionDef):
            declared[node.name] = set()
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            declared[node.target.id] = set()
    public = {n for n in dir(_quadric_slam) if not n.startswith("_") or n == "__version__"}
    assert public == set(declared), (public ^ set(declared))
    for name, members in declared.items():
        obj = getattr(_quadric_slam, name)
        if isinstance(obj, type) and not issubclass(obj, Exception):
            actual = {m for m in dir(obj) if not m.startswith("_")}
            assert actual == members, f"{name}: {actual ^ members}"
