"""numba's cache lives in a folder keyed by the sources (estimation.numba_cache): numba invalidates a
cached kernel by its own file's time stamp only, so a change in a callee's module would otherwise
leave the old compiled code running."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numba

from estimation import numba_cache


def _tree(root: Path, text: str) -> None:
    for pkg in numba_cache.PACKAGES:
        (root / pkg).mkdir(parents=True, exist_ok=True)
        (root / pkg / "__init__.py").write_text("")
    (root / "estimation" / "callee.py").write_text(text)


def test_any_source_change_selects_another_folder(tmp_path):
    _tree(tmp_path, "def f(x):\n    return x + 1\n")
    first = numba_cache.source_digest(tmp_path)
    assert numba_cache.source_digest(tmp_path) == first
    (tmp_path / "estimation" / "callee.py").write_text("def f(x):\n    return x + 2\n")
    assert numba_cache.source_digest(tmp_path) != first
    (tmp_path / "estimation" / "callee.py").write_text("def f(x):\n    return x + 1\n")
    assert numba_cache.source_digest(tmp_path) == first  # the contents, not the time stamps
    (tmp_path / "control" / "new.py").write_text("")
    assert numba_cache.source_digest(tmp_path) != first  # a new file too


def test_the_packages_kernels_cache_in_the_digest_folder():
    assert numba_cache.CACHE_DIR is not None
    assert Path(numba.config.CACHE_DIR) == numba_cache.CACHE_DIR == numba_cache.cache_dir()
    assert numba_cache.CACHE_DIR.name == numba_cache.source_digest()
    from azimut_env.physics.kernels import step_kernel

    assert Path(step_kernel._cache._cache_path).is_relative_to(numba_cache.CACHE_DIR)


def test_a_fresh_process_writes_its_kernels_there_and_workers_agree(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("_AZIMUT_NUMBA") and k != "NUMBA_CACHE_DIR"}
    env["AZIMUT_CACHE_DIR"] = str(tmp_path)
    code = ("import os, numba, estimation.numba_cache as c; from estimation.kinematics import steering_from_lambda; "
            "import numpy as np; from estimation import RobotGeometry; "
            "steering_from_lambda(np.array([[0.0, 0.0, 1.0]]), RobotGeometry.azimut3()); "
            "print(c.CACHE_DIR); print(os.environ['NUMBA_CACHE_DIR'])")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    folder, inherited = out.split()
    assert Path(folder).parent == tmp_path / "numba" and folder == inherited
    assert list(Path(folder).rglob("*.nbi")), "no kernel cached in the digest folder"
    # a worker (the child of that process) keys its own folder from the same base, not a nested one
    env2 = dict(env, NUMBA_CACHE_DIR=folder, _AZIMUT_NUMBA_CACHE_SET=folder, _AZIMUT_NUMBA_CACHE_BASE=str(tmp_path))
    out2 = subprocess.run([sys.executable, "-c", "import estimation.numba_cache as c; print(c.CACHE_DIR)"], env=env2,
                          capture_output=True, text=True, check=True).stdout.strip()
    assert out2 == folder
    # a user's NUMBA_CACHE_DIR is the base
    env3 = dict(env, NUMBA_CACHE_DIR=str(tmp_path / "mine"))
    out3 = subprocess.run([sys.executable, "-c", "import estimation.numba_cache as c; print(c.CACHE_DIR)"], env=env3,
                          capture_output=True, text=True, check=True).stdout.strip()
    assert Path(out3).parent == tmp_path / "mine" / "numba"


def test_train_and_jobs_define_no_kernel():
    """The digest covers the packages that hold kernels; a kernel in ``train`` or ``jobs`` would need
    its package added to ``numba_cache.PACKAGES`` (numba used for anything else, such as capping its
    threads, is fine)."""
    import ast

    kernel_decorators = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "jitclass", "generated_jit", "overload",
                         "register_jitable", "overload_method", "intrinsic"}

    def name(node):
        node = node.func if isinstance(node, ast.Call) else node
        return node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")

    root = Path(numba_cache.__file__).resolve().parents[1]
    found = []
    for pkg in ("train", "jobs"):
        for path in (root / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and any(
                        name(d) in kernel_decorators for d in node.decorator_list):
                    found.append(f"{path.relative_to(root)}:{node.lineno}")
    assert not found, f"compiled kernels outside {numba_cache.PACKAGES}: {found}"
